"""A crash-safe store of learned data: every trial's record and the feed-forward it led to.

Layout, one directory per *learning key* under the store root::

    <root>/<key>/meta.json           what the key covers (written once)
    <root>/<key>/trial_0001.npz      trial 1: q, qdot, u_ff, u, effort, levels, aborted_at,
                                     next_feedforward / next_levels (what trial 2 uses), and
                                     the true q, qdot when the sensors differ (else empty)
    <root>/<key>/index.json          the completed trials: file, sha256, summary

Every file is written atomically: a temp file in the same directory, flush + fsync, os.replace,
fsync of the directory. A trial's ``.npz`` is written before the index names it, so after a crash
(kill -9, power loss) the index lists only complete trials; a file the index does not name is
left-over work and is overwritten. Reading checks each file's sha256 against the index.

The learning key is a hash of the sampled reference (the trajectory) and of every parameter
that shapes the learned data, i.e. all parameters **except** ``live`` ones and the run-control
ones in :data:`NOT_KEYED`. Live parameters (law gains, schedules, envelope, ...) may change
while the graph runs, at a trial boundary; keying on them would split one therapy session into
several stores at the first change. They are recorded with every trial instead (``live`` in the
index), so a resume with other live values is possible and visible. ``Config.digest()`` (every
value) is recorded too.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StoreError
from ..learning.laws import FeedforwardUpdate
from ..loop.patient import PatientModel
from ..loop.plant import saturation_counts
from ..loop.record import TrialRecord
from ..params import schema
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .files import _atomic, write_json_atomic

STORE_VERSION = 1
NOT_KEYED = frozenset({"max_trials", "mode", "real_time_rate", "pace", "wait_for_recorder",
                       "max_late_commands", "thread_priority",
                       "safety.watchdog_periods", "watchdog_min_timeout",
                       "safety.hold_kp", "safety.hold_kd", "safety.hold_ramp",
                       "store.directory",
                       "store.resume", "abort.max_consecutive"})
"""Non-live parameters that change how a run is driven, not what it learns."""

_ARRAYS = ("position", "velocity", "feedforward", "control_input", "effort")


def keyed_values(config: Config) -> dict[str, Any]:
    """The parameter values the learning key covers (module docstring). The virtual patient's
    ``patient.*`` values only when one of its effects is on: a run without them keeps the key
    it had before they existed (so does a cone arm without the URDF keys; a URDF arm is keyed by
    its file's contents, not its path)."""

    patient = PatientModel(config).enabled
    return config.identity_values(p.name for p in schema.PARAMETERS
                                  if not p.live and p.name not in NOT_KEYED
                                  and (patient or not p.name.startswith("patient.")))


def live_values(config: Config) -> dict[str, Any]:
    """The live parameter values (recorded with each trial, not keyed)."""
    return {p.name: config[p.name] for p in schema.PARAMETERS if p.live}


def learning_key(config: Config, reference: SampledReference) -> str:
    """16 hex digits: sha256 of the keyed values and the sampled reference's bytes."""
    digest = hashlib.sha256(json.dumps(keyed_values(config), sort_keys=True).encode())
    for array in (reference.position, reference.velocity, reference.acceleration):
        digest.update(np.ascontiguousarray(array, dtype="<f8").tobytes())
    return digest.hexdigest()[:16]


@dataclass(frozen=True)
class StoredTrial:
    """One completed trial as stored: its record and the update it led to."""

    record: TrialRecord
    next_update: FeedforwardUpdate
    summary: dict[str, Any]


def _optional(array: np.ndarray | None) -> np.ndarray:
    return np.empty((0,)) if array is None else np.asarray(array, dtype=float)


class RunStore:
    """The store of one learning key: save after every trial, load to resume."""

    def __init__(self, root: Path | str, config: Config, reference: SampledReference) -> None:
        self.key = learning_key(config, reference)
        self.directory = Path(root) / self.key
        self.config = config
        self.reference = reference
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(f"{self.directory}: cannot create the store: {exc.strerror}") \
                from None
        meta = self.directory / "meta.json"
        if not meta.exists():
            write_json_atomic(meta, {"version": STORE_VERSION, "key": self.key,
                                     "keyed": keyed_values(config)})
        self._index = self._read_index()

    @property
    def index_path(self) -> Path:
        """The JSON index of completed trials."""
        return self.directory / "index.json"

    def _read_index(self) -> list[dict[str, Any]]:
        path = self.index_path
        if not path.exists():
            return []
        try:
            document = json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise StoreError(f"{path}: unreadable index: {exc}") from None
        if document.get("version") != STORE_VERSION or document.get("key") != self.key:
            raise StoreError(f"{path}: version/key {document.get('version')}/"
                             f"{document.get('key')} do not match {STORE_VERSION}/{self.key}")
        trials = list(document["trials"])
        for k, entry in enumerate(trials, start=1):
            if entry.get("trial") != k:
                raise StoreError(f"{path}: entry {k} is trial {entry.get('trial')}, expected {k}")
        return trials

    @property
    def completed(self) -> int:
        """Number of trials stored (trial numbers 1..completed)."""
        return len(self._index)

    @property
    def summaries(self) -> list[dict[str, Any]]:
        """The index entries (trial, file, sha256, aborted_at, max_abs_error, levels, ...)."""
        return json.loads(json.dumps(self._index))

    def save(self, record: TrialRecord, next_update: FeedforwardUpdate,
             config: Config | None = None) -> None:
        """Persist trial ``record`` (it must be trial ``completed + 1``) and the update the next
        trial uses; returns once both are on disk."""
        expected = self.completed + 1
        if record.trial != expected:
            raise StoreError(f"{self.directory}: trial {record.trial} saved out of order, "
                             f"expected trial {expected}")
        cfg = config or self.config
        name = f"trial_{record.trial:04d}.npz"
        buffer = io.BytesIO()
        arrays = {k: np.asarray(getattr(record, k), dtype=float) for k in _ARRAYS}
        np.savez(buffer, position=arrays["position"], velocity=arrays["velocity"],
                 feedforward=arrays["feedforward"], control_input=arrays["control_input"],
                 effort=arrays["effort"], levels=_optional(record.levels),
                 aborted_at=np.int64(-1 if record.aborted_at is None else record.aborted_at),
                 next_feedforward=np.asarray(next_update.feedforward, dtype=float),
                 next_levels=_optional(next_update.levels),
                 true_position=_optional(record.true_position),
                 true_velocity=_optional(record.true_velocity),
                 joint_force=_optional(record.joint_force),
                 next_joint_force=_optional(next_update.joint_force))
        blob = buffer.getvalue()
        with _atomic(self.directory / name) as handle:
            handle.write(blob)
        limit = np.asarray(cfg["control.effort_limit"], dtype=float)
        entry = {
            "trial": record.trial, "file": name, "sha256": hashlib.sha256(blob).hexdigest(),
            "aborted_at": record.aborted_at,
            "max_abs_error": [float(x) for x in record.max_abs_error],
            "true_max_abs_error": [float(x) for x in record.true_max_abs_error],
            "max_abs_feedforward": [float(x) for x in np.max(np.abs(record.feedforward), 0)],
            "max_abs_effort": [float(x) for x in np.max(np.abs(record.effort), 0)],
            "saturated_samples": [int(x) for x in saturation_counts(record.effort, limit)],
            "levels": None if record.levels is None else np.asarray(record.levels).tolist(),
            "config_digest": cfg.digest(), "live": live_values(cfg),
        }
        index = [*self._index, entry]
        write_json_atomic(self.index_path, {"version": STORE_VERSION, "key": self.key,
                                            "trials": index})
        self._index = index

    def load(self) -> list[StoredTrial]:
        """Every stored trial, in order, each file checked against its sha256."""
        out = []
        for entry in self._index:
            path = self.directory / entry["file"]
            try:
                blob = path.read_bytes()
            except OSError as exc:
                raise StoreError(f"{path}: cannot read: {exc.strerror}") from None
            if hashlib.sha256(blob).hexdigest() != entry["sha256"]:
                raise StoreError(f"{path}: sha256 does not match the index (corrupt file)")
            with np.load(io.BytesIO(blob)) as data:
                arrays = {k: np.array(data[k]) for k in data.files}
            levels = arrays["levels"] if arrays["levels"].size else None
            aborted = int(arrays["aborted_at"])
            true_q = arrays.get("true_position", np.empty(0))
            true_qd = arrays.get("true_velocity", np.empty(0))
            force = arrays.get("joint_force", np.empty(0))
            next_force = arrays.get("next_joint_force", np.empty(0))
            record = TrialRecord(entry["trial"], self.reference, arrays["position"],
                                 arrays["velocity"], arrays["feedforward"],
                                 arrays["control_input"], arrays["effort"], levels,
                                 None if aborted < 0 else aborted,
                                 true_q if true_q.size else None,
                                 true_qd if true_qd.size else None,
                                 force if force.size else None)
            next_levels = arrays["next_levels"] if arrays["next_levels"].size else None
            out.append(StoredTrial(record, FeedforwardUpdate(
                arrays["next_feedforward"], next_levels,
                joint_force=next_force if next_force.size else None), dict(entry)))
        return out
