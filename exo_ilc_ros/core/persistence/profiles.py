"""Learned profiles: the feed-forward a patient's sessions learned for one exercise, kept from
session to session so that the next session starts where the last one ended.

Layout under the profiles root (``--profiles DIR``, default :func:`default_root`)::

    <root>/<patient>/<exercise>/index.json    versions, their provenance, the current one
    <root>/<patient>/<exercise>/v0001.npz     version 1: feedforward (N+1, joints), levels
    <root>/<patient>/<exercise>/v0001.patient-start.npz, v0001.patient.npz
                                              a learning virtual patient's states with it
                                              (:mod:`.patient_states`)

Each session writes one new version and rewrites it after every trial (status ``in_progress``;
``complete`` at the end), so a killed session leaves the feed-forward learned up to its last
completed trial. Versions are never deleted; ``rollback`` only moves ``current``. Every file is
written atomically (temp file, fsync, rename, as :mod:`.store`) and each version's sha256 is in
the index; a file that does not match is refused, never overwritten. A save keeps the file the
index lists as ``vNNNN.npz.previous`` until the index names the new one, so a save interrupted
between the two leaves the last completed trial readable (:mod:`.listed_files`).

Sessions of the same patient and exercise may run at once (two terminals, a study): every change
of the index (a version begun, a trial saved, a rollback) reads, changes and writes it under an
exclusive ``flock`` of ``<root>/<patient>/<exercise>/.lock`` (:func:`.files.locked`). A
session's version number is allocated there when it begins (an entry with status ``started``),
so a concurrent session gets the next number and never overwrites another's. A session that
started from version N while N+1.. were begun by others still writes its own version; its
provenance names them (``not_included``) and ``current`` moves to it only if no higher version
is current. The version number is also the session's number for the virtual patient
(``patient.session``: each session draws its own noise, :mod:`.patient`).

A profile is used only with the model and reference it was learned with: the nominal model and
the loop (:data:`.profile_format.MODEL_KEYS`) and the sampled reference (sha256 of its arrays).
The files' format is :mod:`.profile_format`, a session's writer :mod:`.profile_writer`. The
plant (the patient's arm, mass uncertainty, ...) is deliberately not part of it: it is what
changes between sessions. A mismatch is a :class:`ProfileError` naming what differs.
"""

from __future__ import annotations

import io
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ProfileError
from ..learning.laws import FeedforwardUpdate
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .files import _atomic, locked, write_bytes_atomic, write_json_atomic
from .patient_states import (
    START_FILE,
    START_KEY,
    STATE_KEY,
    PatientState,
    file_entry,
    read_state,
)
from .profile_format import (
    PROFILE_FORMAT,
    Profile,
    read_index,
    read_npz,
    reopenable,
    unfinished_entry,
)
from .profile_writer import ProfileWriter

ROOT_ENVIRONMENT = "EXO_ILC_PROFILES"
"""Beside the index: the file every index change of a patient's exercise is locked on."""


def default_root() -> Path:
    """``$EXO_ILC_PROFILES``, else ``.exo-ilc/profiles`` in the working directory (beside the
    run stores of ``exo-ilc run``)."""
    return Path(os.environ.get(ROOT_ENVIRONMENT) or Path(".exo-ilc") / "profiles")


def check_name(kind: str, name: str) -> str:
    """A patient id or exercise name usable as a directory: letters, digits, ``_``, ``-``."""
    if not name or not all(c.isalnum() or c in "_-" for c in name) or name.startswith("-"):
        raise ProfileError(f"{kind} {name!r}: use letters, digits, _ and - only")
    return name


