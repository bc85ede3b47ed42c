"""A learned profile on disk (:mod:`.profiles` explains the layout): what it was learned for
(:data:`MODEL_KEYS`, the reference's digest), one version as read back (:class:`Profile`), the
index and the version files under their sha256."""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ProfileError
from ..learning.laws import FeedforwardUpdate
from ..params import schema
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .listed_files import read_listed
from .patient_states import PatientState

PROFILE_FORMAT = 1


MODEL_KEYS = ("joint_names", "model.link_masses", "model.link_lengths", "model.radius_proximal",
              "model.radius_distal", "model.joint_axes", "model.gravity",
              "model.gravity_direction", "control.period", "control.kp", "control.kd",
              "control.min_stiffness", "control.min_damping", "control.velocity_observer",
              *schema.URDF_KEYS, *schema.PERSON_KEYS)
"""What a feed-forward was learned *for*: the controller's nominal model and loop (a URDF arm by
its file's contents, a person's segments only with ``person.enabled``,
:meth:`~exo_ilc_ros.core.params.config.Config.identity_values`)."""


SESSION_KEY = "patient.session"
"""The config key a session's version number goes to (the virtual patient's session)."""


def model_values(config: Config) -> dict[str, Any]:
    """The :data:`MODEL_KEYS` values of ``config`` (as identities: a URDF by its contents)."""
    return config.identity_values(MODEL_KEYS)


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
        differ = [k for k in MODEL_KEYS if stored.get(k) != now.get(k)]
        if differ:
            detail = "; ".join(f"{k} {stored.get(k)!r} there, {now.get(k)!r} now"
                               for k in differ)
            raise ProfileError(f"{what} was learned with another model: {detail}")
        if self.provenance.get("reference_digest") != reference_digest(reference) or \
                self.feedforward.shape != reference.position.shape:
            raise ProfileError(
                f"{what} was learned with another reference: {self.provenance.get('samples')} "
                f"samples of exercise {self.provenance.get('exercise_name')!r} (digest "
                f"{self.provenance.get('reference_digest')}), now {reference.samples} samples "
                f"(digest {reference_digest(reference)}); was the exercise changed?")


def read_npz(path: Path, sha256: str) -> dict[str, np.ndarray]:
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


def reopenable(index: dict[str, Any], started_from: Profile | None,
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


def unfinished_entry(index: dict[str, Any], version: int, directory: Path) -> dict[str, Any]:
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
