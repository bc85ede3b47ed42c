"""The norm-optimal law against the linear law: the numbers of docs/norm-optimal.md.

Run with ``.venv/bin/python -m bench.norm_optimal_bench [--trials 1000]`` (~5 min). Prints, per mass
uncertainty, the first / settled trial per joint of both laws, the floor (max |e| of the last
trial) and the boundedness of the learned input over the run (max |u_ff| at trials 100, 500 and
the last, and the growth check of ``exo-ilc simulate``); then the constrained law against the
clipped linear law with the effort limit just above what the movement needs. Asserts nothing.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.convergence.growth import fit_growth
from exo_ilc_ros.core.loop.plant import saturation_counts
from exo_ilc_ros.core.session.result import RunResult


def _its(result: RunResult) -> str:
    its = result.iterations_to_bound()
    return ", ".join(f"{'-' if f is None else f}/{'-' if s is None else s}"
                     for f, s in zip(its.first, its.settled, strict=True))


def speed_and_floor(trials: int) -> None:
    """Both laws, shipped config, no Q-filter, 5/10/15 %."""
    config = load_config()
    for delta in (0.05, 0.10, 0.15):
        for law in ("linear", "norm_optimal"):
            start = time.perf_counter()
            result = run_trials(config, delta, trials, law=law)
            seconds = time.perf_counter() - start
            ff = result.max_abs_feedforward.max(axis=1)
            marks = [k for k in (100, 500) if k < trials]
            fit = fit_growth(result.max_abs_feedforward)
            growth = "-" if fit is None else (
                "GROWING" if fit.any_growing else "bounded") + " (" + "/".join(
                f"{100 * r:+.4f}" for r in fit.rate) + " %/trial)"
            print(f"delta {delta:.2f} {law:<13} first/settled {_its(result):<18} floor "
                  f"{result.max_abs_errors[-1].max():.2e} (min over run "
                  f"{result.max_abs_errors.max(axis=1).min():.2e})  max|u_ff| "
                  + " ".join(f"@{k} {ff[k - 1]:.6g}" for k in marks)
                  + f" @{trials} {ff[-1]:.6g}  growth {growth}  ({seconds:.1f} s)")


def constrained(trials: int, margin: float = 1.001) -> None:
    """Effort limit = margin x the converged movement's max |effort| per joint (15 %): the
    linear and the norm-optimal law clipped by the controller, and the constrained norm-optimal
    law with no effort margin and with 1 % kept free for the prediction's error."""
    base = load_config()
    delta = 0.15
    need = run_trials(base, delta, 30, law="linear").max_abs_effort[-1]
    limit = [float(x) for x in margin * need]
    print(f"\nconstrained, delta {delta}: the movement needs max |effort| "
          + "/".join(f"{x:.3f}" for x in need) + f" N m; effort_limit {margin:g} x that = "
          + "/".join(f"{x:.3f}" for x in limit))
    constrained_law = {"law": "norm_optimal", "norm_optimal.constrained": True}
    variants: list[tuple[str, dict[str, Any]]] = [
        ("linear (clipped)", {"law": "linear"}),
        ("norm_optimal (clipped)", {"law": "norm_optimal"}),
        ("constrained, margin 0", constrained_law),
        ("constrained, margin 0.01", {**constrained_law, "norm_optimal.effort_margin": 0.01}),
    ]
    for label, overrides in variants:
        config = base.replace({**overrides, "control.effort_limit": limit})
        start = time.perf_counter()
        result = run_trials(config, delta, trials)
        seconds = time.perf_counter() - start
        saturated = np.array([saturation_counts(r.effort, np.asarray(limit)).sum()
                              for r in result.records])
        print(f"  {label:<25} first/settled {_its(result):<18} floor "
              f"{result.max_abs_errors[-1].max():.2e}; samples at the limit: trials 2-{trials} "
              f"{saturated[1:].sum()} (per trial from 2: "
              + " ".join(str(int(x)) for x in saturated[1:9])
              + f" ...); constraints active at {len(result.notes)} updates ({seconds:.1f} s)")


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--trials", type=int, default=1000)
    parser.add_argument("--constrained-trials", type=int, default=30)
    args = parser.parse_args()
    speed_and_floor(args.trials)
    constrained(args.constrained_trials)


if __name__ == "__main__":
    main()
