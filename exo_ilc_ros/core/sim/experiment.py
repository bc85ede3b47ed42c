"""The paper's experiment in-process: config -> nominal model, plant, reference and law; one
trial of the closed loop (:class:`Experiment`). The trial-to-trial loop is ``core.session``."""

from __future__ import annotations

import numpy as np

from ..arm.build import build_arm, build_plant
from ..errors import SafetyError
from ..loop.controller import controller_of
from ..loop.divergence import plant_damping, stable_substeps
from ..loop.gains import feedback_gains, velocity_observer_gains
from ..loop.hold import ramp_samples
from ..loop.patient import PatientModel, patient_trial
from ..loop.plant import PlantDynamics, plant_integration
from ..loop.rate import with_control_rate
from ..loop.record import TrialRecord
from ..loop.stepper import ArmStepper, PlantStepper
from ..loop.trial import simulate_trial_guarded
from ..params.config import Config
from ..reference.build import build_reference

_NO_TORQUE = np.zeros((0, 0))


class Experiment:
    """The closed loop of one configuration: nominal model in the controller, the plant with
    masses scaled by (1 + mass_uncertainty) and a person's segments (``person.*``), the sampled
    reference, gains and limits, at the period ``control.period_rule`` gives
    (:func:`~..loop.rate.with_control_rate`)."""

    def __init__(self, config: Config) -> None:
        self.config = config = with_control_rate(config)
        self.mass_uncertainty = float(config["mass_uncertainty"])
        self.nominal = build_arm(config)
        self.plant = build_plant(config)
        self.reference = build_reference(config)
        self.kp, self.kd = feedback_gains(config)
        """K_P, K_D of eq (11): control.kp, control.kd with their floors (:mod:`..loop.gains`)."""
        self.velocity_observer = velocity_observer_gains(config)
        """The velocity observer's gains per joint (:mod:`..loop.observer`; zeros: none)."""
        self.effort_limit = np.asarray(config["control.effort_limit"], dtype=float)
        self.error_envelope = np.asarray(config["safety.error_envelope"], dtype=float)
        self.hold_kp = np.asarray(config["safety.hold_kp"], dtype=float)
        self.hold_kd = np.asarray(config["safety.hold_kd"], dtype=float)
        self.hold_ramp = ramp_samples(config["safety.hold_ramp"], config["control.period"])
        """The safe hold's gains and ramp (samples) (:mod:`.hold`): every place that commands
        the hold takes them from here."""
        self.period = float(config["control.period"])
        self.substeps = int(round(self.period / config["integration_step"]))
        self.dynamics = PlantDynamics.FULL if config["dynamics"] == "full" \
            else PlantDynamics.PAPER_APPROXIMATION
        self.patient = PatientModel(config)
        """The virtual patient's effects (all off by default)."""
        self.substeps = stable_substeps(self.plant, self.reference.position,
                                        plant_damping(self.patient), self.period, self.substeps)
        """RK4 sub-steps per period: ``integration_step``'s, more where a joint damping is too
        stiff for it (:func:`divergence.stable_substeps`)."""

    def make_stepper(self) -> ArmStepper:
        """The plant one control period at a time, for the graph's plant node: our RK4 plant
        with the virtual patient (a person with muscles: its strapped model)."""
        return PlantStepper(self)

    def trial_inputs(self, feedforward: np.ndarray, trial: int,
                     joint_force: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """A trial's feed-forward and joint forces as contiguous arrays of the reference's
        shape (no joint forces: zeros), refused unless finite: what :meth:`run_trial` runs."""
        shape = self.reference.position.shape
        u_ff = np.ascontiguousarray(feedforward, dtype=float)
        if u_ff.shape != shape:
            raise ValueError(f"feed-forward must have shape {shape}, got {u_ff.shape}")
        if not np.all(np.isfinite(u_ff)):
            raise SafetyError(f"trial {trial}: the feed-forward holds non-finite values; "
                              "refusing to run it")
        force = np.zeros(shape) if joint_force is None else \
            np.ascontiguousarray(joint_force, dtype=float)
        if force.shape != shape or not np.all(np.isfinite(force)):
            raise SafetyError(f"trial {trial}: the joint forces must be finite and "
                              f"{shape}; refusing to run them")
        return u_ff, force

    def run_trial(self, feedforward: np.ndarray, trial: int,
                  levels: np.ndarray | None = None,
                  learned: np.ndarray | None = None,
                  joint_force: np.ndarray | None = None) -> TrialRecord:
        """One trial with the given feed-forward, from x_d(0), guarded by the error envelope
        (``record.aborted_at`` set if it left it: safe hold from that sample on), with the
        virtual patient's effects and trial ``trial``'s draws (:mod:`.patient`); ``learned``:
        the torque a learning patient adds (:class:`.patient.PatientLearning`; None: none);
        ``joint_force``: the identified joint forces computed torque adds, N m per sample
        (:mod:`exo_ilc_ros.core.learning.patient_model`; None: none)."""
        ref = self.reference
        u_ff, force = self.trial_inputs(feedforward, trial, joint_force)
        patient = self.patient
        draws = patient.draws(trial, ref.samples)
        q, qd, u, effort, abort, q_true, qd_true = simulate_trial_guarded(
            u_ff, force, controller_of(self),
            plant_integration(self.period, self.substeps, self.plant.kernel_args,
                              self.nominal.kernel_args, int(self.dynamics)),
            patient_trial(patient, draws, ref.position, ref.velocity,
                          learned if learned is not None
                          else np.zeros(ref.position.shape) if patient.learns else _NO_TORQUE))
        measured = patient.measures
        return TrialRecord(trial, ref, q, qd, u_ff, u, effort, levels,
                           None if abort < 0 else int(abort), q_true if measured else None,
                           qd_true if measured else None,
                           None if joint_force is None else force)
