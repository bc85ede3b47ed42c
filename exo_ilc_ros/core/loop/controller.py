"""The controller: PD feedback over the feed-forward (eq (11)), computed torque with the nominal
model (eqs (9)/(16)), the error envelope and the safe hold. One sample at a time, compiled.

Error envelope (``safety.error_envelope``): at every sample the controller compares
|e_j| = |q_d,j - q_j| with the envelope of joint j (:func:`outside_envelope`, the one check). At
the first sample where any joint is outside (or the state is not finite) the trial is aborted
*at that sample*: from it on the effort is the **safe hold** and the trial record carries
``aborted_at`` = that index; the learning session learns from an aborted trial only up to that
index (core/session/abort.py).

Safe hold: the same computed-torque controller with the reference frozen at the pose measured at
the abort, zero reference velocity and no feed-forward, with the hold's own gains:

    Q = a_N(q) (K_P,h (q_hold - q) - K_D,h qdot) + c_N(q, qdot), clamped to +-effort_limit,

i.e. nominal gravity (and Coriolis) compensation at the current pose, plus ``safety.hold_kp``,
``safety.hold_kd`` as stiffness and damping around the abort pose, reached from the controller's
gains over ``safety.hold_ramp`` (:mod:`.hold`: why those gains, and what "at rest" means). It
brings the arm to rest near where the fault was seen instead of following the reference on or
letting the limb drop; with mass uncertainty delta it rests with a small gravity sag (delta
times the gravity torque over K_P,h).

Every command is clamped to +-effort_limit by the plant's rule (:func:`plant.clamp`), so the
plant's own limit never changes it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.dynamics import inertia_and_bias_into, workspace
from .hold import hold_gains_into
from .observer import VELOCITY_FED_BACK, feedback_velocity_into, observer_state, remember_command
from .plant import clamp
from .setup import LoopSetup


class Setpoint(NamedTuple):
    """What the controller is asked for at one sample: the feed-forward and the reference."""

    u_ff: np.ndarray
    """u_ff,k at the sample (eq (11))."""
    q_ref: np.ndarray
    """q_d at the sample."""
    qd_ref: np.ndarray
    """qdot_d at the sample."""


class ComputedTorque(NamedTuple):
    """What the computed torque of eq (16) needs besides the state, as one kernel argument."""

    nominal: tuple
    """The nominal arm's ``kernel_args``."""
    effort_limit: np.ndarray
    """The clamp of every command (:func:`plant.clamp`)."""
    ws: tuple
    """A :func:`dynamics.workspace` (scratch)."""


class Controller(NamedTuple):
    """The controller's settings as one kernel argument (:func:`controller_of`)."""

    kp: np.ndarray
    """K_P of eq (11)."""
    kd: np.ndarray
    """K_D of eq (11)."""
    torque: ComputedTorque
    """The computed torque of eq (16)."""
    envelope: np.ndarray
    """The error envelope per joint (:func:`outside_envelope`)."""
    hold_kp: np.ndarray
    """The safe hold's stiffness (:mod:`.hold`)."""
    hold_kd: np.ndarray
    """The safe hold's damping."""
    hold_ramp: int
    """Samples the hold's gains ramp over."""
    observer: np.ndarray
    """(4, n) the velocity observer's gains per joint (:mod:`.observer`: l_q, l_v / T,
    l_d / T^2, T); a joint whose l_q is 0 feeds back the measured velocity."""


class Guard(NamedTuple):
    """What the error envelope and the safe hold keep from sample to sample, as one kernel
    argument (:func:`guard_of`)."""

    state: np.ndarray
    """The guard state (:func:`guard_state`: :data:`ABORT`, :data:`HOLD_COUNT`)."""
    q_hold: np.ndarray
    """The pose the safe hold keeps."""
    gains: np.ndarray
    """(2, n) scratch: the hold's ramped K_P and K_D."""
    observer: np.ndarray
    """(5, n) the velocity observer's state (:mod:`.observer`: its estimates, the last
    command, the velocity fed back)."""


def controller_of(experiment: LoopSetup, envelope: np.ndarray | None = None) -> Controller:
    """The :class:`Controller` of a configuration, with its own scratch; ``envelope``: the
    error envelope array to read (None: the configuration's)."""
    n = experiment.reference.position.shape[1]
    return Controller(experiment.kp, experiment.kd,
                      ComputedTorque(experiment.nominal.kernel_args, experiment.effort_limit,
                                     workspace(n)),
                      experiment.error_envelope if envelope is None else envelope,
                      experiment.hold_kp, experiment.hold_kd, int(experiment.hold_ramp),
                      experiment.velocity_observer)


