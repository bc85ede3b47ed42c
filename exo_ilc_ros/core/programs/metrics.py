"""What a therapist reads from a trial: tracking, assistance, the patient's share of the work,
smoothness and a spasticity indicator, per trial (:func:`trial_metrics`) and per session
(:func:`session_metrics`).

Definitions (per joint j over the samples of the trial; an aborted trial up to the abort):

* tracking: RMS and peak of the *true* error q_d - q (the plant's state where the sensors made
  the measured one differ, ``TrialRecord.true_position``), rad;
* assistance: RMS of the robot's torque beyond the nominal gravity compensation,
  tau_robot - g_N(q) with g_N(q) = c_N(q, 0) of eq (8), N m; and RMS of the learned
  feed-forward u_ff, rad/s^2 (the units of u in eq (11));
* the patient's share of the work (Guidali et al., JRRD 50(3), 2013): 1 - sum|tau_robot| /
  sum|tau_required|, tau_required = a(q) qdd + c(q, qdot) of the arm being moved (the plant:
  the model with the trial's true masses) along the true movement, qdd by central differences,
  plus the passive arm's friction and stiffness (:class:`PassiveArm`; not its spasticity).
  0: the robot did all of it; 1: the patient did; < 0: the patient worked against the robot.
  Per joint and over all joints together. Its resolution: the robot's torque is held over a
  control period while the movement's need changes within it, so the two sums cannot be told
  apart closer than half the sum of the need's sample-to-sample changes,
  r = sum|tau_req(i+1) - tau_req(i)| / (2 sum|tau_req|); a share within +-r is 0 (a passive
  patient's share, never a tiny negative number that would read "worked against the robot");
* smoothness: the spectral arc length (SPARC, Balasubramanian et al., J NeuroEng Rehabil 12:112,
  2015) of the joint-space speed |qdot|: negative, closer to 0 is smoother (a rest-to-rest
  quintic gives about -1.5);
* spasticity indicator: B_j (N m s/rad), the least-squares slope of the torque the robot had to
  add beyond the required one, tau_robot - tau_required (what the patient resisted), against
  the joint velocity (McCrea et al. 2003: a velocity-dependent resistance B qdot that rises
  with the Modified Ashworth grade). About 0 for a relaxed arm, > 0 when the arm resists
  motion in proportion to its speed. Not measurable (NaN) on a joint that moved less than
  :data:`MIN_RANGE_OF_MOTION` in the trial: its velocities are too small and too few for a
  velocity-dependent term to be told apart from the rest (a fit there gave -6.5 N m s/rad on a
  joint an exercise held still).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..arm.build import build_arm, build_plant
from ..arm.model import ArmModel
from ..loop.patient import patient_values, rest_positions
from ..loop.record import TrialRecord
from ..params.config import Config

METRIC_UNITS = {
    "rms_error": "rad", "max_error": "rad", "assistance_rms": "N m",
    "feedforward_rms": "rad/s^2", "patient_share": "1", "smoothness": "1",
    "spasticity": "N m s/rad",
}
"""The unit of each metric (for tables, summaries and the report)."""
PER_JOINT = ("rms_error", "max_error", "assistance_rms", "feedforward_rms", "patient_share",
             "spasticity")
"""Metrics with one value per joint (the rest: one value for the whole arm)."""
OPTIONAL_PER_JOINT = ("range_of_motion", "patient_share_resolution")
"""Per-joint values added later (a bag or export without them reads them as unknown)."""
SUMMARY_PREFIX = "metric/"
MIN_RANGE_OF_MOTION = float(np.radians(5.0))
"""rad: a joint that moved less than 5 degrees in a trial has no measurable spasticity
indicator."""


@dataclass(frozen=True)
class TrialMetrics:
    """The metrics of one trial (module docstring); arrays have one entry per joint."""

    trial: int
    rms_error: np.ndarray
    max_error: np.ndarray
    assistance_rms: np.ndarray
    feedforward_rms: np.ndarray
    patient_share: np.ndarray
    patient_share_total: float
    smoothness: float
    spasticity: np.ndarray
    aborted: bool = False
    range_of_motion: np.ndarray | None = None
    """rad, max q - min q per joint (None: not recorded, a bag of an earlier version)."""
    patient_share_resolution: np.ndarray | None = None
    """Per joint: the share's resolution r (module docstring; None: not recorded)."""
    patient_share_total_resolution: float = 0.0

    def to_json(self) -> dict[str, Any]:
        """Plain numbers, by metric name (``patient_share_total`` beside the per-joint one);
        a value not measurable is null."""
        out: dict[str, Any] = {"trial": self.trial, "aborted": self.aborted}
        for name in PER_JOINT + OPTIONAL_PER_JOINT:
            values = getattr(self, name)
            if values is not None:
                out[name] = [float(x) if np.isfinite(x) else None for x in values]
        out["patient_share_total"] = float(self.patient_share_total)
        out["patient_share_total_resolution"] = float(self.patient_share_total_resolution)
        out["smoothness"] = float(self.smoothness)
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> TrialMetrics:
        """Inverse of :meth:`to_json`."""
        arrays = {name: np.array([np.nan if x is None else x for x in data[name]], dtype=float)
                  for name in PER_JOINT + OPTIONAL_PER_JOINT if name in data}
        return cls(int(data["trial"]), patient_share_total=float(data["patient_share_total"]),
                   smoothness=float(data["smoothness"]), aborted=bool(data.get("aborted")),
                   patient_share_total_resolution=float(
                       data.get("patient_share_total_resolution", 0.0)), **arrays)

    def spasticity_reasons(self) -> list[str]:
        """Per joint: why the spasticity indicator is not measurable ("" where it is)."""
        out = []
        for j, value in enumerate(self.spasticity):
            moved = None if self.range_of_motion is None else float(self.range_of_motion[j])
            if moved is not None and moved < MIN_RANGE_OF_MOTION:
                out.append(f"the joint barely moved ({np.degrees(moved):.2g} deg, needs "
                           f"{np.degrees(MIN_RANGE_OF_MOTION):g} deg)")
            elif not np.isfinite(value):
                out.append("no velocity to fit against")
            else:
                out.append("")
        return out

    def summary_values(self, names: Sequence[str]) -> list[tuple[str, str]]:
        """``metric/<name>/<joint>`` and ``metric/<name>`` key-values (floats as repr) for the
        trial summary (``wire.protocol``)."""
        out = []
        for name in PER_JOINT + OPTIONAL_PER_JOINT:
            values = getattr(self, name)
            if values is not None:
                out += [(f"{SUMMARY_PREFIX}{name}/{n}", repr(float(x)))
                        for n, x in zip(names, values, strict=True)]
        out.append((f"{SUMMARY_PREFIX}patient_share", repr(float(self.patient_share_total))))
        out.append((f"{SUMMARY_PREFIX}patient_share_resolution",
                    repr(float(self.patient_share_total_resolution))))
        out.append((f"{SUMMARY_PREFIX}smoothness", repr(float(self.smoothness))))
        return out

    @classmethod
    def from_summary(cls, trial: int, values: dict[str, str], names: Sequence[str],
                     aborted: bool = False) -> TrialMetrics | None:
        """Inverse of :meth:`summary_values` (None if the summary has no metrics)."""
        try:
            arrays = {name: np.array([float(values[f"{SUMMARY_PREFIX}{name}/{n}"])
                                      for n in names]) for name in PER_JOINT}
            total = float(values[f"{SUMMARY_PREFIX}patient_share"])
            smooth = float(values[f"{SUMMARY_PREFIX}smoothness"])
            for name in OPTIONAL_PER_JOINT:
                keys = [f"{SUMMARY_PREFIX}{name}/{n}" for n in names]
                if all(key in values for key in keys):
                    arrays[name] = np.array([float(values[key]) for key in keys])
            resolution = float(values.get(f"{SUMMARY_PREFIX}patient_share_resolution", 0.0))
        except (KeyError, ValueError):
            return None
        return cls(trial, patient_share_total=total, smoothness=smooth, aborted=aborted,
                   patient_share_total_resolution=resolution, **arrays)


