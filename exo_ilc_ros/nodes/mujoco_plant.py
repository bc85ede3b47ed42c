"""mujoco_plant: the arm simulated by MuJoCo (``core/sim/mujoco_arm.py``), as the graph's plant,
without reset or start services: it behaves as an arm does, so the trials need ``protocol:
homing``.

It runs under the plant's node name (``plant_simulator``: the same parameter section, so the
supervisor reads its mass uncertainty as from our simulator) and publishes ``/joint_states`` and
``/clock``, takes ``/effort_controller/commands``. ``mode: lock_step`` advances one control
period per command and nothing else (the first sample goes out once a controller is linked, and
again after 1 s while no command came); ``real_time`` steps on a wall-clock timer with the last
command held, and once the plant's watchdog (:func:`exo_ilc_ros.core.loop.safety.watchdog_for`,
the controller's rule: ``safety.watchdog_periods`` periods of wall time, never less than
``watchdog_min_timeout``) saw no command applies the safe hold around the pose of that moment
instead, until commands come again.

:class:`FreeRunningPlant` is the node with any stepper; ``free_running_plant`` runs it with our
own simulator's RK4 (``core/loop/plant.py``): our simulator as any arm, for ``protocol: homing``.
Commands are checked and clamped as in ``plant_simulator``.

A state that stops being finite (our RK4 too stiff for a joint damping, or MuJoCo finding the
state bad: it resets its simulation to the rest pose then, which this node never passes on)
stops the plant: no sample of it is sent, ``diverged`` on /diagnostics says when, on which
joint and why (MuJoCo's cause, :func:`exo_ilc_ros.core.arm.mujoco_urdf.bad_state`), and the
supervisor ends the trial there (or, while homing, the run). The node runs on without stepping,
its health ERROR: a plant without reset has no state to go back to.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..core.loop.divergence import PlantDivergence, state_divergence
from ..core.loop.plant import finite_state
from ..core.loop.stepper import PlantStepper
from ..core.person.experiment import uses_person
from ..core.sim.mujoco_arm import MujocoArm, effects_not_simulated
from .common import spin, wall_clock
from .plant_base import NAME, Pace, PlantNode
from .realtime import plant_scheduling

__all__ = ["FIRST_SAMPLE_AGAIN", "NAME", "FreeRunningPlant", "MujocoPlant", "main"]

FIRST_SAMPLE_AGAIN = 1.0
"""Lock-step: wall seconds without any command before the first sample is sent again (it may
have gone out before the controller's subscription matched)."""


class FreeRunningPlant(PlantNode):
    """A plant that keeps its own clock and offers no services (``stepper``: position,
    velocity, applied, step(effort, saturated))."""

    engine = "rk4"
    hold_reason = "no effort command; safe hold"

    def __init__(self) -> None:
        super().__init__(self.on_command)
        config = self.params.config
        self.stepper: Any = self.make_stepper()
        ref = self.experiment.reference
        self.stepper_state(ref.position[0], ref.velocity[0])
        finite_state(ref.position[0], ref.velocity[0])  # compiled now, not at the first step
        self.now_ns = self.step_ns
        self.index = 0
        self.started = False
        self.stalls = 0
        """Periods the plant stepped on its own (the safe hold): no command came in time."""
        self.last_command_ns = 0
        """Lock-step: when the last command (or the first sample sent again) was."""
        self.pace = Pace(float(config["pace"]) if self.lock_step else 0.0)
        """Lock-step: simulated s per wall s at most, counted from the start (homing and the
        trials alike: this plant has no trial start of its own)."""
        wall_period = self.experiment.period / config["real_time_rate"]
        self.create_timer(wall_period if not self.lock_step else 0.05, self.on_tick,
                          clock=wall_clock())
        self.scheduler = plant_scheduling(self, config["thread_priority"], self.lock_step)
        self.get_logger().info(
            f"{self.engine} plant without services ({config['mode']}), mass uncertainty "
            f"{self.experiment.mass_uncertainty:g}; trials need protocol: homing")

    def make_stepper(self) -> Any:
        """Our simulator's RK4 stepper."""
        return PlantStepper(self.experiment)

    def stepper_state(self, q: np.ndarray, qd: np.ndarray) -> None:
        """Where the arm is when the node starts (at rest at q_d(0))."""
        self.stepper.position[:] = q
        self.stepper.velocity[:] = qd

    def on_command(self, raw: bytes) -> None:
        """Lock-step: apply the command over one period and publish the next sample;
        real-time: hold it. A command that is not one finite value per joint is rejected."""
        effort = self.command_of(raw)
        if effort is None:
            return
        if effort.shape != self.held.shape or not np.isfinite(effort).all():
            self.reject_effort(effort)
            return
        if self.diverged is not None:  # stopped: nothing is stepped, nothing sent
            return
        self.commands += 1
        if np.any(np.abs(effort) > self.limit):
            self.over_limit += 1
        self.held[:] = effort
        now = time.monotonic_ns()
        self.last_command_ns = now
        if self.watchdog.tripped:  # a command again: the watchdog runs on, the hold ends
            self.watchdog.arm(now)
        else:
            self.watchdog.feed(now)
        if self.hold_pose is not None:
            self.hold_pose = None
            self.get_logger().info("effort commands again; safe hold released")
        if self.lock_step and self.started:
            self._advance(self.held)

    def on_tick(self) -> None:
        """Both modes: start once a controller is linked. Lock-step: nothing moves without a
        command (simulated time stands still, as in plant_simulator); the first sample is sent
        again while no command ever came. Real time: one period with the held command, the
        safe hold once the watchdog (core.loop.safety) saw no command for its timeout."""
        now = time.monotonic_ns()
        if self.diverged is not None:
            return
        if not self.started:
            if self.state_pub.get_subscription_count() >= 1 and \
                    self.command_sub.get_publisher_count() >= 1 and \
                    self.command_sub.trusted_known():
                self.started = True
                self.last_command_ns = now
                self.watchdog.arm(now)
                self.pace.start(self.now_ns)
                self._publish()
            return
        if self.lock_step:
            if not self.commands and now - self.last_command_ns > FIRST_SAMPLE_AGAIN * 1e9:
                self.last_command_ns = now
                self._publish()
            return
        if self.watchdog.check(now):
            self.latch_safe_hold(self.stepper.position, "safe hold around the current pose "
                                 "until commands come again")
        if self.hold_pose is not None:
            effort = self.safe_hold.hold(np.array(self.stepper.position),
                                         np.array(self.stepper.velocity))
            self.stalls += 1
            self._advance(effort)
        else:
            self._advance(self.held)

    def _advance(self, effort: np.ndarray) -> None:
        before = (np.array(self.stepper.position), np.array(self.stepper.velocity))
        self.stepper.step(effort, self.saturated)
        self.index += 1
        self.now_ns += self.step_ns
        if not finite_state(self.stepper.position, self.stepper.velocity):
            self.report_divergence(self.divergence(*before), self.now_ns)
            return
        self.pace.wait(self.now_ns)
        self._publish()

    def divergence(self, position: np.ndarray, velocity: np.ndarray) -> PlantDivergence:
        """The divergence of our RK4 stepper (its state before the step given): the joint and
        cause by the in-process rule (:func:`state_divergence`; the sample is the plant's own
        count, the supervisor places it by its stamp)."""
        return state_divergence(self.experiment, 0, self.index, position, velocity,
                                self.params.config["joint_names"])

    def _publish(self) -> None:
        stepper = self.stepper
        self.state_pub.publish(self.state.write(self.now_ns, stepper.position, stepper.velocity,
                                                stepper.applied))
        if self.index % self.clock_every:
            return
        self.publish_clock(self.now_ns)

    def effort_values(self) -> list[tuple[str, str]]:
        """The engine, the scheduler, the stalls and simulated time, on its health."""
        return [("engine", self.engine), ("scheduler", self.scheduler),
                ("stalls", str(self.stalls)), ("simulated_time_ns", str(self.now_ns))]


class MujocoPlant(FreeRunningPlant):
    """The arm in MuJoCo (core/sim/mujoco_arm.py): masses scaled by (1 + mass_uncertainty), RK4 at
    ``integration_step`` (``implicitfast`` where the joint damping needs it)."""

    engine = "mujoco"

    def make_stepper(self) -> Any:
        """MuJoCo's arm of this configuration."""

        config = self.params.config
        if uses_person(config):  # the exoskeleton strapped to a person with muscles
            return self.experiment.make_stepper()
        if config["dynamics"] != "full":
            self.get_logger().warning("dynamics: MuJoCo always simulates the full plant "
                                      f"(eq (15)); {config['dynamics']!r} ignored")
        missing = effects_not_simulated(config)
        if missing:
            self.get_logger().warning("virtual patient: MuJoCo simulates friction, passive and "
                                      "spastic stiffness and damping only; not simulated here: "
                                      + ", ".join(missing))
        return MujocoArm.from_config(config)

    def stepper_state(self, q: np.ndarray, qd: np.ndarray) -> None:
        """At rest at q_d(0) when the node starts."""
        self.stepper.set_state(q, qd)

    def divergence(self, position: np.ndarray, velocity: np.ndarray) -> PlantDivergence:
        """MuJoCo's own word on the bad state (the DOF it named, why: its warning, its
        integrator, h b / I), not our RK4's rule."""
        arm = self.stepper
        names = self.params.config["joint_names"]
        joint = arm.diverged_joint if 0 <= arm.diverged_joint < len(names) else 0
        return PlantDivergence(0, self.index, self.index * self.experiment.period, joint,
                               str(names[joint]), arm.diverged or "MuJoCo's state is not finite")


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros mujoco_plant``."""
    return spin(MujocoPlant, args)


if __name__ == "__main__":
    raise SystemExit(main())
