"""Homing instead of a reset (core/protocol/homing.py) and the trial protocol without services
(core/protocol/homing_protocol.py), without ROS: an arm that keeps its own clock (our RK4 plant or
MuJoCo) driven sample by sample by the controller's homing decisions, its samples and reports
handed to the protocol as the nodes would."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core import Experiment, load_config, run_trials
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.controller import GuardedControlStep
from exo_ilc_ros.core.loop.stepper import PlantStepper
from exo_ilc_ros.core.protocol.homing import (
    ControllerMode,
    Homing,
    HomingController,
    HomingPath,
    HomingSettings,
    HomingState,
    fill_missing,
    grid_index,
    homing_duration,
)
from exo_ilc_ros.core.protocol.homing_protocol import HomingProtocol
from exo_ilc_ros.core.protocol.trial_protocol import Phase
from exo_ilc_ros.core.session.learning_session import TrialConclusion

SHORT = {"trajectory.duration": 1.0, "protocol": "homing"}
DELTA = 0.1
MS = 1_000_000


def _settings(**kw: Any) -> HomingSettings:
    base = dict(speed_limit=0.5, position_tolerance=np.full(3, 1e-3),
                velocity_tolerance=np.full(3, 1e-2), dwell=0.2, timeout=1.0,
                kp=np.full(3, 192.0), kd=np.full(3, 24.0), ki=np.full(3, 512.0),
                integral_limit=np.full(3, 10.0))
    base.update(kw)
    return HomingSettings(**base)  # type: ignore[arg-type]


def test_duration_from_distance_and_speed_limit() -> None:
    """T = 15/8 max|dq| / v, rounded up to whole periods: 1 rad at 0.5 rad/s -> 3.75 s; the
    path's peak speed is then the limit (the quintic's peak 15/8 |dq| / T at T/2)."""
    assert homing_duration(np.zeros(3), np.array([0.2, -1.0, 0.5]), 0.5, 0.01) == \
        pytest.approx(3.75)
    assert homing_duration(np.zeros(3), np.array([0.0, 0.001, 0.0]), 0.5, 0.01) == \
        pytest.approx(0.01)  # 3.75 ms: one period
    assert homing_duration(np.ones(3), np.ones(3), 0.5, 0.01) == 0.0
    path = HomingPath(np.zeros(3), np.array([0.2, -1.0, 0.5]), 0.5, 0.01)
    q, qd, _ = path(path.duration / 2)
    np.testing.assert_allclose(qd, [0.1, -0.5, 0.25], rtol=1e-12)
    np.testing.assert_allclose(q, [0.1, -0.5, 0.25], rtol=1e-12)  # half way at T/2
    q, qd, qdd = path(path.duration + 1.0)
    np.testing.assert_array_equal(q, [0.2, -1.0, 0.5])
    assert not qd.any() and not qdd.any()


def test_settles_after_the_dwell_and_fails_on_timeout_or_motion() -> None:
    """READY once within both tolerances for the dwell; FAILED when it does not settle within
    the timeout after the path, or when the arm leaves the tolerances during the dwell."""
    goal = np.zeros(3)
    at = np.zeros(3)
    homing = Homing(_settings(), goal, 0.01, 0, at)  # already there: no path
    assert homing.path.duration == 0.0
    assert homing.update(0, at, at) is HomingState.DWELL
    assert homing.update(190 * MS, at, at) is HomingState.DWELL
    assert homing.update(200 * MS, at, at) is HomingState.READY
    moved = Homing(_settings(), goal, 0.01, 0, at)
    moved.update(0, at, at)
    assert moved.update(100 * MS, at, np.array([0.0, 0.02, 0.0])) is HomingState.FAILED
    assert "moved during the dwell" in moved.reason and "0.02" in moved.reason
    away = np.array([0.0, 0.0, 0.01])
    stuck = Homing(_settings(), goal, 0.01, 0, away)  # 0.01 rad: a 40 ms path
    assert stuck.update(10 * MS, away, at) is HomingState.PATH
    assert stuck.update(500 * MS, away, at) is HomingState.SETTLING
    assert stuck.update(1041 * MS, away, at) is HomingState.FAILED
    assert "did not settle within 1 s" in stuck.reason
    nan = Homing(_settings(), goal, 0.01, 0, at)
    assert nan.update(0, np.full(3, np.nan), at) is HomingState.SETTLING


def test_the_dwell_begins_within_half_the_tolerances_and_ends_outside_the_whole() -> None:
    """Hysteresis: 0.8 mrad away (within the 1 mrad tolerance, not within half of it) does not
    begin the dwell; 0.4 mrad does, and the arm may then drift to 0.9 mrad (its PID still
    settling) without failing; beyond 1 mrad fails."""
    goal, rest = np.zeros(3), np.zeros(3)
    near = Homing(_settings(), goal, 0.01, 0, goal)
    assert near.update(0, np.array([8e-4, 0.0, 0.0]), rest) is HomingState.SETTLING
    assert near.update(10 * MS, np.array([4e-4, 0.0, 0.0]), rest) is HomingState.DWELL
    assert near.update(100 * MS, np.array([9e-4, 0.0, 0.0]), rest) is HomingState.DWELL
    assert near.update(210 * MS, np.array([9e-4, 0.0, 0.0]), rest) is HomingState.READY
    slow = Homing(_settings(), goal, 0.01, 0, goal)  # half the velocity tolerance, too
    assert slow.update(0, goal, np.array([0.0, 8e-3, 0.0])) is HomingState.SETTLING
    assert slow.update(10 * MS, goal, np.array([0.0, 4e-3, 0.0])) is HomingState.DWELL
    assert slow.update(20 * MS, np.array([0.0, 0.0, 1.1e-3]), rest) is HomingState.FAILED


def test_grid_and_interpolation() -> None:
    """Stamps go to the nearest grid point (offset kept); missing rows are interpolated."""
    step = 10 * MS
    assert grid_index(1_000 * MS, 1_000 * MS, step) == (0, 0)
    assert grid_index(1_000 * MS + 14 * MS, 1_000 * MS, step) == (1, 4 * MS)
    assert grid_index(1_000 * MS + 16 * MS, 1_000 * MS, step) == (2, -4 * MS)
    values = np.array([[0.0], [9.0], [2.0], [9.0], [9.0], [8.0]])
    got = fill_missing(values, np.array([True, False, True, False, False, True]))
    np.testing.assert_array_equal(got[:, 0], [0.0, 1.0, 2.0, 4.0, 6.0, 8.0])


def test_homing_parameters_are_checked() -> None:
    with pytest.raises(ConfigError, match=r"homing\.position_tolerance"):
        load_config(overrides={"homing.position_tolerance": [0.001, 0.0, 0.001]})
    with pytest.raises(ConfigError, match="protocol"):
        load_config(overrides={"protocol": "teleport"})
    with pytest.raises(ConfigError, match=r"homing\.ki: .*must be >= 0"):
        load_config(overrides={"homing.ki": -1.0})
    # the trial's PD (kp 16, kd 8) with ki 200 > kp kd: unstable by the integral (the PD
    # part alone is stable); a triple pole at -40 s^-1 is too fast for 100 Hz with the
    # command one period late, and fine at 1 kHz
    with pytest.raises(ConfigError, match=r"homing\.ki: joint 1: .*not stable"):
        load_config(overrides={"homing.kp": 16.0, "homing.kd": 8.0, "homing.ki": 200.0})
    load_config(overrides={"homing.kp": 16.0, "homing.kd": 8.0, "homing.ki": 100.0})
    with pytest.raises(ConfigError, match=r"homing\.kd: joint 1: .*not stable"):
        load_config(overrides={"homing.kp": 4800.0, "homing.kd": 120.0, "homing.ki": 64000.0})
    load_config(overrides={"homing.kp": 4800.0, "homing.kd": 120.0, "homing.ki": 64000.0,
                           "control.period": 0.001})
    with pytest.raises(ConfigError, match=r"homing\.kd: joint 1: .*not stable"):
        load_config(overrides={"homing.kp": 40000.0, "homing.kd": 400.0, "homing.ki": 0.0})


def test_the_integral_is_bounded_and_waits_while_the_effort_is_at_its_limit() -> None:
    """Anti-windup: an arm held 0.1 rad away makes z grow by 0.1 period per sample until
    |K_I z| reaches integral_limit, then no further; a sample whose last effort was at its
    limit leaves z as it is."""
    settings = _settings(integral_limit=np.array([10.0, 10.0, 0.0]))
    goal = np.zeros(3)
    held = np.full(3, -0.1)
    homing = Homing(settings, goal, 0.01, 0, goal)  # already there: the path is q_d(0)
    u_ff, q_path, _ = homing.command(0, held, saturated=False)
    np.testing.assert_allclose(homing.integral, [1e-3, 1e-3, 0.0])
    np.testing.assert_allclose(u_ff, 512.0 * homing.integral)
    np.testing.assert_array_equal(q_path, goal)
    before = homing.integral.copy()
    homing.command(10 * MS, held, saturated=True)
    np.testing.assert_array_equal(homing.integral, before)
    for k in range(2, 400):
        u_ff, _, _ = homing.command(k * 10 * MS, held, saturated=False)
    np.testing.assert_allclose(u_ff, [10.0, 10.0, 0.0])  # at the bound; joint 3: no integral


PANDA = {"protocol": "homing", "mass_uncertainty": DELTA}


def _panda_graph(overrides: dict[str, Any]) -> tuple[ArmGraph, HomingProtocol]:
    from exo_ilc_ros.core.params.config import config_dir
    from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

    config = load_config(config_dir() / "arms" / "panda.yaml", overrides={**PANDA, **overrides})
    graph = ArmGraph(config, MujocoArm.from_config(config))
    protocol = HomingProtocol(config, graph)
    graph.protocol = protocol
    protocol.open({"mass_uncertainty": DELTA})
    protocol.tick(graph_ready=True)
    return graph, protocol


def test_the_heavier_panda_on_mujoco_homes_with_the_integral_and_learns() -> None:
    """The Panda (config/arms/panda.yaml) on MuJoCo, 10 % heavier than its model, through
    the controller's homing decisions and the protocol: homing's PID settles within 1 mrad
    (its integral takes out the gravity error at q_d(0)), each homing takes the path and
    less than 0.5 s more (to within half the tolerance, then the 0.2 s dwell), and the
    linear law is within the bound on every joint at trial 3, as in-process. With the
    trial's PD (kp 16, kd 8) and no integral, homing leaves the gravity sag (0.25 rad on
    joint 6) and fails."""
    from exo_ilc_ros.core.protocol.homing import homing_duration

    graph, protocol = _panda_graph({"max_trials": 4})
    graph.run(10_000)
    assert protocol.phase is Phase.FINISHED and not graph.errors, graph.errors
    config = graph.experiment.config
    ref = graph.experiment.reference
    path = homing_duration(ref.position[-1], ref.position[0], config["homing.speed_limit"],
                           config["control.period"])
    times = [float(v["homing_time"]) for v in graph.summaries]
    # the path starts where the hold left the arm (near q_d(T)): about this long
    assert all(path <= t <= path + 0.5 for t in times), (path, times)
    for values in graph.summaries:
        e0 = np.array([float(values[f"initial_error/{n}"]) for n in config["joint_names"]])
        assert np.all(np.abs(e0) <= 1e-3), e0
    errors = np.array([c.record.max_abs_error for c in graph.conclusions])
    local = run_trials(config.replace({"protocol": "services"}), DELTA, trials=4)
    np.testing.assert_allclose(errors[0], local.max_abs_errors[0], rtol=0.01)
    assert np.all(errors[2:] <= 0.005) and np.any(errors[1] > 0.005), errors
    assert local.iterations_to_bound().first == [3] * 7

    pd_only, failing = _panda_graph({"max_trials": 1, "homing.kp": 16.0, "homing.kd": 8.0,
                                     "homing.ki": 0.0})
    pd_only.run(2_000)
    assert failing.error is not None and "did not settle" in failing.error
    assert pd_only.driver.homing is not None
    offset = np.abs(pd_only.arm.position - pd_only.driver.homing.goal)
    assert 0.2 < offset[5] < 0.3, offset


class ArmGraph:
    """An arm with its own clock (no reset) under the controller's homing decisions; every
    sample goes to the protocol, every report too, as the nodes pass them on."""

    def __init__(self, config: Any, arm: Any = None, start: np.ndarray | None = None
                 ) -> None:
        self.experiment = Experiment(config.with_mass_uncertainty(DELTA))
        ref = self.experiment.reference
        self.arm = arm or PlantStepper(self.experiment)
        q0 = ref.position[-1] if start is None else np.asarray(start, float)
        if isinstance(self.arm, PlantStepper):
            self.arm.position[:] = q0
            self.arm.velocity[:] = 0.0
        else:  # MuJoCo: q and qdot are copies
            self.arm.set_state(q0, np.zeros_like(q0))
        self.driver = HomingController(GuardedControlStep(self.experiment),
                                       HomingSettings.from_config(config),
                                       self.experiment.period, ref.samples)
        self.step_ns = 10 * MS
        self.stamp = 5 * self.step_ns
        self.protocol: HomingProtocol | None = None
        self.token = -1
        self.pushed: list[tuple[int, np.ndarray]] = []
        self.conclusions: list[TrialConclusion] = []
        self.summaries: list[dict[str, str]] = []
        """The homing keys of each summary, as the supervisor adds them when it publishes."""
        self.events: list[tuple[str, dict[str, str]]] = []
        self.errors: list[str] = []
        self.drop: set[int] = set()
        """Stamps (as sample counts) whose message is lost on the way to the supervisor."""
        self.push: Any = None
        self.jitter: Any = None
        """Called with the sample count -> an offset (ns) of that sample's stamp (an arm whose
        clock is not the control grid's)."""
        """Called at every sample with (stamp, q, qd) -> an extra joint torque (a person)."""
        self.count = 0

    # GraphPort
    def reset(self) -> None:
        raise AssertionError("homing: no reset service is called")

    def start(self) -> None:
        raise AssertionError("homing: no start service is called")

    def push_feedforward(self, trial: int, t0_ns: int, feedforward: np.ndarray,
                         joint_force: np.ndarray | None = None) -> None:
        ref = self.experiment.reference
        self.pushed.append((trial, feedforward.copy()))
        self.token = t0_ns
        self.driver.load(trial, feedforward.copy(), ref.position, ref.velocity)
        assert self.protocol is not None
        self.protocol.on_acknowledged(trial, t0_ns)

    def publish_conclusion(self, conclusion: TrialConclusion, end_ns: int) -> None:
        self.conclusions.append(conclusion)
        assert self.protocol is not None
        self.summaries.append(dict(self.protocol.summary_values(
            conclusion.record, self.experiment.config["joint_names"])))

    def event(self, message: str, values: Sequence[tuple[str, str]],
              stamp_ns: int | None = None) -> None:
        self.events.append((message, dict(values)))

    def log(self, error: bool, text: str) -> None:
        if error:
            self.errors.append(text)

    # driving
    def run(self, samples: int) -> None:
        """``samples`` periods of the arm: sample out, controller, reports, one period."""
        protocol = self.protocol
        assert protocol is not None
        for _ in range(samples):
            if protocol.phase is Phase.FINISHED:
                return
            q, qd = self.arm.position.copy(), self.arm.velocity.copy()
            stamp = self.stamp + (0 if self.jitter is None else self.jitter(self.count))
            effort, events = self.driver(stamp, q, qd)
            if self.count not in self.drop:
                protocol.on_sample(stamp, q, qd)
            for ev in events:
                if ev.kind == "homed":
                    assert self.driver.homing is not None
                    protocol.on_homed(ev.trial, self.token, ev.stamp_ns,
                                      self.driver.homing.start_ns)
                elif ev.kind == "homing_failed":
                    protocol.on_homing_failed(ev.trial, self.token, ev.reason)
                elif ev.kind == "done":
                    protocol.on_done(ev.trial, self.driver.t0_ns,
                                     {"aborted_at": str(self.driver.aborted_at),
                                      "watchdog_trips": "0"})
            applied = effort.copy()
            if self.push is not None:
                applied += self.push(self.stamp, q, qd)
            self.arm.step(applied)
            self.stamp += self.step_ns
            self.count += 1