def guard_of(q_hold: np.ndarray) -> Guard:
    """A fresh :class:`Guard` (not aborted, no hold command yet) around the pose array
    ``q_hold`` (read and written by the kernels)."""
    return Guard(guard_state(), q_hold, np.empty((2, q_hold.shape[0])),
                 observer_state(q_hold.shape[0]))


@njit(cache=True, error_model="numpy")
def feedback_into(u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                  qd: np.ndarray, kp: np.ndarray, kd: np.ndarray, out: np.ndarray) -> None:
    """u = u_ff + K_P e + K_D e_dot, eq (11), with e = q_d - q, into ``out``."""
    for j in range(q.shape[0]):
        out[j] = u_ff[j] + kp[j] * (q_ref[j] - q[j]) + kd[j] * (qd_ref[j] - qd[j])


@njit(cache=True, error_model="numpy")
def computed_torque_into(q: np.ndarray, qd: np.ndarray, u: np.ndarray, tau_p: np.ndarray,
                         torque: ComputedTorque, out: np.ndarray) -> None:
    """Q^u = a_N(q) u + c_N(q, qdot) + tau_p, eqs (9)/(16) with eq (6)'s joint forces ``tau_p``
    (the identified patient's, :mod:`exo_ilc_ros.core.learning.patient_model`; zeros: the
    paper's law), clamped to +-effort_limit, into ``out``."""
    n = u.shape[0]
    effort_limit = torque.effort_limit
    an = inertia_and_bias_into(q, qd, *torque.nominal, torque.ws, out)
    for j in range(n):
        out[j] += tau_p[j]
        for k in range(n):
            out[j] += an[j, k] * u[k]
    for j in range(n):
        out[j] = clamp(out[j], effort_limit[j])


@njit(cache=True, error_model="numpy")
def control_into(setpoint: Setpoint, q: np.ndarray, qd: np.ndarray, tau_p: np.ndarray,
                 kp: np.ndarray, kd: np.ndarray, torque: ComputedTorque, u_out: np.ndarray,
                 effort_out: np.ndarray) -> None:
    """One sample of the controller: u by eq (11) with the gains ``kp``, ``kd`` into ``u_out``,
    then the effort by eq (16) with the joint forces ``tau_p`` (clamped) into ``effort_out``."""
    feedback_into(setpoint.u_ff, setpoint.q_ref, setpoint.qd_ref, q, qd, kp, kd, u_out)
    computed_torque_into(q, qd, u_out, tau_p, torque, effort_out)


@njit(cache=True, error_model="numpy")
def feedback_control_into(i: int, setpoint: Setpoint, q: np.ndarray, qd: np.ndarray,
                          tau_p: np.ndarray, controller: Controller, guard: Guard,
                          u_out: np.ndarray, effort_out: np.ndarray) -> None:
    """:func:`control_into` at trial sample ``i`` with the velocity the feedback uses: the
    measured ``qd``, or on a joint with the velocity observer its estimate
    (:func:`.observer.feedback_velocity_into`), which then remembers the command u."""
    velocity = guard.observer[VELOCITY_FED_BACK]
    feedback_velocity_into(i, q, qd, controller.observer, guard.observer, velocity)
    control_into(setpoint, q, velocity, tau_p, controller.kp, controller.kd,
                 controller.torque, u_out, effort_out)
    remember_command(i, controller.observer, guard.observer, u_out)


@njit(cache=True, error_model="numpy")
def safe_hold_into(q_hold: np.ndarray, q: np.ndarray, qd: np.ndarray, kp: np.ndarray,
                   kd: np.ndarray, torque: ComputedTorque, u_out: np.ndarray,
                   effort_out: np.ndarray) -> None:
    """The safe hold around ``q_hold`` (module docstring): :func:`control_into` with the
    reference frozen at ``q_hold``, zero reference velocity and no feed-forward."""
    zero = np.zeros(q.shape[0])
    control_into(Setpoint(zero, q_hold, zero), q, qd, zero, kp, kd, torque, u_out, effort_out)


@njit(cache=True, error_model="numpy")
def outside_envelope(q_ref: np.ndarray, q: np.ndarray, envelope: np.ndarray) -> bool:
    """True if any |q_ref_j - q_j| exceeds ``envelope_j`` or is not finite (NaN counts as
    outside): the one error-envelope check."""
    for j in range(q.shape[0]):  # noqa: SIM110  (a loop numba compiles)
        if not abs(q_ref[j] - q[j]) <= envelope[j]:
            return True
    return False


