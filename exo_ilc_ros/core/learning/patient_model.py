"""The identified patient in the loop: between trials, the joint forces of the trial just run
are identified (:mod:`.identification`) and, once trustworthy, computed torque adds them along
the reference in the next trial, eqs (9)/(16) with eq (6)'s Q^v, Q^c, Q^f and the reflex back
in (:func:`.joint_force_term.joint_force_term`)::

    Q = a_N(q) u + c_N(q, qdot) + tau_p(q_d, qdot_d)

The rules, per joint, at every trial boundary (:meth:`JointForceModel.conclude`):

1. Only from ``identification.first_trial`` on, and only a joint whose passive parameters
   are trustworthy (excited, not collinear, within ``identification.relative_precision``,
   plausible) and finite, with its reflex only when that is trustworthy too
   (:func:`.joint_force_term.joint_force_term`).
   A refused trial (chatter, non-finite samples) or an estimate that is not trustworthy
   changes nothing: the joint keeps the forces it had (none before its first trustworthy
   estimate), and the step says why.
2. The forces stay within +-``identification.trust_limit`` (N m) at every sample, and move
   toward the new estimate's by at most ``identification.max_change`` (N m) at any sample from
   one trial to the next: the patient never feels a jump.
3. After an envelope abort the forces are kept (the trial is still identified).
4. The learned feed-forward follows (``identification.adoption``, the session applies it):
   ``handover`` gives up a_N(q_d)^-1 times the forces' change, so the total input never
   jumps; ``restart`` starts a newly adopted joint from the law's first feed-forward; ``keep``
   leaves it.
5. The law's update inverts the arm with the patient (:meth:`JointForceModel.
   learning_correction`, ``identification.inverse_gain``); with norm-optimal its model is
   rebuilt about the forces' linearisation instead (:meth:`JointForceModel.linearisation`).

The forces are evaluated on the reference, not the measured state: no quantised velocity and no
delayed reflex is fed back (docs/patient-identification.md). The learning law then learns only
what the model does not explain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arm.model import ArmModel
from ..loop.rate import with_control_rate
from ..loop.record import TrialRecord
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .identification import JointForceIdentifier
from .identification_settings import IdentificationSettings
from .joint_force_term import joint_force_term
from .norm_optimal_model import PatientLinearisation
from .patient_estimate import PatientEstimate
from .qfilter import qfilter_of

_UNBOUNDED = 1e12
"""N m: the limit of a joint-force term that is not clamped (a difference of two)."""


@dataclass(frozen=True)
class JointForceSettings:
    """The ``identification.*`` keys (module docstring for the rules)."""

    in_loop: bool
    first_trial: int
    trust_limit: np.ndarray
    max_change: np.ndarray
    adoption: str
    inverse_gain: float
    mass_error: bool
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
                   bool(config["identification.mass_error"]),
                   IdentificationSettings.from_config(
                       config, forgetting=float(config["identification.forgetting"]),
                       voluntary=bool(config["identification.voluntary"]),
                       relative_precision=float(config["identification.relative_precision"]),
                       reversal_speed=float(config["identification.reversal_speed"])))


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
        config = with_control_rate(config)  # the period the reference was sampled at
        self.settings = JointForceSettings.from_config(config)
        self.reference = reference
        self.identifier = JointForceIdentifier(nominal, self.settings.identification)
        n = nominal.dof
        self.joint_force = np.zeros(reference.position.shape)
        """The forces the next trial adds (zeros until a joint's estimate is trusted)."""
        self.used = np.zeros(n, dtype=bool)
        self._nominal = nominal
        self._qfilter = qfilter_of(config)
        self._inertia: np.ndarray | None = None
        self._nominal_torque: np.ndarray | None = None

    def linearisation(self) -> PatientLinearisation | None:
        """The forces in use linearised along the reference (norm-optimal's model is rebuilt
        about it): per joint stiffness K (+ K_v, the patient's own pull, when fitted) and
        damping B + F_c / v_s sech^2(qdot_d / v_s) (+ D_v) (+ G where |qdot_d| exceeds the
        reflex threshold, its delay neglected). None before any joint is in use."""
        estimate = self.identifier.estimate
        if estimate is None or not np.any(self.used):
            return None
        s = self.settings.identification
        v = self.reference.velocity
        stiffness = np.zeros(v.shape)
        damping = np.zeros(v.shape)
        for j, joint in enumerate(estimate.joints):
            if not self.used[j]:
                continue
            k, b, f = (0.0 if name in joint.absorbed else max(joint.value(name), 0.0)
                       for name in ("stiffness", "viscous", "coulomb"))
            d = b + f / s.stribeck_velocity / np.cosh(v[:, j] / s.stribeck_velocity) ** 2
            if s.voluntary:
                for name in ("voluntary_stiffness", "voluntary_damping"):
                    value = joint.value(name)
                    if joint[name].trustworthy and np.isfinite(value) and value > 0.0:
                        k, d = (k + value, d) if name == "voluntary_stiffness" else (k, d + value)
            if joint.reflex_detected and all(joint[name].trustworthy for name in
                                             ("reflex_gain", "reflex_threshold")):
                d = d + np.where(np.abs(v[:, j]) > joint.value("reflex_threshold"),
                                 max(joint.value("reflex_gain"), 0.0), 0.0)
            stiffness[:, j] = k
            damping[:, j] = d
        if not (np.all(np.isfinite(stiffness)) and np.all(np.isfinite(damping))):
            return None
        return PatientLinearisation(stiffness, damping)

    def nominal_torque(self) -> np.ndarray:
        """a_N(q_d) qddot_d + c_N(q_d, qdot_d) at every sample of the reference, eq (16)'s
        torque without feedback (cached)."""
        if self._nominal_torque is None:
            ref = self.reference
            self._nominal_torque = np.array([
                self._nominal.inverse_dynamics(q, qd, qdd) for q, qd, qdd
                in zip(ref.position, ref.velocity, ref.acceleration, strict=True)])
        return self._nominal_torque

    def acceleration(self, torque: np.ndarray) -> np.ndarray:
        """a_N(q_d)^-1 tau at every sample of the reference: a torque profile in the units of
        the feed-forward (eq (16) maps u to a_N u)."""
        if self._inertia is None:
            self._inertia = self._nominal.metric_tensors(self.reference.position)
        return np.linalg.solve(self._inertia, torque[..., None])[..., 0]

    @property
    def estimate(self) -> PatientEstimate | None:
        """The latest identification (None before the first trial)."""
        return self.identifier.estimate

    def learning_correction(self, record: TrialRecord) -> np.ndarray | None:
        """g a_N(q_d)^-1 [tau_p(q_d, qdot_d) - tau_p(q, qdot) + K_v e + D_v e_dot] along the
        trial, Q-filtered as the law's update is (rule 5): the identified joint forces'
        difference between the reference and the measured motion (the secant, bounded where
        the Coulomb term saturates) and the patient's own pull toward the reference when it is
        fitted, g = ``identification.inverse_gain``, on the joints in use. What the law's
        update adds so that it inverts the arm *with* the patient: an update that inverts only
        the nominal arm, like robust.yaml's u += PD e + e_ddot, leaves a contraction of ~0.9
        per trial where the patient is stiffer than the controller (the forearm's 1 N m/rad
        against K_P a_N ~ 0.5 N m/rad). None: nothing to add."""
        estimate = self.identifier.estimate
        g = self.settings.inverse_gain
        if g == 0.0 or estimate is None or record.aborted or not np.any(self.used):
            return None
        ref = self.reference
        s = self.settings.identification
        at_reference = joint_force_term(estimate, ref.position, ref.velocity, _UNBOUNDED, s)
        measured = joint_force_term(estimate, record.position, record.velocity, _UNBOUNDED, s)
        use = self.used & at_reference.used & measured.used
        torque = np.where(use[None, :], at_reference.torque - measured.torque, 0.0)
        if s.reversal_speed > 0.0:  # no Coulomb secant where either velocity is slow
            torque = torque - self._slow_coulomb(estimate, record, use)
        if s.voluntary:  # the patient's own pull toward q_d, a stiffness and damping on e
            for name, signal in (("voluntary_stiffness", record.error),
                                 ("voluntary_damping", record.error_velocity)):
                gain = estimate.values(name)
                ok = use & np.isfinite(gain) & np.array([j[name].trustworthy
                                                         for j in estimate.joints])
                torque = torque + np.where(ok, np.clip(gain, 0.0, None), 0.0) * signal
        torque = g * torque
        if not np.all(np.isfinite(torque)):
            return None
        correction = self.acceleration(torque)
        return correction if self._qfilter is None else self._qfilter.apply(correction)

    def _slow_coulomb(self, estimate: PatientEstimate, record: TrialRecord,
                      use: np.ndarray) -> np.ndarray:
        """F_c [tanh(qdot_d / v_s) - tanh(qdot / v_s)] on the joints in ``use`` at the samples
        where the reference's or the measured speed is below ``reversal_speed``: there the
        Coulomb law is not known (a hard law sticks, the tanh's secant is a damping F_c / v_s,
        3 N m s/rad for 0.3 N m), so the update does not invert it (measured on MuJoCo's hard
        friction, a reversing exercise: with it patient_aware stayed above 0.005 rad through
        trial 10, without it within from trial 5)."""
        s = self.settings.identification
        v_ref, v = self.reference.velocity, record.velocity
        out = np.zeros(v.shape)
        for j, joint in enumerate(estimate.joints):
            f = joint.value("coulomb")
            if not use[j] or "coulomb" in joint.absorbed or not np.isfinite(f):
                continue
            slow = np.minimum(np.abs(v_ref[:, j]), np.abs(v[:, j])) < s.reversal_speed
            secant = np.tanh(v_ref[:, j] / s.stribeck_velocity) \
                - np.tanh(v[:, j] / s.stribeck_velocity)
            out[:, j] = np.where(slow, min(max(f, 0.0), s.bounds["coulomb"][1]) * secant, 0.0)
        return out

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
        torque = term.torque
        if s.mass_error:  # eq (15): the plant's mass error along the nominal torque
            scale = estimate.values("model_scale")
            known = np.array([j["model_scale"].trustworthy for j in estimate.joints]) \
                & np.isfinite(scale) & term.used
            torque = np.clip(torque + np.where(known, scale, 0.0) * self.nominal_torque(),
                             -s.trust_limit, s.trust_limit)
        target = np.where(term.used[None, :], torque, self.joint_force)
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
