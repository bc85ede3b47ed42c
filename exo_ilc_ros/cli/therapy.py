"""``exo-ilc simulate --patient ID --exercise NAME ...``: a therapy session in-process, each
exercise starting from the patient's latest profile (core/programs/therapy.py)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..analysis.wording import count_phrase
from ..core.errors import ConfigError
from ..core.persistence.files import write_json_atomic
from ..core.persistence.profiles import ProfileBook
from .arguments import directory, nonempty, shown_command
from .progress import progress_bar
from .therapy_resume import Step, resume_command, resumed_steps, stored_summary

if TYPE_CHECKING:
    from ..core.programs.therapy import ExerciseResult
    from ..core.session.summary import RunSummary


def add_therapy_arguments(parser: argparse.ArgumentParser) -> None:
    """--patient, --exercise, --session, --profiles, --new-patient (simulate and run)."""
    group = parser.add_argument_group("therapy session (docs/therapy.md)")
    group.add_argument("--patient", metavar="ID", type=nonempty,
                       help="the patient: each exercise starts from their latest learned "
                       "profile and the session's is saved after every trial")
    group.add_argument("--exercise", metavar="NAME", nargs="+",
                       help="exercise(s) to run, --trials each (default: the config's "
                       "exercise.name; names from the exercises file)")
    group.add_argument("--session", metavar="PLAN", help="a session plan of the exercises file "
                       "(exercises and trials each) instead of --exercise")
    group.add_argument("--profiles", metavar="DIR", type=directory,
                       help="profiles root (default: $EXO_ILC_PROFILES or .exo-ilc/profiles)")
    group.add_argument("--new-patient", action="store_true",
                       help="the patient has no profile yet (a first session); without it an "
                       "unknown patient id is an error (a typo would start from zero)")


def uses_therapy(args: argparse.Namespace) -> bool:
    """True if any therapy flag was given (then --patient is required)."""
    given = [f for f in ("exercise", "session", "profiles") if getattr(args, f, None)]
    if given or getattr(args, "new_patient", False):
        if not args.patient:
            flag = "--" + (given[0].replace("_", "-") if given else "new-patient")
            raise ConfigError(flag, "needs --patient ID")
        return True
    return bool(getattr(args, "patient", None))


def plan_of(args: argparse.Namespace, config: Any) -> list[tuple[str, int | None]]:
    """(exercise, trials) in order: --session's plan, else --exercise (None: --trials or
    max_trials), else the config's exercise."""
    from ..core.reference.exercise import exercises_path, load_book
    if args.session and args.exercise:
        raise ConfigError("--session", "cannot be combined with --exercise")
    if args.session:
        book = load_book(exercises_path(config), config.joints)
        return [(item.exercise, item.trials) for item in book.session(args.session)]
    names = args.exercise or [config["exercise.name"]]
    if len(set(names)) != len(names):
        raise ConfigError("--exercise", f"names an exercise twice: {names}")
    return [(name, None) for name in names]


def simulate_session(args: argparse.Namespace, config: Any) -> tuple[list[ExerciseResult],
                                                                      list[RunSummary]]:
    """Check everything, then run every exercise; returns the results and their summaries."""
    from ..analysis.therapy import format_session_metrics
    from ..bag import run_name, unique_path, write_run
    from ..core.programs.divergences import add_divergences
    from ..core.programs.therapy import prepare, profiles_root, run_exercise, session_id
    from ..core.session.summary import RunSummary
    if args.mass_uncertainty and len(args.mass_uncertainty) > 1:
        raise ConfigError("--mass-uncertainty", "one value with --patient (one patient's arm)")
    if args.resume or args.store or args.replay:
        raise ConfigError("--patient", "cannot be combined with --store, --resume or --replay "
                          "(the profile is saved after every trial)")
    if args.mass_uncertainty:
        config = config.with_mass_uncertainty(args.mass_uncertainty[0])
    book = ProfileBook(profiles_root(args.profiles))
    plan = plan_of(args, config)
    prepared = [prepare(config, book, args.patient, name, args.new_patient)
                for name, _ in plan]  # every check before anything runs or is written
    session = session_id()
    results: list[ExerciseResult] = []
    runs: list[RunSummary] = []
    for order, (item, (name, trials)) in enumerate(zip(prepared, plan, strict=True), start=1):
        count = trials or item.config["max_trials"]
        start = "from zero" if item.start is None else \
            f"from profile v{item.start.version} ({item.start.provenance.get('trials_total')} " \
            "trials learned)"
        print(f"patient {args.patient}, exercise {name}: {count_phrase(count, 'trial')}, {start}",
              file=sys.stderr)
        with progress_bar(total=count, desc=f"{args.patient} {name}", unit="trial") as bar:
            def progress(record: Any, bar: Any = bar) -> None:
                bar.update(1)
                bar.set_postfix_str("max|e| " + " ".join(f"{x:.1e}"
                                                         for x in record.max_abs_error))
            done = run_exercise(item, book, count, on_trial=progress, session=session)
        results.append(done)
        summary = RunSummary.from_result(done.result)
        summary.extra["therapy"] = done.to_json()
        add_divergences(summary, done.result, done.config)
        if done.identified:
            summary.extra["identified"] = done.identified[-1].to_json()
        runs.append(summary)
        print(f"profile: {book.directory(args.patient, name)} v{done.version} (the patient's "
              f"session {done.config['patient.session']} of {name})", file=sys.stderr)
        stopped = bool(done.result.stop_message)
        if args.bag:
            path = unique_path(args.bag, run_name(f"sim_{args.patient}_{name}", done.result.law,
                                                  done.result.mass_uncertainty))
            write_run(path, done.config, done.result, metrics=done.metrics,
                      extra_custom_data=therapy_custom_data(done, session, order))
            print(f"bag: {path}", file=sys.stderr)
        if stopped:  # the session stops with the exercise (core/session/abort.py)
            _stopped_by_aborts(args.patient, plan[order:])
            break
    for done in results:
        print(format_session_metrics(done, list(done.config["joint_names"])))
        print()
    return results, runs


