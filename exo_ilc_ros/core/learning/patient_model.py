"""The identified patient in the loop: between trials, the joint forces of the trial just run
are identified (:mod:`.identification`) and, once trustworthy, computed torque adds them along
the reference in the next trial, eqs (9)/(16) with eq (6)'s Q^v, Q^c, Q^f and the reflex back
in (:func:`.joint_force_term.joint_force_term`)::

    Q = a_N(q) u + c_N(q, qdot) + tau_p(q_d, qdot_d)

The rules, per joint, at every trial boundary (:meth:`JointForceModel.conclude`):

1. Only from ``identification.first_trial`` on, and only a joint whose estimate is
   trustworthy (excited, precise, plausible: :attr:`JointEstimate.trustworthy`) and finite.
   A refused trial (chatter, non-finite samples) or an estimate that is not trustworthy
   changes nothing: the joint keeps the forces it had (none before its first trustworthy
   estimate), and the step says why.
2. The forces stay within +-``identification.trust_limit`` (N m) at every sample, and move
   toward the new estimate's by at most ``identification.max_change`` (N m) at any sample from
   one trial to the next: the patient never feels a jump.
3. After an envelope abort the forces are kept (the trial is still identified).

The forces are evaluated on the reference, not the measured state: no quantised velocity and no
delayed reflex is fed back (docs/patient-identification.md). The learning law then learns only
what the model does not explain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arm.model import ArmModel
from ..loop.record import TrialRecord
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .identification import JointForceIdentifier
from .identification_settings import IdentificationSettings
from .joint_force_term import joint_force_term
from .patient_estimate import PatientEstimate


@dataclass(frozen=True)
class JointForceSettings:
    """The ``identification.*`` keys (module docstring for the rules)."""

    in_loop: bool
    first_trial: int
    trust_limit: np.ndarray
    max_change: np.ndarray
    adoption: str
    inverse_gain: float
    identification: IdentificationSettings

    @classmethod
    def from_config(cls, config: Config) -> JointForceSettings:
        """The settings of ``config``."""
        return cls(bool(config["identification.in_loop"]),
                   int(config["identification.first_trial"]),
                   np.asarray(config["identification.trust_limit"], dtype=float),
                   np.asarray(config["identification.max_change"], dtype=float),
                   str(config["identification.adoption"]),
                   float(config["identification.inverse_gain"]),
                   IdentificationSettings.from_config(
                       config, forgetting=float(config["identification.forgetting"]),
                       voluntary=bool(config["identification.voluntary"])))


@dataclass(frozen=True, eq=False)
class JointForceStep:
    """What a trial boundary did to the joint forces."""

    estimate: PatientEstimate
    """The identification after the trial."""
    joint_force: np.ndarray | None
    """(samples, n) N m the next trial adds; None: identification only (not in the loop)."""
    used: np.ndarray
    """(n,) bool: the joint's forces follow a trustworthy estimate (this or an earlier one)."""
    reasons: tuple[str, ...]
    """Per joint: why this boundary did not move its forces to the estimate ("": it did)."""
    change: np.ndarray
    """(n,) N m: the largest change of the joint's forces at any sample."""
    adopted: np.ndarray | None = None
    """(n,) bool: joints whose forces follow an estimate for the first time at this boundary."""
    handover: np.ndarray | None = None
    """(samples, n) rad/s^2 to subtract from the learned feed-forward so that the total input
    does not jump: a_N(q_d)^-1 (tau_new - tau_old) along the reference (``adoption:
    handover``; None: no change)."""


