"""The ROS 2 graph over real DDS: same numbers as in-process, live parameters, Ctrl-C, colcon.

Each test starts its own processes on the session's domain (conftest) or a claimed one, waits
for discovery with timeouts, and stops everything at teardown.
"""

from __future__ import annotations

import json
import os
import select
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from processes import alive, children

from exo_ilc_ros.core.learning.factory import build_law
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.sim.experiment import Experiment
from exo_ilc_ros.nodes.realtime import thread_policies
from exo_ilc_ros.orchestration.launcher import claim_domain_id

pytestmark = pytest.mark.graph

ROOT = Path(__file__).resolve().parents[1]
SHORT = {"trajectory.duration": 1.0}
"""101 samples per trial keep the graph tests short."""


def _short_config(**overrides: Any) -> Config:
    return load_config(overrides={**SHORT, **overrides})


def _exo_ilc(*args: str, timeout: float, **kwargs: Any) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", *args], text=True,
                          capture_output=True, timeout=timeout, stdin=subprocess.DEVNULL,
                          check=False, **kwargs)


def test_run_json_equals_simulate(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`exo-ilc run` through the graph gives simulate's per-trial numbers to 1e-9."""
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    graph_json, local_json = tmp_path / "graph.json", tmp_path / "local.json"
    result = _exo_ilc("run", "--no-bag", "--config", str(config_file), "--trials", "3",
                      "--json", str(graph_json), timeout=150, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Iterations to the bound" in result.stdout
    from exo_ilc_ros.cli.main import main as exo_ilc  # simulate in this process: no start-up

    capsys.readouterr()
    assert exo_ilc(["simulate", "--config", str(config_file), "--trials", "3", "--json",
                    str(local_json)]) == 0
    local_out = capsys.readouterr().out
    graph, reference = json.loads(graph_json.read_text()), json.loads(local_json.read_text())
    assert graph["config"] == reference["config"]
    (g,), (r,) = graph["runs"], reference["runs"]
    assert len(g["trials"]) == len(r["trials"]) == 3
    for key in ("max_abs_error", "max_abs_feedforward", "max_abs_effort"):
        np.testing.assert_allclose([t[key] for t in g["trials"]], [t[key] for t in r["trials"]],
                                   rtol=0.0, atol=1e-9, err_msg=key)
    assert g["iterations_to_bound"] == r["iterations_to_bound"]
    # The per-trial table and the iterations are the same text as simulate's.
    for marker in ("(* above the bound)", "('-': never within"):
        assert result.stdout.split(marker)[0] == local_out.split(marker)[0]


def test_norm_optimal_graph_equals_in_process(tmp_path: Path) -> None:
    """`law: norm_optimal` through the graph: the supervisor builds the same cached learning
    matrix and learns the same feed-forward as in-process, to 1e-9 (3 short trials)."""
    config_file = tmp_path / "norm_optimal.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                           "ilc_supervisor:\n  ros__parameters:\n    law: norm_optimal\n")
    graph_json = tmp_path / "graph.json"
    result = _exo_ilc("run", "--no-bag", "--config", str(config_file), "--trials", "3",
                      "--mass-uncertainty", "0.15", "--json", str(graph_json), timeout=150,
                      cwd=tmp_path)  # its store in tmp_path, not in the checkout
    assert result.returncode == 0, result.stderr[-3000:]
    reference = run_trials(load_config(config_file), 0.15, 3)
    (g,) = json.loads(graph_json.read_text())["runs"]
    assert g["law"] == "norm_optimal" and len(g["trials"]) == 3
    np.testing.assert_allclose([t["max_abs_error"] for t in g["trials"]],
                               reference.max_abs_errors, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose([t["max_abs_feedforward"] for t in g["trials"]],
                               reference.max_abs_feedforward, rtol=0.0, atol=1e-9)
    assert reference.max_abs_errors[-1].max() < 0.1 * reference.max_abs_errors[0].max()


def _parameter_client(session: Any) -> Any:
    """The supervisor's parameter client, its services discovered (on a loaded machine that
    can take longer than a short run's trials: discover before the trials run out)."""
    from rclpy.parameter_client import AsyncParameterClient

    client = AsyncParameterClient(session.node, "ilc_supervisor")
    assert client.wait_for_services(timeout_sec=20.0), "ilc_supervisor parameter services"
    return client


def _set(session: Any, name: str, value: Any, client: Any = None) -> Any:
    from rclpy.parameter import Parameter

    client = client or _parameter_client(session)
    future = client.set_parameters([Parameter(name, value=value)])
    session.spin_until(future.done, timeout=20.0)
    return future.result().results[0]


def _in_process_with_change(config: Config, changed: Config, trials: int,
                            first_changed: int) -> np.ndarray:
    """max |e| per trial when the new parameters form the feed-forward of trial
    ``first_changed`` onwards (the change applied at that trial boundary)."""
    experiment = Experiment(config)
    laws = build_law(config), build_law(changed)
    feedforward, levels = laws[0].initial_feedforward(experiment.reference), None
    errors = []
    for k in range(1, trials + 1):
        record = experiment.run_trial(feedforward, k, levels)
        errors.append(record.max_abs_error)
        update = laws[1 if k + 1 >= first_changed else 0].update(record)
        feedforward, levels = update.feedforward, update.levels
    return np.array(errors)


def test_live_threshold_changes_next_trial_and_bad_values_are_rejected() -> None:
    """SetParameters on the supervisor: bad values refused with their reason (the old value
    stays); a new threshold changes the M levels from the next trial boundary on, and the whole
    run still equals in-process with the change applied at that boundary."""
    from exo_ilc_ros.orchestration.graph import GraphSession

    # 100 short trials take ~4 s: the run must still be going after the five SetParameters
    # calls below (25 trials were over before the change on the faster graph, 5 runs in 14).
    trials = 100
    config = _short_config(max_trials=trials)
    change = {"schedule.position.threshold_low": [0.0, 0.0, 0.0]}  # every sum > 0: level_mid
    with GraphSession(config) as session:
        session.spin_until(lambda: len(session.summaries) >= 2, timeout=90.0)
        bad = _set(session, "schedule.position.threshold_low", [30.0, 2.0, 1.0])
        assert not bad.successful
        assert "thresholds must increase" in bad.reason
        negative = _set(session, "schedule.velocity.level_mid", [-0.1, 0.005, 0.005])
        assert not negative.successful and "must be >= 0" in negative.reason
        short = _set(session, "schedule.position.level_low", [0.001, 0.001])
        assert not short.successful and "one entry per joint" in short.reason
        fixed = _set(session, "max_trials", 3)
        assert not fixed.successful and "cannot change" in fixed.reason
        assert _set(session, "schedule.position.threshold_low", [0.0, 0.0, 0.0]).successful
        seen = len(session.summaries)
        # Lock-step: the controller asked the plant its mode and kept the normal scheduler (at
        # SCHED_FIFO the ping-pong starved the machine; nodes/realtime.py).
        session.spin_until(lambda: "plant_simulator is lock-step" in session.processes.log_tail(
            "computed_torque_controller", 200), timeout=30.0)
        policies = {n: set(thread_policies(p.pid).values())
                    for n, p in session.processes.processes.items()}
        assert all(p == {os.SCHED_OTHER} for p in policies.values()), policies
        assert len(policies) == 3
        session.spin_until(lambda: session.finished, timeout=120.0, stall_timeout=60.0)
    joints = config["joint_names"]
    assert [s.trial for s in session.summaries] == list(range(1, trials + 1))
    graph = np.array([s.row("max_abs_error", joints) for s in session.summaries])
    unchanged = run_trials(config)
    changed = config.replace(change)
    first = None
    for candidate in range(3, trials + 1):
        expected = _in_process_with_change(config, changed, trials, candidate)
        if np.max(np.abs(graph - expected)) <= 1e-9:
            first = candidate
            break
    assert first is not None, "the graph equals in-process with the change at one boundary"
    assert first <= seen + 3, (first, seen)
    np.testing.assert_allclose(graph[:first - 1], unchanged.max_abs_errors[:first - 1],
                               rtol=0.0, atol=1e-9)
    before = session.summaries[first - 2].levels(joints)
    after = session.summaries[first - 1].levels(joints)
    old_after = unchanged.records[first - 1].levels
    assert after is not None and old_after is not None
    assert not np.array_equal(after[0], old_after[0]), "the new threshold changed M"
    np.testing.assert_array_equal(after[0], [0.03, 0.05, 0.05])  # level_mid everywhere
    if before is not None and first - 2 >= 1:
        np.testing.assert_array_equal(before, unchanged.records[first - 2].levels)


def test_ctrl_c_stops_every_process(tmp_path: Path) -> None:
    """SIGINT to `exo-ilc run` mid-run: exit 130, the command that resumes the run printed,
    every node process gone."""
    claim = claim_domain_id()
    env = dict(os.environ, ROS_DOMAIN_ID=str(claim.domain_id))
    process = subprocess.Popen(
        [sys.executable, "-m", "exo_ilc_ros.cli.main", "run", "--trials", "100",
         "--domain-id", str(claim.domain_id)], stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, stdin=subprocess.DEVNULL, env=env, text=True, cwd=tmp_path)
    try:
        deadline = time.monotonic() + 90.0
        nodes: list[int] = []
        while time.monotonic() < deadline and len(nodes) < 3:
            nodes = children(process.pid)
            time.sleep(0.2)
        assert len(nodes) >= 3, "the three nodes started"
        time.sleep(8.0)  # let trials run (the nodes are up and discovering)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
        assert process.returncode == 130, err[-2000:]
        assert "Continue with:" in err and " --resume" in err, err[-2000:]  # issue 25
        gone_by = time.monotonic() + 15.0
        while time.monotonic() < gone_by and any(alive(pid) for pid in nodes):
            time.sleep(0.1)
        assert not any(alive(pid) for pid in nodes)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        claim.release()


def _fifo_allowed() -> bool:
    """Whether this machine lets a process of ours run at SCHED_FIFO 50 (tried in a child)."""
    probe = "import os; os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True,
                          check=False).returncode == 0


def test_real_time_mode_runs_trials() -> None:
    """Real-time plant (4x wall rate): trials complete, errors close to lock-step, and the
    second trial learned from the first.

    Not equal: a command that misses its 2.5 ms wall period is applied one period late (the
    plant holds the previous one), so the errors depend on the machine's load. The linear law
    keeps that small from trial to trial; the sign law's step gains jump when an error sum sits
    near a threshold, which turned a 1e-4 difference in trial 1 into 60 % in trial 2 at load
    average 7. A broken loop (commands ignored, the arm falling) is off by far more than 50 %."""
    from exo_ilc_ros.orchestration.graph import GraphSession, summaries_to_run

    config = _short_config(max_trials=2, mode="real_time", real_time_rate=4.0, law="linear",
                           max_late_commands=1.0)  # late ones expected here: see above
    with GraphSession(config) as session:
        session.spin_until(lambda: session.started_at is not None, timeout=90.0)
        session.spin_until(lambda: "control loop at" in session.processes.log_tail(
            "computed_torque_controller", 200), timeout=30.0)  # asked the plant its mode
        policies = {name: set(thread_policies(process.pid).values())
                    for name, process in session.processes.processes.items()}
        session.spin_until(lambda: session.finished, timeout=120.0, stall_timeout=60.0)
        errors = summaries_to_run(session.summaries, config).max_abs_error
    # The control loop (controller, real-time plant) runs at SCHED_FIFO thread_priority (50)
    # on every thread where the OS allows it (nodes/realtime.py; the controller once the plant
    # said it is real time: a 2-trial run is long enough), the rest normally.
    fifo = {os.SCHED_FIFO} if _fifo_allowed() else {os.SCHED_OTHER}
    assert policies == {"plant_simulator": fifo, "computed_torque_controller": fifo,
                        "ilc_supervisor": {os.SCHED_OTHER}}, policies
    local = run_trials(config)
    assert errors.shape == (2, 3)
    np.testing.assert_allclose(errors[0], local.max_abs_errors[0], rtol=0.5)
    # Trial 2 learned from a trial 1 with late commands in it, which a slow machine's run (about
    # 1 000 lock-step steps/s) turned into an elbow error half the in-process one (0.011 against
    # 0.023 rad): bounded above only, where a broken loop would show.
    assert np.all(errors[1] <= 1.5 * local.max_abs_errors[1]), (errors, local.max_abs_errors)
    assert np.all(errors[1] < errors[0]), "trial 2 learned from trial 1"


def test_colcon_build_gives_ros2_run_executables(tmp_path: Path) -> None:
    """colcon builds the package: lib/exo_ilc_ros/<node> exist, ament_index finds the package,
    and the built executables run a trial together."""
    colcon = Path(sys.executable).parent / "colcon"
    if not colcon.exists():
        pytest.skip("colcon is not installed in this environment")
    source = tmp_path / "src" / "exo_ilc_ros"
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        ".venv", ".git", "build", "install", "log", "bags", "*.egg-info", "__pycache__",
        ".ros_log", ".pytest_cache", ".mypy_cache", ".ruff_cache", "test", "bench"))
    build = subprocess.run(
        [str(colcon), "build", "--base-paths", str(tmp_path / "src"), "--build-base",
         str(tmp_path / "build"), "--install-base", str(tmp_path / "install")],
        cwd=tmp_path, env=dict(os.environ, CI="true"), capture_output=True, text=True,
        timeout=180, stdin=subprocess.DEVNULL, check=False)
    assert build.returncode == 0, build.stdout[-2000:] + build.stderr[-2000:]
    prefix = tmp_path / "install" / "exo_ilc_ros"
    names = ("plant_simulator", "computed_torque_controller", "ilc_supervisor")
    for name in (*names, "bag_recorder", "container"):
        exe = prefix / "lib" / "exo_ilc_ros" / name
        assert exe.is_file() and os.access(exe, os.X_OK), exe
    site = next((prefix / "lib").glob("python3*/site-packages"))
    env = dict(os.environ, AMENT_PREFIX_PATH=f"{prefix}:{sys.prefix}",
               PYTHONPATH=str(site), EXO_ILC_CONFIG_DIR=str(prefix / "share/exo_ilc_ros/config"))
    found = subprocess.run(
        [sys.executable, "-c", "from ament_index_python.packages import get_package_prefix, "
         "get_package_share_directory as s; print(get_package_prefix('exo_ilc_ros')); "
         "print(s('exo_ilc_ros'))"], env=env, capture_output=True, text=True, timeout=60,
        check=False)
    assert found.returncode == 0, found.stderr
    assert found.stdout.split() == [str(prefix), str(prefix / "share" / "exo_ilc_ros")]
    assert (prefix / "share/exo_ilc_ros/config/exo_ilc.yaml").is_file()
    assert (prefix / "share/exo_ilc_ros/launch/exo_ilc.launch.py").is_file()

    # Each built executable starts, reads its parameters and refuses a bad one with the rule
    # (exit 2, before any kernel is compiled: cheap) ...
    for name in names:
        bad = subprocess.run([str(prefix / "lib" / "exo_ilc_ros" / name), "--ros-args", "-p",
                              "control.period:=-1.0"], env=env, capture_output=True, text=True,
                             timeout=120, stdin=subprocess.DEVNULL, check=False)
        assert bad.returncode == 2, bad.stdout + bad.stderr
        assert "control.period: must be > 0" in bad.stdout + bad.stderr
    unknown = subprocess.run([str(prefix / "lib/exo_ilc_ros/container"), "ilc_supervisor",
                              "plant", "--ros-args"], env=env, capture_output=True, text=True,
                             timeout=120, stdin=subprocess.DEVNULL, check=False)
    assert unknown.returncode == 2 and "unknown node 'plant'" in unknown.stderr, unknown.stderr
    # ... and one comes up with the installed config and stops cleanly on SIGINT.
    params = prefix / "share/exo_ilc_ros/config/exo_ilc.yaml"
    plant = subprocess.Popen([str(prefix / "lib/exo_ilc_ros/plant_simulator"), "--ros-args",
                              "--params-file", str(params)], env=env, stdout=subprocess.PIPE,
                             stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True)
    try:
        assert plant.stdout is not None
        deadline = time.monotonic() + 150.0
        lines: list[str] = []
        while time.monotonic() < deadline:
            ready, _, _ = select.select([plant.stdout], [], [], deadline - time.monotonic())
            if not ready:
                break
            line = plant.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "lock_step plant" in line:
                break
        assert any("lock_step plant" in line for line in lines), "".join(lines)
        plant.send_signal(signal.SIGINT)
        assert plant.wait(timeout=30) == 0
    finally:
        if plant.poll() is None:
            plant.kill()
            plant.wait()


