"""The trial protocol without ROS: a fake graph port that runs each trial with the in-process
kernel and answers like the plant, the controller and the recorder would. The protocol must give
run_trials' numbers, run a discarded trial again with the same feed-forward, store a trial only
once the recorder filed it, and stop on a store error."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from exo_ilc_ros.core import Experiment, load_config, run_trials
from exo_ilc_ros.core.params.config import config_dir, scenario_path
from exo_ilc_ros.core.persistence.store import RunStore
from exo_ilc_ros.core.protocol.timing import STEP_TIMEOUT
from exo_ilc_ros.core.protocol.trial_protocol import Phase, TrialProtocol
from exo_ilc_ros.core.session.learning_session import TrialConclusion

SHORT = {"trajectory.duration": 1.0}
PLANT = {"mass_uncertainty": 0.1}
CHANGE_LIVE = {"error_bound": 0.006}


class FakeGraph:
    """Plant, controller and recorder answering at once (``auto``) or when told."""

    def __init__(self, config: Any, auto_file: bool = True) -> None:
        self.experiment = Experiment(config.with_mass_uncertainty(PLANT["mass_uncertainty"]))
        self.protocol: TrialProtocol | None = None
        self.t0 = 1_000_000_000
        self.pushed: list[tuple[int, np.ndarray]] = []
        self.pushed_forces: list[np.ndarray | None] = []
        self.conclusions: list[TrialConclusion] = []
        self.events: list[tuple[str, dict[str, str]]] = []
        self.errors: list[str] = []
        self.infos: list[str] = []
        self.auto_file = auto_file
        self.drop_sample: int | None = None
        self.watchdog_once = False
        self.pending_start = False
        self.now = 0.0

    # GraphPort
    def reset(self) -> None:
        self.t0 += 10_000_000_000
        assert self.protocol is not None
        self.protocol.on_reset(self.t0)

    def push_feedforward(self, trial: int, t0_ns: int, feedforward: np.ndarray,
                         joint_force: np.ndarray | None = None) -> None:
        self.pushed.append((trial, feedforward.copy()))
        self.pushed_forces.append(None if joint_force is None else joint_force.copy())
        assert self.protocol is not None
        self.protocol.on_acknowledged(trial, t0_ns)

    def start(self) -> None:
        self.pending_start = True

    def publish_conclusion(self, conclusion: TrialConclusion, end_ns: int) -> None:
        self.conclusions.append(conclusion)

    def event(self, message: str, values: Sequence[tuple[str, str]],
              stamp_ns: int | None = None) -> None:
        self.events.append((message, dict(values)))

    def log(self, error: bool, text: str) -> None:
        if error:
            self.errors.append(text)
        else:
            self.infos.append(text)

    # driving
    def run_started_trial(self) -> None:
        """The plant runs the trial that was started: samples, then the controller's done."""
        protocol = self.protocol
        assert protocol is not None and protocol.session is not None and self.pending_start
        self.pending_start = False
        protocol.on_started(True)
        trial, ff = self.pushed[-1]
        record = self.experiment.run_trial(ff, trial, protocol.session.levels, None,
                                           self.pushed_forces[-1])
        step = protocol.samples.step_ns
        for i in range(record.position.shape[0]):
            if i == self.drop_sample:
                self.drop_sample = None
                continue
            protocol.on_sample(self.t0 + i * step, record.position[i], record.velocity[i])
        trips = "1" if self.watchdog_once else "0"
        self.watchdog_once = False
        aborted = "-1" if record.aborted_at is None else str(record.aborted_at)
        protocol.on_done(trial, self.t0, {"watchdog_trips": trips, "aborted_at": aborted})
        if self.auto_file:
            protocol.on_recorder_filed(trial)

    def clock(self) -> float:
        return self.now


def _protocol(graph: FakeGraph, **overrides: Any) -> TrialProtocol:
    config = load_config(overrides={**SHORT, **overrides})
    protocol = TrialProtocol(config, graph, clock=graph.clock)
    graph.protocol = protocol
    protocol.open(PLANT)
    protocol.tick(graph_ready=True)
    return protocol


