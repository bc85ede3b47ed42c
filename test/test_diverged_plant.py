"""A plant that cannot blow up silently, in MuJoCo and through the graph (issue 33, point 5).

MuJoCo: the light wrist (2 N m s/rad on 1.4e-4 kg m^2, h b / I ~ 14 at 1 ms) integrates with
``implicitfast`` and stays finite; forced onto RK4 it diverges, and MuJoCo's silent reset to the
rest pose becomes a NaN state with the cause. Every shipped arm and scenario keeps RK4 (their
numbers unchanged). Graph: a plant whose state stops being finite reports it instead of the
sample; the supervisor ends the trial there as the trial kernel does, and ``exo-ilc run`` says
"the plant diverged at t on joint j" with the cause and exits 5, as ``exo-ilc simulate``."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_plant_stability import DIVERGING_DAMPING, _light_wrist_arm

from exo_ilc_ros.core.arm.build import build_plant
from exo_ilc_ros.core.arm.mujoco_urdf import (
    IMPLICIT,
    IMPLICIT_ABOVE,
    MujocoUrdfArm,
    damping_modes,
)
from exo_ilc_ros.core.loop.divergence import (
    DAMPING_STEP,
    DIVERGED,
    state_divergence,
    trial_divergence,
)
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.protocol.trial_protocol import Phase, TrialProtocol
from exo_ilc_ros.core.session.abort import ABORT_STOP_KEY
from exo_ilc_ros.core.session.learning_session import TrialConclusion, run_trials
from exo_ilc_ros.core.sim.experiment import Experiment
from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm, effects_from_config
from exo_ilc_ros.wire import topics

SHIPPED = (None, "arms/panda.yaml", "arms/ur5.yaml", "arms/panda_1khz_norm_optimal.yaml")
SCENARIOS = (None, "scenarios/spastic.yaml", "scenarios/stiff.yaml", "scenarios/friction.yaml",
             "scenarios/realistic.yaml")


def test_the_threshold_is_our_plants() -> None:
    """Both plants change their integration on the same arms (h max eig(a^-1 B) over 1.4)."""
    assert IMPLICIT_ABOVE == DAMPING_STEP
    assert topics.DIVERGED_REASON == DIVERGED


@pytest.mark.parametrize("arm", SHIPPED)
def test_shipped_arms_and_scenarios_keep_rk4(arm: str | None) -> None:
    """No shipped arm or scenario (a URDF arm's damping applied too) is stiff enough to leave
    RK4: their MuJoCo numbers do not change. Measured: h max eig(M^-1 B) <= 0.038."""
    for scenario in SCENARIOS:
        overlays = [config_dir() / scenario] if scenario else []
        config = load_config(config_dir() / arm if arm else None, overlays=overlays)
        variants = [config]
        if config["model.source"] == "urdf":
            variants.append(config.replace({"model.urdf_joint_dynamics": "apply"}))
        for variant in variants:
            mujoco_arm = MujocoArm.from_config(variant)
            assert mujoco_arm.integrator == "RK4", (arm, scenario)
            assert 'integrator="RK4"' in mujoco_arm.xml
            stiffest, _ = damping_modes(mujoco_arm.model, [mujoco_arm.model.qpos0])
            assert variant["integration_step"] * stiffest < 0.05, (arm, scenario)


def _effort(arm: MujocoArm, q_ref: np.ndarray, qd_ref: np.ndarray) -> np.ndarray:
    """PD plus gravity through MuJoCo's own inertia and bias (kp 16, kd 8, as the config)."""
    mass, bias = arm.inertia_and_bias(*_state(arm))
    q, qd = _state(arm)
    return np.asarray(mass @ (16.0 * (q_ref - q) + 8.0 * (qd_ref - qd)) + bias)


def _state(arm: MujocoArm) -> tuple[np.ndarray, np.ndarray]:
    return arm.position, arm.velocity


def test_light_wrist_on_mujoco_is_implicit_and_finite(tmp_path: Path) -> None:
    """The damped wrist: implicitfast (h max eig(M^-1 B) ~ 14 at 1 ms, over 1.4), and a whole
    trial of tracking (computed torque through MuJoCo's own model) stays finite and tracks the
    reference within 0.02 rad on the shoulder and the elbow."""
    config = load_config(_light_wrist_arm(tmp_path))
    arm = MujocoArm.from_config(config)
    assert arm.integrator == IMPLICIT and 'integrator="implicitfast"' in arm.xml
    stiffest, joint = damping_modes(arm.model, [arm.model.qpos0])
    assert config["integration_step"] * stiffest > 10.0 and joint == 2
    ref = Experiment(config).reference
    arm.set_state(ref.position[0], ref.velocity[0])
    worst = np.zeros(3)
    for i in range(ref.samples - 1):
        arm.step(_effort(arm, ref.position[i], ref.velocity[i]))
        worst = np.maximum(worst, np.abs(ref.position[i + 1] - arm.position))
    assert arm.diverged is None and np.all(np.isfinite(arm.position))
    assert np.all(worst[:2] < 0.02), worst


def test_light_wrist_forced_onto_rk4_diverges_loudly(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """The same arm on MuJoCo's RK4 at 1 ms: MuJoCo finds a huge acceleration on the wrist and
    resets its simulation to the rest pose (before, the plant went on from there as if nothing
    happened); now the arm's state is NaN from then on, with MuJoCo's cause, and it does not
    move again until set_state."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warning to MUJOCO_LOG.TXT here
    config = load_config(_light_wrist_arm(tmp_path))
    arm = MujocoArm(build_plant(config), config["joint_names"], config["control.period"],
                    config["integration_step"], config["control.effort_limit"],
                    effects_from_config(config), integrator="RK4")
    ref = Experiment(config).reference
    arm.set_state(ref.position[0], ref.velocity[0])
    steps = 0
    while arm.diverged is None and steps < 10:
        arm.step(np.array([0.0, 0.0, 0.001]))
        steps += 1
    assert arm.diverged is not None, "RK4 at h b / I ~ 14 should diverge"
    assert "MuJoCo found a non-finite or huge" in arm.diverged
    assert "(wrist_roll)" in arm.diverged and "RK4 at h = 0.001 s" in arm.diverged
    assert arm.diverged_joint == 2
    assert np.all(np.isnan(arm.position)) and np.all(np.isnan(arm.velocity))
    time = arm.time
    arm.step(np.zeros(3))
    assert arm.time == time  # not stepped again
    arm.set_state(ref.position[0], ref.velocity[0])
    assert arm.diverged is None and np.all(np.isfinite(arm.position))


def test_urdf_arm_in_mujoco_chooses_its_integrator(tmp_path: Path,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """MujocoUrdfArm (MuJoCo's own URDF parser): RK4 without damping, implicitfast with the
    wrist's damping applied; forced onto RK4, a NaN state and the cause instead of the reset."""
    monkeypatch.chdir(tmp_path)  # MuJoCo writes its warning to MUJOCO_LOG.TXT here
    _light_wrist_arm(tmp_path)
    urdf = tmp_path / "light_wrist.urdf"
    plain = MujocoUrdfArm(urdf, "base_link", "hand")
    assert plain.integrator == "RK4"
    damped = MujocoUrdfArm(urdf, "base_link", "hand", damping=True)
    assert damped.integrator == IMPLICIT
    damped.set_state([0.0, 0.3, 0.0], np.zeros(3))
    for _ in range(100):
        q, qd = damped.step([0.0, 0.0, 0.001])
    assert np.all(np.isfinite(q)) and qd[2] == pytest.approx(0.001 / 2.0, rel=1e-3)
    forced = MujocoUrdfArm(urdf, "base_link", "hand", damping=True)
    forced.use_integrator("RK4")
    forced.set_state([0.0, 0.3, 0.0], np.zeros(3))
    for _ in range(5):
        q, qd = forced.step([0.0, 0.0, 0.001])
    assert np.all(np.isnan(q)) and forced.diverged is not None and forced.diverged_joint == 2


def test_state_divergence_is_the_in_process_report(tmp_path: Path) -> None:
    """What a plant node reports from its state before the non-finite sample equals what the
    in-process report gives for the trial kernel's record of the same trial."""
    config = load_config(_light_wrist_arm(tmp_path, DIVERGING_DAMPING))
    experiment = Experiment(config)
    record = experiment.run_trial(np.zeros(experiment.reference.position.shape), 1)
    names = config["joint_names"]
    expected = trial_divergence(experiment, record, names)
    assert expected is not None and expected.joint_name == "wrist_roll"
    s = expected.sample
    # the kernel's record is NaN from s on; the state before it is the plant's at s - 1
    found = state_divergence(experiment, 1, s, record.position[s - 1], record.velocity[s - 1],
                             names)
    assert found == expected


class DivergingGraph:
    """A graph port whose plant runs the trial in-process and, like the plant nodes, sends no
    sample from the first non-finite one on but its ``diverged`` report."""

    def __init__(self, experiment: Experiment) -> None:
        self.experiment = experiment
        self.protocol: TrialProtocol | None = None
        self.t0 = 1_000_000_000
        self.pushed: list[np.ndarray] = []
        self.conclusions: list[TrialConclusion] = []
        self.divergences: list[Any] = []
        self.events: list[tuple[str, dict[str, str]]] = []

    def reset(self) -> None:
        self.t0 += 10_000_000_000
        assert self.protocol is not None
        self.protocol.on_reset(self.t0)

    def push_feedforward(self, trial: int, t0_ns: int, feedforward: np.ndarray,
                         joint_force: np.ndarray | None = None) -> None:
        self.pushed.append(feedforward.copy())
        assert self.protocol is not None
        self.protocol.on_acknowledged(trial, t0_ns)

    def start(self) -> None:
        protocol = self.protocol
        assert protocol is not None and protocol.session is not None
        protocol.on_started(True)
        record = self.experiment.run_trial(self.pushed[-1], protocol.trial)
        names = protocol.config["joint_names"]
        found = trial_divergence(self.experiment, record, names)
        assert found is not None
        step = protocol.samples.step_ns
        for i in range(found.sample):
            protocol.on_sample(self.t0 + i * step, record.position[i], record.velocity[i])
        protocol.on_plant_diverged({
            "stamp_ns": str(self.t0 + found.sample * step), "t0_ns": str(self.t0),
            "joint": str(found.joint), "joint_name": found.joint_name, "cause": found.cause})

    def publish_conclusion(self, conclusion: TrialConclusion, end_ns: int) -> None:
        assert self.protocol is not None
        self.conclusions.append(conclusion)
        self.divergences.append(self.protocol.divergence)

    def event(self, message: str, values: Sequence[tuple[str, str]],
              stamp_ns: int | None = None) -> None:
        self.events.append((message, dict(values)))

    def log(self, error: bool, text: str) -> None:
        pass


def test_protocol_ends_a_diverged_trial_as_the_kernel_does(tmp_path: Path) -> None:
    """The supervisor's protocol, given the samples before the divergence and the plant's
    report: the same record (NaN from the sample on, aborted there), the same divergence and
    the same stop message as in-process; the run finishes after that trial."""
    config = load_config(_light_wrist_arm(tmp_path, DIVERGING_DAMPING),
                         overrides={"max_trials": 3})
    local = run_trials(config)
    experiment = Experiment(config)
    graph = DivergingGraph(experiment)
    protocol = TrialProtocol(config, graph)
    graph.protocol = protocol
    protocol.open({"mass_uncertainty": config["mass_uncertainty"]})
    protocol.tick(graph_ready=True)
    assert protocol.phase is Phase.FINISHED and protocol.error is None
    assert len(graph.conclusions) == 1 == len(local.records)
    record, expected = graph.conclusions[0].record, local.records[0]
    assert record.aborted_at == expected.aborted_at
    np.testing.assert_array_equal(record.position, expected.position)
    np.testing.assert_array_equal(record.effort, expected.effort)
    divergence = trial_divergence(experiment, expected, config["joint_names"])
    assert graph.divergences == [divergence]
    assert graph.conclusions[0].stop_message == local.stop_message


def _command(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env.pop("EXO_ILC_TRACEBACK", None)
    return subprocess.run([sys.executable, "-m", "exo_ilc_ros.cli.main", *args], text=True,
                          capture_output=True, env=env, timeout=600, cwd=cwd, check=False)


@pytest.mark.graph
def test_run_through_the_graph_reports_the_divergence_and_exits_5(tmp_path: Path) -> None:
    """``exo-ilc run`` on the arm whose wrist damping no sub-step count integrates (real DDS,
    lock-step): the plant node reports the divergence instead of the sample, the trial ends
    there, and the run says what ``exo-ilc simulate`` says (the same ERROR line, stop message,
    exit 5 and plant_diverged in --json), never "no progress", an envelope abort or a
    traceback; --json's metrics hold no IndexError either."""
    config = _light_wrist_arm(tmp_path, DIVERGING_DAMPING)
    local = _command("simulate", "--config", str(config), "--trials", "3", "--metrics",
                     "--json", str(tmp_path / "local.json"), cwd=tmp_path)
    assert local.returncode == 5, local.stderr[-3000:]
    assert "IndexError" not in local.stderr and "Traceback" not in local.stderr
    graph = _command("run", "--no-bag", "--no-store", "--config", str(config), "--trials",
                     "3", "--json", str(tmp_path / "graph.json"), cwd=tmp_path)
    assert graph.returncode == 5, graph.stderr[-3000:]
    for bad in ("Traceback", "internal error", "no progress", "ABORTED by the error envelope",
                "no trial summary", "IndexError"):
        assert bad not in graph.stderr, graph.stderr[-3000:]
    ran, expected = (json.loads((tmp_path / f"{n}.json").read_text())["runs"][0]
                     for n in ("graph", "local"))
    assert ran[DIVERGED] == expected[DIVERGED] and len(ran[DIVERGED]) == 1
    assert ran[ABORT_STOP_KEY] == expected[ABORT_STOP_KEY]
    assert len(ran["trials"]) == 1  # the diverged trial kept, not run again (a rerun for a
    # watchdog trip on a loaded machine may come before it: that is no divergence)
    assert all(r["trial"] == 1 for r in ran.get("reruns", []))
    message = expected[DIVERGED][0]["message"]
    assert message.startswith("trial 1: the plant diverged at t = 0.020 s on joint wrist_roll")
    assert f"ERROR: linear d=0.05: {message}" in graph.stderr
    assert graph.stderr.count(expected[ABORT_STOP_KEY]) == 1


@pytest.mark.graph
def test_a_plant_without_reset_reports_the_divergence_within_a_trial(tmp_path: Path) -> None:
    """``protocol: homing`` (free_running_plant: our RK4 without services, homed by the
    controller): the wrist diverges in trial 1, the node reports it, the supervisor ends that
    trial there, and the run stops with the plant's time, joint and cause (exit 5), never
    "homing failed" or a stall."""
    config = _light_wrist_arm(tmp_path, DIVERGING_DAMPING)
    homing = tmp_path / "homing.yaml"
    homing.write_text('"/**":\n  ros__parameters:\n    protocol: homing\n')
    graph = _command("run", "--no-bag", "--no-store", "--config", str(config), "--scenario",
                     str(homing), "--trials", "3", "--json", str(tmp_path / "graph.json"),
                     cwd=tmp_path)
    assert graph.returncode == 5, graph.stderr[-3000:]
    for bad in ("Traceback", "no progress", "homing failed", "ABORTED by the error envelope",
                "no trial summary"):
        assert bad not in graph.stderr, graph.stderr[-3000:]
    run = json.loads((tmp_path / "graph.json").read_text())["runs"][0]
    [diverged] = run[DIVERGED]
    assert diverged["trial"] == 1 and diverged["joint_name"] == "wrist_roll"
    assert 0.0 < diverged["time"] < 0.1 and "explicit-integration stability" in diverged["cause"]
    assert diverged["message"] in graph.stderr and run[ABORT_STOP_KEY]


@pytest.mark.graph
def test_mujoco_that_resets_its_simulation_stops_the_run_with_its_cause(
        tmp_path: Path) -> None:
    """``--plant mujoco`` with a passive stiffness of 1e7 N m/rad (h sqrt(K/I) far over any
    explicit integrator's limit): MuJoCo finds a huge acceleration early in trial 1 and resets
    its simulation to the rest pose; the node no longer goes on from there (the old symptom:
    "homing failed" against an arm that jumped), it reports the divergence, the supervisor
    ends the trial there and the run stops with MuJoCo's cause (exit 5). Where the homing
    before trial 1 already moves the arm enough (which it is depends on when the homing's
    commands arrive), it diverges there: the run stops as a plant that diverged while homing
    (exit 3, docs/exit-codes.md) with the same cause, never "homing failed"."""
    stiff = tmp_path / "stiff.yaml"
    stiff.write_text("plant_simulator:\n  ros__parameters:\n    patient:\n      passive:\n"
                     "        stiffness: [1.0e7, 1.0e7, 1.0e7]\n")
    graph = _command("run", "--plant", "mujoco", "--no-bag", "--no-store", "--scenario",
                     str(stiff), "--trials", "2", cwd=tmp_path)
    assert graph.returncode in (3, 5), graph.stderr[-3000:]
    for bad in ("Traceback", "no progress", "homing failed", "ABORTED by the error envelope"):
        assert bad not in graph.stderr, graph.stderr[-3000:]
    cause = ("on joint shoulder_flexion: MuJoCo found a non-finite or huge acceleration at DOF "
             "0 (shoulder_flexion) and reset its simulation (RK4 at h = 0.001 s")
    assert cause in graph.stderr, graph.stderr[-3000:]
    if graph.returncode == 3:
        assert "trial 1 not started: the plant diverged while homing, " + cause \
            in graph.stderr, graph.stderr[-3000:]
        return
    assert "ERROR: sign d=0.05: trial 1: the plant diverged at t = " in graph.stderr
    assert graph.stderr.count("stopped after an aborted trial: trial 1: the plant diverged") == 1


@pytest.mark.graph
def test_no_table_or_json_shows_a_learned_input_above_its_limit(tmp_path: Path) -> None:
    """feedforward_limit 0.5 (reached from trial 2): ``simulate`` and ``run`` (--learned,
    --json) never print or write a max |u_ff| above it, and both say AT ITS LIMIT."""
    config = tmp_path / "limit.yaml"
    config.write_text('"/**":\n  ros__parameters:\n    trajectory:\n      duration: 1.0\n'
                      "ilc_supervisor:\n  ros__parameters:\n"
                      "    feedforward_limit: [0.5, 0.5, 0.5]\n")
    for command in ("simulate", "run"):
        extra = ("--no-bag", "--no-store") if command == "run" else ()
        out = tmp_path / f"{command}.json"
        done = _command(command, *extra, "--config", str(config), "--trials", "4", "--learned",
                        "--json", str(out), cwd=tmp_path)
        assert done.returncode == 0, done.stderr[-3000:]
        trials = json.loads(out.read_text())["runs"][0]["trials"]
        learned = np.array([t["max_abs_feedforward"] for t in trials])
        assert learned.max() == 0.5 and np.all(learned <= 0.5), learned
        printed = _printed_learned_inputs(done.stdout)
        assert len(printed) == 3 * 4 + 3 and max(printed) <= 0.5, done.stdout
        assert "AT ITS LIMIT on shoulder_flexion, shoulder_abduction, elbow_flexion" \
            in done.stdout


def _printed_learned_inputs(text: str) -> list[float]:
    """Every max |u_ff| a report prints: the per-trial table's rows (``--learned``) and the
    long-run line's ``|u_ff| a b c``."""
    values: list[float] = []
    in_table = False
    for line in text.splitlines():
        if line.startswith("max |u_ff| ("):
            in_table = True
            continue
        if in_table and re.match(r"^\s*\d+ \|", line):
            values += [float(x.rstrip("*")) for x in line.split("|")[1].split()]
        elif in_table and not line.strip():
            in_table = False
        found = re.search(r"\|u_ff\| ([-+.\de ]+) \|effort\|", line)
        if found:
            values += [float(x) for x in found.group(1).split()]
    return values