def _protocol(graph: ArmGraph, **overrides: Any) -> HomingProtocol:
    config = load_config(overrides={**SHORT, **overrides})
    protocol = HomingProtocol(config, graph)
    graph.protocol = protocol
    protocol.open({"mass_uncertainty": DELTA})
    protocol.tick(graph_ready=True)
    return protocol


def test_homing_trials_start_near_xd0_and_learn_like_run_trials() -> None:
    """Each trial starts after homing from where the last one ended (q_d(T)): no reset is
    called, the start error stays within the tolerance, the summary reports it, and the
    linear law learns as in-process (within the start error's effect)."""
    overrides = {"max_trials": 6, "law": "linear"}
    config = load_config(overrides={**SHORT, **overrides})
    graph = ArmGraph(config)
    protocol = _protocol(graph, **overrides)
    graph.run(20_000)
    assert protocol.phase is Phase.FINISHED and not graph.errors
    assert len(graph.conclusions) == 6
    local = run_trials(load_config(overrides={"trajectory.duration": 1.0, **overrides}), DELTA)
    for conclusion, values, expected in zip(graph.conclusions, graph.summaries,
                                            local.max_abs_errors, strict=True):
        e0 = np.array([float(values[f"initial_error/{n}"]) for n in config["joint_names"]])
        v0 = np.array([float(values[f"initial_velocity/{n}"]) for n in config["joint_names"]])
        assert np.all(np.abs(e0) <= 1e-3) and np.all(np.abs(v0) <= 1e-2)
        assert values["samples_missing"] == "0" and values["samples_late"] == "0"
        np.testing.assert_allclose(conclusion.record.max_abs_error, expected, rtol=0.02,
                                   atol=2e-3)
    assert [e for e, _ in graph.events].count("start") == 6


