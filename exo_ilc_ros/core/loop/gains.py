"""The feedback gains the controller runs (:func:`feedback_gains`): ``control.kp`` and
``control.kd`` (s^-2, s^-1, through a_N(q), eqs (11)/(16)), raised on a light joint to the
absolute stiffness and damping ``control.min_stiffness`` (N m/rad) and ``control.min_damping``
(N m s/rad) ask for (issue 33).

Computed torque makes K_P and K_D arm-independent for the arm itself, but not against the
patient: a patient's torque on joint j accelerates it by (a_N(q)^-1)_jj per N m, so the same
K_D is a damping of only K_D / (a_N^-1)_jj N m s/rad against the patient's forces. On the
paper arm's elbow (1 / max_t (a_N(q_d(t))^-1)_jj = 0.011 kg m^2) K_D 30 s^-1 is 0.33 N m s/rad
against a MAS 3 stretch reflex of 2 N m s/rad, 0.1 s late: the elbow limit-cycles at ~5 Hz
(``exo-ilc analyze-loop --patient-ranges``). So, on every arm joint a patient's joint acts on
(``patient.joints``; every arm joint when it is empty), with I_j^-1 = max_t (a_N(q_d(t))^-1)_jj
the joint's lightest inertia along the reference (the one the range analysis takes), and on
every other arm joint k with I_k^-1 = max over the reference and the patient's joints j of
|(a_N(q_d(t))^-1)_kj|, the acceleration a patient's torque gives it through the coupling
(:func:`patient_inverse_inertia`):

    K_P,j = max(kp_j, min(min_stiffness_j I_j^-1, K_P,max)),
    K_D,j = max(kd_j, min(min_damping_j I_j^-1, K_D,max)),                          (G)

the floors capped at K_D,max = :data:`MAX_KD_PERIOD` / T and K_P,max = K_D,max^2 / 4 (critically
damped at the cap; a kp or kd above them is the config's own and kept):
a discrete PD with its command about a period late is stable only for K_D T below ~0.85
(:mod:`.hold`), and a differentiated 14-bit encoder's velocity is that late. An arm joint
no patient joint acts on meets the patient's forces only through a_N^-1; on a light one (the
hand of a human arm from a whole-body URDF: 0.45 kg beyond an elbow the patient acts on) that
coupling left trial 1 1 rad off under PD alone, so its floor scales with the coupling. The
paper arm (every joint a patient's), the UR5 and the Panda (their wrists' coupling times the
minimums is below their kp and kd) keep the gains they had. With the minimums 0 (the default)
the gains are ``control.kp`` and ``control.kd`` exactly.

On the joints a floor raised, ``control.velocity_observer`` (below 1) makes K_D multiply an
observer's velocity instead of the measured one (:func:`velocity_observer_gains`,
:mod:`.observer`): a differenced, low-passed encoder velocity is too late against the reflex
there. The observer stands in for an encoder's velocity, so it is engaged only on a plant
whose measured velocity can be one (the rigid arm, whose ``patient.sensor`` is the device's
encoder); a strapped person (``musculoskeletal.model``) is a plant with no sensor model,
whose measured velocity is the joint's own (MuJoCo's qvel, no lag), and there it is not
engaged: the observer's prediction from the command assumes the nominal arm, which the
person's strapped segments and the cuffs' springs are not (docs/person-with-muscles.md).
"""

from __future__ import annotations

import numpy as np

from ..arm.build import build_arm
from ..params.config import Config
from ..reference.build import build_reference
from .observer import observer_gains
from .patient import patient_joint_indices

MAX_KD_PERIOD = 0.8
"""K_D,max T of (G): below the ~0.85 at which a critically damped PD with its command one
period late stops being stable (:mod:`.hold`)."""


def _inverse_metric_tensors(config: Config) -> np.ndarray:
    """a_N(q_d)^-1 at every sample of the reference, (N+1, n, n)."""
    positions = build_reference(config).position
    return np.asarray(np.linalg.inv(build_arm(config).metric_tensors(positions)))


