"""A plant that diverged: where its state first stopped being finite, and why.

The trial kernel (:func:`trial.simulate_trial_guarded`) stops a trial at the first sample whose
plant state is not finite (:func:`plant.finite_state`); the record then holds NaN from that
sample on (:attr:`record.TrialRecord.diverged_at`). Such a trial is not an error-envelope
abort, whatever the envelope saw before: the report says "the plant diverged at t = ... s on
joint j" with the likely cause (:func:`divergence_message`), never "aborted by the error
envelope" (learning cannot help such a trial).

Cause. Classic RK4 is stable on a decaying mode qdd = -(b/I) qd only while h b / I stays
below about 2.785 (the real-axis limit of its stability region), h the integration sub-step:
a URDF joint damping of 2 N m s/rad on a wrist link of 1.4e-4 kg m^2 at h = 1 ms gives
h b / I = 14, and the state grows ~|R(-14)| ~ 1e3 times per sub-step. :func:`damping_stiffness`
is h times the stiffest mode of a(q)^-1 B, the largest eigenvalue.

Stable damping: the plant integrates the joint damping with more RK4 sub-steps where the
configured ``integration_step`` would not be stable (:func:`stable_substeps`, chosen once per
configuration from the stiffest mode along the reference: h max eig(a^-1 B) <= 1.4, half RK4's
limit). We chose sub-steps over an implicit damping term because they leave every kernel, and so
every number of an arm whose damping the configured step integrates stably (all shipped ones),
bit for bit as they were; the cost is the extra sub-steps of a stiff arm (the light wrist of
test_plant_stability: 10 -> 98 per 10 ms period).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..arm.joint_forces import VISCOUS
from ..arm.model import ArmModel
from .patient import PatientModel
from .record import TrialRecord
from .setup import LoopSetup

RK4_REAL_STABILITY = 2.785
"""Classic RK4's stability limit on the negative real axis: |R(z)| <= 1 for -2.785 <= z <= 0."""
DAMPING_STEP = 1.4
"""h max eig(a^-1 B) per sub-step :func:`stable_substeps` keeps to: half of RK4's limit (the
true state leaves the reference's poses, and RK4's damping error stays small there)."""
MAX_SUBSTEP_FACTOR = 64
""":func:`stable_substeps` raises the sub-steps at most this many times."""
POSE_STRIDE = 25
"""Every this many reference samples a pose is checked (and the last)."""
DIVERGED = "plant_diverged"
"""The abort reason of a trial whose plant diverged (an error-envelope abort has none); the
key of :meth:`PlantDivergence.to_json` in a run's JSON."""


def first_non_finite(position: np.ndarray, velocity: np.ndarray) -> tuple[int, int] | None:
    """(sample, joint) of the first sample whose q or qdot is not finite, the joint of those
    non-finite there the one moving fastest at the sample before (at sample 0: the first
    non-finite one), or None if every sample is finite."""
    bad = ~(np.isfinite(np.asarray(position)) & np.isfinite(np.asarray(velocity)))
    rows = np.flatnonzero(np.any(bad, axis=1))
    if rows.size == 0:
        return None
    sample = int(rows[0])
    candidates = np.flatnonzero(bad[sample])
    if sample > 0:  # the joint moving fastest just before: the one that blew up
        last = np.abs(np.asarray(velocity)[sample - 1, candidates])
        if np.all(np.isfinite(last)):
            return sample, int(candidates[np.argmax(last)])
    return sample, int(candidates[0])


def damping_stiffness(inertia: np.ndarray, damping: np.ndarray,
                      step: float) -> tuple[float, int]:
    """h times the stiffest damping mode, h max eig(a^-1 B) with B = diag(``damping``) and
    ``inertia`` the joint-space inertia a(q) of eq (2) (RK4 at sub-step h diverges on it above
    :data:`RK4_REAL_STABILITY`), and the joint that mode moves most; (0, -1) without damping."""
    b = np.asarray(damping, dtype=float)
    if not np.any(b > 0.0):
        return 0.0, -1
    modes, shapes = np.linalg.eig(np.linalg.solve(np.asarray(inertia, dtype=float), np.diag(b)))
    k = int(np.argmax(modes.real))
    return float(step * modes[k].real), int(np.argmax(np.abs(shapes[:, k])))


@dataclass(frozen=True)
class PlantDivergence:
    """Where a trial's plant state stopped being finite, and the likely cause."""

    trial: int
    sample: int
    time: float
    """``sample`` times the control period (s)."""
    joint: int
    joint_name: str
    cause: str
    reason: str = DIVERGED

    @property
    def message(self) -> str:
        """One sentence for a report: time, joint and cause."""
        return (f"trial {self.trial}: the plant diverged at t = {self.time:.3f} s on joint "
                f"{self.joint_name}: {self.cause}")

    def to_json(self) -> dict[str, object]:
        """The fields and :attr:`message` as JSON."""
        return {"reason": self.reason, "trial": self.trial, "sample": self.sample,
                "time": self.time, "joint": self.joint, "joint_name": self.joint_name,
                "cause": self.cause, "message": self.message}


