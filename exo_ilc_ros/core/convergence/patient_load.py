"""A virtual patient's linear joint forces as the convergence analysis sees them (``exo-ilc
analyze-loop --scenario``): eq (6)'s Q^c and Q^v of a scenario's patient per joint, stiffness and
damping, the passive ones, the spastic arm's (its Modified Ashworth preset) and the patient's
own pull toward the reference, which stiffens and damps the error the same way. The Coulomb
friction and the reflex are not linear and are left out (the Coulomb term saturates over most of
the movement; the reflex acts only above its threshold)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arm.build import build_arm
from ..learning.norm_optimal_model import PatientLinearisation
from ..loop.patient import patient_values, spasticity_values
from ..params.config import Config
from ..reference.build import build_reference


@dataclass(frozen=True)
class PatientLoad:
    """Per joint: the patient's stiffness and damping in N m/rad and N m s/rad, and the same
    per unit of the joint's nominal inertia at the reference's start (s^-2, s^-1:
    :class:`.joint_loop.JointLoop`'s units)."""

    label: str
    torque_stiffness: np.ndarray
    torque_damping: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray

    def along(self, config: Config) -> PatientLinearisation:
        """The same forces at every sample of the config's reference (the lifted check's)."""
        samples = build_reference(config).position.shape[0]
        return PatientLinearisation(np.tile(self.torque_stiffness, (samples, 1)),
                                    np.tile(self.torque_damping, (samples, 1)))


def patient_load(config: Config, label: str = "") -> PatientLoad:
    """The linear joint forces of the patient ``config`` describes (``patient.*`` keys)."""
    spastic_stiffness, spastic_damping, *_ = spasticity_values(config)
    stiffness = patient_values(config, "passive.stiffness") \
        + patient_values(config, "voluntary.stiffness") + np.asarray(spastic_stiffness)
    damping = patient_values(config, "friction.viscous") \
        + patient_values(config, "voluntary.damping") + np.asarray(spastic_damping)
    inertia = np.diag(build_arm(config).metric_tensor(build_reference(config).position[0]))
    return PatientLoad(label, stiffness, damping, stiffness / inertia, damping / inertia)