def lightest_inverse_inertia(config: Config) -> np.ndarray:
    """max over the reference's samples of (a_N(q_d)^-1)_jj per arm joint (kg^-1 m^-2): the
    acceleration per N m of a torque on joint j, the others free."""
    inverse = _inverse_metric_tensors(config)
    return np.asarray(np.max(np.diagonal(inverse, axis1=1, axis2=2), axis=0))


def patient_inverse_inertia(config: Config) -> np.ndarray:
    """Per arm joint k, the acceleration per N m of the patient's torque (kg^-1 m^-2) that the
    floors of (G) scale: on a joint a patient's joint acts on, its own lightest inverse inertia
    (:func:`lightest_inverse_inertia`); on another, max over the reference and the patient's
    joints j of |(a_N(q_d)^-1)_kj|, the acceleration the coupling gives it (a light wrist
    beyond a patient's elbow)."""
    inverse = _inverse_metric_tensors(config)
    out = np.max(np.diagonal(inverse, axis1=1, axis2=2), axis=0)
    on = patient_joint_indices(config)
    off = np.setdiff1d(np.arange(out.shape[0]), on)
    if off.size and len(on):
        out[off] = np.max(np.abs(inverse[:, off][:, :, on]), axis=(0, 2))
    return np.asarray(out)


def gain_caps(period: float) -> tuple[float, float]:
    """(K_P,max, K_D,max) of (G) at the control period ``period`` (s)."""
    kd_max = MAX_KD_PERIOD / float(period)
    return kd_max * kd_max / 4.0, kd_max


def feedback_gains(config: Config) -> tuple[np.ndarray, np.ndarray]:
    """(K_P, K_D) per arm joint by (G): what the controller, the learning law's memory and the
    loop analyses use."""
    kp = np.asarray(config["control.kp"], dtype=float)
    kd = np.asarray(config["control.kd"], dtype=float)
    min_stiffness = np.asarray(config["control.min_stiffness"], dtype=float)
    min_damping = np.asarray(config["control.min_damping"], dtype=float)
    if not (np.any(min_stiffness > 0.0) or np.any(min_damping > 0.0)):
        return kp, kd
    inverse = patient_inverse_inertia(config)
    kp_max, kd_max = gain_caps(config["control.period"])
    kp = np.maximum(kp, np.minimum(min_stiffness * inverse, kp_max))
    kd = np.maximum(kd, np.minimum(min_damping * inverse, kd_max))
    return kp, kd


def measures_true_velocity(config: Config) -> bool:
    """Whether the plant ``config`` runs measures each joint's true velocity whatever the
    config says of sensors: the exoskeleton strapped to a person (``musculoskeletal.model``
    set), a MuJoCo plant with no sensor model (``patient.sensor.*`` is refused with it)."""
    return str(config["musculoskeletal.model"]) != "none"


def velocity_observer_gains(config: Config) -> np.ndarray:
    """(4, n) gains of the velocity observer (:mod:`.observer`) per arm joint: with
    ``control.velocity_observer`` p < 1, on the joints whose K_P or K_D a floor raised above
    ``control.kp``, ``control.kd`` by (G) (the light patient joints, where a lagging velocity
    meets a delayed reflex); zeros elsewhere, with p = 1 (the measured velocity fed back)
    and on a strapped person (``musculoskeletal.model`` set: a plant with no sensor model,
    whose measured velocity is the true one)."""
    kd = np.asarray(config["control.kd"], dtype=float)
    pole = float(config["control.velocity_observer"])
    if pole >= 1.0 or measures_true_velocity(config):
        return np.zeros((4, kd.shape[0]))
    kp_floor, kd_floor = feedback_gains(config)
    raised = (kd_floor > kd) | (kp_floor > np.asarray(config["control.kp"], dtype=float))
    return observer_gains(np.full(kd.shape[0], pole), raised, float(config["control.period"]))