class ProfileBook:
    """The profiles under one root: patients, their exercises, versions."""

    def __init__(self, root: Path | str | None = None) -> None:
        self.root = Path(root) if root is not None else default_root()

    def patients(self) -> list[str]:
        """Patient ids with at least one exercise profile."""
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir()
                      if p.is_dir() and any((e / "index.json").is_file() for e in p.iterdir()))

    def exercises(self, patient: str) -> list[str]:
        """Exercises patient ``patient`` has a profile for (ProfileError if unknown)."""
        self.require_patient(patient)
        return sorted(e.name for e in (self.root / patient).iterdir()
                      if (e / "index.json").is_file())

    def require_patient(self, patient: str) -> None:
        """ProfileError naming ``patient`` (and the known ones) if it has no profile here."""
        check_name("patient", patient)
        if patient not in self.patients():
            known = ", ".join(self.patients()) or "none"
            raise ProfileError(f"unknown patient {patient!r}: no profiles under {self.root} "
                               f"(known: {known})")

    def directory(self, patient: str, exercise: str) -> Path:
        """Where ``patient``'s profile of ``exercise`` lives."""
        return self.root / check_name("patient", patient) / check_name("exercise", exercise)

    def index(self, patient: str, exercise: str) -> dict[str, Any] | None:
        """The index of ``patient``'s profile of ``exercise`` (None if there is none);
        ProfileError for an unreadable or inconsistent index."""
        return read_index(self.directory(patient, exercise) / "index.json")

    def require_index(self, patient: str, exercise: str) -> dict[str, Any]:
        """The index, or ProfileError naming the unknown patient or exercise."""
        self.require_patient(patient)
        index = self.index(patient, exercise)
        if index is None:
            raise ProfileError(f"patient {patient!r} has no profile for exercise {exercise!r} "
                               f"(has: {', '.join(self.exercises(patient))})")
        return index

    def load(self, patient: str, exercise: str, version: int | None = None) -> Profile:
        """Version ``version`` (default: the current one) of the profile, sha256 checked (index
        and file read under the shared lock: a consistent pair while a session writes)."""
        with locked(self.directory(patient, exercise), shared=True):
            return self._load(patient, exercise, version)

    def _load(self, patient: str, exercise: str, version: int | None) -> Profile:
        index = self.require_index(patient, exercise)
        number = index["current"] if version is None else version
        if number is None or not 1 <= number <= len(index["versions"]):
            raise ProfileError(f"patient {patient!r}, exercise {exercise!r} has no version "
                               f"{number} (versions 1-{len(index['versions'])})")
        entry = index["versions"][number - 1]
        if "sha256" not in entry:
            raise ProfileError(f"patient {patient!r}, exercise {exercise!r}: version {number} "
                               f"holds no trial yet (status {entry.get('status')!r}: its "
                               "session is running, or stopped before its first trial)")
        path = self.directory(patient, exercise) / entry["file"]
        data = read_npz(path, entry["sha256"])
        levels = data.get("levels")
        state = entry.get(STATE_KEY)
        return Profile(patient, exercise, number, path, data["feedforward"],
                       levels if levels is not None and levels.size else None, dict(entry),
                       None if state is None else read_state(path.parent, state))

    def latest(self, patient: str, exercise: str) -> Profile | None:
        """The current version, or None if the patient has no profile for the exercise."""
        index = self.index(patient, exercise)
        if index is None or index["current"] is None:
            return None
        return self.load(patient, exercise)

    def rollback(self, patient: str, exercise: str, version: int) -> dict[str, Any]:
        """Make ``version`` the current one (its file checked first); nothing is deleted."""
        profile = self.load(patient, exercise, version)
        directory = self.directory(patient, exercise)
        with locked(directory):
            index = self.require_index(patient, exercise)
            index["current"] = profile.version
            write_json_atomic(directory / "index.json", index)
        return index

    def next_version(self, patient: str, exercise: str, started_from: Profile | None,
                     reopen: bool = False) -> int:
        """The version :meth:`begin` would allocate now (a look without the lock, for checks
        before anything starts; a concurrent session may take it meanwhile)."""
        index = self.index(patient, exercise)
        if index is None:
            return 1
        reopened = reopenable(index, started_from, self.directory(patient, exercise)) \
            if reopen else None
        return reopened or len(index["versions"]) + 1

    def begin(self, patient: str, exercise: str, config: Config, reference: SampledReference,
              started_from: Profile | None, session: str = "", reopen: bool | int = False,
              patient_start: PatientState | None = None,
              run_store: str | None = None) -> ProfileWriter:
        """The version of the session about to run, allocated under the lock (module
        docstring): the next number, its entry (status ``started``) written at once, so that
        a concurrent session takes the one after. ``reopen`` (a resumed run) continues an
        unfinished version instead: the one numbered ``reopen``, or with ``True`` the only
        unfinished one begun from ``started_from`` (ProfileError naming them if there are
        several, :func:`reopenable`); its config must be the one it began with (but
        ``store.resume``). ``patient_start``: a learning virtual patient's state the session
        starts from, written once beside the version (:mod:`.patient_states`). ``run_store``:
        the run store a graph session saves its trials in (None: in-process, none; recorded:
        what ``--resume`` looks for, cli/therapy_resume.py). The writer's ``config`` is
        ``config`` with ``patient.session`` = the version."""
        directory = self.directory(patient, exercise)
        directory.mkdir(parents=True, exist_ok=True)
        with locked(directory):
            index = self.index(patient, exercise) or {
                "format": PROFILE_FORMAT, "patient": patient, "exercise": exercise,
                "current": None, "versions": []}
            versions = index["versions"]
            reopened: int | None = None
            if reopen is True:
                reopened = reopenable(index, started_from, directory)
            elif reopen is not False:
                reopened = int(reopen)
            version = reopened or len(versions) + 1
            after = 0 if started_from is None else started_from.version
            not_included = [v["version"] for v in versions if after < v["version"] < version]
            writer = ProfileWriter(directory, version, config, reference, started_from,
                                   session, not_included)
            writer.base["run_store"] = run_store
            if reopened is not None:
                writer.reopen(unfinished_entry(index, reopened, directory), session)
            else:
                if patient_start is not None:
                    blob = patient_start.encode()
                    name = START_FILE.format(version=version)
                    write_bytes_atomic(directory / name, blob)  # not listed yet: no overwrite
                    writer.base[START_KEY] = file_entry(name, blob)
                index["versions"] = [*versions, {**writer.base, "status": "started",
                                                 "trials": 0,
                                                 "trials_total": writer.base["trials_before"]}]
                write_json_atomic(directory / "index.json", index)
        return writer