def sparc(speed: np.ndarray, rate_hz: float, pad_level: int = 4, cutoff_hz: float = 10.0,
          amplitude_threshold: float = 0.05) -> float:
    """Spectral arc length of a speed profile (Balasubramanian et al. 2015, their reference
    implementation): the arc length of the normalised magnitude spectrum up to the last
    frequency (<= ``cutoff_hz``) where it is above ``amplitude_threshold``."""
    speed = np.asarray(speed, dtype=float)
    if not np.all(np.isfinite(speed)):
        return float("nan")  # a diverged plant (core/loop/divergence.py): no spectrum
    if speed.size < 2 or not np.any(speed):
        return 0.0
    nfft = int(2 ** (np.ceil(np.log2(speed.size)) + pad_level))
    frequency = np.arange(0, rate_hz, rate_hz / nfft)
    magnitude = np.abs(np.fft.fft(speed, nfft))
    magnitude = magnitude / np.max(magnitude)
    keep = frequency <= cutoff_hz
    f_sel, m_sel = frequency[keep], magnitude[keep]
    above = np.flatnonzero(m_sel >= amplitude_threshold)
    if above.size == 0:  # too short for a bin under the cutoff
        return 0.0
    f_sel = f_sel[above[0]:above[-1] + 1]
    m_sel = m_sel[above[0]:above[-1] + 1]
    if f_sel.size < 2:
        return 0.0
    span = f_sel[-1] - f_sel[0]
    return float(-np.sum(np.sqrt((np.diff(f_sel) / span) ** 2 + np.diff(m_sel) ** 2)))


