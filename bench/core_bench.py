"""Benchmark of the in-process core: one 5 s trial and a full 150-trial run.

Run with ``.venv/bin/python -m bench.core_bench``. Prints medians; asserts nothing (wall-clock
timing is noisy on a shared 2-core machine). Target: one trial <= 35 ms.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from exo_ilc_ros.core import Experiment, load_config, run_trials


def main() -> None:
    """Measure and print."""
    config = load_config()
    experiment = Experiment(config, 0.10)
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
    run_times = []
    for law in ("sign", "linear"):
        start = time.perf_counter()
        run_trials(config, 0.10, 150, law)
        run_times.append((law, time.perf_counter() - start))
    for law, seconds in run_times:
        print(f"150-trial run, {law} law, delta 0.10: {seconds:.2f} s "
              f"({seconds / 150 * 1e3:.1f} ms per trial including the law update)")


if __name__ == "__main__":
    main()