ABORT = 0
"""Entry of a guard state (int64 array, :func:`guard_state`): the sample the trial was aborted
at (-1: not aborted)."""
HOLD_COUNT = 1
"""Entry of a guard state: hold commands since the hold pose was latched (the ramp's count,
:func:`hold.hold_gains_into`)."""


def guard_state() -> np.ndarray:
    """A fresh guard state: not aborted, no hold command yet."""
    return np.array([-1, 0], dtype=np.int64)


@njit(cache=True, error_model="numpy")
def hold_into(guard: Guard, q: np.ndarray, qd: np.ndarray, controller: Controller,
              u_out: np.ndarray, effort_out: np.ndarray) -> None:
    """One safe-hold command around ``guard.q_hold``: its gains ramped from the controller's to
    the hold's over ``hold_ramp`` samples (:func:`hold.hold_gains_into`, counted in
    ``guard.state[HOLD_COUNT]``), then :func:`safe_hold_into`."""
    state = guard.state
    gains = guard.gains
    hold_gains_into(state[HOLD_COUNT], controller.hold_ramp, controller.kp, controller.kd,
                    controller.hold_kp, controller.hold_kd, gains)
    state[HOLD_COUNT] += 1
    safe_hold_into(guard.q_hold, q, qd, gains[0], gains[1], controller.torque, u_out,
                   effort_out)


@njit(cache=True, error_model="numpy")
def guarded_control_into(i: int, holding: bool, setpoint: Setpoint, q: np.ndarray,
                         qd: np.ndarray, tau_p: np.ndarray, controller: Controller,
                         guard: Guard, u_out: np.ndarray, effort_out: np.ndarray) -> bool:
    """The controller's rule at sample ``i`` of a trial, the one place it is written (the
    in-process trial kernel, the controller node and homing all call it): the first sample
    outside the error envelope (:func:`outside_envelope`) aborts the trial
    (``guard.state[ABORT] = i``) and latches the hold pose there; from then on, and while
    ``holding`` (a watchdog trip, whose pose the caller latched), the safe hold
    (:func:`hold_into`); otherwise eq (11) and the computed torque of eq (16) with the joint
    forces ``tau_p`` (:func:`control_into`; the hold never adds them). Returns True at the
    abort sample."""
    state = guard.state
    aborted_now = False
    if state[ABORT] < 0 and not holding and outside_envelope(setpoint.q_ref, q,
                                                             controller.envelope):
        state[ABORT] = i
        state[HOLD_COUNT] = 0
        q_hold = guard.q_hold
        for j in range(q.shape[0]):
            q_hold[j] = q[j]
        aborted_now = True
    if state[ABORT] >= 0 or holding:
        hold_into(guard, q, qd, controller, u_out, effort_out)
    else:
        feedback_control_into(i, setpoint, q, qd, tau_p, controller, guard, u_out, effort_out)
    return aborted_now


@njit(cache=True, error_model="numpy")
def computed_torque_kernel(q: np.ndarray, qd: np.ndarray, u: np.ndarray, nominal: tuple,
                           effort_limit: np.ndarray) -> np.ndarray:
    """Q^u = a_N(q) u + c_N(q, qdot), eqs (9)/(16), clamped, as a new array: the allocating
    form of :func:`computed_torque_into`, for tests and interactive use."""
    out = np.empty(u.shape[0])
    computed_torque_into(q, qd, u, np.zeros(u.shape[0]),
                         ComputedTorque(nominal, effort_limit, workspace(u.shape[0])), out)
    return out


@njit(cache=True, error_model="numpy")
def safe_hold_effort(q_hold: np.ndarray, q: np.ndarray, qd: np.ndarray, kp: np.ndarray,
                     kd: np.ndarray, nominal: tuple, effort_limit: np.ndarray) -> np.ndarray:
    """The safe-hold effort at (q, qdot) around the pose ``q_hold`` (module docstring), as a
    new array (the plant's watchdog hold)."""
    n = q.shape[0]
    u = np.empty(n)
    out = np.empty(n)
    safe_hold_into(q_hold, q, qd, kp, kd, ComputedTorque(nominal, effort_limit, workspace(n)),
                   u, out)
    return out


