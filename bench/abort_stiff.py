"""Learning through an abort on the stiff patient (issue 33, docs/safety.md "Learning through an
abort"): a config on config/scenarios/stiff.yaml at the shipped mass uncertainty (5 %): trials
run, aborted trials, whether any aborted feed-forward ran again unchanged, the first trial within
the bound, the last trial's max |e| and the stop message.

    python bench/abort_stiff.py [--trials K] [--max-consecutive N] [--backoff B] [config ...]
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path
from typing import Any

import numpy as np

from exo_ilc_ros.core import load_config, run_trials

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("configs", nargs="*", default=["config/robust.yaml"])
    parser.add_argument("--trials", type=int, default=60)
    parser.add_argument("--max-consecutive", type=int)
    parser.add_argument("--backoff", type=float)
    args = parser.parse_args()
    overrides: dict[str, Any] = {"max_trials": args.trials}
    if args.max_consecutive is not None:
        overrides["abort.max_consecutive"] = args.max_consecutive
    if args.backoff is not None:
        overrides["abort.backoff"] = args.backoff
    for name in args.configs:
        config = load_config(ROOT / name, overrides,
                             overlays=[ROOT / "config" / "scenarios" / "stiff.yaml"])
        result = run_trials(config)
        records = result.records
        repeated = sum(1 for a, b in itertools.pairwise(records)
                       if a.aborted and np.array_equal(a.feedforward, b.feedforward))
        bound = config["error_bound"]
        first = next((r.trial for r in records
                      if not r.aborted and np.all(r.max_abs_error <= bound)), None)
        print(f"{name} {overrides}: {len(records)} trials, {len(result.aborted)} aborted "
              f"{result.aborted}; aborted feed-forwards run again: {repeated}; first within "
              f"{bound} rad: {first}; last trial max|e| {np.max(records[-1].max_abs_error):.4f}")
        print(f"  stop: {result.stop.value if result.stop else '-'} {result.stop_message}")


if __name__ == "__main__":
    main()
