"""The closed loop with a person strapped in the exoskeleton, in-process
(:class:`StrappedExperiment`): the controller of :mod:`~..loop.controller` sample by sample on
the exoskeleton's joints, the plant :class:`.strapped.StrappedArm`, and the cuff forces per
sample and per trial (:func:`cuff_metrics`), with the cuff-force limit of the safety envelope.

The trial calls the controller's kernel and the plant in the order the graph calls them
(``measure``, the control at sample i, ``step``), so ``exo-ilc run`` with the same config
(plant_simulator steps the same :class:`StrappedArm`) gives these trials bit for bit, including
a trial that presses past the cuff-force limit: there the plant node sees the cuffs, commands
the safe hold from that sample on and the supervisor rebuilds the record with it
(``nodes/plant_simulator.py``, ``core/protocol/trial_protocol.py``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..loop.controller import (
    ABORT,
    HOLD_COUNT,
    Setpoint,
    controller_of,
    guard_of,
    guarded_control_into,
)
from ..loop.record import TrialRecord
from ..params.config import Config
from ..sim.experiment import Experiment
from .cuffs import CUFFS, beyond_cuff_limit
from .model import MuscleDrive
from .neural_drive import drive_for
from .strapped import StrappedArm

DriveFactory = Callable[[Config, Any], "MuscleDrive | None"]
"""Builds the muscles' drive of a config for a compiled model (None: passive muscles)."""


def passive_muscles(config: Config, model: Any) -> MuscleDrive | None:
    """No neural drive: the muscles stay at zero excitation (their passive force-length
    curves and activation decay only)."""
    return None


def uses_person(config: Config) -> bool:
    """True if the config straps a person with muscles into the exoskeleton."""
    return str(config["musculoskeletal.model"]) != "none"


class StrappedExperiment(Experiment):
    """:class:`~..sim.experiment.Experiment` whose plant is the exoskeleton strapped to a
    person with muscles (``musculoskeletal.model``)."""

    def __init__(self, config: Config, drive: DriveFactory = drive_for) -> None:
        super().__init__(config)
        if self.patient.enabled:
            raise ConfigError("musculoskeletal.model", "a person with muscles is the patient: "
                              "turn the virtual patient's joint effects (patient.*) off")
        self.arm = StrappedArm(config, self.reference.position[0], drive)
        self.cuff_limit = np.asarray(config["safety.cuff_force_limit"], dtype=float)

    def make_stepper(self) -> StrappedArm:
        """The plant the graph's plant node steps: this experiment's :class:`StrappedArm`."""
        return self.arm

    def run_trial(self, feedforward: np.ndarray, trial: int,
                  levels: np.ndarray | None = None,
                  learned: np.ndarray | None = None,
                  joint_force: np.ndarray | None = None) -> TrialRecord:
        """One trial from the kept start state (:meth:`StrappedArm.reset`): at each sample the
        controller reads the exoskeleton's (q, qdot), forms eq (11) and the computed torque of
        eq (16) (:func:`~..loop.controller.guarded_control_into`, the error envelope's abort
        and safe hold included) and the strapped model runs the period. The first sample where
        a cuff presses past ``safety.cuff_force_limit`` aborts the trial there: the safe hold
        around the pose of that sample, as an envelope abort. A non-finite state stops the
        trial (NaN from that sample on), as the compiled trial does."""
        ref = self.reference
        u_ff, force = self.trial_inputs(feedforward, trial, joint_force)
        if learned is not None:
            raise ConfigError("patient.learning.gain", "a learning virtual patient does not "
                              "apply to a person with muscles")
        n_samples, n = u_ff.shape
        q_log = np.full((n_samples, n), np.nan)
        qd_log = np.full((n_samples, n), np.nan)
        u_log = np.full((n_samples, n), np.nan)
        effort_log = np.full((n_samples, n), np.nan)
        wrench_log = np.full((n_samples, len(CUFFS), 6), np.nan)
        person_joints = len(self.arm.person_joint_names())
        person_q = np.full((n_samples, person_joints), np.nan)
        person_qd = np.full((n_samples, person_joints), np.nan)
        controller = controller_of(self)
        guard = guard_of(np.empty(n))
        state, q_hold = guard.state, guard.q_hold
        limit = [float(x) for x in self.cuff_limit]
        arm = self.arm
        arm.begin_trial(trial)
        for i in range(n_samples):
            q, qd = arm.measure()
            if not math.isfinite(float(q @ q + qd @ qd)):  # diverged (or beyond doubles)
                state[ABORT] = i if state[ABORT] < 0 else state[ABORT]
                break
            q_log[i] = q
            qd_log[i] = qd
            wrench_log[i] = arm.wrench
            arm.person_state_into(person_q[i], person_qd[i])
            if state[ABORT] < 0 and beyond_cuff_limit(arm.wrench, limit) >= 0:
                state[ABORT] = i
                state[HOLD_COUNT] = 0
                q_hold[:] = q
            guarded_control_into(i, False, Setpoint(u_ff[i], ref.position[i], ref.velocity[i]),
                                 q_log[i], qd_log[i], force[i], controller, guard, u_log[i],
                                 effort_log[i])
            if i + 1 < n_samples:  # the plant clamps as the graph's plant does (a no-op:
                arm.step(effort_log[i])  # the controller clamped with the same rule)
        abort = int(state[ABORT])
        return TrialRecord(trial, ref, q_log, qd_log, u_ff, u_log, effort_log, levels,
                           None if abort < 0 else abort, None, None,
                           None if joint_force is None else force, wrench_log,
                           person_q, person_qd)


def experiment_for(config: Config, drive: DriveFactory = drive_for) -> Experiment:
    """The in-process experiment of ``config``: :class:`StrappedExperiment` with a person
    (``musculoskeletal.model``), else :class:`~..sim.experiment.Experiment`."""
    return StrappedExperiment(config, drive) if uses_person(config) else Experiment(config)