def test_missing_samples_within_the_limit_are_filled_beyond_it_rerun() -> None:
    """Two lost samples with max_missing_samples 2: filled, learned from; three: the trial is
    discarded (reason lost) and run again with the same feed-forward."""
    overrides = {"max_trials": 2, "law": "linear", "max_missing_samples": 2}
    graph = ArmGraph(load_config(overrides={**SHORT, **overrides}))
    protocol = _protocol(graph, **overrides)
    while protocol.phase is not Phase.RUNNING:
        graph.run(1)
    graph.drop = {graph.count + 10, graph.count + 11}
    while len(graph.conclusions) < 1:
        graph.run(1)
    assert protocol.session is not None and protocol.session.retried == []
    assert graph.summaries[0]["samples_missing"] == "2"
    while protocol.phase is not Phase.RUNNING:
        graph.run(1)
    graph.drop = {graph.count + 10, graph.count + 20, graph.count + 30}
    graph.run(200)
    assert protocol.session.retried == [(2, "lost")]
    assert [t for t, _ in graph.pushed] == [1, 2, 2]
    np.testing.assert_array_equal(graph.pushed[1][1], graph.pushed[2][1])
    graph.run(5_000)
    assert protocol.phase is Phase.FINISHED and len(graph.conclusions) == 2


