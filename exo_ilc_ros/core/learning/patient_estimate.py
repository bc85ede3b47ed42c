"""What the identification of the patient's joint forces reports (:mod:`.identification`): each
parameter with its interval and whether it is usable, per joint and for the arm."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

PARAMETERS = ("viscous", "coulomb", "stiffness", "rest_position", "offset", "model_scale",
              "voluntary_stiffness", "voluntary_damping", "reflex_gain", "reflex_threshold",
              "reflex_delay")
"""Every parameter a :class:`JointEstimate` reports."""
UNITS = {"viscous": "N m s/rad", "coulomb": "N m", "stiffness": "N m/rad",
         "rest_position": "rad", "offset": "N m", "model_scale": "1",
         "voluntary_stiffness": "N m/rad", "voluntary_damping": "N m s/rad",
         "reflex_gain": "N m s/rad", "reflex_threshold": "rad/s", "reflex_delay": "s"}


@dataclass(frozen=True)
class ParameterEstimate:
    """One identified parameter with its 95 % interval and whether it may be used."""

    name: str
    value: float
    standard_error: float
    """The noise's (autocorrelation-robust); the precision rule of :attr:`trustworthy` reads
    it."""
    low: float
    high: float
    """The 95 % interval: value +- 1.96 :attr:`total_error` (noise and model error)."""
    identifiable: bool
    """The excitation determines it (excited, not collinear with another parameter)."""
    trustworthy: bool
    """Identifiable, finite, precise and physically plausible: usable."""
    reason: str = ""
    """Why not trustworthy ("" when it is)."""
    combined_with: tuple[str, ...] = ()
    """Parameters the movement cannot separate from this one, left out of the fit: this
    estimate carries their combination (e.g. ``offset`` = c + F_c sgn(qdot) on a joint that
    never reverses), its truth is that combination's."""
    model_error: float = 0.0
    """What the friction law's choice moves the estimate by (a smooth tanh, the model's, or
    a hard sign, a dry contact's): a model error more samples do not shrink; 0 when Coulomb
    friction is not fitted."""

    @property
    def total_error(self) -> float:
        """The standard error of the noise and the model error together: the interval's."""
        return math.hypot(self.standard_error, self.model_error)

    @property
    def unit(self) -> str:
        """The parameter's unit."""
        return UNITS[self.name]


@dataclass(frozen=True)
class JointEstimate:
    """Everything identified for one joint after the trials so far."""

    joint: int
    parameters: Mapping[str, ParameterEstimate]
    """By name, every entry of :data:`PARAMETERS`."""
    reflex_detected: bool
    condition_number: float
    """Of the column-scaled information matrix of the model reported."""
    residual_rms: float
    """N m: RMS of the filtered torque the model leaves unexplained."""
    peak_stretch_velocity: float
    """rad/s: the fastest abs(qdot) of every trial so far (what excited the reflex)."""
    trials: int
    trustworthy: bool
    """Every parameter the joint-force term needs (viscous, Coulomb, stiffness, rest position,
    offset and the reflex when detected) is trustworthy."""
    reasons: tuple[str, ...]
    """Why not trustworthy (empty when it is)."""
    inseparable: tuple[tuple[str, str, float], ...] = ()
    """The pairs of parameters the trials so far cannot separate, (kept, left out,
    correlation; nan: by the movement's shape, a joint that never reversed): only their
    combination is determined, carried by the first."""
    absorbed: tuple[str, ...] = ()
    """The parameters left out of the fit because another carries them (no value, not
    identifiable; the joint-force term adds them as 0: their share is in the other's)."""

    def __getitem__(self, name: str) -> ParameterEstimate:
        return self.parameters[name]

    def value(self, name: str) -> float:
        """The estimate of ``name``."""
        return self.parameters[name].value


@dataclass(frozen=True)
class PatientEstimate:
    """The identification after a trial: one :class:`JointEstimate` per joint."""

    trial: int
    joints: tuple[JointEstimate, ...]
    rejected: str = ""
    """Why the last trial's data was not used ("": it was)."""

    @property
    def trustworthy(self) -> bool:
        """Every joint's estimate is usable."""
        return all(j.trustworthy for j in self.joints)

    def values(self, name: str) -> np.ndarray:
        """``name``'s estimate on every joint."""
        return np.array([j.value(name) for j in self.joints])

    def as_dict(self) -> dict[str, Any]:
        """Plain JSON-able values (non-finite numbers as None), for a summary, a bag or
        ``/diagnostics``: per joint every parameter's value, standard error, model error,
        interval, identifiable, trustworthy and reason, and the joint's condition number, residual,
        peak stretch velocity, trials, trustworthy and reasons."""
        return {"trial": self.trial, "rejected": self.rejected,
                "trustworthy": self.trustworthy,
                "joints": [{"joint": j.joint, "trustworthy": j.trustworthy,
                            "reasons": list(j.reasons), "reflex_detected": j.reflex_detected,
                            "condition_number": _plain(j.condition_number),
                            "residual_rms": _plain(j.residual_rms),
                            "peak_stretch_velocity": _plain(j.peak_stretch_velocity),
                            "trials": j.trials,
                            "inseparable": [{"kept": a, "left_out": b,
                                             "correlation": _plain(r)}
                                            for a, b, r in j.inseparable],
                            "parameters": {name: {"value": _plain(p.value),
                                                  "standard_error": _plain(p.standard_error),
                                                  "model_error": _plain(p.model_error),
                                                  "low": _plain(p.low), "high": _plain(p.high),
                                                  "unit": p.unit,
                                                  "identifiable": bool(p.identifiable),
                                                  "trustworthy": bool(p.trustworthy),
                                                  "reason": p.reason,
                                                  "combined_with": list(p.combined_with)}
                                           for name, p in j.parameters.items()}}
                           for j in self.joints]}


def _plain(x: float) -> float | None:
    """A finite float, or None."""
    x = float(x)
    return x if math.isfinite(x) else None
