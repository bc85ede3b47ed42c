"""What the loop's pieces need of a closed-loop configuration (:class:`LoopSetup`): the nominal
and true arm, the sampled reference, gains, limits, the safe hold and the virtual patient.
:class:`exo_ilc_ros.core.sim.experiment.Experiment` provides it; the loop does not know it."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..arm.model import ArmModel
from ..reference.trajectory import SampledReference
from .patient import PatientModel
from .plant import PlantDynamics


class LoopSetup(Protocol):
    """The closed loop of one configuration, as the plant, controller and trial read it."""

    nominal: ArmModel
    """The model the computed torque uses."""
    plant: ArmModel
    """The true (simulated) arm."""
    reference: SampledReference
    kp: np.ndarray
    kd: np.ndarray
    effort_limit: np.ndarray
    error_envelope: np.ndarray
    hold_kp: np.ndarray
    hold_kd: np.ndarray
    hold_ramp: int
    """The safe hold's gains and ramp (samples), :mod:`.hold`."""
    velocity_observer: np.ndarray
    """(4, n) the velocity observer's gains per joint (:mod:`.observer`; zeros: none)."""
    period: float
    substeps: int
    dynamics: PlantDynamics
    patient: PatientModel
