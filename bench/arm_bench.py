"""Trials without a simulator's reset (issue 15): what the MuJoCo plant and homing cost and give
(figures only, no asserts).

    .venv/bin/python -m bench.arm_bench [--trials 10] [--measure] [--robust-trials 300]

(a) the engines in-process: wall time of one control period (10 RK4 sub-steps) of MuJoCo's arm
    and of our plant (core/loop/plant.py);
(b) the graph's lock-step rate within trials (control steps per second, median trial, from the
    supervisor's start and end events) in one run of this script: plant_simulator with its
    services, our simulator without them (free_running_plant, homing) and MuJoCo (homing);
(c) with ``--measure``, issue 15's "done when" on MuJoCo with homing at delta = 10 %: trial 1
    against `exo-ilc simulate` per joint, the linear law's iterations to 0.005 rad in 15 trials,
    config/robust.yaml over ``--robust-trials`` trials (growth of max |u_ff|, worst max |e| after
    trial 10), the start error homing left (max over trials), and our simulator with homing.
Every graph runs on a ROS domain of its own with discovery kept on this machine.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from exo_ilc_ros.core.convergence.growth import fit_growth
from exo_ilc_ros.core.loop.stepper import PlantStepper
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.sim.experiment import Experiment
from exo_ilc_ros.orchestration.graph import GraphRun, GraphSession, run_graph
from exo_ilc_ros.orchestration.launcher import exported_domain_id, graph_nodes

ROBUST = Path(__file__).resolve().parent.parent / "config" / "robust.yaml"


def engine_rates(periods: int = 2000) -> dict[str, float]:
    """(a): microseconds per control period, MuJoCo and our RK4 (the same arm, delta 10 %)."""
    from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

    config = load_config(overrides={"mass_uncertainty": 0.1})
    out = {}
    for name, arm in (("mujoco", MujocoArm.from_config(config)),
                      ("rk4", PlantStepper(Experiment(config)))):
        effort = np.array([1.0, 0.5, 0.2])
        arm.step(effort)
        start = time.perf_counter()
        for _ in range(periods):
            arm.step(effort)
        out[name] = (time.perf_counter() - start) / periods * 1e6
    return out


def _graph(config: Config, plant: str, desc: str) -> tuple[GraphRun, list[float]]:
    """One graph run with a progress bar; the within-trial rates (steps/s) per trial."""
    rates: list[float] = []
    starts: dict[int, float] = {}
    samples = Experiment(config).reference.samples - 1

    def watch(session: GraphSession) -> None:
        def on_event(msg: Any) -> None:
            for item in msg.status:
                values = {kv.key: kv.value for kv in item.values}
                if item.message == "start":
                    starts[int(values["trial"])] = time.monotonic()
                elif item.message == "end" and int(values["trial"]) in starts:
                    rates.append(samples / (time.monotonic() - starts[int(values["trial"])]))
        from diagnostic_msgs.msg import DiagnosticArray

        from exo_ilc_ros.nodes.common import EVENTS_QOS
        from exo_ilc_ros.wire import topics
        session.node.create_subscription(DiagnosticArray, topics.TRIAL_EVENTS, on_event,
                                         EVENTS_QOS)

    with tqdm(total=config["max_trials"], desc=desc, unit="trial", file=sys.stderr) as bar:
        run = run_graph(config, exported_domain_id(), nodes=graph_nodes(plant, config["protocol"]),
                        on_summary=lambda s: bar.update(1), on_start=watch, timeout=7200.0)
    return run, rates


def lock_step_rates(trials: int) -> None:
    """(b)."""
    print(f"(b) lock-step control steps per second within trials (median of {trials} trials, "
          "5 s trials, linear law, delta 10 %):")
    base = {"law": "linear", "max_trials": trials, "mass_uncertainty": 0.1}
    for label, plant, protocol in (("plant_simulator, services", "simulator", "services"),
                                   ("our simulator, homing", "simulator", "homing"),
                                   ("MuJoCo, homing", "mujoco", "homing")):
        config = load_config(overrides={**base, "protocol": protocol})
        run, rates = _graph(config, plant, label)
        per_trial = run.wall_time / trials if run.wall_time else float("nan")
        print(f"  {label:28s} {np.median(rates):8.0f} steps/s   wall per trial "
              f"(homing included) {per_trial:.2f} s")


def _first_within(errors: np.ndarray, bound: float) -> list[int | None]:
    out: list[int | None] = []
    for j in range(errors.shape[1]):
        hits = np.flatnonzero(errors[:, j] <= bound)
        out.append(int(hits[0]) + 1 if hits.size else None)
    return out


def measure(robust_trials: int) -> None:
    """(c)."""
    names = load_config()["joint_names"]
    linear = load_config(overrides={"law": "linear", "max_trials": 15,
                                    "mass_uncertainty": 0.1, "protocol": "homing"})
    run, _ = _graph(linear, "mujoco", "MuJoCo linear")
    local = run_trials(linear.replace({"protocol": "services"}), 0.1)
    graph_e, local_e = run.summary.max_abs_error, local.max_abs_errors
    print("(c) MuJoCo, homing, delta 10 %, linear law, 15 trials:")
    print("  trial 1 max |e| per joint: graph " + " ".join(f"{x:.5f}" for x in graph_e[0]) +
          ", simulate " + " ".join(f"{x:.5f}" for x in local_e[0]) + ", difference " +
          " ".join(f"{100 * (g / s - 1):+.3f} %" for g, s in zip(graph_e[0], local_e[0],
                                                                  strict=True)))
    print(f"  first within 0.005 rad: graph {_first_within(graph_e, 0.005)}, simulate "
          f"{_first_within(local_e, 0.005)}; last trial max |e| "
          + " ".join(f"{x:.2e}" for x in graph_e[-1]))
    start = np.array([[abs(float(s.values[f"initial_error/{n}"])) for n in names]
                      for s in run.summaries])
    speed = np.array([[abs(float(s.values[f"initial_velocity/{n}"])) for n in names]
                      for s in run.summaries])
    print("  start error homing left, max over trials: |q_d(0) - q(0)| " +
          " ".join(f"{x:.1e}" for x in start.max(0)) + " rad, |qdot(0)| " +
          " ".join(f"{x:.1e}" for x in speed.max(0)) + " rad/s; missing samples " +
          str(sum(int(s.values["samples_missing"]) for s in run.summaries)))

    ours, _ = _graph(linear, "simulator", "our simulator linear")
    print(f"  our simulator with protocol homing: first within "
          f"{_first_within(ours.summary.max_abs_error, 0.005)}, last trial max |e| "
          + " ".join(f"{x:.2e}" for x in ours.summary.max_abs_error[-1]))

    robust = load_config(ROBUST, {"max_trials": robust_trials, "mass_uncertainty": 0.1,
                                  "protocol": "homing"})
    run, _ = _graph(robust, "mujoco", "MuJoCo robust.yaml")
    e = run.summary.max_abs_error
    ff = run.summary.max_abs_feedforward
    assert ff is not None
    fit = fit_growth(ff)
    verdict = "too few trials" if fit is None else (
        " ".join(f"{100 * r:+.4f}" for r in fit.rate) + " %/trial over trials "
        f"{fit.first_trial}-{fit.last_trial} -> " + ("GROWING" if fit.any_growing
                                                     else "bounded"))
    print(f"  config/robust.yaml, {robust_trials} trials: first within "
          f"{_first_within(e, 0.005)}, worst max |e| after trial 10 "
          + " ".join(f"{x:.2e}" for x in e[10:].max(0)) + ", max |u_ff| at the last trial "
          + " ".join(f"{x:.3g}" for x in ff[-1]) + "; growth of max |u_ff| " + verdict)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--measure", action="store_true")
    parser.add_argument("--robust-trials", type=int, default=300)
    args = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rates = engine_rates()
    print(f"(a) one control period in-process: MuJoCo {rates['mujoco']:.1f} us, our RK4 "
          f"{rates['rk4']:.1f} us")
    lock_step_rates(args.trials)
    if args.measure:
        measure(args.robust_trials)


if __name__ == "__main__":
    main()