def divergence_cause(stiffness: float, damping: np.ndarray, step: float) -> str:
    """The likely cause: explicit integration of a too-stiff joint damping (``stiffness``, from
    :func:`damping_stiffness`, over :data:`RK4_REAL_STABILITY`), else a non-finite command or
    an unstable plant model."""
    if stiffness > RK4_REAL_STABILITY:
        return (f"explicit-integration stability: the applied joint damping (up to "
                f"{float(np.max(damping)):g} N m s/rad) makes h*b/I = {stiffness:.3g} at the "
                f"integration step h = {step:g} s, over the ~{RK4_REAL_STABILITY} RK4 is "
                "stable for (a smaller integration_step, or model.urdf_joint_dynamics: ignore)")
    return ("a non-finite command or a plant model that is not stable at the integration step "
            f"(h*b/I = {stiffness:.3g} with the applied joint damping, under the "
            f"~{RK4_REAL_STABILITY} RK4 is stable for)")


def plant_divergence(trial: int, position: np.ndarray, velocity: np.ndarray, period: float,
                     names: Sequence[str], cause: str) -> PlantDivergence | None:
    """The :class:`PlantDivergence` of a trial's (true) states, None if they are all finite."""
    first = first_non_finite(position, velocity)
    if first is None:
        return None
    sample, joint = first
    return PlantDivergence(trial, sample, sample * period, joint, str(names[joint]), cause)


def plant_damping(patient: PatientModel) -> np.ndarray:
    """The viscous joint damping b (N m s/rad per joint) the plant integrates: the arm's own
    (``model.urdf_joint_dynamics: apply``) and, with the virtual patient on, the patient's."""
    if patient.enabled:
        return np.maximum(patient.joint[VISCOUS], patient.arm_joint[VISCOUS])
    return np.asarray(patient.arm_joint[VISCOUS], dtype=float)


def stable_substeps(plant: ArmModel, positions: np.ndarray, damping: np.ndarray,
                    period: float, substeps: int) -> int:
    """RK4 sub-steps per control period that keep the joint damping stable: the configured
    ``substeps`` (``integration_step``), raised until h max eig(a(q)^-1 B) <= :data:`DAMPING_STEP`
    at the reference's poses ``positions`` (every :data:`POSE_STRIDE`-th and the last;
    :func:`damping_stiffness`), at most :data:`MAX_SUBSTEP_FACTOR` times the configured ones
    (beyond, the plant may diverge: the trial stops and says so). Without damping, or with a
    damping the configured step integrates stably, ``substeps`` itself: nothing changes."""
    b = np.asarray(damping, dtype=float)
    if not np.any(b > 0.0):
        return int(substeps)
    poses = np.asarray(positions, dtype=float)
    picked = np.vstack([poses[::POSE_STRIDE], poses[-1:]])
    stiffest = max(damping_stiffness(plant.metric_tensor(q), b, 1.0)[0] for q in picked)
    needed = int(np.ceil(period * stiffest / DAMPING_STEP))
    return int(min(max(int(substeps), needed), MAX_SUBSTEP_FACTOR * int(substeps)))


def trial_divergence(setup: LoopSetup, record: TrialRecord,
                     names: Sequence[str]) -> PlantDivergence | None:
    """The :class:`PlantDivergence` of one trial of ``setup`` (None: its plant stayed finite),
    the cause from h b / I at the last finite pose (:func:`damping_stiffness`; over the RK4
    limit, the joint named is the one the stiffest mode moves most)."""
    position = record.position if record.true_position is None else record.true_position
    velocity = record.velocity if record.true_velocity is None else record.true_velocity
    first = first_non_finite(position, velocity)
    if first is None:
        return None
    pose = position[first[0] - 1] if first[0] > 0 else record.reference.position[0]
    if not np.all(np.isfinite(pose)):
        pose = record.reference.position[0]
    damping = plant_damping(setup.patient)
    step = setup.period / setup.substeps
    stiffness, stiff_joint = damping_stiffness(setup.plant.metric_tensor(pose), damping, step)
    found = plant_divergence(record.trial, position, velocity, setup.period, names,
                             divergence_cause(stiffness, damping, step))
    if found is not None and stiffness > RK4_REAL_STABILITY:  # the stiff mode's joint
        found = replace(found, joint=stiff_joint, joint_name=str(names[stiff_joint]))
    return found
