"""Learning through an abort on the stiff patient (issue 33, docs/safety.md): robust.yaml (and
patient_aware.yaml) on config/scenarios/stiff.yaml, mass uncertainty 5 %, up to 60 trials:
trials run, aborted trials, whether any aborted feed-forward ran again unchanged, the last
trial's max |e| and the stop message.

    python bench/abort_stiff.py [config ...]
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np

from exo_ilc_ros.core import load_config, run_trials

ROOT = Path(__file__).resolve().parents[1]


def main(configs: list[str]) -> None:
    for name in configs or ["config/robust.yaml"]:
        config = load_config(ROOT / name, {"max_trials": 60},
                             overlays=[ROOT / "config" / "scenarios" / "stiff.yaml"])
        result = run_trials(config)
        records = result.records
        repeated = sum(1 for a, b in itertools.pairwise(records)
                       if a.aborted and np.array_equal(a.feedforward, b.feedforward))
        completed = [r for r in records if not r.aborted]
        print(f"{name}: {len(records)} trials, {len(result.aborted)} aborted "
              f"{result.aborted}, aborted feed-forwards run again: {repeated}")
        print(f"  last trial max|e| {np.max(records[-1].max_abs_error):.4f} rad; last "
              f"completed trial {completed[-1].trial if completed else '-'} max|e| "
              f"{np.max(completed[-1].max_abs_error) if completed else float('nan'):.4f} rad; "
              f"bound {config['error_bound']} reached: "
              f"{any(np.all(r.max_abs_error <= config['error_bound']) for r in completed)}")
        print(f"  stop: {result.stop.value if result.stop else '-'} {result.stop_message}")


if __name__ == "__main__":
    main(sys.argv[1:])
