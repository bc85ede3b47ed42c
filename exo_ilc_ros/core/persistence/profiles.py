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
exclusive ``flock`` of ``<root>/<patient>/<exercise>/.lock`` (:func:`locked`). A session's version
number is allocated there when it begins (an entry with status ``started``), so a concurrent
session gets the next number and never overwrites another's. A session that started from
version N while N+1.. were begun by others still writes its own version; its provenance names
them (``not_included``) and ``current`` moves to it only if no higher version is current. The
version number is also the session's number for the virtual patient (``patient.session``:
each session draws its own noise, :mod:`.patient`).

A profile is used only with the model and reference it was learned with: the nominal model
and the loop (:data:`MODEL_KEYS`) and the sampled reference (sha256 of its arrays). The plant
(the patient's arm, mass uncertainty, ...) is deliberately not part of it: it is what changes
between sessions. A mismatch is a :class:`ProfileError` naming what differs.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ProfileError
from ..learning.laws import FeedforwardUpdate
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .files import _atomic, locked, write_bytes_atomic, write_json_atomic
from .listed_files import read_listed, replace_keeping_listed
from .patient_states import (
    START_FILE,
    START_KEY,
    STATE_FILE,
    STATE_KEY,
    PatientState,
    file_entry,
    read_state,
)

PROFILE_FORMAT = 1
MODEL_KEYS = ("joint_names", "model.link_masses", "model.link_lengths", "model.radius_proximal",
              "model.radius_distal", "model.joint_axes", "model.gravity", "control.period",
              "control.kp", "control.kd")
"""What a feed-forward was learned *for*: the controller's nominal model and loop."""
ROOT_ENVIRONMENT = "EXO_ILC_PROFILES"
"""Beside the index: the file every index change of a patient's exercise is locked on."""
SESSION_KEY = "patient.session"
"""The config key a session's version number goes to (the virtual patient's session)."""


def default_root() -> Path:
    """``$EXO_ILC_PROFILES``, else ``.exo-ilc/profiles`` in the working directory (beside the
    run stores of ``exo-ilc run``)."""
    return Path(os.environ.get(ROOT_ENVIRONMENT) or Path(".exo-ilc") / "profiles")


def check_name(kind: str, name: str) -> str:
    """A patient id or exercise name usable as a directory: letters, digits, ``_``, ``-``."""
    if not name or not all(c.isalnum() or c in "_-" for c in name) or name.startswith("-"):
        raise ProfileError(f"{kind} {name!r}: use letters, digits, _ and - only")
    return name


def model_values(config: Config) -> dict[str, Any]:
    """The :data:`MODEL_KEYS` values of ``config``."""
    return {k: config[k] for k in MODEL_KEYS}


def reference_digest(reference: SampledReference) -> str:
    """16 hex digits of sha256 over the sampled reference (position, velocity, acceleration)."""
    digest = hashlib.sha256()
    for array in (reference.position, reference.velocity, reference.acceleration):
        digest.update(np.ascontiguousarray(array, dtype="<f8").tobytes())
    return digest.hexdigest()[:16]


@dataclass(frozen=True, eq=False)
class Profile:
    """One version of a patient's profile for an exercise."""

    patient: str
    exercise: str
    version: int
    path: Path
    feedforward: np.ndarray
    levels: np.ndarray | None
    provenance: dict[str, Any]
    patient_state: PatientState | None = None
    """A learning virtual patient's state after the version's last trial (None: none,
    :mod:`.patient_states`)."""

    @property
    def update(self) -> FeedforwardUpdate:
        """The profile as the first feed-forward of a session."""
        return FeedforwardUpdate(self.feedforward.copy(),
                                 None if self.levels is None else self.levels.copy())

    def check_compatible(self, config: Config, reference: SampledReference) -> None:
        """ProfileError naming the differing model values or the reference, if this profile
        was learned with another model or movement than ``config``'s."""
        what = f"profile v{self.version} of patient {self.patient!r}, exercise {self.exercise!r}"
        stored = self.provenance.get("model", {})
        now = model_values(config)
        differ = [k for k in MODEL_KEYS if stored.get(k) != now[k]]
        if differ:
            detail = "; ".join(f"{k} {stored.get(k)!r} there, {now[k]!r} now" for k in differ)
            raise ProfileError(f"{what} was learned with another model: {detail}")
        if self.provenance.get("reference_digest") != reference_digest(reference) or \
                self.feedforward.shape != reference.position.shape:
            raise ProfileError(
                f"{what} was learned with another reference: {self.provenance.get('samples')} "
                f"samples of exercise {self.provenance.get('exercise_name')!r} (digest "
                f"{self.provenance.get('reference_digest')}), now {reference.samples} samples "
                f"(digest {reference_digest(reference)}); was the exercise changed?")


def _read_npz(path: Path, sha256: str) -> dict[str, np.ndarray]:
    try:
        blob = read_listed(path, sha256)  # or the one a save interrupted kept (.previous)
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read: {exc.strerror}") from None
    if blob is None:
        raise ProfileError(f"{path}: corrupt profile file (sha256 does not match its index); "
                           "roll back to an earlier version (exo-ilc profiles rollback)")
    try:
        with np.load(io.BytesIO(blob)) as data:
            return {k: np.array(data[k]) for k in data.files}
    except (OSError, ValueError) as exc:
        raise ProfileError(f"{path}: unreadable profile file: {exc}") from None


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
        data = _read_npz(path, entry["sha256"])
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
        reopened = _reopenable(index, started_from, self.directory(patient, exercise)) \
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
        several, :func:`_reopenable`); its config must be the one it began with (but
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
                reopened = _reopenable(index, started_from, directory)
            elif reopen is not False:
                reopened = int(reopen)
            version = reopened or len(versions) + 1
            after = 0 if started_from is None else started_from.version
            not_included = [v["version"] for v in versions if after < v["version"] < version]
            writer = ProfileWriter(directory, version, config, reference, started_from,
                                   session, not_included)
            writer.base["run_store"] = run_store
            if reopened is not None:
                writer.reopen(_unfinished_entry(index, reopened, directory), session)
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


def read_index(path: Path) -> dict[str, Any] | None:
    """The profile index at ``path`` (None if there is none); ProfileError for an unreadable
    or inconsistent one."""
    if not path.exists():
        return None
    try:
        document = json.loads(path.read_text())
        if document.get("format") != PROFILE_FORMAT:
            raise ValueError(f"format {document.get('format')!r}, expected {PROFILE_FORMAT}")
        versions = document["versions"]
        if [v["version"] for v in versions] != list(range(1, len(versions) + 1)):
            raise ValueError("versions are not 1..n in order")
        current = document["current"]
        if current is not None and not 1 <= current <= len(versions):
            raise ValueError(f"current version {current} does not exist")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ProfileError(f"{path}: corrupt profile index: {exc}") from None
    return dict(document)


def _reopenable(index: dict[str, Any], started_from: Profile | None,
                directory: Path) -> int | None:
    """The only version not ``complete`` that began from ``started_from`` (None: none);
    ProfileError listing them if there are several (which one a resume continues must be
    said: :meth:`ProfileBook.begin` with its number)."""
    start = None if started_from is None else started_from.version
    found = [int(e["version"]) for e in index["versions"]
             if e.get("status") != "complete" and e.get("started_from") == start]
    if len(found) > 1:
        raise ProfileError(f"{directory}: versions {', '.join(f'v{v}' for v in found)} are "
                           f"all unfinished sessions begun from "
                           f"{'zero' if start is None else f'v{start}'}; say which to resume")
    return found[0] if found else None


def _unfinished_entry(index: dict[str, Any], version: int, directory: Path) -> dict[str, Any]:
    """The index entry of version ``version``, which a resume continues: ProfileError if
    there is none or it is complete (nothing of it is rewritten)."""
    versions = index["versions"]
    if not 1 <= version <= len(versions):
        raise ProfileError(f"{directory}: no version {version} to resume (versions "
                           f"1-{len(versions)})")
    entry = dict(versions[version - 1])
    if entry.get("status") == "complete":
        raise ProfileError(f"{directory}: version {version} is complete; a resume continues "
                           "only an unfinished session (nothing overwritten)")
    return entry


class ProfileWriter:
    """Writes one session's version of a profile after every trial (atomic, under the lock)."""

    def __init__(self, directory: Path, version: int, config: Config,
                 reference: SampledReference, started_from: Profile | None, session: str,
                 not_included: list[int]) -> None:
        self.directory = directory
        self.version = version
        self.config = config.replace({SESSION_KEY: version})
        """The session's config: ``patient.session`` is its version number."""
        self.created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        config = self.config
        self.base = {
            "version": self.version, "file": f"v{self.version:04d}.npz",
            "created": self.created, "session": session,
            "config_digest": config.digest(), "model": model_values(config),
            "reference_digest": reference_digest(reference), "samples": reference.samples,
            "exercise_name": config["exercise.name"], "law": config["law"],
            "assist_as_needed": bool(config["assist_as_needed.enabled"]),
            "mass_uncertainty": config["mass_uncertainty"],
            "patient_seed": int(config["patient.seed"]),
            "patient_session": int(config[SESSION_KEY]),
            "started_from": None if started_from is None else started_from.version,
            "not_included": list(not_included),
            "trials_before": 0 if started_from is None else
            int(started_from.provenance.get("trials_total", 0)),
        }
        if config["store.resume"]:  # a resumed run's digest is its first run's
            self.base["config_digest"] = config.replace({"store.resume": False}).digest()

    def reopen(self, entry: dict[str, Any], session: str) -> None:
        """Continue the unfinished version ``entry`` (a resumed run): its config must be the
        one it began with (ProfileError naming both digests); it keeps when and by which
        session it was begun, its patient start state, and lists this run in ``resumed``."""
        if entry.get("config_digest") != self.base["config_digest"] or \
                entry.get("started_from") != self.base["started_from"]:
            raise ProfileError(
                f"{self.directory}: version {self.version} began from "
                f"v{entry.get('started_from')} with config {entry.get('config_digest')}; this "
                f"run would continue it from v{self.base['started_from']} with config "
                f"{self.base['config_digest']}: resume it with the options it was begun with")
        for key in ("created", "session", START_KEY, "not_included"):
            if key in entry:
                self.base[key] = entry[key]
        self.created = str(self.base["created"])
        self.base["resumed"] = [*entry.get("resumed", []), {
            "session": session, "after_trials": int(entry.get("trials", 0)),
            "at": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}]

    def save(self, trials: int, update: FeedforwardUpdate, final_max_abs_error: Any,
             complete: bool = False, metrics: dict[str, Any] | None = None,
             patient_state: PatientState | None = None) -> Path:
        """The feed-forward after ``trials`` trials of this session (and their last max |e|
        per joint, rad) as this version, made current unless a higher version is; returns the
        file written. ``patient_state``: a learning virtual patient's state after the same
        trial, written with it (:mod:`.patient_states`). The index is read, changed and
        written under the lock; a version already complete is never rewritten."""
        buffer = io.BytesIO()
        levels = np.empty((0,)) if update.levels is None else np.asarray(update.levels, float)
        np.savez(buffer, feedforward=np.asarray(update.feedforward, dtype=float), levels=levels)
        blob = buffer.getvalue()
        path = self.directory / self.base["file"]
        entry = dict(self.base)
        entry.update({
            "updated": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "sha256": hashlib.sha256(blob).hexdigest(), "trials": int(trials),
            "trials_total": int(self.base["trials_before"]) + int(trials),
            "final_max_abs_error": [float(x) for x in np.asarray(final_max_abs_error)],
            "status": "complete" if complete else "in_progress",
        })
        if metrics:
            entry["metrics"] = metrics
        index_path = self.directory / "index.json"
        with locked(self.directory):
            index = read_index(index_path)
            if index is None or len(index["versions"]) < self.version:
                raise ProfileError(f"{index_path}: version {self.version} of this session is "
                                   "no longer listed (index replaced meanwhile?); nothing "
                                   "written")
            if index["versions"][self.version - 1].get("status") == "complete":
                raise ProfileError(f"{path}: version {self.version} is complete; nothing "
                                   "rewritten")
            listed = index["versions"][self.version - 1]
            if patient_state is not None:
                state = patient_state.encode()
                name = STATE_FILE.format(version=self.version)
                replace_keeping_listed(self.directory / name, state,
                                       (listed.get(STATE_KEY) or {}).get("sha256"))
                entry[STATE_KEY] = file_entry(name, state)
            replace_keeping_listed(path, blob, listed.get("sha256"))
            index["versions"][self.version - 1] = entry
            if index["current"] is None or index["current"] <= self.version:
                index["current"] = self.version
            write_json_atomic(index_path, index)
        return path


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
    data = _read_npz(path, entry["sha256"])
    levels = data.get("levels")
    profile = Profile(str(index.get("patient")), str(index.get("exercise")),
                      int(entry["version"]), path, data["feedforward"],
                      levels if levels is not None and levels.size else None, dict(entry))
    profile.check_compatible(config, reference)
    return profile.update
