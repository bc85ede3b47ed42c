"""Safety and reliability of the node graph (issue 5): error envelope, bad input, watchdog,
diagnostics, crash-safe store and resume after kill -9, clean shutdown on SIGTERM.

Short trials (trajectory.duration 1.0 s: 101 samples) and few trials keep the graph tests
short. "Equal" below means exactly equal (atol 0): the graph runs the in-process arithmetic.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from processes import sigkill_child

from exo_ilc_ros.core.loop.trial import record_from_samples
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import LearningSession, run_trials
from exo_ilc_ros.core.sim.experiment import Experiment
from exo_ilc_ros.orchestration.launcher import GraphError
from exo_ilc_ros.wire import topics

pytestmark = pytest.mark.graph

SHORT = {"trajectory.duration": 1.0}
JOINTS = ["shoulder_flexion", "shoulder_abduction", "elbow_flexion"]


def _config(**overrides: Any) -> Config:
    return load_config(overrides={**SHORT, **overrides})


def _table(summaries: list[Any], config: Config, key: str = "max_abs_error") -> np.ndarray:
    joints = config["joint_names"]
    return np.array([s.row(key, joints) for s in summaries])


def _same_as_in_process(summaries: list[Any], config: Config) -> None:
    local = run_trials(config)
    assert [s.trial for s in summaries] == list(range(1, config["max_trials"] + 1))
    for key, expected in (("max_abs_error", local.max_abs_errors),
                          ("max_abs_feedforward", local.max_abs_feedforward),
                          ("max_abs_effort", local.max_abs_effort)):
        np.testing.assert_array_equal(_table(summaries, config, key), expected, err_msg=key)


def _health(session: Any) -> dict[str, Any]:
    """Follow /diagnostics: the last health status of each node (by status name)."""
    from diagnostic_msgs.msg import DiagnosticArray

    from exo_ilc_ros.nodes.common import DIAGNOSTICS_QOS

    seen: dict[str, Any] = {}

    def on_msg(msg: Any) -> None:
        for item in msg.status:
            if item.name.endswith("/health"):
                seen[item.name] = item
    session.node.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, on_msg,
                                     DIAGNOSTICS_QOS)
    session.executor.remove_node(session.node)  # EventsExecutor: register the new entity
    session.executor.add_node(session.node)
    return seen


def _values(item: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in item.values}


# --- start-up -------------------------------------------------------------------------------
def test_invalid_yaml_fails_with_file_key_rule_before_any_node_moves(tmp_path: Path) -> None:
    """`exo-ilc run --config bad.yaml` exits 2 naming file, key and rule before starting a node;
    each node started with the file exits 2 with the key and the rule."""
    bad = tmp_path / "bad.yaml"
    bad.write_text('"/**":\n  ros__parameters:\n    control:\n      effort_limit: [80.0, -1.0, '
                   '40.0]\n')
    ros_logs = tmp_path / "ros_log"  # every ROS context started writes its log file here
    result = subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--config",
                             str(bad), "--no-bag", "--no-store"], capture_output=True,
                            text=True, timeout=60, stdin=subprocess.DEVNULL, check=False,
                            env={**os.environ, "ROS_LOG_DIR": str(ros_logs)})
    assert result.returncode == 2, result.stderr
    assert str(bad) in result.stderr and "control.effort_limit" in result.stderr
    assert "must be > 0" in result.stderr
    assert "ROS_DOMAIN_ID" not in result.stderr  # no graph was started
    assert not ros_logs.exists() or not any(ros_logs.iterdir()), "a ROS node was started"
    for module in ("plant_simulator", "computed_torque_controller", "ilc_supervisor"):
        node = subprocess.run([sys.executable, "-m", f"exo_ilc_ros.nodes.{module}",
                               "--ros-args", "--params-file", str(bad)], capture_output=True,
                              text=True, timeout=60, stdin=subprocess.DEVNULL, check=False)
        out = node.stdout + node.stderr
        assert node.returncode == 2, out
        assert "control.effort_limit" in out and "must be > 0" in out, out


# --- bad input at the nodes (callbacks driven directly, no DDS traffic needed) ---------------
def _joint_state_raw(names: list[str], stamp_ns: int, position: list[float],
                     velocity: list[float]) -> bytes:
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    msg = JointState(name=names, position=position, velocity=velocity)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    return bytes(serialize_message(msg))


def test_nodes_reject_bad_input_keep_running_and_report_it() -> None:
    """NaN/inf, wrong lengths, unknown or missing joints, repeated stamps, undecodable bytes:
    rejected, counted per cause on the node's health, never turned into an effort; names in
    another order are reordered; over-limit efforts are clamped by the plant and counted."""
    import rclpy
    from trajectory_msgs.msg import JointTrajectory

    from exo_ilc_ros.nodes.computed_torque_controller import ComputedTorqueController
    from exo_ilc_ros.nodes.ilc_supervisor import IlcSupervisor
    from exo_ilc_ros.nodes.messages import feedforward_message
    from exo_ilc_ros.nodes.plant_simulator import PlantSimulator
    from exo_ilc_ros.wire.cdr import float64_array

    rclpy.init()
    try:
        controller = ComputedTorqueController()
        plant = PlantSimulator()
        supervisor = IlcSupervisor()
        published: list[bytes] = []
        controller.command_pub.publish = lambda msg: published.append(msg)  # type: ignore
        # The supervisor's own feed-forward message for trial 1 at t0 = 10 ms.
        first = LearningSession(supervisor.params.config)

        def trial_1_message() -> JointTrajectory:
            return feedforward_message(supervisor.protocol.reference, first.feedforward, 1,
                                       10_000_000, supervisor.protocol.samples.step_ns,
                                       supervisor.joint_names)

        good_ff = trial_1_message()
        nan_ff = trial_1_message()
        nan_ff.points[5].accelerations[1] = float("nan")
        renamed = trial_1_message()
        renamed.joint_names = ["a", "b", "c"]
        short = trial_1_message()
        short.points = short.points[:-1]
        for bad in (nan_ff, renamed, short, JointTrajectory()):
            controller.on_feedforward(bad)
        assert controller.samples == 0, "no bad profile was loaded"
        controller.on_feedforward(good_ff)
        assert controller.samples == controller.step_count and controller.trial == 1

        q0 = list(controller.q_ref[0])
        zero = [0.0, 0.0, 0.0]
        t0 = controller.t0_ns
        bad_states = [
            _joint_state_raw(JOINTS, t0, [float("nan"), 0.0, 0.0], zero),
            _joint_state_raw(JOINTS, t0, q0, [0.0, float("inf"), 0.0]),
            _joint_state_raw(JOINTS, t0, q0[:2], zero),
            _joint_state_raw(["shoulder_flexion", "wrist", "elbow_flexion"], t0, q0, zero),
            _joint_state_raw(JOINTS[:2], t0, q0[:2], zero[:2]),
            _joint_state_raw([JOINTS[0], JOINTS[0], JOINTS[2]], t0, q0, zero),
            b"\x00\x01\x00\x00\x01",
            b"garbage",
        ]
        for raw in bad_states:
            controller.on_joint_state(raw)
        assert published == [], "no effort from a rejected state"
        # Reordered names are accepted and reordered: same effort as the plant's layout.
        order = [2, 0, 1]
        controller.on_joint_state(_joint_state_raw([JOINTS[j] for j in order], t0,
                                                   [q0[j] for j in order], zero))
        assert len(published) == 1
        controller.on_joint_state(_joint_state_raw(JOINTS, t0, q0, zero))  # repeated stamp
        assert len(published) == 1, "a repeated stamp gives no second command"
        experiment = Experiment(controller.params.config)
        ref = experiment.reference
        record = record_from_samples(experiment, 1, good_ff_array(good_ff), ref.position,
                                     ref.velocity)
        np.testing.assert_allclose(np.frombuffer(published[0][-24:], "<f8"),
                                   record.effort[0], rtol=0.0, atol=1e-12)
        health = controller.health.status()
        causes = _values(health)
        for cause in ("non_finite", "wrong_length", "unknown_joint", "missing_joint",
                      "duplicate_joint", "non_monotonic_stamp", "not_numeric"):
            assert int(causes[f"rejected/{cause}"]) >= 1, (cause, causes)
        assert health.level == health.WARN and "rejected" in health.message

        # The plant: rejected commands never move it; over-limit ones are clamped, counted.
        limit = np.asarray(plant.params.config["control.effort_limit"])
        plant.running = True  # as after /start
        before = plant.stepper.position.copy()
        for raw in (float64_array(np.array([np.nan, 0.0, 0.0])), float64_array(np.zeros(2)),
                    float64_array(np.array([0.0, np.inf, 0.0])), b"\x00\x01\x00\x00"):
            plant.on_command(raw)
        np.testing.assert_array_equal(plant.stepper.position, before)
        assert plant.index == 0
        plant.on_command(float64_array(np.array([1e9, -1e9, 0.0])))
        assert plant.index == 1
        np.testing.assert_array_equal(plant.stepper.applied, [limit[0], -limit[1], 0.0])
        health = plant.health.status()
        values = _values(health)
        assert values["over_limit"] == "1" and values[f"saturated/{JOINTS[0]}"] == "1"
        assert int(values["rejected/non_finite"]) == 2
        assert int(values["rejected/wrong_length"]) == 1
        assert health.level == health.WARN and "beyond the limit" in health.message
        for node in (controller, plant, supervisor):
            node.destroy_node()
    finally:
        rclpy.try_shutdown()


def good_ff_array(msg: Any) -> np.ndarray:
    return np.array([list(p.accelerations) for p in msg.points])


# --- the plant's watchdog in real-time mode (node in-process, no controller) -------------------
def test_plant_watchdog_in_real_time_mode_stops_holding_the_last_command(tmp_path: Path
                                                                         ) -> None:
    """Real-time plant, commands fed for the first ticks, then none: the last command is held
    until ``safety.watchdog_periods`` periods of wall time passed; from then on every tick
    applies the safe hold around the pose at the trip (exactly ``safe_hold_effort`` with the
    hold's gains, ramped from the controller's over ``safety.hold_ramp``), reported
    on /joint_states and as ERROR on /diagnostics; a late command is ignored (counted). The next
    trial (reset + start) clears it and holds commands again."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray
    from std_srvs.srv import Trigger

    from exo_ilc_ros.core.loop.controller import safe_hold_effort
    from exo_ilc_ros.nodes.common import DIAGNOSTICS_QOS, SAMPLES_QOS
    from exo_ilc_ros.nodes.plant_simulator import PlantSimulator
    from exo_ilc_ros.wire.cdr import float64_array

    periods = 10
    config = _config(mode="real_time", watchdog_min_timeout=0.0,
                     **{"trajectory.duration": 3.0, "safety.watchdog_periods": periods})
    params = tmp_path / "params.yaml"
    params.write_text(config.to_ros_yaml("plant watchdog test"))
    rclpy.init(args=["--ros-args", "--params-file", str(params)])
    try:
        plant = PlantSimulator()
        timeout_ns = periods * 10_000_000  # control.period 0.01 s, real_time_rate 1
        assert not plant.lock_step and plant.watchdog.timeout_ns == timeout_ns
        peer = rclpy.create_node("computed_torque_controller")  # the commands' contract node
        states: list[Any] = []
        health: list[Any] = []
        peer.create_subscription(JointState, topics.JOINT_STATES, states.append, SAMPLES_QOS)
        peer.create_subscription(DiagnosticArray, topics.DIAGNOSTICS, lambda m: health.extend(
            s for s in m.status if s.name == "plant_simulator/health"), DIAGNOSTICS_QOS)
        peer.create_publisher(Float64MultiArray, topics.EFFORT_COMMANDS, QoSProfile(depth=10))
        executor = SingleThreadedExecutor()
        executor.add_node(plant)
        executor.add_node(peer)

        def spin_until(done: Any, timeout: float) -> None:
            deadline = time.monotonic() + timeout
            while not done():
                assert time.monotonic() < deadline, "timed out"
                executor.spin_once(timeout_sec=0.01)

        spin_until(lambda: plant.state_pub.get_subscription_count() >= 1 and
                   plant.command_sub.get_publisher_count() >= 1, 10.0)
        # Every step the plant takes: (effort asked, q and qdot before it, wall time, tripped).
        steps: list[tuple[np.ndarray, np.ndarray, np.ndarray, int, bool]] = []
        real_step = plant.stepper.step

        def step(effort: np.ndarray, saturated: np.ndarray | None = None) -> int:
            steps.append((effort.copy(), plant.stepper.position.copy(),
                          plant.stepper.velocity.copy(), time.monotonic_ns(),
                          plant.hold_pose is not None))
            return real_step(effort, saturated)
        plant.stepper.step = step  # type: ignore[method-assign]

        assert plant.on_reset(Trigger.Request(), Trigger.Response()).success
        assert plant.on_start(Trigger.Request(), Trigger.Response()).success
        command = np.array([3.0, -2.0, 1.0])
        while len(steps) < 10 and plant.hold_pose is None:  # commands in time: held
            plant.on_command(float64_array(command))
            executor.spin_once(timeout_sec=0.01)
        last_command_ns = plant.watchdog.last_ns  # the last command it took
        spin_until(lambda: plant.hold_pose is not None, 5.0)  # no more commands
        assert plant.watchdog.trips == 1
        first_hold = next(i for i, s in enumerate(steps) if s[4])
        spin_until(lambda: len(steps) >= first_hold + 10, 5.0)
        late = plant.watchdog.late
        plant.on_command(float64_array(np.array([50.0, 50.0, 50.0])))  # late: ignored
        late_at = len(steps)
        spin_until(lambda: len(steps) >= late_at + 5, 5.0)
        assert plant.watchdog.late == late + 1

        before = steps[:first_hold]
        assert before, "the last command was held before the trip"
        for effort, *_ in before:
            np.testing.assert_array_equal(effort, command)
        assert steps[first_hold][3] - last_command_ns > timeout_ns  # not before the timeout
        hold_pose = steps[first_hold][1]
        np.testing.assert_array_equal(plant.hold_pose, hold_pose)
        e = plant.experiment
        for m, (effort, q, qd, _, tripped) in enumerate(steps[first_hold:]):
            assert tripped  # the hold's gains ramp from the controller's over hold_ramp ticks
            w = min(1.0, m / e.hold_ramp)
            kp, kd = (e.hold_kp, e.hold_kd) if w == 1.0 else \
                (e.kp + w * (e.hold_kp - e.kp), e.kd + w * (e.hold_kd - e.kd))
            expected = safe_hold_effort(hold_pose, q, qd, kp, kd, e.nominal.kernel_args,
                                        plant.limit)
            np.testing.assert_array_equal(effort, expected)
            assert not np.array_equal(effort, command)
        # /joint_states reports what was applied: state i follows step i (sample 0 first).
        spin_until(lambda: len(states) >= len(steps) + 1 and any(
            h.level == h.ERROR for h in health), 5.0)
        for i, (effort, *_) in enumerate(steps[:len(states) - 1], start=1):
            np.testing.assert_array_equal(states[i].effort, np.clip(effort, -plant.limit,
                                                                     plant.limit))
        item = next(h for h in health if h.level == h.ERROR)
        assert "watchdog: no effort command; safe hold" in item.message
        values = _values(item)
        assert values["watchdog/state"] == "timed_out" and values["watchdog/trips"] == "1"

        # The next trial clears the trip: commands are held again.
        assert plant.on_reset(Trigger.Request(), Trigger.Response()).success
        assert plant.hold_pose is None
        assert plant.on_start(Trigger.Request(), Trigger.Response()).success
        steps.clear()
        plant.on_command(float64_array(command))
        spin_until(lambda: len(steps) >= 1, 5.0)
        np.testing.assert_array_equal(steps[0][0], command)
        assert not steps[0][4] and plant.health.status().level != item.ERROR
        executor.shutdown()
        plant.destroy_node()
        peer.destroy_node()
    finally:
        rclpy.try_shutdown()