def test_homing_that_cannot_settle_stops_the_run_with_its_reason() -> None:
    """A person holding the arm away from q_d(0) (a constant torque): homing times out, the
    controller holds the arm, the trial is not started, the run stops naming the reason; the
    concluded trial is kept."""
    overrides = {"max_trials": 3, "homing.timeout": 0.5}
    graph = ArmGraph(load_config(overrides={**SHORT, **overrides}))
    protocol = _protocol(graph, **overrides)
    while len(graph.conclusions) < 1:
        graph.run(1)
    graph.push = lambda stamp, q, qd: np.array([0.0, 0.0, 0.5])
    graph.run(2_000)
    assert protocol.phase is Phase.FINISHED and protocol.exit_code == 1
    assert protocol.error is not None and "trial 2 not started: homing failed: did not " \
        "settle within 0.5 s" in protocol.error
    assert ("aborted", {"trial": "2", "reason": "homing", "detail": graph.driver.failure}) \
        in graph.events
    assert graph.driver.mode is ControllerMode.FAILED
    assert protocol.completed == 1 and len(graph.conclusions) == 1


@pytest.mark.parametrize("stored", [False, True], ids=["no_store", "store"])
def test_a_stopped_run_says_whether_its_trials_can_be_resumed(stored: bool,
                                                              tmp_path: Path) -> None:
    """Homing fails at trial 2 after one completed trial: with a store the message says the
    trial is stored there (resume the run); without one (``exo-ilc run --no-store``) it does
    not claim to have stored anything."""
    overrides: dict[str, Any] = {"max_trials": 3, "homing.timeout": 0.5}
    if stored:
        overrides["store.directory"] = str(tmp_path / "store")
    graph = ArmGraph(load_config(overrides={**SHORT, **overrides}))
    protocol = _protocol(graph, **overrides)
    while len(graph.conclusions) < 1:
        graph.run(1)
    graph.push = lambda stamp, q, qd: np.array([0.0, 0.0, 0.5])
    graph.run(2_000)
    assert protocol.error is not None and protocol.completed == 1
    if stored:
        assert protocol.store is not None and protocol.store.completed == 1
        assert f"Every completed trial (1) is stored in {protocol.store.directory}: resume " \
            "the run once the arm is safe" in protocol.error
        assert str(protocol.store.directory).startswith(str(tmp_path / "store"))
    else:
        assert "is stored" not in protocol.error and "resume the run" not in protocol.error
        assert "No store (store.directory is empty: exo-ilc run --no-store): the 1 completed " \
            "trial(s) cannot be resumed" in protocol.error