def _run_to_end(graph: FakeGraph, protocol: TrialProtocol, limit: int = 100) -> None:
    for _ in range(limit):
        if protocol.phase is Phase.FINISHED:
            return
        graph.run_started_trial()
    raise AssertionError("the protocol did not finish")


def test_protocol_gives_run_trials_numbers() -> None:
    config = load_config(overrides={**SHORT, "max_trials": 5})
    graph = FakeGraph(config)
    protocol = _protocol(graph, max_trials=5)
    _run_to_end(graph, protocol)
    local = run_trials(config, PLANT["mass_uncertainty"])
    np.testing.assert_array_equal([c.record.max_abs_error for c in graph.conclusions],
                                  local.max_abs_errors)
    assert [c.config["mass_uncertainty"] for c in graph.conclusions] == [0.1] * 5
    assert graph.events[-1] == ("finished", {"trials": "5"})


def test_the_identified_joint_forces_reach_the_controller_as_in_process() -> None:
    """With the patient in the loop (config/patient_aware.yaml over ``friction``) the protocol
    pushes the session's joint forces with every feed-forward, rebuilds each record with them
    (the effort the controller formed) and gives run_trials' numbers exactly."""
    overlays = [config_dir() / "patient_aware.yaml", scenario_path("friction")]
    config = load_config(overlays=overlays, overrides={  # the tanh law trusted at every
        # speed: on the paper's one-way movement the shipped reversal_speed leaves Coulomb
        # friction to the offset and nothing is adopted in 3 trials
        "max_trials": 3, "identification.reversal_speed": 0.0})
    graph = FakeGraph(config)
    protocol = TrialProtocol(config, graph, clock=graph.clock)
    graph.protocol = protocol
    protocol.open(PLANT)
    protocol.tick(graph_ready=True)
    _run_to_end(graph, protocol)
    local = run_trials(config, PLANT["mass_uncertainty"])
    assert graph.pushed_forces[0] is not None and not np.any(graph.pushed_forces[0])
    assert any(np.any(f) for f in graph.pushed_forces if f is not None)  # adopted on the way
    for conclusion, record in zip(graph.conclusions, local.records, strict=True):
        np.testing.assert_array_equal(conclusion.record.effort, record.effort)
        np.testing.assert_array_equal(conclusion.record.joint_force, record.joint_force)
    np.testing.assert_array_equal(graph.conclusions[-1].update.feedforward,
                                  local.final.feedforward)
    np.testing.assert_array_equal(graph.conclusions[-1].update.joint_force,
                                  local.final.joint_force)


@pytest.mark.parametrize("fault", ["watchdog", "lost"])
def test_a_discarded_trial_runs_again_with_the_same_feedforward(fault: str) -> None:
    config = load_config(overrides={**SHORT, "max_trials": 3})
    graph = FakeGraph(config)
    protocol = _protocol(graph, max_trials=3)
    graph.run_started_trial()
    if fault == "watchdog":
        graph.watchdog_once = True
    else:
        graph.drop_sample = 50
    graph.run_started_trial()  # trial 2, discarded
    assert [trial for trial, _ in graph.pushed] == [1, 2, 2]
    np.testing.assert_array_equal(graph.pushed[1][1], graph.pushed[2][1])
    _run_to_end(graph, protocol)
    assert protocol.session is not None and protocol.session.retried == [(2, fault)]
    local = run_trials(config, PLANT["mass_uncertainty"])
    np.testing.assert_array_equal([c.record.max_abs_error for c in graph.conclusions],
                                  local.max_abs_errors)


def test_a_stuck_step_is_discarded_after_the_timeout() -> None:
    graph = FakeGraph(load_config(overrides=SHORT))
    protocol = _protocol(graph)
    graph.pending_start = False
    protocol.on_started(True)  # running, but no sample ever comes
    graph.now += STEP_TIMEOUT + 1
    protocol.tick(graph_ready=True)
    assert ("aborted", {"trial": "1", "reason": "timeout", "phase": "running"}) in graph.events
    assert [trial for trial, _ in graph.pushed] == [1, 1]


