"""Benchmark of the in-process core: one 5 s trial, each law's between-trial update (and the
norm-optimal learning matrix) and a full 150-trial run.

Run with ``.venv/bin/python -m bench.core_bench``. Prints medians; asserts nothing (wall-clock
timing is noisy on a shared 2-core machine). Target: one trial <= 35 ms.

``--trials-only [--arm FILE ...] [--repeats R]``: only the 5 s trial in-process at the config's
rate (100 Hz control, RK4 at 1 ms), min and median of R repeats, for the paper's 3-joint arm
(``--arm default``) and each arm file (default: ``default config/arms/panda.yaml``; issue 27's
targets: 3 joints <= 6 ms, 7 joints <= 20 ms), and one plant period called from Python.
"""

from __future__ import annotations

import argparse
import statistics
import time
from typing import Any

import numpy as np

from exo_ilc_ros.core import Experiment, load_config, run_trials
from exo_ilc_ros.core.learning.factory import build_law
from exo_ilc_ros.core.loop.plant import plant_integration, rk4_period
from exo_ilc_ros.core.params.config import Config


def plant_step_times(experiment: Experiment, repeats: int = 2000) -> list[float]:
    """Seconds per control period of the plant alone (what the simulator node's lock-step step
    runs), called from Python: RK4 on the sub-steps, 4 plant evaluations each."""
    ref = experiment.reference
    n = ref.position.shape[1]
    q, qd = np.empty(n), np.empty(n)
    effort = np.resize([0.5, -1.0, 0.2], n)  # any number of joints
    integration = plant_integration(experiment.period, experiment.substeps,
                                    experiment.plant.kernel_args,
                                    experiment.nominal.kernel_args, int(experiment.dynamics))
    times = []
    for _ in range(5):
        start = time.perf_counter()
        for _ in range(repeats):
            q[:] = ref.position[1]  # the same state each time: no drift
            qd[:] = ref.velocity[1]
            rk4_period(q, qd, effort, integration)
        times.append((time.perf_counter() - start) / repeats)
    return times


def between_trials(config: Config) -> None:
    """The supervisor's between-trial computation: each law's update (median of 21) from one
    5 s trial's record, and the norm-optimal law's learning matrix (once per configuration)."""
    from exo_ilc_ros.core.learning import norm_optimal_model

    experiment = Experiment(config.with_mass_uncertainty(0.10))
    record = experiment.run_trial(np.zeros_like(experiment.reference.position), 1)
    norm_optimal_model.clear_cache()
    start = time.perf_counter()
    norm_optimal_model.learning_matrices(config)
    cold = time.perf_counter() - start
    start = time.perf_counter()
    norm_optimal_model.learning_matrices(config.replace({"error_bound": 0.004}))
    cached = time.perf_counter() - start
    n = record.feedforward.size
    print(f"norm-optimal learning matrix ({n} x {n}, linearised model; analyze-loop's): built "
          f"in {cold:.2f} s once per configuration; {cached * 1e3:.2f} ms from the cache after a "
          "live change of another parameter")
    norm_optimal_model.clear_cache()
    start = time.perf_counter()
    gains = norm_optimal_model.recursive_matrices(config).gains
    print(f"norm-optimal Riccati gains (the law's; {gains.nbytes / 1e6:.1f} MB): built in "
          f"{time.perf_counter() - start:.2f} s once per configuration, the model included")
    variants: list[tuple[str, dict[str, Any]]] = [
        ("sign", {"law": "sign"}), ("linear", {"law": "linear"}),
        ("norm_optimal", {"law": "norm_optimal"}),
        ("norm_optimal constrained (QP)", {"law": "norm_optimal",
                                           "norm_optimal.constrained": True})]
    for label, overrides in variants:
        law = build_law(config.replace(overrides))
        times = []
        for _ in range(21 if "QP" not in label else 5):
            start = time.perf_counter()
            law.update(record)
            times.append(time.perf_counter() - start)
        print(f"between trials, {label} update: median {statistics.median(times) * 1e3:.2f} ms "
              f"(min {min(times) * 1e3:.2f} ms, {len(times)} runs)")


