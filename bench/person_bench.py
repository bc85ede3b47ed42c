"""Benchmark of the exoskeleton strapped to a person with muscles (core/person/): the cost of
one in-process 5 s trial (501 samples, the controller, the strapped MuJoCo model, the cuffs)
with MyoArm and with the small elbow model, at MuJoCo steps of 1, 2, 5 and 10 ms, and how far
each step's trial is from the 1 ms one (max |q| difference of the exoskeleton's joints, peak
cuff force difference).

Run with ``.venv/bin/python -m bench.person_bench [myoarm|myoelbow ...]``. Prints, per model
and step, the median wall time and CPU time (``time.process_time``: this process only, less
hurt by a loaded machine) of a trial, and the load average. Asserts nothing. Targets (issue
#34): a 5 s trial with MyoArm <= 1 s, with the small model <= 0.1 s.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
import warnings

import numpy as np

from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.person.cuffs import cuff_metrics
from exo_ilc_ros.core.person.experiment import StrappedExperiment

STEPS = (0.001, 0.002, 0.005, 0.01)


def trial_costs(model: str, timestep: float, repeats: int = 5
                ) -> tuple[list[float], list[float], np.ndarray, np.ndarray]:
    """(wall s, CPU s) per 5 s trial, the last trial's exoskeleton q and its cuff metrics."""
    config = load_config(config_dir() / f"{model}.yaml",
                         overrides={"musculoskeletal.timestep": timestep,
                                    "mass_uncertainty": 0.1})
    experiment = StrappedExperiment(config)
    u_ff = np.zeros_like(experiment.reference.position)
    record = experiment.run_trial(u_ff, 1)  # compiles the kernels
    walls, cpus = [], []
    for k in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        record = experiment.run_trial(u_ff, k + 2)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    assert record.cuff_wrench is not None
    return walls, cpus, record.position, cuff_metrics(record.cuff_wrench)


def main(models: list[str]) -> None:
    warnings.simplefilter("ignore")
    for model in models:
        print(f"{model}: 5 s trial (501 samples), median of 5; load average "
              f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print("  step (ms) | wall (s) | CPU (s) | max |dq| vs 1 ms (rad) | peak cuff force "
              "(N) | vs 1 ms (N)")
        reference: tuple[np.ndarray, np.ndarray] | None = None
        for step in STEPS:
            walls, cpus, q, metrics = trial_costs(model, step)
            if reference is None:
                reference = (q, metrics)
            dq = float(np.nanmax(np.abs(q - reference[0])))
            dforce = float(np.max(np.abs(metrics[:, 0] - reference[1][:, 0])))
            peaks = ", ".join(f"{x:.1f}" for x in metrics[:, 0])
            print(f"  {step * 1e3:9.0f} | {statistics.median(walls):8.3f} | "
                  f"{statistics.median(cpus):7.3f} | {dq:22.2e} | {peaks:>20} | "
                  f"{dforce:.2f}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["myoelbow", "myoarm"])