def export_profile(profile: Profile, path: Path | str) -> Path:
    """``profile`` to ``path``: ``.json`` (provenance and the feed-forward as lists) or
    ``.npz`` (the arrays and the provenance as JSON text); written atomically."""
    path = Path(path)
    if path.suffix == ".json":
        document = {"patient": profile.patient, "exercise": profile.exercise,
                    "version": profile.version, "provenance": profile.provenance,
                    "feedforward": profile.feedforward.tolist(),
                    "levels": None if profile.levels is None else profile.levels.tolist()}
        write_json_atomic(path, document)
    elif path.suffix == ".npz":
        buffer = io.BytesIO()
        np.savez(buffer, feedforward=profile.feedforward,
                 levels=np.empty((0,)) if profile.levels is None else profile.levels,
                 provenance=np.array(json.dumps(profile.provenance, sort_keys=True)))
        with _atomic(path) as handle:
            handle.write(buffer.getvalue())
    else:
        raise ProfileError(f"{path}: export to .json or .npz")
    return path


def load_initial(path: Path | str, config: Config,
                 reference: SampledReference) -> FeedforwardUpdate:
    """The first feed-forward of a session from a profile version file (``profile.initial``):
    its sha256 checked against the index beside it, its model and reference against
    ``config``'s (:meth:`Profile.check_compatible`)."""
    path = Path(path)
    with locked(path.parent, shared=True):
        return _load_initial(path, config, reference)


def _load_initial(path: Path, config: Config, reference: SampledReference) -> FeedforwardUpdate:
    index_path = path.parent / "index.json"
    try:
        index = json.loads(index_path.read_text())
        entry = next(v for v in index["versions"] if v["file"] == path.name)
    except (OSError, ValueError, KeyError, TypeError, StopIteration) as exc:
        raise ProfileError(f"{path}: not a profile version listed in {index_path} "
                           f"({type(exc).__name__}: {exc})") from None
    if "sha256" not in entry:
        raise ProfileError(f"{path}: version {entry.get('version')} holds no trial yet "
                           f"(status {entry.get('status')!r})")
    data = read_npz(path, entry["sha256"])
    levels = data.get("levels")
    profile = Profile(str(index.get("patient")), str(index.get("exercise")),
                      int(entry["version"]), path, data["feedforward"],
                      levels if levels is not None and levels.size else None, dict(entry))
    profile.check_compatible(config, reference)
    return profile.update