def test_an_arm_moved_during_the_dwell_fails_homing() -> None:
    """A push during the dwell: homing fails with "moved during the dwell"."""
    overrides = {"max_trials": 2}
    graph = ArmGraph(load_config(overrides={**SHORT, **overrides}), start=np.zeros(3))
    protocol = _protocol(graph, **overrides)
    graph.push = lambda stamp, q, qd: np.array([2.0, 0.0, 0.0]) \
        if graph.driver.homing is not None and \
        graph.driver.homing.state is HomingState.DWELL else np.zeros(3)
    graph.run(500)
    assert protocol.error is not None and "moved during the dwell" in protocol.error


def test_the_mujoco_arm_homes_and_runs_a_trial_as_our_plant() -> None:
    """The same in-process loop on MuJoCo: homing from q_d(T), then trial 1 within 1e-9 rad of
    the loop on our plant (the two arms agree to rounding)."""
    from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

    overrides = {"max_trials": 1}
    config = load_config(overrides={**SHORT, **overrides, "mass_uncertainty": DELTA})
    runs = []
    for arm in (None, MujocoArm.from_config(config)):
        graph = ArmGraph(config, arm)
        protocol = _protocol(graph, **overrides)
        graph.run(2_000)
        assert protocol.phase is Phase.FINISHED and len(graph.conclusions) == 1
        runs.append(graph.conclusions[0].record)
    np.testing.assert_allclose(runs[1].position, runs[0].position, atol=1e-9)