# --- the error envelope in the graph ----------------------------------------------------------
def test_envelope_abort_in_the_graph_equals_in_process_and_sigterm_stops_cleanly() -> None:
    """A tight envelope aborts every trial: the graph gives exactly run_trials' table, marks
    each trial aborted (event and summary), learns up to each abort as in-process, reports it
    on /diagnostics; SIGTERM then stops every node (exit 0)."""
    from exo_ilc_ros.orchestration.graph import GraphSession

    config = _config(max_trials=3, **{"safety.error_envelope": [0.01, 0.01, 0.01]})
    local = run_trials(config)
    assert local.aborted == [1, 2, 3]
    with GraphSession(config) as session:
        health = _health(session)
        session.spin_until(lambda: session.finished, timeout=120.0, stall_timeout=60.0)
        session.spin_until(lambda: "computed_torque_controller/health" in health and
                           "ilc_supervisor/health" in health and _values(
                               health["computed_torque_controller/health"]).get(
                                   "aborted_trials") == "1 2 3" and "aborted by" in
                           health["ilc_supervisor/health"].message, timeout=10.0)
        _same_as_in_process(session.summaries, config)
        assert [s.values["aborted_at"] for s in session.summaries] == \
            [str(r.aborted_at) for r in local.records]
        aborted = [v for m, v, _ in session.events if m == "aborted" and
                   v["reason"] == "error_envelope"]
        assert [v["trial"] for v in aborted] == ["1", "2", "3"]
        ff = _table(session.summaries, config, "max_abs_feedforward")
        np.testing.assert_allclose(ff, local.max_abs_feedforward, rtol=0.0, atol=1e-9)
        controller = health["computed_torque_controller/health"]
        assert controller.level >= controller.WARN
        assert _values(controller)["aborted_trials"] == "1 2 3"
        supervisor = health["ilc_supervisor/health"]
        assert "aborted by the error envelope" in supervisor.message
        processes = session.processes.processes
        for process in processes.values():
            process.send_signal(signal.SIGTERM)
        codes = {name: process.wait(timeout=20) for name, process in processes.items()}
        assert codes == dict.fromkeys(processes, 0), codes


