"""A learning virtual patient's state per session (``patient.learning.*``, the two-state motor
adaptation of :class:`.patient.PatientLearning`), kept beside its profile version so that any
session can be re-run exactly and a rolled-back profile comes with the patient state it went
with (simulation only; a real patient keeps their state themselves).

Beside ``vNNNN.npz`` of a profile (:mod:`.profiles`), for a session under a learning patient:

    vNNNN.patient-start.npz   (fast, slow) the session started from: written once when the
                              version begins, never rewritten
    vNNNN.patient.npz         (fast, slow) after the session's last saved trial: rewritten
                              with the profile after every trial (the same lock and index
                              update, so the pair is always consistent), never once complete

Each file's sha256 is in the version's index entry (``patient_start``, ``patient_state``); a
file that does not match is refused with a message naming it, never overwritten. A session
starts from the end state of the version it starts from (zeros from no version); versions
written before these files existed fall back on the exercise's ``virtual_patient.npz`` (the
latest state only, read but no longer written).
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ProfileError
from .files import locked
from .listed_files import read_listed

START_FILE = "v{version:04d}.patient-start.npz"
STATE_FILE = "v{version:04d}.patient.npz"
START_KEY = "patient_start"
"""The index entry's key of the state the session started from (file, sha256)."""
STATE_KEY = "patient_state"
"""The index entry's key of the state after the session's last saved trial (file, sha256)."""
LEGACY_FILE = "virtual_patient.npz"
"""The exercise's latest state, as written before states were kept per version."""


@dataclass(frozen=True, eq=False)
class PatientState:
    """The learning patient's fast and slow states, (N+1, joints) each (N m)."""

    fast: np.ndarray
    slow: np.ndarray

    @classmethod
    def zeros(cls, samples: int, joints: int) -> PatientState:
        """A patient who has learned nothing yet."""
        return cls(np.zeros((samples, joints)), np.zeros((samples, joints)))

    def encode(self) -> bytes:
        """The state as ``.npz`` bytes (deterministic: the same state, the same bytes)."""
        buffer = io.BytesIO()
        np.savez(buffer, fast=np.asarray(self.fast, dtype=float),
                 slow=np.asarray(self.slow, dtype=float))
        return buffer.getvalue()

    def equals(self, other: PatientState) -> bool:
        """Every number equal (bit for bit)."""
        return bool(np.array_equal(self.fast, other.fast) and
                    np.array_equal(self.slow, other.slow))


def file_entry(name: str, blob: bytes) -> dict[str, str]:
    """The index entry of a state file: its name and sha256."""
    return {"file": name, "sha256": hashlib.sha256(blob).hexdigest()}


def read_state(directory: Path, entry: dict[str, Any]) -> PatientState:
    """The state file an index entry names (``{"file", "sha256"}``), sha256 checked;
    ProfileError naming the file if it is missing, corrupt or unreadable."""
    try:
        path = directory / str(entry["file"])
        expected = str(entry["sha256"])
    except (KeyError, TypeError) as exc:
        raise ProfileError(f"{directory / 'index.json'}: corrupt patient state entry {entry!r}: "
                           f"{exc}") from None
    try:
        blob = read_listed(path, expected)  # or the one a save interrupted kept (.previous)
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read the virtual patient's state: "
                           f"{exc.strerror}") from None
    if blob is None:
        raise ProfileError(f"{path}: corrupt virtual patient state (sha256 does not match its "
                           "index); kept as it is, nothing overwritten")
    try:
        with np.load(io.BytesIO(blob)) as data:
            return PatientState(np.array(data["fast"]), np.array(data["slow"]))
    except (OSError, ValueError, KeyError) as exc:
        raise ProfileError(f"{path}: unreadable virtual patient state: {exc}") from None


def read_legacy(directory: Path, samples: int) -> PatientState | None:
    """The exercise's ``virtual_patient.npz`` (None: none, or of another movement)."""
    path = directory / LEGACY_FILE
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            state = PatientState(np.array(data["fast"]), np.array(data["slow"]))
    except (OSError, ValueError, KeyError) as exc:
        raise ProfileError(f"{path}: unreadable virtual patient state: {exc}") from None
    if state.fast.shape[0] == samples == state.slow.shape[0]:
        return state
    return None


def session_start(directory: Path, version: int) -> PatientState | None:
    """The state session ``version`` of the profile in ``directory`` started from, as stored
    (None: the version records none: no learning patient, or written before states were kept
    per version); ProfileError for a missing or corrupt index or file."""

    index_path = directory / "index.json"
    with locked(directory, shared=True):
        return _session_start(directory, index_path, version)


def _session_start(directory: Path, index_path: Path, version: int) -> PatientState | None:
    try:
        index = json.loads(index_path.read_text())
        entry = index["versions"][int(version) - 1]
        if int(entry["version"]) != int(version):
            raise ValueError(f"entry {version} is version {entry['version']}")
    except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
        raise ProfileError(f"{index_path}: no version {version} readable "
                           f"({type(exc).__name__}: {exc})") from None
    found = entry.get(START_KEY)
    return None if found is None else read_state(directory, found)
