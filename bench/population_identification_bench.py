"""What the loop uses of the identification over a drawn population (issue 33): patients of
:mod:`exo_ilc_ros.core.population.distributions` with a 14-bit encoder each, under
config/patient_aware.yaml on the paper's movement; every used joint's damping and Coulomb
friction (not left out) against the patient's truth, and the first trial within 0.005 rad.

    python -m bench.population_identification_bench [--patients 16] [--trials 10]
"""

from __future__ import annotations

import argparse

import numpy as np

from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.loop.patient import patient_values, spasticity_values
from exo_ilc_ros.core.params.config import config_dir
from exo_ilc_ros.core.population.distributions import PopulationSpec, draw_population


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--patients", type=int, default=16)
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    base = load_config(overlays=[config_dir() / "patient_aware.yaml"])
    used = off = 0
    firsts = []
    for patient in draw_population(base, PopulationSpec(encoder_share=1.0), args.patients,
                                   args.seed):
        config = base.replace(patient.overrides)
        _, spastic_damping, _, _, _ = spasticity_values(config)
        truth = {"viscous": patient_values(config, "friction.viscous")
                 + np.asarray(spastic_damping, dtype=float),
                 "coulomb": patient_values(config, "friction.coulomb")}
        result = run_trials(config, trials=args.trials)
        firsts.append(max(x or args.trials + 1 for x in result.iterations_to_bound().first))
        for trial, step in sorted(result.joint_forces.items()):
            for j, joint in enumerate(step.estimate.joints):
                if not step.used[j]:
                    continue
                for name, values in truth.items():
                    if name in joint.absorbed:
                        continue
                    value, true = joint.value(name), float(values[j])
                    used += 1
                    if abs(value - true) > 0.1 * max(true, 0.02):
                        off += 1
                        print(f"patient {patient.index} trial {trial} joint {j} {name} "
                              f"{value:.4g} (truth {true:.4g})")
    print(f"used joint-parameter-trials {used}, more than 10 % off (or 0.002 below 0.02) "
          f"{off}; first trial within 0.005 rad (worst joint, {args.trials + 1}: not by the "
          f"last) {firsts}")


if __name__ == "__main__":
    main()
