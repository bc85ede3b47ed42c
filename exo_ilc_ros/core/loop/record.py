"""What one trial produced (:class:`TrialRecord`): the record every law learns from, every
store keeps and every report reads."""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ..reference.trajectory import SampledReference


@dataclass(frozen=True, eq=False)
class TrialRecord:
    """What one trial produced, sampled at t_i = i * period, i = 0..N.

    ``control_input`` is the whole u of eq (11) the controller formed (feed-forward plus
    feedback), ``effort`` the torque it commanded, ``levels`` the M, M', M'' (rows) per joint
    that formed this trial's feed-forward (None for trial 1, which has no predecessor).
    """

    trial: int
    reference: SampledReference
    position: np.ndarray
    velocity: np.ndarray
    feedforward: np.ndarray
    control_input: np.ndarray
    effort: np.ndarray
    levels: np.ndarray | None = None
    aborted_at: int | None = None
    """Index of the first sample outside the error envelope (the trial was aborted there and
    the safe hold commanded from it on); None for a completed trial. No law learns from it."""
    true_position: np.ndarray | None = None
    """The plant's true q at every sample when the sensors (:mod:`.patient`) made the measured
    ``position`` differ from it; None: the measured state is the true one."""
    true_velocity: np.ndarray | None = None
    """The plant's true qdot, as ``true_position``."""
    joint_force: np.ndarray | None = None
    """The identified patient's joint forces (N m per sample) computed torque added to the
    effort (:mod:`exo_ilc_ros.core.learning.patient_model`); None: none."""
    cuff_wrench: np.ndarray | None = None
    """A person strapped in cuffs (:mod:`exo_ilc_ros.core.person`): per sample and cuff
    (upper arm, forearm) the force (N) and torque (N m) the cuff applies to the person, in the
    cuff's frame, shape (N+1, 2, 6); None: no person."""
    person_position: np.ndarray | None = None
    """A person strapped in: the person's own joint angles per sample (rad, its MuJoCo joints
    in qpos order; what ``/person/joint_states`` carries), shape (N+1, joints); None: no
    person (or a record rebuilt from the wire, which does not read them)."""
    person_velocity: np.ndarray | None = None
    """As ``person_position``: the person's joint velocities (rad/s)."""

    @property
    def aborted(self) -> bool:
        """True if the trial was aborted by the error envelope."""
        return self.aborted_at is not None

    @cached_property
    def error(self) -> np.ndarray:
        """e = q_d - q."""
        return np.asarray(self.reference.position - self.position)

    @cached_property
    def error_velocity(self) -> np.ndarray:
        """e_dot = qdot_d - qdot, from the measured velocity."""
        return np.asarray(self.reference.velocity - self.velocity)

    @cached_property
    def error_acceleration(self) -> np.ndarray:
        """e_ddot = qddot_d - qddot, qddot by finite differences of the measured velocity
        (central inside, one-sided at the ends: ``numpy.gradient``); no acceleration is measured."""
        estimate = np.gradient(self.velocity, self.reference.period, axis=0)
        return np.asarray(self.reference.acceleration - estimate)

    @cached_property
    def max_abs_error(self) -> np.ndarray:
        """max_t |e_j(t)| per joint (of an aborted trial: up to and including the abort
        sample, the tracking part; the hold after it does not track the reference)."""
        end = None if self.aborted_at is None else self.aborted_at + 1
        return np.asarray(np.max(np.abs(self.error[:end]), axis=0))

    @cached_property
    def true_max_abs_error(self) -> np.ndarray:
        """max_t |q_d,j(t) - q_j(t)| per joint of the plant's true state (as
        :attr:`max_abs_error`, which holds what the controller measured); equal to it when
        the record has no true state apart."""
        if self.true_position is None:
            return self.max_abs_error
        end = None if self.aborted_at is None else self.aborted_at + 1
        error = self.reference.position - self.true_position
        return np.asarray(np.max(np.abs(error[:end]), axis=0))


def position_velocity_record(record: TrialRecord, kd: np.ndarray,
                             fed_back: np.ndarray | None = None) -> TrialRecord:
    """``record`` re-read with qdot from its measured position by central differences
    (``numpy.gradient``: zero phase, possible between trials; the first and last sample take
    their neighbour's: the one-sided differences there are twice as noisy, and the last
    sample's feed-forward, never applied, random-walked on them) instead of the velocity the
    controller measured during the trial, and ``control_input`` as the controller would have
    formed it with that velocity (u + K_D (qdot_measured - qdot_position)). A differentiated,
    filtered encoder velocity lags (half a period for the difference, the filter's time
    constant on top); a law that learns from it drives K_P e + K_D (e_dot + tau qddot) + ...
    to zero, not e, and keeps a repeating error ~ tau K_D / K_P qddot_d
    (docs/patient-aware.md). The learning law's ``learning_velocity: position``.
    ``fed_back``: the velocity the controller fed back where it was not the measured one (the
    velocity observer's, :func:`.observer.fed_back_velocity`; None: the measured), so u +
    K_D (qdot_fed_back - qdot_position)."""
    velocity = np.gradient(record.position, record.reference.period, axis=0)
    if velocity.shape[0] > 2:  # the ends held at their neighbours' (one-sided differences
        velocity[0], velocity[-1] = velocity[1], velocity[-2]  # spiked the last u_ff sample)
    control_input = record.control_input + np.asarray(kd, dtype=float) * (
        (record.velocity if fed_back is None else fed_back) - velocity)
    return replace(record, velocity=velocity, control_input=control_input)