def test_stop_when_settled_is_the_same_in_process_and_in_the_graph() -> None:
    """``stop_when_settled: 3`` at 5 %: the graph stops after the same trial as `simulate`
    (the session's rule, written once) with the same table."""
    from exo_ilc_ros.orchestration.graph import run_graph

    config = _short_config(max_trials=40, stop_when_settled=3, mass_uncertainty=0.05)
    local = run_trials(config)
    assert local.stop is not None and local.stop.value == "settled"
    assert len(local.records) < 40
    graph = run_graph(config, timeout=300.0)
    assert [s.trial for s in graph.summaries] == [r.trial for r in local.records]
    np.testing.assert_allclose(graph.summary.max_abs_error, local.max_abs_errors,
                               rtol=0.0, atol=1e-9)
    assert graph.summary.mass_uncertainty == 0.05


def test_recorded_live_change_replays_in_process_exactly(tmp_path: Path) -> None:
    """A graph run recorded to a bag, its threshold changed mid-run: `exo-ilc simulate
    --replay BAG` reproduces every trial summary of the bag, and the change took effect at the
    trial the summaries name."""
    from exo_ilc_ros.bag import read_bag
    from exo_ilc_ros.cli.main import main as exo_ilc
    from exo_ilc_ros.orchestration.graph import GraphSession
    from exo_ilc_ros.orchestration.recording import Recording

    config = _short_config(max_trials=60, wait_for_recorder=True)
    change = {"schedule.position.threshold_low": [0.0, 0.0, 0.0]}
    with Recording(config, tmp_path / "bags") as recording, \
            GraphSession(config, nodes=recording.graph_nodes()) as session:
        client = _parameter_client(session)  # before the 60 short trials run out
        session.spin_until(lambda: len(session.summaries) >= 3, timeout=120.0)
        assert _set(session, "schedule.position.threshold_low", [0.0, 0.0, 0.0],
                    client).successful
        session.spin_until(lambda: session.finished, timeout=180.0, stall_timeout=60.0)
    marked = [s.trial for s in session.summaries if "parameters_changed" in s.values]
    assert len(marked) == 1, "exactly one trial boundary applied the change"
    assert json.loads(session.summaries[marked[0] - 1].values["parameters_changed"]) == change
    run = read_bag(recording.path)
    assert max(run.completed) == 60
    out = tmp_path / "replay.json"
    code = exo_ilc(["simulate", "--replay", str(recording.path), "--quiet", "--json", str(out)])
    assert code == 0, "the replay equals the recording"
    replayed = json.loads(out.read_text())["runs"][0]["trials"]
    graph = [s.row("max_abs_error", config["joint_names"]) for s in session.summaries]
    np.testing.assert_array_equal([t["max_abs_error"] for t in replayed], graph)
    without = run_trials(config)
    assert not np.array_equal(without.max_abs_errors, np.array(graph)), "the change mattered"


