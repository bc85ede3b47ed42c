"""The rule the safe hold's and homing's gains must meet (checked with the config): stable with
the command one control period late. Here, below the config, so the schema can check it; the
hold itself is :mod:`exo_ilc_ros.core.loop.hold`, homing :mod:`exo_ilc_ros.core.protocol.homing`."""

from __future__ import annotations

from typing import Any

import numpy as np

RULE_DELAY_PERIODS = 1
"""The schema's rule: the hold must be stable with the command this many periods late."""


def hold_radius(kp: float, kd: float, period: float, delay: int) -> float:
    """Spectral radius of one joint's hold as the controller sees it: the double integrator
    qddot = u of computed torque with the nominal model, u = -kp q - kd qdot held over each
    ``period`` (zero-order hold) and applied ``delay`` periods after its sample. Below 1:
    stable."""
    t = float(period)
    n = 2 + delay
    a = np.zeros((n, n))
    a[0, 0] = a[1, 1] = 1.0
    a[0, 1] = t
    gain = np.array([-kp, -kd])
    if delay == 0:
        a[0, :2] += 0.5 * t * t * gain
        a[1, :2] += t * gain
    else:
        a[0, 2] = 0.5 * t * t  # the oldest command is applied now
        a[1, 2] = t
        for s in range(2, n - 1):
            a[s, s + 1] = 1.0  # the queue moves on
        a[n - 1, :2] = gain  # this sample's command joins the queue
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def pid_radius(kp: float, kd: float, ki: float, period: float, delay: int) -> float:
    """Spectral radius of one joint's homing loop as the controller sees it: :func:`hold_radius`'s
    double integrator under u = kp e + kd e_dot + ki z, e = -q, with the integral z summed
    before use (z_k = z_(k-1) + period e_k), held over each ``period`` and applied ``delay``
    periods after its sample (ki 0: :func:`hold_radius`, the integral not used). Below 1:
    stable."""
    if ki == 0.0:
        return hold_radius(kp, kd, period, delay)
    t = float(period)
    n = 3 + delay
    a = np.zeros((n, n))
    a[0, 0] = a[1, 1] = a[2, 2] = 1.0
    a[0, 1] = t
    a[2, 0] = -t  # z_k = z_(k-1) - period q_k: state 2 holds z_(k-1)
    gain = np.array([-(kp + ki * t), -kd, ki])
    if delay == 0:
        a[0, :3] += 0.5 * t * t * gain
        a[1, :3] += t * gain
    else:
        a[0, 3] = 0.5 * t * t
        a[1, 3] = t
        for s in range(3, n - 1):
            a[s, s + 1] = 1.0
        a[n - 1, :3] = gain
    return float(np.max(np.abs(np.linalg.eigvals(a))))


def homing_gain_problem(values: Any) -> tuple[str, str] | None:
    """(key, rule) if homing's gains (``homing.kp``, ``kd``, ``ki``) are not stable with
    :data:`RULE_DELAY_PERIODS` periods of delay at ``control.period`` (:func:`pid_radius`),
    else None."""
    period = values["control.period"]
    for j, (kp, kd, ki) in enumerate(zip(values["homing.kp"], values["homing.kd"],
                                         values["homing.ki"], strict=True)):
        radius = pid_radius(kp, kd, ki, period, RULE_DELAY_PERIODS)
        if not radius < 1.0:
            return ("homing.ki" if ki > 0.0 and hold_radius(kp, kd, period,
                                                            RULE_DELAY_PERIODS) < 1.0
                    else "homing.kd",
                    f"joint {j + 1}: homing kp {kp:g}, kd {kd:g}, ki {ki:g} at control.period "
                    f"{period:g} s are not stable with the command {RULE_DELAY_PERIODS} periods "
                    f"late (spectral radius {radius:.3f} >= 1); a triple pole at -a "
                    "(kd 3a, kp 3a^2, ki a^3) is stable for a x control.period up to ~0.2, "
                    "and ki must stay below kp x kd")
    return None


def hold_gain_problem(values: Any) -> tuple[str, str] | None:
    """(key, rule) if the hold's gains are not stable with :data:`RULE_DELAY_PERIODS` periods
    of delay at ``control.period`` (:func:`hold_radius`), else None."""
    period = values["control.period"]
    for j, (kp, kd) in enumerate(zip(values["safety.hold_kp"], values["safety.hold_kd"],
                                     strict=True)):
        radius = hold_radius(kp, kd, period, RULE_DELAY_PERIODS)
        if not radius < 1.0:
            return ("safety.hold_kd",
                    f"joint {j + 1}: hold_kp {kp:g}, hold_kd {kd:g} at control.period "
                    f"{period:g} s are not stable with the command {RULE_DELAY_PERIODS} periods "
                    f"late (spectral radius {radius:.3f} >= 1); keep hold_kd x control.period "
                    "below ~0.5 with hold_kp near hold_kd^2 / 4")
    return None