def therapy_custom_data(done: ExerciseResult, session: str, order: int) -> dict[str, str]:
    """The bag's custom data naming the patient, exercise (and its place ``order`` in the
    session), session and profile versions."""
    from ..analysis import session_report as keys
    return {keys.PATIENT: done.patient, keys.EXERCISE: done.exercise, keys.SESSION: session,
            keys.PROFILE_STARTED_FROM: str(done.started_from or ""),
            keys.PROFILE_VERSION: str(done.version or ""), keys.EXERCISE_ORDER: str(order)}


def run_session_graph(args: argparse.Namespace, config: Any, store_root: Path,
                      run_one: Callable[..., RunSummary]) -> list[RunSummary]:
    """``exo-ilc run --patient``: the same checks as in-process, then each exercise through
    the graph (the supervisor starts from the profile: ``profile.initial``). The profile is
    written from the run's store (every completed trial) when the graph ends, also when it
    was stopped, so a killed session keeps what it learned; it then prints the command that
    resumes exactly this session. ``--resume [SESSION]`` continues it (its unfinished
    versions, the same session numbers, so the same store keys: cli/therapy_resume.py)."""
    from ..core.programs.therapy import profiles_root, session_id
    from ..core.session.abort import ABORT_STOP_KEY
    book = ProfileBook(profiles_root(args.profiles))
    invocation = session_id()
    session, steps = _graph_steps(args, config, book, store_root, invocation)
    runs: list[RunSummary] = []
    for order, step in enumerate(steps, start=1):
        if step.done is not None:  # reported from its store, as the first run would have
            print(f"patient {args.patient}, exercise {step.name}: session {session}'s "
                  f"v{step.done.get('version')} is complete ({step.done.get('trials')} "
                  "trials); not run again", file=sys.stderr, flush=True)
            earlier = stored_summary(step, store_root)
            if earlier is not None:
                runs.append(earlier)
            continue
        summary = _exercise_through_graph(args, step, order, book, session, invocation,
                                          store_root, run_one)
        if summary is not None:
            runs.append(summary)
            if summary.extra.get(ABORT_STOP_KEY):  # the session stops with the exercise
                _stopped_by_aborts(args.patient, steps[order:])
                break
    return runs


def _graph_steps(args: argparse.Namespace, config: Any, book: ProfileBook, store_root: Path,
                 invocation: str) -> tuple[str, list[Step]]:
    """The session's id and its exercises (a resumed session's own), every check made
    before any node starts: one arm, no learning virtual patient, no store in the way."""
    from ..core.loop.patient import PatientModel
    from ..core.programs.therapy import prepare
    from ..core.session.learning_session import stored_trials
    if args.mass_uncertainty and len(args.mass_uncertainty) > 1:
        raise ConfigError("--mass-uncertainty", "one value with --patient (one patient's arm)")
    if args.mass_uncertainty:
        config = config.with_mass_uncertainty(args.mass_uncertainty[0])
    if PatientModel(config).learns:
        raise ConfigError("patient.learning.gain", "a learning virtual patient's therapy "
                          "sessions run in-process (exo-ilc simulate --patient): in the graph "
                          "its adaptation lives in the plant node, which neither starts from "
                          "the state stored with the profile nor resumes it")
    plan = plan_of(args, config)
    if args.resume:
        session, steps = resumed_steps(args, config, book, plan, store_root)
    else:
        session = invocation
        steps = [Step(name, trials, prepare(config, book, args.patient, name, args.new_patient))
                 for name, trials in plan]
    for step in steps:
        if step.done is not None:
            continue
        item = step.prepared
        version = step.reopen or book.next_version(args.patient, step.name, item.start)
        stored_trials(item.config.replace({
            "max_trials": step.trials or item.config["max_trials"],
            "store.directory": str(store_root), "patient.session": version}), args.resume)
    return session, steps