def test_stored_only_after_the_recorder_filed_it(tmp_path: Path) -> None:
    config = load_config(overrides={**SHORT, "max_trials": 2})
    graph = FakeGraph(config, auto_file=False)
    protocol = _protocol(graph, max_trials=2, wait_for_recorder=True,
                         **{"store.directory": str(tmp_path)})
    graph.run_started_trial()
    assert protocol.store is not None and protocol.store.completed == 0
    assert protocol.phase is Phase.WAIT_RECORDER, "trial 2 prepared, not started"
    assert not graph.pending_start
    protocol.on_recorder_filed(1)
    assert protocol.store.completed == 1 and graph.pending_start
    graph.run_started_trial()
    assert protocol.phase is Phase.WAIT_RECORDER and protocol.store.completed == 1
    protocol.on_recorder_filed(2)
    assert protocol.phase is Phase.FINISHED and protocol.store.completed == 2


def test_a_silent_recorder_does_not_hold_the_run(tmp_path: Path) -> None:
    graph = FakeGraph(load_config(overrides=SHORT), auto_file=False)
    protocol = _protocol(graph, max_trials=2, wait_for_recorder=True)
    graph.run_started_trial()
    graph.now += 6.0
    protocol.tick(graph_ready=True)
    assert protocol.recorder_lost and graph.pending_start
    assert any("has not filed trial 1" in e for e in graph.errors)


def test_a_store_that_cannot_save_stops_the_run(tmp_path: Path) -> None:
    graph = FakeGraph(load_config(overrides=SHORT))
    protocol = _protocol(graph, **{"store.directory": str(tmp_path)})
    assert protocol.store is not None

    def broken(*args: Any) -> None:
        raise OSError("disk full")

    protocol.store.save = broken  # type: ignore[method-assign]
    graph.run_started_trial()
    assert protocol.exit_code == 1 and protocol.phase is Phase.FINISHED
    message, values = graph.events[-1]
    assert message == "finished" and values["trials"] == "0" and "disk full" in values["error"]


def test_resume_continues_after_the_stored_trials(tmp_path: Path) -> None:
    config = load_config(overrides={**SHORT, "max_trials": 4})
    run_trials(config, PLANT["mass_uncertainty"], 2, store=tmp_path)
    graph = FakeGraph(config)
    protocol = _protocol(graph, max_trials=4, **{"store.directory": str(tmp_path),
                                                 "store.resume": True})
    assert graph.events[0] == ("resumed", {"trials": "2"})
    _run_to_end(graph, protocol)
    assert [c.record.trial for c in graph.conclusions] == [3, 4]
    whole = run_trials(config, PLANT["mass_uncertainty"])
    np.testing.assert_array_equal([c.record.max_abs_error for c in graph.conclusions],
                                  whole.max_abs_errors[2:])
    assert RunStore(tmp_path, config.replace(PLANT), protocol.reference).completed == 4


def test_a_store_holding_trials_without_resume_stops_before_trial_1(tmp_path: Path) -> None:
    config = load_config(overrides=SHORT)
    run_trials(config, PLANT["mass_uncertainty"], 1, store=tmp_path)
    graph = FakeGraph(config)
    protocol = _protocol(graph, **{"store.directory": str(tmp_path)})
    assert protocol.exit_code == 2 and graph.pushed == []
    assert "already holds 1 trials" in graph.events[-1][1]["error"]


