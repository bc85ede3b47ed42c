"""Homing instead of a reset, ROS-free: how any arm (no simulator's ``reset`` service) is brought
to x_d(0) between trials, and when a trial may start.

Between trials the controller moves the arm from wherever it stopped to q_d(0) along a
rest-to-rest quintic in joint space (eq (14)'s polynomial, :class:`HomingPath`) under computed
torque with homing's own PID (eq (16) with u = qddot_path + K_P e + K_D e_dot + K_I z, e =
q_path - q, z its integral: :meth:`Homing.command`). The nominal model's gravity error at q_d(0)
is a constant torque there: PD alone leaves it as an offset (delta a_N^-1 g_N / K_P: 0.24 rad on
the Panda's joints 4 and 6 at kp 16 and delta 10 %), the integral takes it out. The integral is
bounded (|K_I z| <= ``integral_limit``) and frozen while any effort is at its limit
(anti-windup), so an arm held away meets at most a_N ``integral_limit`` more and homing still
times out. Its duration
follows from the distance and a speed limit: the quintic's peak speed is 15/8 |Δq| / T, so
T = 15/8 max_j |Δq_j| / ``speed_limit``, rounded up to whole control periods. Once the path has
ended, :class:`Homing` waits until the arm is within half of both tolerances
(:data:`DWELL_ENTRY`), then until |q - q_d(0)| <= ``position_tolerance`` and |qdot| <=
``velocity_tolerance`` (every joint) have held for ``dwell`` seconds; the trial then starts at
the next sample. Two faults end homing in the safe hold, the trial not started:

* it does not settle within ``timeout`` seconds after the path's end;
* the arm leaves the tolerances during the dwell (someone moved it).

Time is the arm's own: the stamps of its samples (``/joint_states``), not the wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..loop.controller import GuardedControlStep
from ..params.config import Config
from ..reference.trajectory import QuinticTrajectory

QUINTIC_PEAK_SPEED = 15.0 / 8.0
"""Peak of d/dtau (10 tau^3 - 15 tau^4 + 6 tau^5) on [0, 1], at tau = 1/2."""
DWELL_ENTRY = 0.5
"""The dwell begins once the arm is within this fraction of both tolerances (it fails only if
the arm leaves the whole tolerances): a hysteresis band, since homing's PID, still settling,
can move a joint back out by a little (up to 1.2e-4 rad on the Panda on MuJoCo at 10-15 %),
which without it would read as the arm being moved during the dwell."""


@dataclass(frozen=True)
class HomingSettings:
    """The homing parameters (``homing.*`` of config/exo_ilc.yaml)."""

    speed_limit: float
    """Peak joint speed of the path (rad/s)."""
    position_tolerance: np.ndarray
    """|q_j - q_d,j(0)| allowed at the start of a trial, per joint (rad)."""
    velocity_tolerance: np.ndarray
    """|qdot_j| allowed at the start of a trial, per joint (rad/s)."""
    dwell: float
    """How long both must hold before the trial starts (s)."""
    timeout: float
    """How long after the path's end the arm may take to come within the tolerances (s)."""
    kp: np.ndarray
    """K_P of homing's PID, per joint (s^-2, through a_N(q))."""
    kd: np.ndarray
    """K_D of homing's PID, per joint (s^-1)."""
    ki: np.ndarray
    """K_I of homing's PID, per joint (s^-3; 0: no integral)."""
    integral_limit: np.ndarray
    """Bound on |K_I z|, per joint (rad/s^2)."""

    @classmethod
    def from_config(cls, config: Config) -> HomingSettings:
        """The settings of ``config``."""
        def joints(key: str) -> np.ndarray:
            return np.asarray(config[key], dtype=float)

        return cls(float(config["homing.speed_limit"]), joints("homing.position_tolerance"),
                   joints("homing.velocity_tolerance"), float(config["homing.dwell"]),
                   float(config["homing.timeout"]), joints("homing.kp"), joints("homing.kd"),
                   joints("homing.ki"), joints("homing.integral_limit"))


def homing_duration(start: np.ndarray, goal: np.ndarray, speed_limit: float,
                    period: float) -> float:
    """T of the homing quintic: 15/8 max_j |goal_j - start_j| / speed_limit (its peak speed is
    then the limit), rounded up to whole control periods (0 when already there)."""
    distance = float(np.max(np.abs(np.asarray(goal, float) - np.asarray(start, float))))
    periods = math.ceil(QUINTIC_PEAK_SPEED * distance / speed_limit / period - 1e-9)
    return max(periods, 0) * period