# --- bad input in a running graph, and the watchdog -------------------------------------------
def test_bad_messages_and_a_stalled_plant_change_nothing_learned() -> None:
    """While the graph runs: bad /joint_states and effort commands are rejected by every node
    (counted on /diagnostics); the plant frozen (SIGSTOP) mid-trial trips the controller's
    watchdog (safe hold, ERROR, the trial run again). The table still equals in-process."""
    from rclpy.qos import QoSProfile
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    from exo_ilc_ros.nodes.common import SAMPLES_QOS
    from exo_ilc_ros.orchestration.graph import GraphSession

    # 30 s trials last ~1-2 s of wall time in lock-step, so the freeze below lands mid-trial
    # (a 3 s trial can be over before the signal arrives on a busy machine).
    config = _config(max_trials=6, **{"trajectory.duration": 30.0})
    with GraphSession(config) as session:
        health = _health(session)
        state_pub = session.node.create_publisher(JointState, topics.JOINT_STATES, SAMPLES_QOS)
        effort_pub = session.node.create_publisher(Float64MultiArray, topics.EFFORT_COMMANDS,
                                                   QoSProfile(depth=10))
        session.spin_until(lambda: len(session.summaries) >= 1 and
                           state_pub.get_subscription_count() >= 2 and
                           effort_pub.get_subscription_count() >= 1, timeout=90.0)
        for _ in range(3):
            state_pub.publish(JointState(name=JOINTS, position=[float("nan")] * 3,
                                         velocity=[0.0] * 3))
            state_pub.publish(JointState(name=["x", "y", "z"], position=[0.0] * 3,
                                         velocity=[0.0] * 3))
            state_pub.publish(JointState(name=JOINTS, position=[0.0] * 2, velocity=[0.0] * 3))
            effort_pub.publish(Float64MultiArray(data=[float("nan"), 0.0, 0.0]))
            effort_pub.publish(Float64MultiArray(data=[0.0, 0.0]))
        # Freeze the plant in the middle of a trial (from trial 3 on; tried again on the next
        # trial if the stop fell between two trials).
        plant = session.processes.processes["plant_simulator"]

        def tripped() -> bool:
            item = health.get("computed_torque_controller/health")
            return item is not None and "watchdog" in item.message

        for trial in (3, 4, 5):
            session.spin_until(lambda t=trial: any(m == "start" and v.get("trial") == str(t)
                                                   for m, v, _ in session.events),
                               timeout=60.0)
            # "start" comes before the plant's start service: let sample 0 and a few go by.
            end = time.monotonic() + 0.1
            while time.monotonic() < end:
                session.executor.spin_once(timeout_sec=0.01)
            plant.send_signal(signal.SIGSTOP)
            try:
                with contextlib.suppress(GraphError):
                    session.spin_until(tripped, timeout=6.0)  # >= watchdog_min_timeout
            finally:
                plant.send_signal(signal.SIGCONT)
            if tripped():
                break
        assert tripped(), "the controller's watchdog tripped"
        assert health["computed_torque_controller/health"].level == b"\x02"  # ERROR
        session.spin_until(lambda: session.finished, timeout=120.0, stall_timeout=60.0)
        nodes = ("plant_simulator", "computed_torque_controller", "ilc_supervisor")

        def messages() -> dict[str, str]:
            return {n: getattr(health.get(f"{n}/health"), "message", "") for n in nodes}

        try:
            session.spin_until(lambda: all("rejected" in m for m in messages().values()),
                               timeout=10.0)
        except GraphError:
            pytest.fail(f"not every node reports the rejected input: {messages()}")
    _same_as_in_process(session.summaries, config)
    retried = [v for m, v, _ in session.events if m == "aborted"]
    assert any(v.get("reason") == "watchdog" for v in retried), retried
    for name in ("plant_simulator", "computed_torque_controller", "ilc_supervisor"):
        values = _values(health[f"{name}/health"])
        assert sum(int(v) for k, v in values.items() if k.startswith("rejected/")) >= 3, name