@pytest.mark.parametrize(("store", "bag"), [(False, True), (True, False)])
def test_run_reports_the_mass_uncertainty_it_ran(tmp_path: Path, store: bool,
                                                 bag: bool) -> None:
    """`exo-ilc run --mass-uncertainty 0.15`: the table, the JSON, the bag (provenance, run
    name, `analyze`), the store key and the supervisor's summaries all say 0.15, with or
    without a store and a bag (the supervisor once labelled a run without a store 0.05): each
    of the two with and without the other (the bag without a store: where the label went
    wrong; four graph runs for the four pairs cost the suite ~1 min)."""
    config_file = tmp_path / "short.yaml"
    config_file.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n')
    out = tmp_path / "run.json"
    args = ["run", "--config", str(config_file), "--mass-uncertainty", "0.15", "--trials", "2",
            "--json", str(out)]
    args += ["--store", str(tmp_path / "store")] if store else ["--no-store"]
    args += ["--bag-dir", str(tmp_path / "bags")] if bag else ["--no-bag"]
    result = _exo_ilc(*args, timeout=150, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    assert json.loads(out.read_text())["runs"][0]["mass_uncertainty"] == 0.15
    table_rows = [line for line in result.stdout.splitlines() if line.startswith("sign ")]
    assert table_rows and all(line.split()[1] == "0.150" for line in table_rows), table_rows
    assert " 0.050" not in result.stdout
    local = run_trials(load_config(str(config_file)), 0.15, 2)
    np.testing.assert_allclose(json.loads(out.read_text())["runs"][0]["trials"][-1]
                               ["max_abs_error"], local.max_abs_errors[-1], rtol=0, atol=1e-9)
    if store:
        (meta,) = (tmp_path / "store").glob("*/meta.json")
        assert json.loads(meta.read_text())["keyed"]["mass_uncertainty"] == 0.15
    if bag:
        from exo_ilc_ros.bag import read_bag

        (path,) = (tmp_path / "bags").iterdir()
        assert "_d0.15_" in path.name
        run = read_bag(path)
        assert run.mass_uncertainty == 0.15
        assert all(v["mass_uncertainty"] == "0.15" for v in run.summaries.values())
        analyzed = tmp_path / "analyze.json"
        report = _exo_ilc("analyze", str(path), "--quiet", "--json", str(analyzed),
                          timeout=60)
        assert report.returncode == 0, report.stderr
        assert json.loads(analyzed.read_text())["runs"][0]["mass_uncertainty"] == 0.15


def test_urdf_arm_through_the_graph_equals_in_process(tmp_path: Path) -> None:
    """The Panda (config/arms/panda.yaml, 7 joints from its URDF) with a person strapped to it
    (config/person.yaml: in the plant, not in the nominal model) and the friction scenario
    mapped onto its joints (patient.joints) through the graph: every node validates the 7-joint
    config (the other nodes' per-joint keys from the parameters file, not the shipped 3-joint
    defaults; the patient's 3-joint lists by the mapping) and the trials are simulate's to
    1e-9."""
    arm = ROOT / "config" / "arms" / "panda.yaml"
    graph_json, local_json = tmp_path / "graph.json", tmp_path / "local.json"
    common = ["--config", str(arm), "--scenario", str(ROOT / "config" / "person.yaml"),
              "friction", "--trials", "2", "--mass-uncertainty", "0.1"]
    result = _exo_ilc("run", "--no-bag", "--no-store", *common, "--json", str(graph_json),
                      timeout=200, cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-3000:]
    from exo_ilc_ros.cli.main import main as exo_ilc  # simulate in this process: no start-up

    assert exo_ilc(["simulate", *common, "--json", str(local_json)]) == 0
    (g,), (r,) = json.loads(graph_json.read_text())["runs"], json.loads(
        local_json.read_text())["runs"]
    for key in ("max_abs_error", "max_abs_feedforward", "max_abs_effort"):
        np.testing.assert_allclose([t[key] for t in g["trials"]], [t[key] for t in r["trials"]],
                                   rtol=0.0, atol=1e-9, err_msg=key)
    assert len(g["trials"][0]["max_abs_error"]) == 7