class HomingPath:
    """The rest-to-rest quintic from ``start`` to ``goal`` (eq (14)'s form) over
    :func:`homing_duration`; before it, ``start``; after it, ``goal`` at rest."""

    def __init__(self, start: np.ndarray, goal: np.ndarray, speed_limit: float,
                 period: float) -> None:
        self.start = np.array(start, dtype=float)
        self.goal = np.array(goal, dtype=float)
        self.duration = homing_duration(self.start, self.goal, speed_limit, period)
        self._curve = QuinticTrajectory.rest_to_rest(
            self.start.tolist(), self.goal.tolist(), self.duration) \
            if self.duration > 0.0 else None
        self._zero = np.zeros_like(self.goal)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, qdot and qddot of the path at ``t`` seconds after its start."""
        if self._curve is None or t >= self.duration:
            return self.goal, self._zero, self._zero
        q, qd, qdd = self._curve.evaluate(max(t, 0.0))
        return q, qd, qdd


class HomingState(Enum):
    """Where homing is."""

    PATH = "path"
    """Following the path."""
    SETTLING = "settling"
    """The path has ended; waiting for the arm to come within the tolerances."""
    DWELL = "dwell"
    """Within the tolerances; waiting for the dwell time."""
    READY = "ready"
    """Within the tolerances for the dwell time: the trial starts at the next sample."""
    FAILED = "failed"
    """Did not settle in time, or moved during the dwell: safe hold, trial not started."""


class Homing:
    """One homing: the path from the pose of its first sample, the settle check at every
    sample (:meth:`update`). Stamps are integer nanoseconds of the arm's clock."""

    def __init__(self, settings: HomingSettings, goal: np.ndarray, period: float,
                 stamp_ns: int, q: np.ndarray) -> None:
        self.settings = settings
        self.goal = np.array(goal, dtype=float)
        self.period = float(period)
        self.path = HomingPath(q, self.goal, settings.speed_limit, period)
        self.integral = np.zeros_like(self.goal)
        """z, the integral of q_path - q (rad s), within +-integral_limit / K_I."""
        ki = settings.ki
        self._integral_bound = np.divide(settings.integral_limit, ki,
                                         out=np.zeros_like(self.goal), where=ki > 0.0)
        self.start_ns = int(stamp_ns)
        self.state = HomingState.PATH
        self.dwell_since: int | None = None
        self.reason = ""
        """Why homing failed (empty otherwise)."""

    def elapsed(self, stamp_ns: int) -> float:
        """Seconds since the first sample."""
        return (int(stamp_ns) - self.start_ns) * 1e-9

    def reference(self, stamp_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The path's q, qdot, qddot at this sample (the controller's reference)."""
        return self.path(self.elapsed(stamp_ns))

    def command(self, stamp_ns: int, q: np.ndarray, saturated: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u_ff, q_path, qdot_path) at this sample: u_ff = qddot_path + K_I z, the PID's
        feed-forward and integral part (K_P, K_D act on the path through the controller).
        z += period (q_path - q) first, clipped to +-integral_limit / K_I; not while
        ``saturated`` (an effort of the last sample at its limit)."""
        q_path, qd_path, qdd_path = self.reference(stamp_ns)
        if not saturated:
            np.clip(self.integral + self.period * (q_path - q), -self._integral_bound,
                    self._integral_bound, out=self.integral)
        return qdd_path + self.settings.ki * self.integral, q_path, qd_path

    def within(self, q: np.ndarray, qd: np.ndarray, fraction: float = 1.0) -> bool:
        """|q - q_d(0)| and |qdot| within ``fraction`` of the tolerances, every joint (NaN is
        not)."""
        s = self.settings
        return bool(np.all(np.abs(q - self.goal) <= fraction * s.position_tolerance) and
                    np.all(np.abs(qd) <= fraction * s.velocity_tolerance))

    def update(self, stamp_ns: int, q: np.ndarray, qd: np.ndarray) -> HomingState:
        """The state after the sample (stamp, q, qdot); READY and FAILED are final."""
        if self.state in (HomingState.READY, HomingState.FAILED):
            return self.state
        s = self.settings
        t = self.elapsed(stamp_ns)
        if t < self.path.duration:
            return self.state
        inside = self.within(q, qd)
        if self.state is HomingState.DWELL and not inside:
            self._fail(f"the arm moved during the dwell: {self._distance(q, qd)} after "
                       f"{(int(stamp_ns) - (self.dwell_since or 0)) * 1e-9:.3g} s of the "
                       f"{s.dwell:g} s dwell")
        elif self.state is HomingState.DWELL or (inside and self.within(q, qd, DWELL_ENTRY)):
            if self.dwell_since is None:
                self.dwell_since = int(stamp_ns)
                self.state = HomingState.DWELL
            if (int(stamp_ns) - self.dwell_since) * 1e-9 >= s.dwell - 1e-12:
                self.state = HomingState.READY
        elif t - self.path.duration > s.timeout:
            self._fail(f"did not settle within {s.timeout:g} s after the {self.path.duration:g}"
                       f" s path: {self._distance(q, qd)}")
        else:
            self.state = HomingState.SETTLING
        return self.state

    def _distance(self, q: np.ndarray, qd: np.ndarray) -> str:
        s = self.settings
        return (f"|q - q_d(0)| = {_fmt(np.abs(q - self.goal))} rad (tolerance "
                f"{_fmt(s.position_tolerance)}), |qdot| = {_fmt(np.abs(qd))} rad/s (tolerance "
                f"{_fmt(s.velocity_tolerance)})")

    def _fail(self, reason: str) -> None:
        self.state = HomingState.FAILED
        self.reason = "homing failed: " + reason