def test_a_late_start_reply_does_not_lose_the_trial() -> None:
    """The plant's start reply can arrive after the whole trial (a reliable reply resent after a
    lost packet): the samples prove the plant started, the controller's done is kept, and the
    trial ends (before, it waited for the 30 s timeout and was run again)."""
    config = load_config(overrides={**SHORT, "max_trials": 2})
    graph = FakeGraph(config)
    protocol = _protocol(graph, max_trials=2)
    assert protocol.phase is Phase.STARTING
    trial, ff = graph.pushed[-1]
    record = graph.experiment.run_trial(ff, trial)
    step = protocol.samples.step_ns
    protocol.on_done(trial, graph.t0, {"watchdog_trips": "0", "aborted_at": "-1"})
    for i in range(record.position.shape[0]):
        protocol.on_sample(graph.t0 + i * step, record.position[i], record.velocity[i])
    assert [c.record.trial for c in graph.conclusions] == [1]
    protocol.on_started(True)  # the late reply changes nothing
    assert [trial for trial, _ in graph.pushed] == [1, 2]
    assert protocol.session is not None and protocol.session.retried == []


def test_a_live_change_the_session_refuses_is_logged_not_raised() -> None:
    """The node validated the change against its own parameters; should the session (which
    also holds the plant's) refuse it at the boundary, the run goes on without it."""
    from exo_ilc_ros.core.errors import ConfigError

    config = load_config(overrides={**SHORT, "max_trials": 2})
    graph = FakeGraph(config)
    changed = config.replace(CHANGE_LIVE)
    protocol = TrialProtocol(config, graph, live=lambda: changed, clock=graph.clock)
    graph.protocol = protocol
    protocol.open(PLANT)
    assert protocol.session is not None

    def refuse(values: Any) -> None:
        raise ConfigError("error_bound", "refused for the test")

    protocol.session.stage = refuse  # type: ignore[method-assign]
    protocol.tick(graph_ready=True)
    _run_to_end(graph, protocol)
    assert [c.record.trial for c in graph.conclusions] == [1, 2]
    assert all(c.applied == {} for c in graph.conclusions)
    assert any("not applied" in e and "error_bound" in e for e in graph.errors)


def test_a_lost_acknowledgement_is_asked_for_again_within_a_second() -> None:
    """The controller's acknowledgement (or the profile itself) is lost: the protocol pushes
    the same feed-forward again after ACK_RETRY (well under a second), not after the 30 s step
    timeout, and the trial runs as if nothing happened."""
    from exo_ilc_ros.core.protocol.timing import ACK_RETRY

    assert ACK_RETRY < 0.5
    config = load_config(overrides={**SHORT, "max_trials": 2})
    graph = FakeGraph(config)
    lost: list[int] = []
    real_push = graph.push_feedforward

    def push_losing_the_first_ack(trial: int, t0_ns: int, feedforward: np.ndarray,
                                  joint_force: np.ndarray | None = None) -> None:
        if not lost:  # the first push reaches nobody
            lost.append(trial)
            graph.pushed.append((trial, feedforward.copy()))
            graph.pushed_forces.append(joint_force)
            return
        real_push(trial, t0_ns, feedforward, joint_force)

    graph.push_feedforward = push_losing_the_first_ack  # type: ignore[method-assign]
    protocol = _protocol(graph, max_trials=2)
    assert protocol.phase is Phase.WAIT_ACK and not graph.pending_start
    graph.now += ACK_RETRY / 2
    protocol.tick(graph_ready=True)
    assert protocol.phase is Phase.WAIT_ACK and len(graph.pushed) == 1, "not before ACK_RETRY"
    graph.now += ACK_RETRY
    protocol.tick(graph_ready=True)
    assert protocol.phase is Phase.STARTING and graph.pending_start
    assert [trial for trial, _ in graph.pushed] == [1, 1] and protocol.ack_retries == 1
    np.testing.assert_array_equal(graph.pushed[0][1], graph.pushed[1][1])
    _run_to_end(graph, protocol)
    assert protocol.session is not None and protocol.session.retried == []
    local = run_trials(config, PLANT["mass_uncertainty"])
    np.testing.assert_array_equal([c.record.max_abs_error for c in graph.conclusions],
                                  local.max_abs_errors)