# --- nothing lost: kill -9 and resume ----------------------------------------------------------
def _kill_mid_trial(config: Config, victim: str, after: int) -> int:
    """Run the graph with a store, kill -9 ``victim`` as soon as ``after`` trials are stored
    (i.e. during trial ``after + 1``); returns the number of trials stored."""
    from exo_ilc_ros.orchestration.graph import GraphSession, stored_summaries

    with GraphSession(config) as session:
        def stored() -> bool:
            found = list(Path(config["store.directory"]).glob("*/index.json"))
            return bool(found) and len(json.loads(found[0].read_text())["trials"]) >= after
        deadline = time.monotonic() + 90.0
        while not stored() and time.monotonic() < deadline:
            session.executor.spin_once(timeout_sec=0.005)
        session.processes.processes[victim].send_signal(signal.SIGKILL)
        with pytest.raises(GraphError, match=f"node {victim} exited with code -9"):
            session.spin_until(lambda: False, timeout=20.0)
    return len(stored_summaries(config))


def test_kill_9_a_node_mid_trial_then_resume_is_bit_identical(tmp_path: Path) -> None:
    """kill -9 of the plant in the middle of trial 3, then, in the resumed graph, of the
    controller in the middle of trial 5 (trials of 3 s, 301 samples): each time the graph stops
    with the node named and the store holds the trials before (the killed one too if it ended
    first); the graph resumed again finishes with exactly the uninterrupted table (the trials
    the first resume stored included). One store for both kills: a graph session less than a
    run per victim."""
    from exo_ilc_ros.orchestration.graph import run_graph

    config = _config(max_trials=6, **{"store.directory": str(tmp_path / "store"),
                                      "trajectory.duration": 3.0})
    stored = _kill_mid_trial(config, "plant_simulator", 2)
    assert stored in (2, 3), stored
    resume = config.replace({"store.resume": True})
    stored = _kill_mid_trial(resume, "computed_torque_controller", 4)
    assert stored in (4, 5), stored
    resumed = run_graph(resume, timeout=120.0, stall_timeout=60.0)
    assert resumed.summaries[stored].trial == stored + 1
    _same_as_in_process(resumed.summaries, config)


