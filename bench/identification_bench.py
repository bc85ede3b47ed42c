"""Benchmark of the between-trial identification of the patient's joint forces
(core/learning/identification.py): the cost of one trial's update (filtered regression, the
recursive least squares of every reflex grid point, the estimate and its checks) and of the
joint-force term computed torque would add along the reference, at 100 Hz with 5 s trials
(501 samples), for the paper's 3 joints and a 7-joint arm, ``friction`` and ``spastic`` with
the encoders, reflex grid on and off. A refused trial (chatter: the 7-joint spastic arm's
lightest joint chatters from trial 3 on) costs less than a full update; the column says how
many.

Run with ``.venv/bin/python -m bench.identification_bench``. Prints medians and maxima; asserts
nothing (wall-clock timing is noisy on a shared 2-core machine). What it answers: the update
runs between trials, off the control loop; a 100 Hz graph never waits for it if it takes less
than the pause between trials (and it is far below a trial's 5 s, so it can also run while the
next trial runs, its estimate used one trial later).
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.learning.identification import JointForceIdentifier
from exo_ilc_ros.core.learning.identification_settings import IdentificationSettings
from exo_ilc_ros.core.learning.joint_force_term import joint_force_term
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import Config, config_dir, load_config, scenario_path
from exo_ilc_ros.core.session.learning_session import LearningSession, run_trials
from exo_ilc_ros.core.sim.experiment import Experiment

TRIALS = 12


def seven_joint_config(scenario: str, laid_under: tuple[Path, ...] = ()) -> Config:
    """A 7-joint arm (the paper's three links, then four lighter ones) under ``scenario`` with
    the encoders (over the configs ``laid_under``)."""
    overlays = [*laid_under, scenario_path(scenario), scenario_path("sensor")]
    base = load_config(overlays=overlays)
    n = 7
    overrides: dict[str, Any] = {}
    for p in schema.PARAMETERS:
        value = base[p.name]
        if isinstance(value, list) and len(value) == 3 and p.name != "joint_names":
            overrides[p.name] = (value + [value[-1]] * 4)[:n]
    overrides.update({
        "joint_names": [f"joint_{i}" for i in range(n)],
        "model.joint_axes": ["x", "y", "x", "y", "x", "y", "x"],
        "model.link_masses": [0.0, 1.4, 1.1, 1.0, 0.8, 0.6, 0.5],
        "model.link_lengths": [0.0, 0.369, 0.36, 0.2, 0.2, 0.15, 0.15],
        "trajectory.goal": [1.0, 0.6, 0.5, 0.6, 0.5, 0.6, 0.5],
    })
    return load_config(overlays=overlays, overrides=overrides)


def update_times(config: Config, reflex: bool) -> tuple[list[float], list[float], int]:
    """Seconds per trial of the update and of the joint-force term (first trial: compile,
    not counted), and how many trials were refused (chatter: cheap, not a full update)."""
    records = run_trials(config, 0.05, TRIALS).records
    settings = IdentificationSettings.from_config(config, reflex=reflex)
    identifier = JointForceIdentifier(build_arm(config), settings)
    reference = records[0].reference
    identifier.update_record(records[0])
    updates, terms = [], []
    refused = 0
    for record in records[1:]:
        start = time.perf_counter()
        estimate = identifier.update_record(record)
        middle = time.perf_counter()
        refused += bool(estimate.rejected)
        joint_force_term(estimate, reference.position, reference.velocity,
                         np.asarray(config["control.effort_limit"]), settings)
        end = time.perf_counter()
        updates.append(middle - start)
        terms.append(end - middle)
    return updates, terms, refused


def boundary_times(scenario: str, joints: int) -> tuple[list[float], list[float]]:
    """Seconds per trial boundary of config/patient_aware.yaml's session (identification,
    forces, handover and the update's inverse with the patient: ``LearningSession.conclude``)
    and of the same boundary with identification off (the law alone), trials 2..TRIALS."""
    overlays = [config_dir() / "patient_aware.yaml", scenario_path(scenario)]
    config = load_config(overlays=overlays) if joints == 3 else \
        seven_joint_config(scenario, (config_dir() / "patient_aware.yaml",))
    out: list[list[float]] = []
    for enabled in (True, False):
        cfg = config.replace({"identification.enabled": enabled})
        session = LearningSession(cfg)
        experiment = Experiment(cfg)
        times = []
        for _ in range(TRIALS):
            record = experiment.run_trial(session.feedforward, session.trial, session.levels,
                                          None, session.joint_force)
            start = time.perf_counter()
            session.conclude(record)
            times.append(time.perf_counter() - start)
        out.append(times[1:])
    return out[0], out[1]


def main() -> None:
    """Print the medians and maxima."""
    cases = [(3, "spastic", load_config(overlays=[scenario_path("spastic"),
                                                  scenario_path("sensor")])),
             (3, "friction", load_config(overlays=[scenario_path("friction"),
                                                   scenario_path("sensor")])),
             (7, "friction", seven_joint_config("friction")),
             (7, "spastic", seven_joint_config("spastic"))]
    print(f"identification between trials, 100 Hz, 5 s trials (501 samples), {TRIALS - 1} "
          "trials each (+ sensor), ms")
    print(f"{'joints':>6} {'scenario':>9} {'reflex grid':>11} {'update median':>14} {'max':>7} "
          f"{'term median':>12} {'max':>7} {'per joint':>10} {'refused':>8}")
    for n, name, config in cases:
        for reflex in (True, False):
            updates, terms, refused = update_times(config, reflex)
            med = statistics.median(updates) * 1e3
            print(f"{n:>6} {name:>9} {'on' if reflex else 'off':>11} {med:>14.1f} "
                  f"{max(updates) * 1e3:>7.1f} {statistics.median(terms) * 1e3:>12.2f} "
                  f"{max(terms) * 1e3:>7.2f} {med / n:>10.1f} {refused:>8}")
    print(f"\nthe whole trial boundary of config/patient_aware.yaml (LearningSession.conclude: "
          f"law, identification, forces, handover, inverse), trials 2-{TRIALS}, ms; a 100 Hz "
          "graph waits for none of it if it ends within the pause between trials")
    print(f"{'joints':>6} {'scenario':>9} {'boundary median':>16} {'max':>7} "
          f"{'law alone median':>17} {'max':>7}")
    for n, name in ((3, "friction"), (3, "spastic"), (3, "realistic"), (7, "friction")):
        aware, alone = boundary_times(name, n)
        print(f"{n:>6} {name:>9} {statistics.median(aware) * 1e3:>16.1f} "
              f"{max(aware) * 1e3:>7.1f} {statistics.median(alone) * 1e3:>17.1f} "
              f"{max(alone) * 1e3:>7.1f}")


if __name__ == "__main__":
    main()
