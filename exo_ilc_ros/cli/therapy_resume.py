"""``exo-ilc run --patient ... --store DIR --resume [SESSION]``: which unfinished therapy
session a resume continues, said exactly.

A graph session records its session id (``session``, printed by the run and in the resume
command it prints when it stops) and its run store (``run_store``) in every version it begins.
``--resume SESSION`` continues the versions of that session (or ``--resume vN``: version N of
the one exercise); a bare ``--resume`` continues the only unfinished session whose run store is
``--store DIR``. When several could match and nothing says which, or none does, it is refused
with each unfinished session listed and the exact command that resumes it. Exercises of the
session already complete are skipped; those it had not begun yet start as a new session would.
"""

from __future__ import annotations

import argparse
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..analysis.wording import count_phrase
from ..core.errors import ProfileError
from ..core.params.config import Config
from ..core.persistence.profiles import ProfileBook
from .arguments import shown_command

if TYPE_CHECKING:
    from ..core.programs.therapy import PreparedExercise
    from ..core.session.summary import RunSummary

RUN_STORE = "run_store"
"""The index entry's key of the run store a graph session saves its trials in (None: an
in-process session, which keeps none and cannot be resumed through the graph)."""


@dataclass(frozen=True)
class Unfinished:
    """One version a session left unfinished."""

    exercise: str
    entry: dict[str, Any]

    @property
    def key(self) -> str:
        """What ``--resume`` accepts for it: the session id, else ``vN``."""
        return str(self.entry.get("session") or f"v{self.entry['version']}")

    def describe(self) -> str:
        """``exercise vN (status, trials, from vM, begun DATE)``."""
        e = self.entry
        start = "zero" if e.get("started_from") is None else f"v{e['started_from']}"
        return (f"{self.exercise} v{e['version']} ({e.get('status')}, "
                f"{count_phrase(e.get('trials', 0), 'trial')}, from {start}, begun "
                f"{e.get('created', '?')})")


@dataclass
class Step:
    """One exercise of a resumed session: run it (``reopen``: the version it continues, None:
    a new one) or skip it (``done``: its complete version; ``prepared`` as it was run)."""

    name: str
    trials: int | None
    prepared: PreparedExercise
    reopen: int | None = None
    done: dict[str, Any] | None = None


def unfinished(book: ProfileBook, patient: str, exercises: list[str]) -> list[Unfinished]:
    """Every version of the exercises not complete, in the order of the exercises and
    versions."""
    found: list[Unfinished] = []
    for name in exercises:
        index = book.index(patient, name)
        for entry in [] if index is None else index["versions"]:
            if entry.get("status") != "complete":
                found.append(Unfinished(name, dict(entry)))
    return found


def resume_command(argv: list[str], store: str, key: str, program: str = "") -> str:
    """The exact command resuming session ``key``: ``argv`` without --resume [value],
    --store DIR and --new-patient (the patient has a profile now), then --store and
    --resume ``key``; ``program`` is how to type exo-ilc here (default: ``shown_command()``)."""
    kept: list[str] = []
    skip = False
    for i, arg in enumerate(argv):
        if skip:
            skip = False
            continue
        if arg in ("--store", "--resume"):
            following = argv[i + 1] if i + 1 < len(argv) else None
            skip = arg == "--store" or (following is not None and not following.startswith("-"))
            continue
        if arg.startswith(("--store=", "--resume=")) or arg == "--new-patient":
            continue
        kept.append(arg)
    return (program or shown_command()) + " " + shlex.join([*kept, "--store", store, "--resume",
                                                             key])


def _listing(found: list[Unfinished], argv: list[str], store: Path) -> str:
    lines: list[str] = []
    for key in dict.fromkeys(u.key for u in found):
        mine = [u for u in found if u.key == key]
        stores = {u.entry.get(RUN_STORE, str(store)) for u in mine}
        where = next(iter(stores))
        lines.append(f"  session {key}: " + ", ".join(u.describe() for u in mine))
        if where is None:
            lines.append("    began in-process (exo-ilc simulate): no run store, not resumable; "
                         "its trials are in the profile")
        else:
            lines.append(f"    {resume_command(argv, str(where), key)}")
    return "\n".join(lines)


def choose_session(book: ProfileBook, patient: str, exercises: list[str], wanted: str | None,
                   store: Path, argv: list[str]) -> str:
    """The session ``--resume`` continues (module docstring); ProfileError listing the
    unfinished sessions and how to resume each when it is not said unambiguously."""
    found = unfinished(book, patient, exercises)
    if wanted is not None:
        if wanted.startswith("v") and wanted[1:].isdigit():
            if len(exercises) != 1:
                raise ProfileError(f"--resume {wanted}: a version number names one exercise's "
                                   "session; with several exercises give the session id")
            version = int(wanted[1:])
            index = book.require_index(patient, exercises[0])
            if not 1 <= version <= len(index["versions"]):
                raise ProfileError(f"--resume {wanted}: patient {patient!r} has no version "
                                   f"{version} of {exercises[0]!r}")
            return str(index["versions"][version - 1].get("session") or wanted)
        if not _versions_of(book, patient, exercises, wanted):
            raise ProfileError(f"--resume {wanted}: no session {wanted} of patient {patient!r} "
                               f"in {', '.join(exercises)}" + _unfinished_text(found, argv, store))
        return wanted
    mine = [u for u in found if u.entry.get(RUN_STORE, str(store)) == str(store)]
    keys = list(dict.fromkeys(u.key for u in mine))
    if len(keys) == 1:
        return keys[0]
    if not found:
        raise ProfileError(f"--resume: patient {patient!r} has no unfinished session of "
                           f"{', '.join(exercises)}; drop --resume to begin a new one")
    if len(keys) > 1:
        raise ProfileError(f"--resume: {len(keys)} unfinished sessions of patient {patient!r} "
                           f"saved their trials in {store}; say which to continue:\n"
                           + _listing(mine, argv, store))
    raise ProfileError(f"--resume: no unfinished session of patient {patient!r} saved its "
                       f"trials in {store}" + _unfinished_text(found, argv, store))


