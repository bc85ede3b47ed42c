"""The rule the safe hold's gains must meet (checked with the config): stable with the command
one control period late. Here, below the config, so the schema can check it; the hold itself is
:mod:`exo_ilc_ros.core.loop.hold`."""

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