def test_with_a_recorder_the_next_trial_is_pushed_only_once_the_last_is_filed(
        tmp_path: Any) -> None:
    """No start service holds a homed arm back, so under homing the next feed-forward goes out
    only after the recorder filed (and the store saved) the last trial; until then the
    controller holds the arm. Then the run goes on as usual."""
    overrides = {"max_trials": 2, "wait_for_recorder": True,
                 "store.directory": str(tmp_path / "store")}
    graph = ArmGraph(load_config(overrides={**SHORT, **overrides}))
    protocol = _protocol(graph, **overrides)
    while len(graph.conclusions) < 1:
        graph.run(1)
    graph.run(300)
    assert len(graph.pushed) == 1 and protocol.phase is Phase.WAIT_RECORDER
    assert graph.driver.mode is ControllerMode.HOLD
    assert protocol.store is not None and protocol.store.completed == 0
    protocol.on_recorder_filed(1)
    assert protocol.store.completed == 1 and [t for t, _ in graph.pushed] == [1, 2]
    while len(graph.conclusions) < 2:
        graph.run(1)
    protocol.on_recorder_filed(2)
    assert protocol.phase is Phase.FINISHED and protocol.store.completed == 2


def test_stamps_off_the_grid_are_placed_on_it_and_counted_late() -> None:
    """An arm whose stamps wander up to 4 ms off the 10 ms grid (every third sample 3-4 ms
    late or early): controller and supervisor place each sample on the nearest grid point, so
    the trials are those of on-grid stamps up to where homing left the arm (its path and settle
    run on the stamps, so a trial starts elsewhere within the homing tolerance: trial 1 starts
    2.4e-5 rad apart here, trial 2 1.2e-6) and they never drift further apart than that start;
    samples more than a quarter period off are counted late."""
    overrides = {"max_trials": 2, "law": "linear", "homing.dwell": 0.0}
    runs = []
    for jitter in (None, lambda k: (3 + k % 2) * MS * (1 if k % 6 == 0 else -1)
                   if k % 3 == 0 else 0):
        graph = ArmGraph(load_config(overrides={**SHORT, **overrides}))
        graph.jitter = jitter
        protocol = _protocol(graph, **overrides)
        graph.run(5_000)
        assert protocol.phase is Phase.FINISHED
        runs.append(graph)
    for exact, jittered in zip(runs[0].conclusions, runs[1].conclusions, strict=True):
        start_gap = np.abs(jittered.record.position[0] - exact.record.position[0])
        assert np.all(start_gap <= 1e-3), start_gap  # homing.position_tolerance
        gap = np.abs(jittered.record.position - exact.record.position).max()
        assert gap <= 1.5 * start_gap.max() + 2e-6, (gap, start_gap)  # never beyond the start's
    late = [int(v["samples_late"]) for v in runs[1].summaries]
    assert [int(v["samples_late"]) for v in runs[0].summaries] == [0, 0]
    assert all(30 <= n <= 36 for n in late), late  # ~1 in 3 of 101 samples


def test_a_bag_reader_tells_a_failed_homing_in_plain_words() -> None:
    """An ``aborted`` event with ``reason: homing`` is not a rerun: the run stopped there."""
    from exo_ilc_ros.bag.reader import rerun_note

    note = rerun_note(2, {"reason": "homing", "detail": "homing failed: did not settle"})
    assert note.startswith("trial 2 was not started: homing failed: did not settle")
    assert "run again" not in note
