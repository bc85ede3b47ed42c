"""How the between-trial identification of the patient's joint forces filters, forgets and
judges (:mod:`.identification`), and its linear columns."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..params.config import Config

PASSIVE_PARAMETERS = ("viscous", "coulomb", "stiffness", "offset", "model_scale")
"""The linear parameters a usable estimate needs, in column order."""
BASE_PARAMETERS = (*PASSIVE_PARAMETERS, "voluntary_stiffness", "voluntary_damping")
"""Every joint's linear columns: the passive ones, then the patient's own effort (nuisance
parameters, zero columns when no reference is given)."""
KEEP_ORDER = ("stiffness", "viscous", "offset", "coulomb", "voluntary_stiffness",
              "voluntary_damping", "model_scale")
"""Of two parameters the movement cannot separate, one of them Coulomb friction (with
``reversal_speed`` > 0), the one earlier here is kept and carries their combination, the other
is left out of the fit."""


def _default_thresholds() -> tuple[float, ...]:
    return tuple(float(x) for x in np.round(np.arange(0.05, 1.0 + 1e-9, 0.025), 6))


def _default_precision() -> dict[str, float]:
    return {"viscous": 0.02, "coulomb": 0.02, "stiffness": 0.1, "rest_position": 0.05,
            "offset": 0.02, "model_scale": 0.01, "reflex_gain": 0.05}


def _default_bounds() -> dict[str, tuple[float, float]]:
    return {"viscous": (0.0, 20.0), "coulomb": (0.0, 10.0), "stiffness": (0.0, 100.0),
            "rest_position": (-math.pi, math.pi), "model_scale": (-0.5, 0.5),
            "reflex_gain": (0.0, 20.0)}


Z95 = 1.959963984540054
"""The normal distribution's 97.5 % quantile: 95 % intervals."""