def _rms(x: np.ndarray) -> np.ndarray:
    return np.asarray(np.sqrt(np.mean(np.square(x), axis=0)))


def gravity_compensation(model: ArmModel, position: np.ndarray) -> np.ndarray:
    """g(q) = c(q, 0) of eq (8) at every sample: the torque that holds the arm still."""
    zero = np.zeros(position.shape[1])
    return np.array([model.bias_forces(q, zero) for q in position])


@dataclass(frozen=True)
class PassiveArm:
    """The passive joint forces of the patient's arm that moving it requires (the virtual
    patient's friction and passive stiffness, ``patient.friction.*``, ``patient.passive.*``;
    not the spastic part, which the spasticity indicator shows): per joint
    B qdot + F_c tanh(qdot / v_s) + K (q - q_0)."""

    viscous: np.ndarray
    coulomb: np.ndarray
    stribeck_velocity: float
    stiffness: np.ndarray
    rest_position: np.ndarray

    @classmethod
    def from_config(cls, config: Config) -> PassiveArm | None:
        """The config's passive arm, None when it has none (or no ``patient.*``)."""
        try:
            arm = cls(patient_values(config, "friction.viscous"),
                      patient_values(config, "friction.coulomb"),
                      float(config["patient.friction.stribeck_velocity"]),
                      patient_values(config, "passive.stiffness"),
                      rest_positions(config))
        except KeyError:
            return None
        if not (np.any(arm.viscous) or np.any(arm.coulomb) or np.any(arm.stiffness)):
            return None
        return arm

    def torque(self, position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """The torque that overcomes the passive forces at every sample (N m)."""
        return np.asarray(self.viscous * velocity
                          + self.coulomb * np.tanh(velocity / self.stribeck_velocity)
                          + self.stiffness * (position - self.rest_position))


def required_torque(model: ArmModel, position: np.ndarray, velocity: np.ndarray,
                    period: float, passive: PassiveArm | None = None) -> np.ndarray:
    """a(q) qdd + c(q, qdot) of ``model`` along the movement (qdd by ``numpy.gradient``), plus
    the ``passive`` arm's forces."""
    acceleration = np.gradient(velocity, period, axis=0)
    rigid = np.array([model.inverse_dynamics(q, v, a)
                      for q, v, a in zip(position, velocity, acceleration, strict=True)])
    return rigid if passive is None else rigid + passive.torque(position, velocity)


def velocity_slope(resistance: np.ndarray, velocity: np.ndarray,
                   range_of_motion: np.ndarray | None = None) -> np.ndarray:
    """Per joint the least-squares slope B of resistance = B qdot + c; NaN where it is not
    identifiable: qdot constant, or the joint moved less than :data:`MIN_RANGE_OF_MOTION`
    (``range_of_motion``, rad)."""
    out = np.full(resistance.shape[1], np.nan)
    for j in range(resistance.shape[1]):
        if range_of_motion is not None and range_of_motion[j] < MIN_RANGE_OF_MOTION:
            continue
        v = velocity[:, j] - velocity[:, j].mean()
        denominator = math.fsum(v * v)
        if denominator > 1e-12:
            out[j] = math.fsum(v * (resistance[:, j] - resistance[:, j].mean())) / denominator
    return out


def share_resolution(required: np.ndarray) -> tuple[np.ndarray, float]:
    """r = sum|tau_req(i+1) - tau_req(i)| / (2 sum|tau_req|) per joint and for the whole arm:
    how closely sums of a torque held over each control period can match the movement's need
    (module docstring)."""
    change = np.sum(np.abs(np.diff(required, axis=0)), axis=0)
    need = np.sum(np.abs(required), axis=0)
    per_joint = np.where(need > 0.0, 0.5 * change / np.where(need > 0.0, need, 1.0), 0.0)
    total = 0.5 * float(np.sum(change)) / float(np.sum(need)) if np.sum(need) > 0 else 0.0
    return np.asarray(per_joint), total


def _resolved(share: np.ndarray | float, resolution: np.ndarray | float) -> Any:
    """``share``, with 0 where it is within +-``resolution`` (not resolvable from 0)."""
    return np.where(np.abs(share) <= resolution, 0.0, share)


def trial_metrics(record: TrialRecord, nominal: ArmModel, plant: ArmModel,
                  passive: PassiveArm | None = None) -> TrialMetrics:
    """The metrics of ``record`` (module docstring): ``nominal`` is the controller's model
    (gravity compensation), ``plant`` the arm being moved and ``passive`` its passive forces
    (required torque)."""
    end = None if record.aborted_at is None else record.aborted_at + 1
    true_q = getattr(record, "true_position", None)
    true_qd = getattr(record, "true_velocity", None)
    q = np.asarray(record.position if true_q is None else true_q)[:end]
    qd = np.asarray(record.velocity if true_qd is None else true_qd)[:end]
    error = (record.reference.position[:end] - q)
    period = record.reference.period
    # The effort of sample i is held over [t_i, t_i+1): the torque acting at sample i.
    effort = np.asarray(record.effort)[:end]
    beyond_gravity = effort - gravity_compensation(nominal, np.asarray(record.position)[:end])
    required = required_torque(plant, q, qd, period, passive) if q.shape[0] > 2 else effort
    robot = np.sum(np.abs(effort), axis=0)
    needed = np.sum(np.abs(required), axis=0)
    share = np.where(needed > 0.0, 1.0 - robot / np.where(needed > 0.0, needed, 1.0), 0.0)
    total = 1.0 - float(np.sum(robot)) / float(np.sum(needed)) if np.sum(needed) > 0 else 0.0
    resolution, total_resolution = share_resolution(required)
    speed = np.linalg.norm(qd, axis=1)
    moved = np.max(q, axis=0) - np.min(q, axis=0)
    return TrialMetrics(record.trial, _rms(error), np.max(np.abs(error), axis=0),
                        _rms(beyond_gravity), _rms(np.asarray(record.feedforward)[:end]),
                        np.asarray(_resolved(share, resolution)),
                        float(_resolved(total, total_resolution)), sparc(speed, 1.0 / period),
                        velocity_slope(effort - required, qd, moved), record.aborted, moved,
                        resolution, total_resolution)


@dataclass(frozen=True)
class SessionMetrics:
    """One exercise of a session: its first and last trial's metrics and their change."""

    trials: int
    aborted: int
    first: TrialMetrics
    last: TrialMetrics

    def to_json(self) -> dict[str, Any]:
        """``{"trials", "aborted", "first", "last"}`` (the trials' :meth:`TrialMetrics.to_json`)."""
        return {"trials": self.trials, "aborted": self.aborted, "first": self.first.to_json(),
                "last": self.last.to_json()}


def session_metrics(metrics: Sequence[TrialMetrics]) -> SessionMetrics | None:
    """The session's summary (None for no trials)."""
    if not metrics:
        return None
    return SessionMetrics(len(metrics), sum(m.aborted for m in metrics), metrics[0], metrics[-1])


_MODELS: dict[str, tuple[ArmModel, ArmModel, PassiveArm | None]] = {}


def config_models(config: Config) -> tuple[ArmModel, ArmModel, PassiveArm | None]:
    """The nominal model, the plant (:func:`~exo_ilc_ros.core.arm.build.build_plant`) and the
    passive arm of ``config``, cached by the config's digest (a node measures every trial with
    them)."""
    key = config.digest()
    if key not in _MODELS:
        _MODELS.clear()
        _MODELS[key] = (build_arm(config), build_plant(config), PassiveArm.from_config(config))
    return _MODELS[key]


def config_metrics(record: TrialRecord, config: Config) -> TrialMetrics:
    """The metrics of ``record``, a trial of ``config``."""
    return trial_metrics(record, *config_models(config))


def metric_summary_values(record: TrialRecord, config: Config,
                          names: Sequence[str]) -> list[tuple[str, str]]:
    """The ``metric/...`` key-values of ``record``'s trial summary (the supervisor's)."""
    return config_metrics(record, config).summary_values(names)
