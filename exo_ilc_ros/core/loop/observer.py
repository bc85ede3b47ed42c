"""The velocity the feedback uses on a joint with ``control.velocity_observer`` (issue 33): an
observer of the joint's position, velocity and unknown acceleration driven by the command
the controller gave, instead of the measured velocity (:mod:`.gains` says on which joints).

A differenced, low-passed encoder velocity lags the true one (half a period for the backward
difference, the filter's time constant on top: 15 ms for a 14-bit encoder at 100 Hz with a
10 ms filter). Against a stretch reflex that acts on the velocity 0.1 s ago, that lag turns
K_D's damping into too little at ~14 Hz on a light joint, and the joint chatters there
(docs/patient-aware.md). A drive that knows what it commanded can predict the motion a period
ahead and correct the prediction with the measured position only (a Luenberger observer of
the double integrator computed torque makes of the nominal arm, with the patient's and the
model's errors as an unknown acceleration d; the alpha-beta-gamma tracker with a known input).
Per joint, at sample i with the measured position q_i and the command u_{i-1} of the sample
before:

    predicted  q^- = q^_{i-1} + T v^_{i-1} + T^2 / 2 (u_{i-1} + d^_{i-1}),
               v^- = v^_{i-1} + T (u_{i-1} + d^_{i-1}),
    corrected  r = q_i - q^-,  q^_i = q^- + l_q r,  v^_i = v^- + l_v / T r,
               d^_i = d^_{i-1} + l_d / T^2 r,                                            (O)

and v^_i is the velocity eq (11)'s K_D multiplies. With l_q = 1 - p^3, l_v = 3/2 (1 - p)^2
(1 + p) and l_d = (1 - p)^3 the estimate's error decays with the triple pole p (the
observer's ``control.velocity_observer``; 0: deadbeat, the error of a constant d gone in three
samples). At i = 0 the estimate starts at the measured (q_0, qdot_0) and, once the command
u_0 is formed, d^ = -u_0: the joint at rest over the first period (a learned input that holds
a patient's pull at the start is no acceleration; with d^ = 0 the prediction took u_0 for one,
and the kick it gave the velocity fed back left a ~1e-3 rad error at the trial's start that no
trial removed: patients with ideal sensors 0.0014 rad off at trial 25 instead of 2e-5).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)

# Rows of the observer's gains (``Controller.observer``, :func:`observer_gains`):
GAIN_POSITION = 0  # l_q
GAIN_VELOCITY = 1  # l_v / T (1/s)
GAIN_DISTURBANCE = 2  # l_d / T^2 (1/s^2)
GAIN_PERIOD = 3  # T (s)
# Rows of the observer's state (``Guard.observer``, :func:`observer_state`):
POSITION = 0  # q^
VELOCITY = 1  # v^
DISTURBANCE = 2  # d^
COMMAND = 3  # u of the sample before
VELOCITY_FED_BACK = 4  # what the feedback used at the last sample (every joint)


def observer_gains(pole: np.ndarray, on: np.ndarray, period: float) -> np.ndarray:
    """(4, n) gains of (O) per joint with the triple pole ``pole`` on the joints ``on`` (bool
    mask); the other joints' columns are 0 (they feed back the measured velocity)."""
    p = np.asarray(pole, dtype=float)
    gains = np.zeros((4, p.shape[0]))
    gains[GAIN_POSITION] = np.where(on, 1.0 - p ** 3, 0.0)
    gains[GAIN_VELOCITY] = np.where(on, 1.5 * (1.0 - p) ** 2 * (1.0 + p) / period, 0.0)
    gains[GAIN_DISTURBANCE] = np.where(on, (1.0 - p) ** 3 / period ** 2, 0.0)
    gains[GAIN_PERIOD] = period
    return gains


def observer_state(n: int) -> np.ndarray:
    """A fresh (5, n) observer state (:func:`feedback_velocity_into` starts it at sample 0)."""
    return np.zeros((5, n))


@njit(cache=True, error_model="numpy")
def feedback_velocity_into(i: int, q: np.ndarray, qd: np.ndarray, gains: np.ndarray,
                           state: np.ndarray, out: np.ndarray) -> None:
    """The velocity eq (11) feeds back at trial sample ``i`` into ``out``: on a joint with the
    observer (l_q > 0) v^_i of (O), from the measured position ``q`` and the state (the
    estimate is started at the measured (q, qdot) at i = 0); on the others the measured
    ``qd``."""
    for j in range(q.shape[0]):
        l_q = gains[GAIN_POSITION, j]
        if l_q == 0.0:
            out[j] = qd[j]
            continue
        if i == 0:
            state[POSITION, j] = q[j]
            state[VELOCITY, j] = qd[j]
            state[DISTURBANCE, j] = 0.0
        else:
            period = gains[GAIN_PERIOD, j]
            acceleration = state[COMMAND, j] + state[DISTURBANCE, j]
            predicted = state[POSITION, j] + period * state[VELOCITY, j] \
                + 0.5 * period * period * acceleration
            residual = q[j] - predicted
            state[POSITION, j] = predicted + l_q * residual
            state[VELOCITY, j] += period * acceleration + gains[GAIN_VELOCITY, j] * residual
            state[DISTURBANCE, j] += gains[GAIN_DISTURBANCE, j] * residual
        out[j] = state[VELOCITY, j]


@njit(cache=True, error_model="numpy")
def remember_command(i: int, gains: np.ndarray, state: np.ndarray, u: np.ndarray) -> None:
    """Keep the command u of eq (11) the controller formed at sample ``i`` for the next
    sample's prediction in (O) (on the joints with the observer). At i = 0 the unknown
    acceleration starts at d^ = -u_0: the joint is taken to start at rest (no acceleration
    over the first period), whatever the command (a learned input that holds a patient's pull
    is not an acceleration of the joint)."""
    for j in range(u.shape[0]):
        if gains[GAIN_POSITION, j] != 0.0:
            state[COMMAND, j] = u[j]
            if i == 0:
                state[DISTURBANCE, j] = -u[j]


def fed_back_velocity(position: np.ndarray, velocity: np.ndarray, control_input: np.ndarray,
                      gains: np.ndarray) -> np.ndarray:
    """The velocity the feedback used at every sample of a trial, from its measured position
    and velocity and the commands u it formed (the observer of (O) run again over the trial,
    the same arithmetic in the same order: the measured velocity on the joints without it)."""
    n_samples, n = position.shape
    state = observer_state(n)
    out = np.empty((n_samples, n))
    for i in range(n_samples):
        feedback_velocity_into(i, position[i], velocity[i], gains, state, out[i])
        remember_command(i, gains, state, control_input[i])
    return out