def _fmt(x: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.3g}" for v in np.asarray(x, float)) + "]"


def grid_index(stamp_ns: int, t0_ns: int, step_ns: int) -> tuple[int, int]:
    """The control-grid index nearest to ``stamp_ns`` in a trial starting at ``t0_ns`` and the
    stamp's offset from that grid point (ns): a plant with its own clock stamps its samples
    near, not on, t0 + i period."""
    offset = int(stamp_ns) - int(t0_ns)
    i = (offset + step_ns // 2) // step_ns
    return int(i), offset - int(i) * step_ns


def fill_missing(values: np.ndarray, received: np.ndarray) -> np.ndarray:
    """``values`` (samples x joints) with the rows not ``received`` linearly interpolated in
    the sample index between their received neighbours (held at the ends)."""
    out = np.array(values, dtype=float)
    if received.all() or not received.any():
        return out
    index = np.arange(received.shape[0])
    for j in range(out.shape[1]):
        out[~received, j] = np.interp(index[~received], index[received], out[received, j])
    return out


class ControllerMode(Enum):
    """What the controller does at a sample under the homing protocol."""

    HOLD = "hold"
    """No trial loaded, or the last one ended: the safe hold around the pose latched then."""
    HOMING = "homing"
    """Bringing the arm to q_d(0) (:class:`Homing`)."""
    TRIAL = "trial"
    """Running the loaded trial (eq (11) + (16) on the control grid)."""
    FAILED = "failed"
    """Homing failed: the safe hold around the pose where it failed, until the next load."""


@dataclass(frozen=True)
class ControllerEvent:
    """Something the controller must report (``homed``, ``homing_failed``, ``aborted``,
    ``done``) with the sample it happened at."""

    kind: str
    trial: int
    stamp_ns: int
    index: int = -1
    """The trial's sample index (``aborted``, ``done``)."""
    reason: str = ""


class HomingController:
    """The computed-torque controller's sample-by-sample decisions under the homing protocol,
    ROS-free (the node publishes the efforts and reports the events).

    :meth:`load` takes the next trial's profile; homing starts at the next sample, from
    wherever the arm is. When :class:`Homing` is READY, the following sample is the trial's
    sample 0 (its stamp is t0: ``homed``); every later sample goes to the nearest control-grid
    index (:func:`grid_index`), the error envelope guards it as in a services trial, and the
    first sample at or past the last index ends the trial (``done``). Between trials, and
    after a failed homing, the safe hold (module :mod:`.controller`) keeps the arm where it is.
    """

    def __init__(self, step: GuardedControlStep, settings: HomingSettings, period: float,
                 samples: int) -> None:
        self.step = step
        self.settings = settings
        self.period = period
        self.step_ns = int(round(period * 1e9))
        self.samples = samples
        self.mode = ControllerMode.HOLD
        self.trial = 0
        self.t0_ns = -1
        self.feedforward = np.zeros((0, 0))
        self.q_ref = self.feedforward
        self.qd_ref = self.feedforward
        self.loaded = False
        """A profile waits for the next sample to start homing."""
        self.homing: Homing | None = None
        self.saturated = False
        """An effort of the last homing sample was at its limit (the integral waits)."""
        self.start_next = False
        self.aborted_at = -1
        self.tripped = False
        self.hold_latched = False
        self.index = -1
        """Grid index of the last trial sample (-1: none)."""
        self.failure = ""
        """The last homing failure's reason (empty after a successful homing)."""

    def load(self, trial: int, feedforward: np.ndarray, q_ref: np.ndarray,
             qd_ref: np.ndarray) -> None:
        """The profile of ``trial``: home at the next sample, then run it."""
        self.trial = trial
        self.feedforward, self.q_ref, self.qd_ref = feedforward, q_ref, qd_ref
        self.loaded = True

    def trip(self, q: np.ndarray) -> None:
        """The watchdog tripped during the trial: the safe hold around ``q`` to its end."""
        if self.mode is ControllerMode.TRIAL and not self.tripped:
            self.tripped = True
            if self.aborted_at < 0:
                self.step.hold_at(q)

    def _hold_here(self, q: np.ndarray) -> None:
        self.step.hold_at(q)
        self.hold_latched = True

    def __call__(self, stamp_ns: int, q: np.ndarray, qd: np.ndarray
                 ) -> tuple[np.ndarray, list[ControllerEvent]]:
        """The effort for the sample (stamp, q, qdot) and the events it causes."""
        events: list[ControllerEvent] = []
        if self.loaded:
            self.loaded = False
            self.homing = Homing(self.settings, self.q_ref[0], self.period, stamp_ns, q)
            self.saturated = False
            self.mode = ControllerMode.HOMING
            self.start_next = False
            self.failure = ""
        if self.mode is ControllerMode.HOMING:
            if self.start_next:
                self.mode = ControllerMode.TRIAL
                self.t0_ns = int(stamp_ns)
                self.aborted_at, self.tripped, self.index = -1, False, -1
                self.step.begin_trial()
                events.append(ControllerEvent("homed", self.trial, stamp_ns))
            else:
                return self._homing_effort(stamp_ns, q, qd, events), events
        if self.mode is ControllerMode.TRIAL:
            return self._trial_effort(stamp_ns, q, qd, events), events
        if not self.hold_latched:
            self._hold_here(q)
        return self.step.hold(q, qd), events

    def _homing_effort(self, stamp_ns: int, q: np.ndarray, qd: np.ndarray,
                       events: list[ControllerEvent]) -> np.ndarray:
        homing = self.homing
        assert homing is not None
        state = homing.update(stamp_ns, q, qd)
        if state is HomingState.FAILED:
            self.mode = ControllerMode.FAILED
            self.failure = homing.reason
            self._hold_here(q)
            events.append(ControllerEvent("homing_failed", self.trial, stamp_ns,
                                          reason=homing.reason))
            return self.step.hold(q, qd)
        if state is HomingState.READY:
            self.start_next = True
        u_ff, q_path, qd_path = homing.command(stamp_ns, q, self.saturated)
        s = self.settings
        effort = self.step.with_gains(u_ff, q_path, qd_path, q, qd, s.kp, s.kd)
        self.saturated = self.step.saturated()
        return effort

    def _trial_effort(self, stamp_ns: int, q: np.ndarray, qd: np.ndarray,
                      events: list[ControllerEvent]) -> np.ndarray:
        i, _ = grid_index(stamp_ns, self.t0_ns, self.step_ns)
        last = self.samples - 1
        i = min(max(i, 0), last)
        self.index = i
        if self.step.sample(i, self.feedforward[i], self.q_ref[i], self.qd_ref[i], q, qd,
                            self.tripped):
            self.aborted_at = i
            events.append(ControllerEvent("aborted", self.trial, stamp_ns, i))
        effort = self.step.effort
        if i >= last:
            events.append(ControllerEvent("done", self.trial, stamp_ns, i))
            self.mode = ControllerMode.HOLD
            if self.aborted_at < 0 and not self.tripped:
                self.step.hold_at(q)  # from the next sample: hold where the trial ended
            self.hold_latched = True
        return effort