def test_real_time_warms_up_then_reruns_a_trial_with_too_many_late_commands() -> None:
    """Real-time plant: the first attempt is a warm-up (run again); a trial whose plant reports
    more than max_late_commands of its periods on a late command is run again with the same
    feed-forward, not learned from; within the share it is concluded; LATE_RERUNS in a row stop
    the run. The table equals run_trials."""
    from exo_ilc_ros.core.protocol.timing import LATE_RERUNS

    config = load_config(overrides={**SHORT, "max_trials": 3, "max_late_commands": 0.02})
    graph = FakeGraph(config)
    protocol = TrialProtocol(config, graph, clock=graph.clock)
    graph.protocol = protocol
    protocol.open({**PLANT, "mode": "real_time"})
    protocol.tick(graph_ready=True)
    assert protocol.real_time
    periods = protocol.reference.samples - 1

    def run(late: int) -> None:
        graph.run_started_trial()
        assert protocol.phase is Phase.RUNNING, "waits for the plant's report"
        protocol.on_plant_done(graph.t0, {"late_commands": str(late), "periods": str(periods)})

    def aborted() -> list[dict[str, str]]:
        return [values for message, values in graph.events if message == "aborted"]

    run(0)  # the warm-up attempt
    assert aborted() == [{"trial": "1", "reason": "warm_up"}]
    run(2)  # 2 of 100 periods late: within 2 %
    run(3)  # trial 2: 3 % late, run again
    assert aborted()[-1] == {"trial": "2", "reason": "late_commands", "late_commands": "3",
                             "periods": str(periods)}
    run(0)
    run(0)
    assert protocol.phase is Phase.FINISHED
    assert protocol.session is not None
    assert protocol.session.retried == [(1, "warm_up"), (2, "late_commands")]
    assert [trial for trial, _ in graph.pushed] == [1, 1, 2, 2, 3]
    np.testing.assert_array_equal(graph.pushed[2][1], graph.pushed[3][1])
    local = run_trials(config, PLANT["mass_uncertainty"])
    np.testing.assert_array_equal([c.record.max_abs_error for c in graph.conclusions],
                                  local.max_abs_errors)

    # A machine that never keeps up: the run stops after LATE_RERUNS late attempts in a row.
    graph = FakeGraph(config)
    protocol = TrialProtocol(config, graph, clock=graph.clock)
    graph.protocol = protocol
    protocol.open({**PLANT, "mode": "real_time"})
    protocol.tick(graph_ready=True)
    run(0)
    for _ in range(LATE_RERUNS):
        run(periods // 2)
    assert protocol.phase is Phase.FINISHED and protocol.exit_code == 1
    assert "does not keep the control rate" in graph.events[-1][1]["error"]


def test_opening_rehearses_the_conclusion_without_changing_the_session(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The protocol warms the conclusion's kernels up when it opens the session (the graph's
    first conclusion paid 0.2-0.3 s of numba cache load); the session is untouched, and a law
    that fails on the throwaway record only costs the warm-up."""
    from exo_ilc_ros.core.params.config import load_config
    from exo_ilc_ros.core.session.learning_session import LearningSession
    from exo_ilc_ros.core.sim.experiment import Experiment

    config = load_config(overrides={"trajectory.duration": 1.0, "max_trials": 3})
    session = LearningSession(config)
    before = session.feedforward.copy()
    session.rehearse(Experiment(config))
    assert session.trial == 1 and session.completed == 0
    np.testing.assert_array_equal(session.feedforward, before)

    class Failing:
        def initial_feedforward(self, reference: Any) -> np.ndarray:
            return np.zeros((reference.samples, 3))

        def update(self, record: Any) -> Any:
            raise RuntimeError("no update on a throwaway record")

    failing = LearningSession(config, law=Failing())  # type: ignore[arg-type]
    with pytest.raises(RuntimeError):
        failing.rehearse(Experiment(config))

    def refuse(self: Any, experiment: Any) -> None:
        raise RuntimeError("no update on a throwaway record")

    monkeypatch.setattr(LearningSession, "rehearse", refuse)
    graph = FakeGraph(config)
    protocol = TrialProtocol(config, graph, clock=graph.clock)
    graph.protocol = protocol
    protocol.open(PLANT)
    assert protocol.session is not None and not graph.errors
    assert any("warm-up of the trial conclusion skipped" in t for t in graph.infos)