def test_kill_9_the_supervisor_then_exo_ilc_run_resume(tmp_path: Path) -> None:
    """`exo-ilc run --store DIR`: kill -9 of ilc_supervisor mid-trial stops the graph with the
    node named and the resume command (exit 3); `--resume` finishes the run and its JSON equals
    `exo-ilc simulate`'s exactly. Without --resume the used store is refused before any node
    starts."""
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    store = tmp_path / "store"
    common = [sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--no-bag", "--config",
              str(config_file), "--trials", "5", "--store", str(store)]
    process = subprocess.Popen(common, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               stdin=subprocess.DEVNULL, text=True)
    try:
        index = None
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and process.poll() is None:
            found = list(store.glob("*/index.json"))
            if found and len(json.loads(found[0].read_text())["trials"]) >= 2:
                index = found[0]
                break
            time.sleep(0.02)
        assert index is not None, "two trials stored"
        err = sigkill_child(process, "ilc_supervisor")
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    _assert_stopped_for_resume(process, err, "ilc_supervisor", store)
    refused = subprocess.run(common, capture_output=True, text=True, timeout=60,
                             stdin=subprocess.DEVNULL, check=False)
    assert refused.returncode == 2 and "add --resume" in refused.stderr, refused.stderr
    graph_json, local_json = tmp_path / "graph.json", tmp_path / "local.json"
    resumed = subprocess.run([*common, "--resume", "--json", str(graph_json)],
                             capture_output=True, text=True, timeout=180,
                             stdin=subprocess.DEVNULL, check=False)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert "resuming after trial" in resumed.stderr
    from exo_ilc_ros.cli.main import main as exo_ilc  # simulate in this process: no start-up

    assert exo_ilc(["simulate", "--config", str(config_file), "--trials", "5", "--json",
                    str(local_json)]) == 0
    (g,), (r,) = json.loads(graph_json.read_text())["runs"], json.loads(
        local_json.read_text())["runs"]
    assert g["trials"] == r["trials"]
    assert g["iterations_to_bound"] == r["iterations_to_bound"]


