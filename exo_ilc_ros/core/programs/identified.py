"""The identified patient as a therapist and a bag see it: per joint the damping B, Coulomb
friction F_c, passive stiffness K, rest position q0 and reflex gain G with their 95 % intervals,
whether the estimate is trustworthy and whether the loop uses it (:class:`Identified`, from a
trial boundary's :class:`..learning.patient_model.JointForceStep`).

In a trial summary (``wire.protocol``; floats as repr, booleans ``true``/``false``), the same
keys every trial of a run with ``identification.enabled`` (none without it):

* ``identified/<p>/<joint>``, ``identified/<p>/low/<joint>``, ``identified/<p>/high/<joint>``:
  the estimate of ``p`` (:data:`SHOWN`) and its 95 % interval, in ``p``'s unit (:data:`UNITS`),
  ``nan`` where unknown;
* ``identified/<p>/identifiable/<joint>``: the trials so far determine ``p``;
* ``identified/trustworthy/<joint>``: every parameter the joint-force term needs is usable;
* ``identified/used/<joint>``: computed torque adds the joint's identified forces in the next
  trial (``identification.in_loop``);
* ``identified/reason/<joint>``: why this boundary did not move the joint's forces to the
  estimate, and why the estimate is not trustworthy ("" when neither);
* ``identified/inseparable/<joint>``: the parameters the trials cannot separate, e.g.
  ``offset carries coulomb (never reversed)`` or ``stiffness ~ model_scale (r -0.999)``: only
  their combination is determined ("" when none);
* ``identified/rejected``: why the trial's data was not used at all ("": it was).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..learning.patient_estimate import UNITS as ESTIMATE_UNITS
from ..learning.patient_model import JointForceStep

SUMMARY_PREFIX = "identified/"
SHOWN = ("viscous", "coulomb", "stiffness", "rest_position", "reflex_gain")
"""The parameters shown per joint (of :data:`..learning.patient_estimate.PARAMETERS`)."""
SYMBOLS = {"viscous": "B", "coulomb": "F_c", "stiffness": "K", "rest_position": "q0",
           "reflex_gain": "G"}
WORDS = {"viscous": "damping", "coulomb": "Coulomb friction", "stiffness": "stiffness",
         "rest_position": "rest position", "reflex_gain": "reflex gain"}
"""What a therapist calls each parameter."""
UNITS = {name: ESTIMATE_UNITS[name] for name in SHOWN}


@dataclass(frozen=True)
class IdentifiedParameter:
    """One parameter: estimate and 95 % interval (NaN: unknown), identifiable or not."""

    value: float
    low: float
    high: float
    identifiable: bool


@dataclass(frozen=True)
class IdentifiedJoint:
    """One joint's identification after a trial."""

    name: str
    parameters: Mapping[str, IdentifiedParameter]
    """By name, every entry of :data:`SHOWN`."""
    trustworthy: bool
    used: bool
    """Computed torque adds the joint's identified forces in the next trial."""
    reason: str
    """Why not used or not trustworthy ("" when neither)."""
    inseparable: str = ""
    """The pairs the trials cannot separate (:func:`inseparable_text`; "" when none)."""

    def __getitem__(self, name: str) -> IdentifiedParameter:
        return self.parameters[name]