def trial_times(config: Config, repeats: int) -> tuple[float, list[float]]:
    """(seconds of the first trial: numba's compile or cache load, seconds of each of
    ``repeats`` further 5 s trials) of the in-process trial at delta 0.10, zero feed-forward."""
    experiment = Experiment(config.with_mass_uncertainty(0.10))
    feedforward = np.zeros_like(experiment.reference.position)
    start = time.perf_counter()
    experiment.run_trial(feedforward, 1)
    warmup = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        experiment.run_trial(feedforward, 1)
        times.append(time.perf_counter() - start)
    return warmup, times


TRIAL_TARGET_MS = {3: 6.0, 7: 20.0}
"""Issue 27's targets for the 5 s trial at 100 Hz control, by joints."""


def trials_only(arms: list[str], repeats: int) -> None:
    """The 5 s trial per arm (module docstring)."""
    for arm in arms:
        config = load_config(None if arm == "default" else arm)
        warmup, times = trial_times(config, repeats)
        experiment = Experiment(config.with_mass_uncertainty(0.10))
        step = statistics.median(plant_step_times(experiment, 500))
        target = TRIAL_TARGET_MS.get(config.joints)
        print(f"{arm}: {config.joints} joints, control {1 / config['control.period']:g} Hz, RK4 "
              f"{config['integration_step'] * 1e3:g} ms: one 5 s trial min "
              f"{min(times) * 1e3:.2f} ms, median {statistics.median(times) * 1e3:.2f} ms "
              f"({repeats} repeats"
              + ("" if target is None else f"; target <= {target:g} ms") + f"; first "
              f"{warmup:.2f} s); one plant period from Python median {step * 1e6:.1f} us")


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials-only", action="store_true",
                        help="only the 5 s trial of each --arm")
    parser.add_argument("--arm", nargs="+", default=["default", "config/arms/panda.yaml"],
                        help="with --trials-only: 'default' (the paper's arm) or arm files")
    parser.add_argument("--repeats", type=int, default=21)
    args = parser.parse_args()
    if args.trials_only:
        trials_only(args.arm, args.repeats)
        return
    config = load_config()
    experiment = Experiment(config.with_mass_uncertainty(0.10))
    feedforward = np.zeros_like(experiment.reference.position)
    start = time.perf_counter()
    experiment.run_trial(feedforward, 1)  # compiles, or loads the numba cache
    warmup = time.perf_counter() - start
    trial_times = []
    for _ in range(21):
        start = time.perf_counter()
        experiment.run_trial(feedforward, 1)
        trial_times.append(time.perf_counter() - start)
    samples = experiment.reference.samples
    substeps = (samples - 1) * experiment.substeps
    median = statistics.median(trial_times)
    print(f"first trial (compile or cache load): {warmup:.2f} s")
    print(f"one 5 s trial ({samples} control samples, {substeps} RK4 sub-steps): "
          f"median {median * 1e3:.1f} ms, min {min(trial_times) * 1e3:.1f} ms "
          f"over {len(trial_times)} runs (target <= 35 ms)")
    print(f"  per RK4 sub-step: {median / substeps * 1e6:.2f} us "
          f"(4 plant evaluations + the controller every {experiment.substeps})")
    step = statistics.median(plant_step_times(experiment))
    evaluations = 4 * experiment.substeps
    print(f"plant step (one period, {experiment.substeps} RK4 sub-steps = {evaluations} plant "
          f"evaluations, called from Python): median {step * 1e6:.1f} us "
          f"({step / evaluations * 1e9:.0f} ns per evaluation, call overhead included)")
    between_trials(config)
    run_times = []
    for law in ("sign", "linear", "norm_optimal"):
        start = time.perf_counter()
        run_trials(config, 0.10, 150, law)
        run_times.append((law, time.perf_counter() - start))
    for law, seconds in run_times:
        print(f"150-trial run, {law} law, delta 0.10: {seconds:.2f} s "
              f"({seconds / 150 * 1e3:.1f} ms per trial including the law update)")


if __name__ == "__main__":
    main()