def _exercise_through_graph(args: argparse.Namespace, step: Step, order: int,
                            book: ProfileBook, session: str, invocation: str,
                            store_root: Path, run_one: Callable[..., RunSummary]
                            ) -> RunSummary | None:
    """One exercise of the session through the graph, its profile written from the store
    when the graph ends (also when it was stopped: the resume command is attached then)."""
    from ..core.persistence.store import RunStore
    from ..core.reference.build import build_reference
    from ..orchestration.launcher import GraphError
    name = step.name
    item = step.prepared
    count = step.trials or item.config["max_trials"]
    cfg = item.config.replace({"max_trials": count, "store.directory": str(store_root),
                               "store.resume": bool(args.resume)})
    reference = build_reference(cfg)
    # The version (the patient's session: its own noise) first, under the profile's lock;
    # a resume continues the very version the stopped run began (the store's key).
    writer = book.begin(args.patient, name, cfg, reference, item.start,
                        invocation if step.reopen else session,
                        reopen=step.reopen or False, run_store=str(store_root))
    cfg = writer.config
    start = "from zero" if item.start is None else f"from profile v{item.start.version}"
    again = f" (resuming v{writer.version})" if step.reopen else ""
    print(f"patient {args.patient}, exercise {name}: {count_phrase(count, 'trial')} through the "
          f"graph, {start}, session {writer.version}{again}, session id {session}, store "
          f"{store_root}", file=sys.stderr, flush=True)
    summary: RunSummary | None = None
    try:
        summary = run_one(args, cfg, cfg["mass_uncertainty"], count)
    except (GraphError, KeyboardInterrupt) as exc:  # run.py prints it with the error
        setattr(exc, "resume",  # noqa: B010 (an attribute GraphError does not declare)
                f"to continue this session exactly (v{writer.version} of {name}):\n  "
                + resume_command(list(args.argv), str(store_root), session,
                                 shown_command()))
        raise
    finally:
        stored = RunStore(store_root, cfg, reference).load()
        done = _profile_from_store(writer, cfg, stored, count)
        if done is not None and summary is not None:
            summary.extra["therapy"] = {"patient": args.patient, "exercise": name,
                                        "profile_started_from": None if item.start is None
                                        else item.start.version,
                                        "profile_version": writer.version,
                                        "patient_session": writer.version,
                                        "metrics": [m.to_json() for m in done]}
            bag = summary.extra.get("bag")
            if bag:
                _write_sidecar(Path(bag), args.patient, name, session,
                               item.start.version if item.start else None,
                               writer.version, order)
        if done is not None:
            print(f"profile: {writer.directory} v{writer.version} "
                  f"({count_phrase(len(done), 'trial')})", file=sys.stderr)
    return summary


def _profile_from_store(writer: Any, config: Any, stored: list[Any],
                        count: int) -> list[Any] | None:
    """Metrics of the stored trials and the profile version from the last one (None: no trial
    completed, nothing written)."""
    from ..core.programs.metrics import config_metrics
    from ..core.programs.therapy import IDENTIFICATION, identified_of_records

    if not stored:
        return None
    metrics = [config_metrics(s.record, config) for s in stored]
    last = stored[-1]
    filed = metrics[-1].to_json()
    identified = identified_of_records(config, [s.record for s in stored])
    if identified is not None:  # the version keeps the last estimate, as in-process
        filed[IDENTIFICATION] = identified.to_json()
    true_error = getattr(last.record, "true_max_abs_error", last.record.max_abs_error)
    writer.save(last.record.trial, last.next_update, true_error,
                complete=len(stored) >= count, metrics=filed)
    return metrics


SIDECAR = "therapy.json"
"""Beside a graph run's bag: patient, exercise, session and profile versions (the recorder
node does not know them)."""


def _write_sidecar(bag: Path, patient: str, exercise: str, session: str,
                   started_from: int | None, version: int, order: int) -> None:
    if bag.is_dir():
        write_json_atomic(bag / SIDECAR, {"patient": patient, "exercise": exercise,
                                          "session": session, "profile_started_from":
                                          started_from, "profile_version": version,
                                          "exercise_order": order})


def _stopped_by_aborts(patient: str, left: Sequence[Any]) -> None:
    """An exercise stopped by aborted trials ends the therapy session: the exercises ``left``
    are not run (each one's message is printed with the run's, exit 5)."""
    if left:
        print(f"patient {patient}: the session stops here (aborted trials in a row); "
              f"{count_phrase(len(left), 'exercise')} not run", file=sys.stderr)
