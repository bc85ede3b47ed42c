"""Which plants norm-optimal ILC converges on (eq (NO2) of
:mod:`exo_ilc_ros.core.learning.norm_optimal`): its trial-to-trial factor per frequency against
plants of other masses than its model's, and the mass range over which it stays below one
(``exo-ilc analyze-loop``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ModelError
from ..learning.norm_optimal_model import (
    PatientLinearisation,
    Weights,
    learning_matrices,
    lifted_model,
)
from ..loop.gains import feedback_gains
from ..params.config import Config
from ..reference.build import build_reference
from .joint_loop import JointLoop
from .patient_load import PatientLoad


def frequency_factor(config: Config, delta: float, frequency_hz: np.ndarray,
                     patient: PatientLoad | None = None) -> list[np.ndarray]:
    """|F(e^jw)| per joint of (NO2) for long trials, per-joint model of gain g_m against the plant
    of gain 1 / (1 + delta):

        F = (We |P_m|^2 + Wd - We conj(P_m) P) / (We |P_m|^2 + Wd + Wu),

    P_m, P the sampled closed loops u_ff -> q (:class:`.convergence.JointLoop`) of the model and
    the plant (with the ``patient``'s linear joint forces, in the model too when the config's
    identification is in the loop). The ``linearised`` model's gravity terms are not in this
    per-joint picture; the lifted check (:func:`lifted_factor`) has them."""
    about = patient is not None and config["identification.enabled"] and \
        config["identification.in_loop"]
    period = float(config["control.period"])
    z = np.exp(2j * np.pi * np.asarray(frequency_hz, dtype=float) * period)
    model_gain = 1.0 / (1.0 + float(config["norm_optimal.model_mass_uncertainty"]))
    weights = Weights.of(config)
    out = []
    kp_all, kd_all = feedback_gains(config)
    for j, (kp, kd) in enumerate(zip(kp_all.tolist(), kd_all.tolist(), strict=True)):
        s, d = (0.0, 0.0) if patient is None else \
            (float(patient.stiffness[j]), float(patient.damping[j]))
        pm, _ = JointLoop(model_gain, kp, kd, period, *((s, d) if about else (0.0, 0.0))
                          ).closed_loop(z)
        pt, _ = JointLoop(1.0 / (1.0 + delta), kp, kd, period, s, d).closed_loop(z)
        we, wd, wu = weights.error[j], weights.input_change[j], weights.input_size[j]
        den = we * np.abs(pm) ** 2 + wd + wu
        out.append(np.asarray(np.abs((we * np.abs(pm) ** 2 + wd - we * np.conj(pm) * pt) / den)))
    return out


@dataclass(frozen=True)
class LiftedRobustness:
    """The whole-trial map du_ff,k+1 = F du_ff,k of (NO2) on the plant of one delta:
    F = Phi - L G_delta, G_delta the ``linearised`` lifted model of that plant."""

    delta: float
    norm: float
    """||F||_2: < 1 the learned input's change shrinks every trial (monotone), ~1 (the
    directions the weights leave unlearned) it stays bounded, > 1 it can grow."""
    radius: float | None = None
    """Spectral radius of F (None: not computed)."""


LIFTED_LIMIT_BYTES = 500e6
"""The largest dense lifted matrix the check builds (it holds several and takes their 2-norm):
7 joints at 100 Hz (5 s: 98 MB) are checked, 3 joints at 1 kHz (1.8 GB) are not."""


def lifted_bytes(config: Config) -> int:
    """Bytes of one dense lifted matrix of the config ((joints (N+1))^2 doubles)."""
    size = config.joints * build_reference(config).samples
    return size * size * 8


def lifted_too_large(config: Config) -> str:
    """Why the lifted check is not run for the config ("": it is)."""
    size = lifted_bytes(config)
    if size <= LIFTED_LIMIT_BYTES:
        return ""
    return (f"the lifted check is not run: one dense lifted matrix of {config.joints} joints at "
            f"{1 / float(config['control.period']):g} Hz would take {size / 1e9:.1f} GB (limit "
            f"{LIFTED_LIMIT_BYTES / 1e9:g} GB); the per-frequency factor stands alone")


def lifted_factor(config: Config, delta: float, radius: bool = False,
                  patient: PatientLinearisation | None = None,
                  model_about_patient: bool = False) -> LiftedRobustness:
    """:class:`LiftedRobustness` of the config's weights against a plant with masses
    (1 + delta) (its closed loop linearised along the reference, (NO4) with delta) and the
    ``patient``'s joint forces; ``model_about_patient``: the law's model rebuilt about them
    (the identification in the loop, taken as exact). ModelError when the matrices would be
    too large (:func:`lifted_too_large`)."""
    too_large = lifted_too_large(config)
    if too_large:
        raise ModelError(too_large)
    matrices = learning_matrices(config, patient if model_about_patient else None)
    plant = lifted_model(config.replace({"norm_optimal.model_kind": "linearised",
                                         "norm_optimal.model_mass_uncertainty": float(delta)}),
                         patient)
    f = matrices.phi - matrices.learning @ plant.g
    rho = float(np.max(np.abs(np.linalg.eigvals(f)))) if radius else None
    return LiftedRobustness(float(delta), float(np.linalg.norm(f, 2)), rho)


def robustness_range(config: Config) -> tuple[float, float]:
    """``norm_optimal.uncertainty_range`` as (low, high)."""
    low, high = config["norm_optimal.uncertainty_range"]
    return float(low), float(high)


def robust_deltas(config: Config, points: int = 3) -> list[float]:
    """The deltas the robustness warning checks: ``points`` evenly over the range."""
    low, high = robustness_range(config)
    if math.isclose(low, high):
        return [low]
    return [float(x) for x in np.linspace(low, high, points)]


@dataclass(frozen=True)
class Robustness:
    """The weights against every delta of ``norm_optimal.uncertainty_range`` checked."""

    low: float
    high: float
    frequency_worst: list[float]
    """max over joints and frequencies of |F| (:func:`frequency_factor`) per delta."""
    lifted: list[LiftedRobustness]
    """Per delta; empty when the lifted check is not run (:attr:`lifted_skipped`)."""
    lifted_skipped: str = ""
    """Why the lifted check was not run ("": it was)."""
    deltas: tuple[float, ...] = ()
    """The deltas checked (those of :attr:`frequency_worst`)."""

    @property
    def robust(self) -> bool:
        """No delta of the range makes a factor exceed 1 (beyond rounding)."""
        return (all(f <= 1.0 + ROBUST_TOLERANCE for f in self.frequency_worst)
                and all(r.norm <= 1.0 + ROBUST_TOLERANCE for r in self.lifted))


ROBUST_TOLERANCE = 1e-6
"""|F| or ||F||_2 up to 1 + this counts as 1 (the directions the law leaves unlearned)."""


def robustness(config: Config, points: int = 3, frequencies: int = 2001) -> Robustness:
    """Check the config's norm-optimal weights and model over ``norm_optimal.uncertainty_range``
    (``points`` deltas): the per-joint factor per frequency and the lifted map's 2-norm (not
    for a lifted matrix above :data:`LIFTED_LIMIT_BYTES`)."""
    low, high = robustness_range(config)
    frequency = np.linspace(0.0, 0.5 / float(config["control.period"]), frequencies)
    deltas = robust_deltas(config, points)
    worst = [max(float(np.max(f)) for f in frequency_factor(config, d, frequency))
             for d in deltas]
    skipped = lifted_too_large(config)
    lifted = [] if skipped else [lifted_factor(config, d) for d in deltas]
    return Robustness(low, high, worst, lifted, skipped, tuple(deltas))
