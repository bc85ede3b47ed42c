"""plant_simulator: the arm with its true masses, integrated one control period at a time.

Publishes /joint_states and /clock, takes efforts on /effort_controller/commands, and offers
the reset/start services of the trial protocol (see :mod:`exo_ilc_ros.topics`). Lock-step mode
advances one period per command; real-time mode steps on a wall-clock timer with the last
command held.
"""

from __future__ import annotations

import numpy as np
from rclpy.node import Node
from rclpy.timer import Timer
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

from .. import topics
from ..core import schema
from ..core.experiment import Experiment
from ..core.loop import PlantStepper, period_ns
from .cdr import CdrError, JointStateWriter, read_float64_array
from .common import CLOCK_QOS, SAMPLES_QOS, SchemaParameters, spin, wall_clock

NAME = schema.PLANT


class PlantSimulator(Node):
    """The simulated exoskeleton arm (true masses, ``mass_uncertainty``)."""

    def __init__(self) -> None:
        super().__init__(NAME)
        self.params = SchemaParameters(self, NAME)
        config = self.params.config
        self.experiment = Experiment(config)
        self.stepper = PlantStepper(self.experiment)
        self.lock_step = config["mode"] == "lock_step"
        self.clock_every = int(config["clock_every"])
        self.step_ns = period_ns(self.experiment.period)
        self.last_index = self.experiment.reference.samples - 1
        self.now_ns = 0
        self.t0_ns = 0
        self.index = 0
        self.armed = False
        self.running = False
        self.held = np.zeros(config.joints)
        self.timer: Timer | None = None

        self.state = JointStateWriter(config["joint_names"])
        self.clock = Clock()
        self.state_pub = self.create_publisher(JointState, topics.JOINT_STATES, SAMPLES_QOS)
        self.clock_pub = self.create_publisher(Clock, topics.CLOCK, CLOCK_QOS)
        self.command_sub = self.create_subscription(
            Float64MultiArray, topics.EFFORT_COMMANDS, self.on_command, SAMPLES_QOS, raw=True)
        self.create_service(Trigger, topics.RESET_SERVICE, self.on_reset)
        self.create_service(Trigger, topics.START_SERVICE, self.on_start)
        if not self.lock_step:
            wall_period = self.experiment.period / config["real_time_rate"]
            self.timer = self.create_timer(wall_period, self.on_tick, clock=wall_clock(),
                                           autostart=False)
        self.stepper.step(self.held)  # compile the kernels now, not in the first trial
        self.stepper.reset()
        self.get_logger().info(
            f"{config['mode']} plant, mass uncertainty {self.experiment.mass_uncertainty:g}, "
            f"{self.last_index + 1} samples per trial")

    def on_reset(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """Put the arm at x_d(0), stop stepping, announce the next trial's t0."""
        self._stop()
        self.stepper.reset()
        self.held[:] = 0.0
        self.t0_ns = self.now_ns + self.step_ns
        self.armed = True
        response.success = True
        response.message = f"{topics.T0_PREFIX}{self.t0_ns}"
        return response

    def on_start(self, request: Trigger.Request, response: Trigger.Response
                 ) -> Trigger.Response:
        """Publish sample 0 and step until the last sample."""
        if not self.armed:
            response.success = False
            response.message = "call reset before start"
            return response
        if self.state_pub.get_subscription_count() < 1 or \
                self.command_sub.get_publisher_count() < 1:
            response.success = False
            response.message = "waiting for a controller on " + topics.EFFORT_COMMANDS
            return response
        self.armed = False
        self.running = True
        self.index = 0
        self.now_ns = self.t0_ns
        self._publish()
        if self.timer is not None:
            self.timer.reset()
        response.success = True
        response.message = f"{topics.T0_PREFIX}{self.t0_ns}"
        return response

    def on_command(self, raw: bytes) -> None:
        """Lock-step: apply the command for the current sample and advance; real-time: hold."""
        try:
            effort = read_float64_array(raw)
        except CdrError as exc:
            self.get_logger().error(f"bad effort command ignored: {exc}",
                                    throttle_duration_sec=5.0)
            return
        if effort.shape[0] != self.held.shape[0]:
            self.get_logger().error(f"effort command with {effort.shape[0]} entries ignored; "
                                    f"expected {self.held.shape[0]}", throttle_duration_sec=5.0)
        elif self.lock_step:
            if self.running:
                self._advance(effort)
        else:
            self.held[:] = effort

    def on_tick(self) -> None:
        """Real-time mode: one period with the held command."""
        if self.running:
            self._advance(self.held)

    def _advance(self, effort: np.ndarray) -> None:
        self.stepper.step(effort)
        self.index += 1
        self.now_ns += self.step_ns
        self._publish()
        if self.index >= self.last_index:
            self._stop()

    def _stop(self) -> None:
        self.running = False
        if self.timer is not None:
            self.timer.cancel()

    def _publish(self) -> None:
        stepper = self.stepper
        self.state_pub.publish(self.state.write(self.now_ns, stepper.position, stepper.velocity,
                                                stepper.applied))
        if self.index % self.clock_every and self.index < self.last_index:
            return  # /clock at every clock_every-th sample, the first and the last
        sec, nanosec = divmod(self.now_ns, 1_000_000_000)
        self.clock.clock.sec = sec
        self.clock.clock.nanosec = nanosec
        self.clock_pub.publish(self.clock)


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros plant_simulator``."""
    return spin(PlantSimulator, args)


if __name__ == "__main__":
    raise SystemExit(main())