@dataclass(frozen=True)
class IdentificationSettings:
    """How the identification filters, forgets and judges (module docstring)."""

    period: float = 0.01
    """T (s): the control period of the samples."""
    stribeck_velocity: float = 0.1
    """v_s (rad/s) of the Coulomb column tanh(qdot / v_s) (MAHI Open Exo's tanh(10 qdot))."""
    filter_bandwidth: float = 2.0 * math.pi * 4.0
    """w_f (rad/s) of H(s) = w_f^2 / (s + w_f)^2: above the movement's band (a 5 s quintic's
    energy is below ~1 Hz), below the loop's noise (4 Hz: the least error on the virtual
    patient over 1-6 Hz, docs/patient-identification.md)."""
    smoothing_cutoff: float = 10.0
    """Hz: the zero-phase low-pass (4th-order Butterworth, forward and backward) of the
    position the nonlinear columns and the arm's momentum are built from."""
    forgetting: float = 0.9
    """lambda per trial: memory ~1 / (1 - lambda) trials (0.9: ~10)."""
    effort_delay: int = 0
    """Control periods between a command and its torque at the joint (known, not identified)."""
    burn_in: float = 0.3
    """s at each trial's start left out (the filters' start, and a learned feed-forward's
    first samples, which shake the arm faster than the first-order hold follows)."""
    model_scale: bool = True
    """Identify delta (the plant's mass error along the nominal torque); False: trust a_N."""
    reflex: bool = True
    """Identify the stretch reflex (G, v_th, tau_r)."""
    voluntary: bool = False
    """With the trial's reference: columns for the patient's own effort toward it,
    -L[q_d - q] and -L[qdot_d - qdot] (L: a first-order lag), so that it is not taken for
    stiffness and damping. Off by default: for a passive patient these columns are nearly
    collinear with the passive ones while the learning converges (the damping then misses
    10 %); on for a patient known to push (docs/patient-identification.md)."""
    voluntary_minimum_torque: float = 1e-3
    """N m RMS: the least torque the voluntary columns must explain (when not fitted) for the
    estimate to be suspected of holding the patient's own effort (the shipped scenarios:
    noise-free friction 2e-5, voluntary and realistic 3e-3 to 3e-2)."""
    voluntary_lag: float = 0.15
    """s: the time constant of L (the virtual patient's voluntary.time_constant of
    ``voluntary.yaml``)."""
    reflex_thresholds: tuple[float, ...] = field(default_factory=_default_thresholds)
    """v_th grid (rad/s)."""
    reflex_delays: tuple[float, ...] = (0.05, 0.06, 0.07, 0.08, 0.09, 0.1, 0.11, 0.12, 0.13,
                                        0.14, 0.15)
    """tau_r grid (s), rounded to control periods (the virtual patient's 0.1 s in the middle)."""
    max_condition: float = 1000.0
    """Largest condition number of the column-scaled information matrix (sqrt of the
    eigenvalue ratio: the regressor's own condition number) of a usable estimate."""
    max_variance_inflation: float = 1000.0
    """Largest variance inflation factor of a parameter (its variance over the variance it
    would have with a column orthogonal to the others): above it the parameter is not
    identifiable from this excitation (collinear with another)."""
    relative_precision: float = 0.1
    """Largest 95 % half-width over abs(value) of a usable parameter (the accuracy issue 28
    asks for) ..."""
    absolute_precision: Mapping[str, float] = field(default_factory=_default_precision)
    """... unless the half-width is below this (a parameter near zero)."""
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=_default_bounds)
    """Plausible range of each parameter; an estimate beyond it by more than three standard
    errors (and more than its absolute precision) is absurd and never usable."""
    max_unresolved_motion: float = 5e-4
    """rad: the largest RMS of the measured position above the smoothing cutoff, on any joint,
    of a trial that is used (a 14-bit encoder's quantisation is 1.1e-4; a chattering spastic
    elbow 2e-3 to 7e-3, where the filtered regression is biased on every coupled joint)."""
    reflex_minimum_torque: float = 0.02
    """N m: a reflex is reported only if its fitted torque at the fastest stretch seen
    exceeds this (and G's interval excludes 0)."""
    reversal_speed: float = 0.0
    """rad/s: Coulomb friction is fitted only from the samples where the joint moved faster
    than this (for the filter's memory, at least 1 s of them), and told from the offset only
    on a joint that moved so in both directions (2 v_s = 0.2: tanh 0.964, where a smooth and
    a hard Coulomb law agree within 4 %; config/patient_aware.yaml). 0: the tanh law is
    trusted at every speed (every sample counts).
    Otherwise F_c sgn(qdot) is a constant of the movement wherever the law is known, and what
    separates it from the offset is the slow start and end, where the law is a guess (tanh,
    or MuJoCo's hard ``frictionloss``): the pair is not separately identifiable."""
    max_correlation: float = 0.99
    """Two parameters whose estimates correlate by more than this (in absolute value) are not
    separately identifiable and reported as such; with ``reversal_speed`` > 0 a pair with
    Coulomb friction is fitted as its combination only (the less needed one left out, the other
    carrying it, :data:`KEEP_ORDER`)."""

    def __post_init__(self) -> None:
        if not self.period > 0.0:
            raise ValueError("identification: period must be > 0")
        if not 0.0 < self.forgetting <= 1.0:
            raise ValueError("identification: forgetting must be in (0, 1]")
        if not (self.filter_bandwidth > 0.0 and self.stribeck_velocity > 0.0):
            raise ValueError("identification: filter bandwidth and Stribeck velocity must be > 0")
        if not 0.0 < self.smoothing_cutoff < 0.5 / self.period:
            raise ValueError("identification: the smoothing cutoff must be below Nyquist")
        if not (self.reversal_speed >= 0.0 and 0.0 < self.max_correlation <= 1.0):
            raise ValueError("identification: reversal_speed must be >= 0 and max_correlation "
                             "in (0, 1]")
        if self.effort_delay < 0:
            raise ValueError("identification: effort_delay must be >= 0")

    @classmethod
    def from_config(cls, config: Config, **changes: Any) -> IdentificationSettings:
        """The defaults at the config's control period and actuator delay (the plant's
        ``patient.effort_delay``: known on an arm from its drive, not identified), with
        ``changes``."""
        values: dict[str, Any] = {"period": float(config["control.period"]),
                                  "effort_delay": int(config["patient.effort_delay"])}
        values.update(changes)
        return cls(**values)

    @property
    def delay_samples(self) -> tuple[int, ...]:
        """The reflex delay grid in control periods (distinct, sorted)."""
        return tuple(sorted({int(round(d / self.period)) for d in self.reflex_delays}))


def judge(name: str, value: float, se: float, s: IdentificationSettings) -> str:
    """"" if a parameter's estimate is usable, else why not: finite, within ``s.bounds``
    (3 SE or the precision floor), 95 % half-width of its noise within the precision."""
    if not (math.isfinite(value) and math.isfinite(se)):
        return "non-finite estimate"
    if name in s.bounds:
        low, high = s.bounds[name]
        margin = max(3.0 * se, s.absolute_precision.get(name, 0.0))
        if value < low - margin or value > high + margin:
            return (f"absurd: {value:.4g} outside [{low:g}, {high:g}] by more than "
                    f"{margin:.2g} (3 SE, or the precision floor)")
    half = Z95 * se
    tolerance = max(s.relative_precision * abs(value), s.absolute_precision.get(name, 0.0))
    if half > tolerance:
        return f"imprecise: 95 % half-width {half:.3g} > {tolerance:.3g}"
    return ""
