"""The trial protocol without a simulator's reset (``protocol: homing``), ROS-free: for any arm,
a plant that keeps its own clock and offers no ``reset``/``start`` services.

Per trial: push the session's feed-forward (its header stamp a fresh token, since no reset names
the trial's t0), wait for the controller's acknowledgement, and wait while the controller homes
the arm (:mod:`.homing`); the controller's ``homed`` report names t0, the stamp of the trial's
sample 0. The samples are placed on the control grid by their stamps (nearest grid point:
:func:`.homing.grid_index`; a sample more than a quarter period off its grid point is counted
*late*, a grid point without a sample *missing*). A trial that misses more than
``max_missing_samples`` samples is discarded (:meth:`LearningSession.discard`, reason ``lost``)
and run again with the same feed-forward; fewer are filled by linear interpolation. The end of
a trial is its last sample or the first sample past it. A ``homing_failed`` report stops the run
(the arm is in the safe hold, the trial not started, every completed trial stored when the run
has a store; the message says which).

Everything else (conclusion, store, recorder, live changes, discards) is :class:`TrialProtocol`'s.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..loop.record import TrialRecord
from ..params.config import Config
from .homing import fill_missing, grid_index
from .trial_protocol import GraphPort, Phase, TrialProtocol


class HomingProtocol(TrialProtocol):
    """:class:`TrialProtocol` with homing instead of the plant's reset and start."""

    def __init__(self, config: Config, port: GraphPort,
                 live: Callable[[], Config] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__(config, port, live, clock)
        self.max_missing = int(config["max_missing_samples"])
        self.recent: deque[tuple[int, np.ndarray, np.ndarray]] = deque(
            maxlen=4 * self.samples.received.shape[0])
        """Samples seen while no trial runs (the ``homed`` report may come after sample 0)."""
        self.last_stamp = 0
        self.token = 0
        self.deferred = False
        """The next trial's feed-forward waits until the recorder filed the last trial (the
        controller would home and start it at once: there is no start to hold back)."""
        self.homing_time = 0.0
        """Of the running trial: the arm's seconds from homing's first sample to sample 0."""
        self.past_end = False
        self.late = 0
        self.missing = 0
        """Of the running trial: samples off their grid point by more than a quarter period,
        grid points without a sample (filled)."""

    def open(self, plant: Mapping[str, Any]) -> None:
        """As :meth:`TrialProtocol.open`; a trial ends with the controller's ``done`` and its
        samples only (the plants without services send no report of their own)."""
        super().open(plant)
        self.real_time = False

    # --- steps -----------------------------------------------------------------------------
    def _reset(self) -> None:
        """No reset service: the feed-forward goes out, keyed by a new token (above every
        stamp and token before), and the controller homes the arm once it has it; while the
        recorder has not filed the last trial, only once it has."""
        assert self.session is not None
        if self.unsaved is not None:
            self.deferred = True
            self.after_save = "start"
            self.samples.stop()
            self._enter(Phase.WAIT_RECORDER)
            return
        self.token = token = max(self.token, self.samples.t0_ns, self.last_stamp) + 1
        self.samples.start(token)
        self.done_report = None
        self.past_end = False
        self.late = self.missing = 0
        self._enter(Phase.WAIT_ACK)
        self.pushed_at = self.clock()  # for a base class that pushes again without an ack
        self.port.push_feedforward(self.trial, token, self.session.feedforward)

    def _begin_trial(self) -> None:
        if self.deferred:  # the recorder filed the last trial: now the feed-forward
            self.deferred = False
            self._reset()
            return
        self.refused = False
        self._enter(Phase.HOMING)

    def _start(self) -> None:  # no start service
        self.starting = False

    # --- inputs ----------------------------------------------------------------------------
    def on_homed(self, trial: int, token: int, t0_ns: int, homing_start_ns: int = 0) -> None:
        """The controller homed the arm; the trial's sample 0 is stamped ``t0_ns``, homing's
        first sample ``homing_start_ns`` (0: not reported)."""
        if self.phase is not Phase.HOMING or (trial, token) != (self.trial, self.samples.t0_ns):
            return
        self.samples.start(t0_ns)
        self.homing_time = (int(t0_ns) - int(homing_start_ns)) * 1e-9 if homing_start_ns \
            else 0.0
        self.port.event("start", [("trial", str(trial))], t0_ns)
        self._enter(Phase.RUNNING)
        recent, self.recent = list(self.recent), deque(maxlen=self.recent.maxlen)
        for stamp, q, qd in recent:
            if stamp >= t0_ns and self.phase is Phase.RUNNING and self.samples.running:
                self._place(stamp, q, qd)

    def on_homing_failed(self, trial: int, token: int, reason: str) -> None:
        """Homing did not settle, or the arm moved during the dwell: the controller holds it;
        the trial is not started and the run stops (resume once the arm is safe)."""
        if self.phase not in (Phase.WAIT_ACK, Phase.HOMING, Phase.WAIT_RECORDER) or \
                (trial, token) != (self.trial, self.samples.t0_ns):
            return
        self.port.event("aborted", [("trial", str(trial)), ("reason", "homing"),
                                    ("detail", reason)])
        self.fail(f"trial {trial} not started: {reason}; the arm is in the safe hold. "
                  f"{self._kept()}")

    def _kept(self) -> str:
        """What a stopped run leaves to resume from: the store's trials, or none without one."""
        if self.store is None:
            return (f"No store (store.directory is empty: exo-ilc run --no-store): the "
                    f"{self.completed} completed trial(s) cannot be resumed; run again once "
                    "the arm is safe")
        if self.completed == 0:
            return (f"No trial completed (store {self.store.directory}): run again once the "
                    "arm is safe")
        return (f"Every completed trial ({self.completed}) is stored in "
                f"{self.store.directory}: resume the run once the arm is safe")

    def on_sample(self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray) -> None:
        """A checked sample: placed on the running trial's grid, else kept for a moment (the
        ``homed`` report may follow it)."""
        self.last_stamp = max(self.last_stamp, int(stamp_ns))
        if self.phase is Phase.HOMING:
            self.phase_since = self.clock()  # the arm moves: progress (its homing times out)
        if self.phase is not Phase.RUNNING or not self.samples.running:
            self.recent.append((int(stamp_ns), np.array(position), np.array(velocity)))
            return
        self._place(int(stamp_ns), position, velocity)

    def _place(self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray) -> None:
        s = self.samples
        i, offset = grid_index(stamp_ns, s.t0_ns, s.step_ns)
        count = s.received.shape[0]
        if i < 0:
            return
        if i >= count:
            self.past_end = True
        elif not s.received[i]:
            s.position[i] = position
            s.velocity[i] = velocity
            s.received[i] = True
            if abs(offset) > s.step_ns // 4:
                self.late += 1
            self.phase_since = self.clock()
        if not (s.last_in or self.past_end):
            return
        missing = s.missing
        if missing > self.max_missing:
            self.port.log(True, f"trial {self.trial}: {missing} samples missing (at most "
                          f"{self.max_missing} allowed); running the trial again")
            self._retry("lost", [("lost", str(missing))])
            return
        if missing:
            s.position[:] = fill_missing(s.position, s.received)
            s.velocity[:] = fill_missing(s.velocity, s.received)
            s.received[:] = True
            self.missing += missing
        self._maybe_end_trial()

    # --- reporting -------------------------------------------------------------------------
    def summary_values(self, record: TrialRecord, names: list[str]) -> list[tuple[str, str]]:
        """The homing keys of a trial summary: ``samples_missing``, ``samples_late``,
        ``homing_time`` (s of the arm's clock from homing's first sample to the trial's sample
        0: homing's path, settling and dwell; 0 when the controller did not say), and the
        initial-state error homing left, ``initial_error/<joint>`` (q_d(0) - q(0), rad) and
        ``initial_velocity/<joint>`` (qdot(0), rad/s)."""
        e0 = record.reference.position[0] - record.position[0]
        v0 = record.velocity[0]
        return [("samples_missing", str(self.missing)), ("samples_late", str(self.late)),
                ("homing_time", repr(round(self.homing_time, 9))),
                *((f"initial_error/{n}", repr(float(x))) for n, x in zip(names, e0, strict=True)),
                *((f"initial_velocity/{n}", repr(float(x)))
                  for n, x in zip(names, v0, strict=True))]