class ControlStep:
    """The computed-torque controller at one sample, into preallocated buffers."""

    def __init__(self, experiment: LoopSetup) -> None:
        n = experiment.reference.position.shape[1]
        self._kp = experiment.kp
        self._kd = experiment.kd
        self._limit = experiment.effort_limit
        self._torque = ComputedTorque(experiment.nominal.kernel_args, experiment.effort_limit,
                                      workspace(n))
        self._no_force = np.zeros(n)
        self.control_input = np.empty(n)
        """u of eq (11) at the last sample."""
        self.effort = np.empty(n)
        """The commanded effort at the last sample (eq (16), clamped)."""

    def __call__(self, u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray, q: np.ndarray,
                 qd: np.ndarray, tau_p: np.ndarray | None = None) -> np.ndarray:
        """Effort for the measured (q, qdot) at a sample with these reference values (and the
        joint forces ``tau_p``, None: none)."""
        control_into(Setpoint(u_ff, q_ref, qd_ref), q, qd,
                     self._no_force if tau_p is None else tau_p, self._kp, self._kd,
                     self._torque, self.control_input, self.effort)
        return self.effort

    def with_gains(self, u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray,
                   q: np.ndarray, qd: np.ndarray, kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
        """As :meth:`__call__` (no joint forces) with the gains ``kp``, ``kd`` instead of the
        controller's (homing's own, :mod:`exo_ilc_ros.core.protocol.homing`)."""
        control_into(Setpoint(u_ff, q_ref, qd_ref), q, qd, self._no_force, kp, kd,
                     self._torque, self.control_input, self.effort)
        return self.effort

    def saturated(self) -> bool:
        """Any joint of the last commanded effort at its limit."""
        return bool(np.any(np.abs(self.effort) >= self._limit))


class GuardedControlStep(ControlStep):
    """:class:`ControlStep` with the error envelope and the safe hold, one sample at a time:
    :meth:`sample` is the rule of :func:`guarded_control_into` (the in-process trial's), with
    the state of the trial begun by :meth:`begin_trial`; :meth:`hold_at` and :meth:`hold` the
    safe hold outside a trial's samples (between trials, a watchdog trip)."""

    def __init__(self, experiment: LoopSetup) -> None:
        super().__init__(experiment)
        self.envelope = np.asarray(experiment.error_envelope, dtype=float).copy()
        """The error envelope (changed in place by a live parameter change)."""
        self._controller = Controller(self._kp, self._kd, self._torque, self.envelope,
                                      experiment.hold_kp, experiment.hold_kd,
                                      int(experiment.hold_ramp), experiment.velocity_observer)
        self._guard = guard_of(np.empty(experiment.reference.position.shape[1]))
        self.q_hold = self._guard.q_hold
        self.state = self._guard.state
        """The trial's guard state (:data:`ABORT`, :data:`HOLD_COUNT`)."""

    @property
    def aborted_at(self) -> int:
        """The sample the trial begun last was aborted at (-1: not aborted)."""
        return int(self.state[ABORT])

    @property
    def hold_samples(self) -> int:
        """Hold commands since the hold pose was latched (the ramp's count, :mod:`.hold`)."""
        return int(self.state[HOLD_COUNT])

    def begin_trial(self) -> None:
        """A trial starts: not aborted."""
        self.state[ABORT] = -1

    def sample(self, i: int, u_ff: np.ndarray, q_ref: np.ndarray, qd_ref: np.ndarray,
               q: np.ndarray, qd: np.ndarray, holding: bool = False,
               tau_p: np.ndarray | None = None) -> bool:
        """The effort at trial sample ``i`` into :attr:`effort` by the rule of
        :func:`guarded_control_into` (``tau_p``: the joint forces at the sample, None: none);
        True if this sample aborted the trial."""
        return bool(guarded_control_into(
            i, holding, Setpoint(u_ff, q_ref, qd_ref), q, qd,
            self._no_force if tau_p is None else tau_p, self._controller, self._guard,
            self.control_input, self.effort))

    def outside(self, q_ref: np.ndarray, q: np.ndarray) -> bool:
        """True if any |q_ref_j - q_j| exceeds the envelope (or is not finite)."""
        return bool(outside_envelope(q_ref, q, self.envelope))

    def hold_at(self, q: np.ndarray) -> None:
        """Latch the pose the safe hold keeps (its gains ramp from the controller's again)."""
        self.q_hold[:] = q
        self.state[HOLD_COUNT] = 0

    def hold(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The safe-hold effort at (q, qdot) around the latched pose (clamped), one call per
        sample: its gains ramp over ``safety.hold_ramp`` (:func:`hold_into`)."""
        hold_into(self._guard, q, qd, self._controller, self.control_input, self.effort)
        return self.effort
