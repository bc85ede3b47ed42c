"""Benchmark of the virtual patient: the cost of one in-process trial with every effect off
(``ideal``) and under each shipped scenario (``realistic``: all of them), and of the node's
plant step.

Run with ``.venv/bin/python -m bench.patient_bench``. Prints medians; asserts nothing
(wall-clock timing is noisy on a shared 2-core machine). Target: a ``realistic`` trial costs at
most 1.5x an ``ideal`` one (issue #14).
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from exo_ilc_ros.core.loop.stepper import PlantStepper
from exo_ilc_ros.core.params.config import load_config, scenario_path
from exo_ilc_ros.core.sim.experiment import Experiment

SCENARIOS = ("ideal", "sensor", "friction", "spastic", "voluntary", "realistic")


def trial_times(scenario: str, repeats: int = 30) -> list[float]:
    """Seconds per 5 s trial (501 samples, 10 RK4 sub-steps each), the patient's draws
    included, at 10 % mass uncertainty with a fixed feed-forward."""
    config = load_config(overlays=[scenario_path(scenario)]).with_mass_uncertainty(0.10)
    experiment = Experiment(config)
    u_ff = np.zeros_like(experiment.reference.position)
    experiment.run_trial(u_ff, 1)  # compile
    times = []
    for k in range(repeats):
        start = time.perf_counter()
        experiment.run_trial(u_ff, k + 2)
        times.append(time.perf_counter() - start)
    return times


def step_times(scenario: str, repeats: int = 3000) -> list[float]:
    """Seconds per control period of the node's plant (measure + step), from Python."""
    config = load_config(overlays=[scenario_path(scenario)]).with_mass_uncertainty(0.10)
    experiment = Experiment(config)
    stepper = PlantStepper(experiment)
    effort = np.array([0.5, 10.0, 2.0])
    samples = experiment.reference.samples
    times = []
    for _ in range(5):
        start = time.perf_counter()
        done = 0
        while done < repeats:
            stepper.begin_trial(1)
            for _ in range(samples - 1):
                stepper.measure()
                stepper.step(effort)
            done += samples - 1
        times.append((time.perf_counter() - start) / done)
    return times


def main() -> None:
    """Print the medians."""
    medians = {name: statistics.median(trial_times(name)) for name in SCENARIOS}
    base = medians["ideal"]
    print("one 5 s trial in-process (median of 30), 10 % mass uncertainty")
    for name, seconds in medians.items():
        print(f"  {name:<10} {seconds * 1e3:7.2f} ms  {seconds / base:5.2f}x ideal")
    target = "met" if medians["realistic"] <= 1.5 * base else "NOT met"
    print(f"target realistic <= 1.5x ideal: {target}")
    for name in ("ideal", "realistic"):
        step = statistics.median(step_times(name))
        print(f"node plant step ({name}, measure + step from Python): {step * 1e6:.1f} us")


if __name__ == "__main__":
    main()
