"""The identified joint forces as the term computed torque would add, eqs (9)/(16) with eq
(6)'s Q^v, Q^c, Q^f (and the reflex) back in, within trust limits."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .identification_settings import PASSIVE_PARAMETERS, IdentificationSettings
from .patient_estimate import JointEstimate, PatientEstimate

REFLEX_PARAMETERS = ("reflex_gain", "reflex_threshold", "reflex_delay")
"""The stretch reflex's parameters: added only when detected and all three trustworthy."""


def _reflex_usable(joint: JointEstimate) -> bool:
    """The joint's reflex is detected and every parameter of it trustworthy."""
    return joint.reflex_detected and all(joint[name].trustworthy for name in REFLEX_PARAMETERS)


@dataclass(frozen=True, eq=False)
class JointForceTerm:
    """The identified joint forces computed torque would add (:func:`joint_force_term`)."""

    torque: np.ndarray
    """(samples, n) N m: tau_p along the given states, 0 on a joint not used, clamped."""
    used: np.ndarray
    """(n,) bool: the joint's estimate was trustworthy and is in ``torque``."""
    reasons: tuple[str, ...]
    """Per joint: why it is not used ("" when it is)."""
    clamped: np.ndarray
    """(n,) int: samples where the limit clamped the joint's term."""


def joint_force_term(estimate: PatientEstimate, position: np.ndarray, velocity: np.ndarray,
                     limit: np.ndarray | float, settings: IdentificationSettings | None = None
                     ) -> JointForceTerm:
    """tau_p = B qdot + F_c tanh(qdot / v_s) + K (q - q_0) + G sgn(v) max(0, abs(v) - v_th)
    (K q + c where no rest position q_0 is defined: no significant stiffness),
    v = qdot(t - tau_r) (the first value before the start), the term eq (6)'s Q^v, Q^f, Q^c
    and the reflex add to computed torque, eqs (9)/(16): Q = a_N(q) u + c_N(q, qdot) + tau_p,
    along the (samples, n) ``position`` and ``velocity`` (the reference's, so that no measured
    velocity is fed back). A joint's passive forces are used when its passive parameters are
    trustworthy and its checks (condition, chatter, the patient's own effort) pass (a parameter
    the movement cannot separate from another adds 0: the other carries their combination,
    e.g. the offset c + F_c sgn(qdot) on a joint that never reverses), its reflex
    only when detected and trustworthy too; each parameter inside its plausible range, the
    term clamped to +-``limit``
    (N m, per joint); any other joint adds 0 and says why."""
    s = settings or IdentificationSettings()
    q = np.asarray(position, dtype=float)
    qd = np.asarray(velocity, dtype=float)
    n = len(estimate.joints)
    if q.ndim != 2 or q.shape[1] != n or qd.shape != q.shape:
        raise ValueError(f"position and velocity must both be (samples, {n}), got {q.shape} "
                         f"and {qd.shape}")
    bound = np.broadcast_to(np.asarray(limit, dtype=float), (n,))
    torque = np.zeros(q.shape)
    used = np.zeros(n, dtype=bool)
    clamped = np.zeros(n, dtype=int)
    reasons = []
    for j, joint in enumerate(estimate.joints):
        rest = joint["rest_position"].trustworthy and math.isfinite(joint.value("rest_position"))
        names = ["viscous", "coulomb", "stiffness", "rest_position" if rest else "offset"]
        reflex = _reflex_usable(joint)
        if reflex:
            names += list(REFLEX_PARAMETERS)
        values = {name: 0.0 if name in joint.absorbed else joint.value(name)
                  for name in names}
        why = ""
        passive = [r for r in joint.reasons
                   if r.split(":", 1)[0] not in REFLEX_PARAMETERS]
        if passive or not all(joint[name].trustworthy for name in PASSIVE_PARAMETERS
                              if name not in joint.absorbed):
            why = "; ".join(passive) or "not trustworthy"
        elif not all(math.isfinite(v) for v in values.values()):
            why = "non-finite estimate"
        elif not (np.all(np.isfinite(q[:, j])) and np.all(np.isfinite(qd[:, j]))
                  and math.isfinite(float(bound[j])) and bound[j] >= 0.0):
            why = "non-finite states or limit"
        if why:
            reasons.append(why)
            continue
        for name, value in values.items():
            if name in s.bounds:
                low, high = s.bounds[name]
                values[name] = min(max(value, low), high)
        v = qd[:, j]
        spring = values["stiffness"] * (q[:, j] - values["rest_position"]) if rest else \
            values["stiffness"] * q[:, j] + values["offset"]  # K q + c: no rest without K
        term = (values["viscous"] * v
                + values["coulomb"] * np.tanh(v / s.stribeck_velocity) + spring)
        if reflex:
            delay = int(round(values["reflex_delay"] / s.period))
            delayed = np.concatenate([np.repeat(v[:1], delay), v[:v.shape[0] - delay]]) \
                if delay > 0 else v
            excess = np.maximum(np.abs(delayed) - values["reflex_threshold"], 0.0)
            term = term + values["reflex_gain"] * np.sign(delayed) * excess
        clamped[j] = int(np.sum(np.abs(term) > bound[j]))
        torque[:, j] = np.clip(term, -bound[j], bound[j])
        used[j] = True
        reasons.append("")
    return JointForceTerm(torque, used, tuple(reasons), clamped)
