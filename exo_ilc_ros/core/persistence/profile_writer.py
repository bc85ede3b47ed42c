"""One session's version of a profile, written after every trial (:class:`ProfileWriter`; the
layout and the locking rules are :mod:`.profiles`')."""

from __future__ import annotations

import hashlib
import io
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ProfileError
from ..learning.laws import FeedforwardUpdate
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .files import locked, write_json_atomic
from .listed_files import replace_keeping_listed
from .patient_states import START_KEY, STATE_FILE, STATE_KEY, PatientState, file_entry
from .profile_format import (
    SESSION_KEY,
    Profile,
    model_values,
    read_index,
    reference_digest,
)


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
