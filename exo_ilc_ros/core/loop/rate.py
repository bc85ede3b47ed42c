"""The control period a law asks for of an arm (``control.period_rule``, issue 33).

A stretch reflex is a velocity feedback of its own, G N m s/rad, that acts on a joint of
inertia I between the controller's samples. Over one period T it changes the joint's velocity
by about G T / I of itself; with G T / I >= 1 no velocity feedback at that period can hold it,
whatever K_D (``exo-ilc analyze-loop --patient-ranges`` reports the ratio as
``JointWorst.sampled_reflex``). MAS 3's reflex (G = 2 N m s/rad, 0.1 s late) on the paper
arm's elbow (I >= 0.011 kg m^2 along the reference) gives 1.83 at 100 Hz: seed 0's patient
464 fails the certificate there at any PD gains and passes at 200 Hz (docs/every-patient.md).
The UR5's and the Panda's patient joints (I >= 0.1) give 0.2 at 100 Hz.

So with ``control.period_rule: reflex`` the configured ``control.period`` is the longest period
the law accepts, and :func:`reflex_period` shortens it to the longest T = period / n (n whole)
with

    max_j G_3 T / I_j < 1,                                                           (R)

over the patient's joints j whose reference is faster than MAS 3's reflex threshold, G_3 MAS
3's reflex gain (:data:`~.patient.MAS_PRESETS`, the strongest the presets hold) and I_j the
joint's lightest inertia along the reference (:func:`~.gains.lightest_inverse_inertia`, as the
floors of (G) and the range analysis take it); T a whole number of the plant's RK4 steps
(``integration_step``) and ``trajectory.duration`` a whole number of T. The paper arm runs
5 ms under config/patient_aware.yaml, the UR5 and the Panda keep 10 ms. A person with muscles
(``musculoskeletal.model``) is left at the configured period: its reflexes are its muscles'
(core/person/neural_drive.py), not the presets', and its MuJoCo step is a period's divisor
of its own. Every program and node runs its config through :func:`with_control_rate` (the
in-process session, the experiment, the trial protocol, the graph's nodes, the CLI), so they
all run the same period.
"""

from __future__ import annotations

import weakref

import numpy as np

from ..errors import ConfigError
from ..params import schema
from ..params.config import Config
from ..reference.build import build_reference
from .gains import lightest_inverse_inertia
from .patient import MAS_PRESETS, patient_joint_indices

REFLEX_RATIO_LIMIT = 1.0
"""(R): G T / I must stay below this on every patient joint."""

DESIGN_GRADE = "3"
"""The MAS grade whose stretch reflex (R) is designed against: the strongest preset."""


def sampled_reflex(config: Config, period: float | None = None) -> np.ndarray:
    """G_3 T / I_j of (R) per arm joint at ``period`` (default: the config's): 0 on a joint no
    patient joint acts on or whose reference never outruns MAS 3's reflex threshold."""
    period = float(config["control.period"]) if period is None else float(period)
    gain, threshold = MAS_PRESETS[DESIGN_GRADE][2], MAS_PRESETS[DESIGN_GRADE][3]
    peak_speed = np.max(np.abs(build_reference(config).velocity), axis=0)
    on = np.zeros(config.joints, dtype=bool)
    on[patient_joint_indices(config)] = True
    active = on & (peak_speed > threshold)
    return np.where(active, gain * period * lightest_inverse_inertia(config), 0.0)


_PERIODS: weakref.WeakKeyDictionary[Config, float] = weakref.WeakKeyDictionary()
"""The period :func:`reflex_period` gave each config still alive (and the config it gave):
a run hands one config to its session, experiment and identification, which each apply the
rule; a Config is immutable, so it is worked out once (~10 ms: the reference and a_N^-1 along
it)."""


def reflex_period(config: Config) -> float:
    """The control period (s) ``config`` runs: ``control.period`` with ``control.period_rule``
    ``fixed`` or a person with muscles, else the longest period / n meeting (R). Raises
    :class:`ConfigError` when no whole number of RK4 steps does."""
    period = float(config["control.period"])
    if config["control.period_rule"] != "reflex" or \
            str(config["musculoskeletal.model"]) != "none":
        return period
    worst = float(np.max(sampled_reflex(config, period), initial=0.0))
    step = float(config["integration_step"])
    duration = float(config["trajectory.duration"])
    for n in range(1, int(round(period / step)) + 1):
        candidate = float(f"{period / n:.12g}")
        if schema.period_problem(candidate, step, duration) is None and \
                worst * candidate / period < REFLEX_RATIO_LIMIT:
            return candidate
    raise ConfigError("control.period_rule",
                      f"no period below control.period {period:g} s in whole RK4 steps "
                      f"(integration_step {step:g} s) holds MAS 3's stretch reflex: G T / I is "
                      f"{worst:.3g} at {period:g} s (core/loop/rate.py)")


def with_control_rate(config: Config) -> Config:
    """``config`` with ``control.period`` the one :func:`reflex_period` gives (``config``
    itself when it is the same). Idempotent: the period it gives meets (R) itself."""
    period = _PERIODS.get(config)
    if period is None:
        period = _PERIODS[config] = reflex_period(config)
    if period == float(config["control.period"]):
        return config
    rated = config.replace({"control.period": period})
    _PERIODS[rated] = period
    return rated