class JointForceModel:
    """The identified joint forces of one session (module docstring)."""

    def __init__(self, config: Config, nominal: ArmModel, reference: SampledReference) -> None:
        self.settings = JointForceSettings.from_config(config)
        self.reference = reference
        self.identifier = JointForceIdentifier(nominal, self.settings.identification)
        n = nominal.dof
        self.joint_force = np.zeros(reference.position.shape)
        """The forces the next trial adds (zeros until a joint's estimate is trusted)."""
        self.used = np.zeros(n, dtype=bool)
        self._nominal = nominal
        self._inertia: np.ndarray | None = None

    def acceleration(self, torque: np.ndarray) -> np.ndarray:
        """a_N(q_d)^-1 tau at every sample of the reference: a torque profile in the units of
        the feed-forward (eq (16) maps u to a_N u)."""
        if self._inertia is None:
            self._inertia = np.array([self._nominal.metric_tensor(q)
                                      for q in self.reference.position])
        return np.linalg.solve(self._inertia, torque[..., None])[..., 0]

    @property
    def estimate(self) -> PatientEstimate | None:
        """The latest identification (None before the first trial)."""
        return self.identifier.estimate

    def learning_correction(self, record: TrialRecord) -> np.ndarray | None:
        """g a_N(q_d)^-1 (K e + B e_dot) along the reference, g = ``identification.
        inverse_gain``, K and B the identified stiffness and damping of each joint in use (rule
        4): what the law's update adds so that it inverts the arm *with* the patient (an update
        that inverts only the nominal arm, like robust.yaml's u += PD e + e_ddot, leaves a
        contraction of ~0.9 per trial when the patient's stiffness exceeds the controller's,
        as the forearm's 1 N m/rad does K_P a_N ~ 0.5 N m/rad). None: nothing to add."""
        estimate = self.identifier.estimate
        g = self.settings.inverse_gain
        if g == 0.0 or estimate is None or record.aborted or not np.any(self.used):
            return None
        stiffness = np.where(self.used, np.clip(estimate.values("stiffness"), 0.0, None), 0.0)
        damping = np.where(self.used, np.clip(estimate.values("viscous"), 0.0, None), 0.0)
        torque = g * (stiffness * record.error + damping * record.error_velocity)
        if not np.all(np.isfinite(torque)):
            return None
        return self.acceleration(torque)

    def conclude(self, record: TrialRecord) -> JointForceStep:
        """Identify trial ``record`` and move the forces of the next trial (rules 1-3)."""
        estimate = self.identifier.update_record(record)
        s = self.settings
        n = self.used.shape[0]
        if not s.in_loop:
            return JointForceStep(estimate, None, self.used.copy(), ("not in the loop",) * n,
                                  np.zeros(n))
        reasons = [""] * n
        if record.trial + 1 < s.first_trial:
            reasons = [f"identification.first_trial is {s.first_trial}"] * n
        elif record.aborted:
            reasons = ["the trial was aborted: forces kept"] * n
        elif estimate.rejected:
            reasons = [estimate.rejected] * n
        if any(reasons):
            return JointForceStep(estimate, self.joint_force.copy(), self.used.copy(),
                                  tuple(reasons), np.zeros(n))
        ref = self.reference
        term = joint_force_term(estimate, ref.position, ref.velocity, s.trust_limit,
                                s.identification)
        target = np.where(term.used[None, :], term.torque, self.joint_force)
        if not np.all(np.isfinite(target)):  # joint_force_term refuses these; never pass one
            bad = np.flatnonzero(~np.all(np.isfinite(target), axis=0))
            target[:, bad] = self.joint_force[:, bad]
        step = np.clip(target - self.joint_force, -s.max_change, s.max_change)
        before = self.joint_force
        self.joint_force = np.clip(self.joint_force + step, -s.trust_limit, s.trust_limit)
        handover = self.acceleration(self.joint_force - before) \
            if s.adoption == "handover" and np.any(self.joint_force != before) else None
        adopted = term.used & ~self.used
        self.used = self.used | term.used
        reasons = [why if not ok else "" for why, ok in zip(term.reasons, term.used,
                                                            strict=True)]
        return JointForceStep(estimate, self.joint_force.copy(), self.used.copy(),
                              tuple(reasons), np.max(np.abs(step), axis=0), adopted, handover)
