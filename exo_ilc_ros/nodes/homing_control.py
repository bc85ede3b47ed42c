"""The computed-torque controller's binding of
:class:`exo_ilc_ros.core.protocol.homing.HomingController`
(``protocol: homing``): every /joint_states sample gets an effort (homing, the trial, or the
safe hold between trials, so a real arm is never left with a stale command), and the
controller's reports go to /diagnostics on ``computed_torque_controller/trial``:

* ``homed``: values ``trial``, ``t0_ns`` (the stamp of the trial's sample 0), ``token`` (the
  feed-forward's header stamp, which names the attempt), ``homing_start_ns`` (the stamp of
  homing's first sample);
* ``homing_failed``: ``trial``, ``t0_ns`` = -1, ``token``, ``reason`` (health ERROR with it);
* ``done``: as under the services protocol (``trial``, ``t0_ns``, ``aborted_at``,
  ``watchdog_trips``).
"""

from __future__ import annotations

import time
from typing import Any, Protocol

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus

from ..core.loop.controller import GuardedControlStep
from ..core.loop.safety import Watchdog
from ..core.loop.wire_input import FeedforwardProfile
from ..core.protocol.homing import ControllerEvent, ControllerMode, HomingController, HomingSettings
from ..wire import topics
from ..wire.cdr import float64_array
from .diagnostics import diagnostic_array, status
from .guard import Health, JointStateGate
from .parameters import SchemaParameters


class ControllerNode(Protocol):
    """What homing needs of the controller node
    (:class:`exo_ilc_ros.nodes.computed_torque_controller.ComputedTorqueController`): its step,
    gate, watchdog, health and publishers, and the trial's state it reports."""

    params: SchemaParameters
    step: GuardedControlStep
    gate: JointStateGate
    watchdog: Watchdog
    health: Health
    command_pub: Any
    diagnostics_pub: Any
    q: np.ndarray
    qd: np.ndarray
    holding: bool
    steps: int
    trial: int
    t0_ns: int
    aborted_at: int
    trial_trips: int
    aborted_trials: list[int]

    def get_logger(self) -> Any: ...

    def get_name(self) -> str: ...

    def _trip(self) -> None: ...

    def _publish_health(self) -> None: ...


class HomingControl:
    """Homing, trial and hold for one controller node (``node``: its step, gate, watchdog
    and publishers)."""

    def __init__(self, node: ControllerNode, period: float, samples: int) -> None:
        self.node = node
        config = node.params.config
        self.driver = HomingController(node.step, HomingSettings.from_config(config), period,
                                       samples)
        self.token = -1
        self.homing_failures: list[int] = []
        node.health.checks.append(self._check)
        here = np.zeros(config.joints)  # load the hold's and the envelope's kernels now,
        node.step.hold_at(here)  # not at the first sample (a lock-step arm waits meanwhile)
        node.step.hold(here, here)
        node.step.outside(here, here)

    def load(self, trial: int, token: int, profile: FeedforwardProfile) -> None:
        """A new trial's profile: home at the next sample, then run it."""
        self.token = token
        self.driver.load(trial, profile.feedforward, profile.position, profile.velocity)

    def on_joint_state(self, raw: bytes) -> None:
        """The effort for this sample; the reports it causes."""
        node = self.node
        sample = node.gate(raw)
        if sample is None:
            return
        stamp, q, qd = sample
        node.q[:] = q
        node.qd[:] = qd
        driver = self.driver
        if driver.mode is ControllerMode.TRIAL:
            if driver.index < 1:
                node.watchdog.arm(time.monotonic_ns())
            else:
                node.watchdog.feed(time.monotonic_ns())
                if node.watchdog.tripped and not node.holding:
                    node._trip()
            if node.holding:
                driver.trip(node.q)
        effort, events = driver(stamp, node.q, node.qd)
        node.command_pub.publish(float64_array(effort))
        node.steps += 1
        for event in events:
            self._report(event)

    def _report(self, event: ControllerEvent) -> None:
        node = self.node
        values = [("trial", str(event.trial)), ("token", str(self.token))]
        if event.kind == "homed":
            node.trial, node.t0_ns = event.trial, event.stamp_ns
            node.aborted_at, node.trial_trips, node.holding = -1, 0, False
            values.append(("t0_ns", str(event.stamp_ns)))
            if self.driver.homing is not None:
                values.append(("homing_start_ns", str(self.driver.homing.start_ns)))
        elif event.kind == "homing_failed":
            self.homing_failures.append(event.trial)
            node.get_logger().error(f"trial {event.trial}: {event.reason}; safe hold "
                                    "commanded, the trial is not started")
            values += [("t0_ns", "-1"), ("reason", event.reason)]
        elif event.kind == "aborted":
            node.aborted_at = event.index
            node.aborted_trials.append(event.trial)
            node.get_logger().error(f"trial {event.trial}: |e| left the error envelope at "
                                    f"sample {event.index}; trial aborted, safe hold commanded")
            node._publish_health()
            return
        else:  # done
            node.watchdog.disarm()
            values += [("t0_ns", str(self.driver.t0_ns)), ("aborted_at", str(node.aborted_at)),
                       ("watchdog_trips", str(node.trial_trips))]
        item = status(topics.CONTROLLER_TRIAL_STATUS, event.kind, values,
                      hardware_id=node.get_name())
        node.diagnostics_pub.publish(diagnostic_array(node, [item], event.stamp_ns))
        if event.kind == "homing_failed":
            node._publish_health()

    def _check(self) -> tuple[bytes, str, list[tuple[str, str]]]:
        driver = self.driver
        values = [("protocol", "homing"), ("homing/mode", driver.mode.value),
                  ("homing/failed_trials", " ".join(map(str, self.homing_failures)))]
        if driver.mode is ControllerMode.FAILED:
            return DiagnosticStatus.ERROR, f"trial {driver.trial}: {driver.failure}; safe " \
                "hold", values
        if driver.mode is ControllerMode.HOMING and driver.homing is not None:
            values.append(("homing/state", driver.homing.state.value))
        return DiagnosticStatus.OK, "", values