@dataclass(frozen=True)
class Identified:
    """The identification after trial ``trial`` (module docstring)."""

    trial: int
    joints: tuple[IdentifiedJoint, ...]
    rejected: str = ""

    @classmethod
    def from_step(cls, step: JointForceStep, names: Sequence[str]) -> Identified:
        """What trial boundary ``step`` identified, for joints ``names``."""
        estimate = step.estimate
        joints = []
        for j, (name, joint) in enumerate(zip(names, estimate.joints, strict=True)):
            parameters = {p: IdentifiedParameter(_float(joint[p].value), _float(joint[p].low),
                                                 _float(joint[p].high),
                                                 bool(joint[p].identifiable))
                          for p in SHOWN}
            parts = [step.reasons[j]] if step.reasons[j] else []
            why = "; ".join(joint.reasons)
            if not joint.trustworthy and why and why not in parts:
                parts.append(why)
            joints.append(IdentifiedJoint(name, parameters, bool(joint.trustworthy),
                                          bool(step.used[j]), "; ".join(parts),
                                          inseparable_text(joint.inseparable,
                                                           joint.absorbed)))
        return cls(int(estimate.trial), tuple(joints), str(estimate.rejected))

    def summary_values(self) -> list[tuple[str, str]]:
        """The ``identified/...`` key-values of the trial summary (module docstring)."""
        out: list[tuple[str, str]] = []
        for p in SHOWN:
            for field_name in ("", "low/", "high/"):
                out += [(f"{SUMMARY_PREFIX}{p}/{field_name}{j.name}",
                         repr(getattr(j[p], field_name.rstrip("/") or "value")))
                        for j in self.joints]
            out += [(f"{SUMMARY_PREFIX}{p}/identifiable/{j.name}", _flag(j[p].identifiable))
                    for j in self.joints]
        out += [(f"{SUMMARY_PREFIX}trustworthy/{j.name}", _flag(j.trustworthy))
                for j in self.joints]
        out += [(f"{SUMMARY_PREFIX}used/{j.name}", _flag(j.used)) for j in self.joints]
        out += [(f"{SUMMARY_PREFIX}reason/{j.name}", j.reason) for j in self.joints]
        out += [(f"{SUMMARY_PREFIX}inseparable/{j.name}", j.inseparable) for j in self.joints]
        out.append((f"{SUMMARY_PREFIX}rejected", self.rejected))
        return out

    def status_values(self) -> list[tuple[str, str]]:
        """``identified/trial`` and one readable ``identified/<joint>`` line each (B, F_c, K,
        q0, G with intervals and units, trusted, in the loop): the supervisor's health on
        ``/diagnostics``."""
        out = [(f"{SUMMARY_PREFIX}trial", str(self.trial))]
        for j in self.joints:
            cells = "; ".join(f"{SYMBOLS[p]} {format_value(p, j[p])} {UNITS[p]}" for p in SHOWN)
            out.append((f"{SUMMARY_PREFIX}{j.name}",
                        f"{cells}; trusted {'yes' if j.trustworthy else 'no'}; in the loop "
                        f"{'yes' if j.used else 'no'}" + (f" ({j.reason})" if j.reason else "")
                        + (f"; not separable: {j.inseparable}" if j.inseparable else "")))
        if self.rejected:
            out.append((f"{SUMMARY_PREFIX}rejected", self.rejected))
        return out

    @classmethod
    def from_summary(cls, trial: int, values: Mapping[str, str],
                     names: Sequence[str]) -> Identified | None:
        """Inverse of :meth:`summary_values` (None: the summary has no identification, e.g.
        a bag of a run without it or of an earlier version)."""
        try:
            joints = []
            for name in names:
                parameters = {p: IdentifiedParameter(
                    float(values[f"{SUMMARY_PREFIX}{p}/{name}"]),
                    float(values[f"{SUMMARY_PREFIX}{p}/low/{name}"]),
                    float(values[f"{SUMMARY_PREFIX}{p}/high/{name}"]),
                    values[f"{SUMMARY_PREFIX}{p}/identifiable/{name}"] == "true")
                    for p in SHOWN}
                joints.append(IdentifiedJoint(
                    name, parameters, values[f"{SUMMARY_PREFIX}trustworthy/{name}"] == "true",
                    values[f"{SUMMARY_PREFIX}used/{name}"] == "true",
                    values.get(f"{SUMMARY_PREFIX}reason/{name}", ""),
                    values.get(f"{SUMMARY_PREFIX}inseparable/{name}", "")))
        except (KeyError, ValueError):
            return None
        return cls(trial, tuple(joints), values.get(f"{SUMMARY_PREFIX}rejected", ""))

    def to_json(self) -> dict[str, Any]:
        """Plain values (non-finite numbers as None): what a profile version keeps of its
        session's last trial (``metrics.identification``)."""
        return {"trial": self.trial, "rejected": self.rejected,
                "joints": [{"joint": j.name, "trustworthy": j.trustworthy, "used": j.used,
                            "reason": j.reason, "inseparable": j.inseparable,
                            "parameters": {p: {"value": _plain(x.value), "low": _plain(x.low),
                                               "high": _plain(x.high), "unit": UNITS[p],
                                               "identifiable": x.identifiable}
                                           for p, x in j.parameters.items()}}
                           for j in self.joints]}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> Identified:
        """Inverse of :meth:`to_json` (KeyError, TypeError or ValueError if malformed)."""
        joints = []
        for j in data["joints"]:
            parameters = {p: IdentifiedParameter(_float(x["value"]), _float(x["low"]),
                                                 _float(x["high"]), bool(x["identifiable"]))
                          for p, x in j["parameters"].items() if p in SHOWN}
            joints.append(IdentifiedJoint(str(j["joint"]), parameters, bool(j["trustworthy"]),
                                          bool(j["used"]), str(j.get("reason", "")),
                                          str(j.get("inseparable", ""))))
        return cls(int(data["trial"]), tuple(joints), str(data.get("rejected", "")))


def inseparable_text(pairs: Sequence[tuple[str, str, float]], absorbed: Sequence[str]) -> str:
    """``offset carries coulomb (never reversed); stiffness ~ model_scale (r -0.999)``: each
    pair the trials cannot separate, "carries" where the second was left out of the fit and
    the first holds their combination (a NaN correlation: by the movement's shape, a joint
    that never reversed, or too slow to tell a smooth Coulomb law from a hard one)."""
    parts = []
    for kept, other, r in pairs:
        how = f"r {r:.3f}" if not math.isnan(r) else \
            "too slow for the friction law" if kept == "viscous" else "never reversed"
        verb = "carries" if other in absorbed else "~"
        parts.append(f"{kept} {verb} {other} ({how})")
    return "; ".join(parts)


def _float(x: Any) -> float:
    return math.nan if x is None else float(x)


def _plain(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _flag(x: bool) -> str:
    return "true" if x else "false"


def format_value(p: str, x: IdentifiedParameter) -> str:
    """``0.82 [0.79, 0.85]`` (``?`` for unknown; ``(n.i.)`` appended when not identifiable)."""
    def g(v: float) -> str:
        return f"{v:.3g}" if math.isfinite(v) else "?"
    text = f"{g(x.value)} [{g(x.low)}, {g(x.high)}]"
    return text if x.identifiable else text + " (n.i.)"