def _unfinished_text(found: list[Unfinished], argv: list[str], store: Path) -> str:
    if not found:
        return "; there is no unfinished session"
    return "; the unfinished ones:\n" + _listing(found, argv, store)


def _versions_of(book: ProfileBook, patient: str, exercises: list[str],
                 key: str) -> dict[str, dict[str, Any]]:
    """Exercise -> the version session ``key`` began of it."""
    out: dict[str, dict[str, Any]] = {}
    for name in exercises:
        index = book.index(patient, name)
        for entry in [] if index is None else index["versions"]:
            if str(entry.get("session") or f"v{entry['version']}") == key:
                out[name] = dict(entry)
    return out


def stored_summary(step: Step, store: Path) -> RunSummary | None:
    """The report of an exercise its session completed before it was stopped (``step.done``),
    from the trials its run store holds, as the uninterrupted run reported it (None: the
    store no longer holds them)."""
    from ..core.persistence.store import RunStore
    from ..core.programs.metrics import config_metrics
    from ..core.reference.build import build_reference
    from ..core.session.result import RunResult
    from ..core.session.summary import RunSummary

    entry = step.done or {}
    cfg = step.prepared.config.replace({
        "max_trials": int(entry.get("trials") or 1), "store.directory": str(store),
        "patient.session": int(entry["version"])})
    stored = RunStore(store, cfg, build_reference(cfg)).load()
    if not stored:
        return None
    result = RunResult(float(cfg["mass_uncertainty"]), str(cfg["law"]),
                       float(cfg["error_bound"]), [s.record for s in stored])
    summary = RunSummary.from_result(result)
    metrics = [config_metrics(s.record, cfg).to_json() for s in stored]
    summary.extra["metrics"] = metrics
    summary.extra["therapy"] = {
        "patient": step.prepared.patient, "exercise": step.name,
        "profile_started_from": entry.get("started_from"),
        "profile_version": entry["version"], "patient_session": entry["version"],
        "metrics": metrics}
    return summary


def resumed_steps(args: argparse.Namespace, config: Config, book: ProfileBook,
                  plan: list[tuple[str, int | None]], store: Path) -> tuple[str, list[Step]]:
    """The session a resume continues and what it does with each exercise of the plan: a
    complete version skipped, an unfinished one continued from the version it began from
    (checked as a new start is), one not begun yet from the latest profile."""
    from ..core.programs.therapy import prepare
    names = [name for name, _ in plan]
    wanted = args.resume if isinstance(args.resume, str) else None
    key = choose_session(book, args.patient, names, wanted, store, list(args.argv))
    versions = _versions_of(book, args.patient, names, key)
    steps: list[Step] = []
    for name, trials in plan:
        entry = versions.get(name)
        if entry is None:
            steps.append(Step(name, trials, prepare(config, book, args.patient, name)))
        elif entry.get("status") == "complete":
            steps.append(Step(name, trials, prepare_from(config, book, args.patient, name,
                                                         entry.get("started_from")),
                              done=entry))
        else:
            if RUN_STORE in entry and entry[RUN_STORE] is None:
                raise ProfileError(f"--resume {key}: {Unfinished(name, entry).describe()} began "
                                   "in-process (exo-ilc simulate), which keeps no run store: "
                                   "it cannot be resumed; its trials are in the profile")
            if RUN_STORE in entry and entry[RUN_STORE] != str(store):
                raise ProfileError(f"--resume {key}: {name} v{entry['version']} saved its "
                                   f"trials in {entry[RUN_STORE]}, not {store}:\n  "
                                   + resume_command(list(args.argv), entry[RUN_STORE], key))
            steps.append(Step(name, trials, prepare_from(config, book, args.patient, name,
                                                         entry.get("started_from")),
                              reopen=int(entry["version"])))
    return key, steps


def prepare_from(config: Config, book: ProfileBook, patient: str, exercise: str,
                 version: int | None) -> PreparedExercise:
    """The exercise prepared to start from profile version ``version`` (None: from zero), as
    :func:`.core.therapy.prepare` prepares it from the latest: the file checked (sha256), its
    model and reference against the config's."""
    from ..core.programs.therapy import PreparedExercise
    from ..core.reference.build import build_reference
    cfg = config.replace({"exercise.name": exercise, "profile.initial": ""})
    start = None
    if version is not None:
        reference = build_reference(cfg)
        start = book.load(patient, exercise, int(version))
        start.check_compatible(cfg, reference)
        cfg = cfg.replace({"profile.initial": str(start.path.resolve())})
    return PreparedExercise(patient, exercise, cfg, start)