@pytest.mark.parametrize(("flags", "process_name"), [
    ([], "ilc_supervisor+bag_recorder"), (["--isolated-recorder"], "bag_recorder")],
    ids=["in_the_supervisors_process", "isolated"])
def test_kill_9_the_recorder_then_resume_keeps_every_trial_in_the_bags(
        tmp_path: Path, flags: list[str], process_name: str) -> None:
    """`exo-ilc run --store DIR --bag-dir B`: kill -9 of the process running bag_recorder (by
    default the supervisor's, which dies with it; or its own with --isolated-recorder) in the
    middle of trial 3 (after it filed trial 2) stops the graph with the process named and the
    resume command (exit 3). `--resume` finishes the run into a second bag; its JSON equals
    run_trials' exactly, and the two bags together (the first up to the kill, the second from
    the resumed trial on) hold every trial exactly once, with run_trials' max |e|. Isolated,
    trial 3 may end before the graph is stopped (the death is polled every 0.5 s), but the
    supervisor stores a trial only once the recorder filed it, so trial 3 is never stored and
    is run again."""
    from exo_ilc_ros.bag import read_bag, trials_filed
    from exo_ilc_ros.core.session.summary import RunSummary

    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 3.0\n')
    store, bags = tmp_path / "store", tmp_path / "bags"
    trials = 5
    common = [sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--quiet", "--config",
              str(config_file), "--trials", str(trials), "--store", str(store), "--bag-dir",
              str(bags), *flags]
    process = subprocess.Popen(common, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               stdin=subprocess.DEVNULL, text=True)
    try:
        first_bag: Path | None = None
        stored_at_kill = -1
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and process.poll() is None:
            found = list(store.glob("*/index.json"))
            stored = len(json.loads(found[0].read_text())["trials"]) if found else 0
            made = list(bags.iterdir()) if bags.is_dir() else []
            if stored >= 2 and made and trials_filed(made[0]) >= 2:
                first_bag, stored_at_kill = made[0], stored
                break
            time.sleep(0.01)
        assert first_bag is not None, "two trials stored and filed"
        time.sleep(0.05)  # into trial 3 (the supervisor starts it once trial 2 is filed)
        err = sigkill_child(process, "bag_recorder")
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    _assert_stopped_for_resume(process, err, process_name, store)
    stored_after = len(json.loads(next(store.glob("*/index.json")).read_text())["trials"])
    assert stored_at_kill == 2 and stored_after >= 2, (stored_at_kill, stored_after)

    graph_json = tmp_path / "graph.json"
    resumed = subprocess.run([*common, "--resume", "--json", str(graph_json)],
                             capture_output=True, text=True, timeout=180,
                             stdin=subprocess.DEVNULL, check=False)
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert f"resuming after trial {stored_after}" in resumed.stderr
    (second_bag,) = [b for b in bags.iterdir() if b != first_bag]
    assert f"bag: {second_bag}" in resumed.stderr

    config = load_config(config_file).replace({"max_trials": trials})
    reference = run_trials(config)
    local = RunSummary.from_result(reference).to_json()
    (graph,) = json.loads(graph_json.read_text())["runs"]
    assert graph["trials"] == local["trials"]  # exactly: floats through repr and JSON
    assert graph["iterations_to_bound"] == local["iterations_to_bound"]

    before, after = read_bag(first_bag), read_bag(second_bag)
    # Stored is a subset of filed: every stored trial is in the first bag. A trial the recorder
    # filed in the instant before SIGKILL (a short trial takes ~30 ms; in the supervisor's
    # process the kill also takes the supervisor before it stored it) is in that bag but not
    # stored, so the resume runs it again: then it is in both bags, identical.
    assert before.completed[:stored_after] == list(range(1, stored_after + 1))
    assert len(before.completed) <= stored_after + 1, (before.completed, stored_after)
    assert before.resumed_after is None
    assert after.completed == list(range(stored_after + 1, trials + 1))
    assert after.resumed_after == stored_after and not after.incomplete
    assert sorted(set(before.completed + after.completed)) == list(range(1, trials + 1))
    for run in (before, after):
        for k in run.completed:
            assert run.trials[k].complete, (run.path, k)
            np.testing.assert_array_equal(run.trials[k].max_abs_error,
                                          reference.max_abs_errors[k - 1])
    assert (first_bag / ".splits").is_dir()  # the killed recorder's unfinished file, unlisted
    assert not (second_bag / ".splits").exists()  # closed normally


def _assert_stopped_for_resume(process: subprocess.Popen[str], err: str, node: str,
                               store: Path) -> None:
    """``exo-ilc run`` stopped with exit 3, named the dead node and printed the resume."""
    assert process.returncode == 3, err[-3000:]
    assert f"node {node} exited with code -9" in err
    assert "--resume" in err and str(store) in err
