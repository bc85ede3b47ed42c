"""The robustness study at full size: the number of docs/study.md, "Which law survives which
patient" (issue 14's target: <= 10 min on 2 cores).

Run with ``.venv/bin/python -m bench.study_bench`` (defaults: the laws sign, tuned, linear and
robust x the six scenarios of issue 14 (ideal .. realistic) x 5/10/15 % x 1000 trials x
1 seed on 2 worker processes).
Prints the wall time, the cost per trial (wall time x workers / trials, and the cells' own
mean), the cost per trial per scenario (patient effects on against ``ideal``; on a machine
others load, that column follows the load over time more than the effects: the patient's own
``bench.patient_bench`` measures them side by side), then the table. Asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

from exo_ilc_ros.analysis.study import format_study_table, run_cells
from exo_ilc_ros.core.programs.study import (
    SCENARIO_ORDER,
    resolve_law,
    resolve_scenario,
    study_cells,
)
from exo_ilc_ros.core.programs.study_rows import study_rows

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # no node here; house rule


def main() -> None:
    """Run the study and print what it cost."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--laws", nargs="+", default=["sign", "tuned", "linear", "robust"])
    parser.add_argument("--scenarios", nargs="+", default=None)
    parser.add_argument("--mass-uncertainty", nargs="+", type=float, default=[0.05, 0.10, 0.15])
    parser.add_argument("--trials", type=int, default=1000)
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    laws = [resolve_law(x) for x in args.laws]
    scenarios = [resolve_scenario(x) for x in (args.scenarios or SCENARIO_ORDER)]
    cells = study_cells(laws, scenarios, args.mass_uncertainty, [0], args.trials)
    total = len(cells) * args.trials
    print(f"study bench: {len(laws)} laws x {len(scenarios)} scenarios x "
          f"{len(args.mass_uncertainty)} uncertainties x 1 seed = {len(cells)} cells, "
          f"{total} trials, {args.workers} workers, {os.cpu_count()} CPUs", flush=True)
    done = 0

    def progress(cell: object) -> None:
        nonlocal done
        done += 1
        print(f"\r{done}/{len(cells)} cells, {time.perf_counter() - start:.0f} s",
              end="", file=sys.stderr, flush=True)

    start = time.perf_counter()
    results = run_cells(cells, args.workers, on_done=progress)
    wall = time.perf_counter() - start
    print(file=sys.stderr)
    print(f"wall time {wall:.1f} s ({wall / 60:.2f} min; target <= 10 min); "
          f"{1e3 * wall * args.workers / total:.2f} ms per trial per worker "
          f"(the cells' own: {1e3 * sum(r.seconds for r in results) / total:.2f} ms)")
    ideal = None
    for scenario in scenarios:
        mine = [r for r in results if r.scenario == scenario.label]
        cost = 1e3 * sum(r.seconds for r in mine) / sum(r.trials for r in mine)
        if scenario.label == "ideal":
            ideal = cost
        ratio = f" ({cost / ideal:.2f} x ideal)" if ideal else ""
        print(f"  {scenario.label:<10} {cost:6.2f} ms per trial{ratio}")
    slowest = max(results, key=lambda r: r.seconds)
    print(f"slowest cell: {slowest.law} / {slowest.scenario} / "
          f"{100 * slowest.mass_uncertainty:g} % {slowest.seconds:.1f} s; median cell "
          f"{np.median([r.seconds for r in results]):.1f} s\n")
    print(format_study_table(study_rows(results, args.trials)))


if __name__ == "__main__":
    main()
