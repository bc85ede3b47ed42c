"""Draws docs/paper_figures.png, the front page's figure, and writes its data beside it
(docs/paper_figures.json): max |e| per trial of each joint for ``make demo``'s three runs, i.e.
``exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15`` (the shipped config: the sign law, 150
trials each), in-process. The ROS 2 graph gives the same numbers (``exo-ilc run`` equals
``simulate``: test_graph.py). Run from the checkout: ``.venv/bin/python docs/paper_figure.py``.

The PNG carries the sha256 of the JSON's curves (its ``Description`` text chunk), and
test_front_figure.py checks that the JSON equals what ``make demo`` computes now and that the
PNG was drawn from that JSON: when a change moves the demo's numbers, run this again."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from exo_ilc_ros.analysis.figures import convergence_figure
from exo_ilc_ros.core import load_config, run_trials
from exo_ilc_ros.core.session.summary import RunSummary

HERE = Path(__file__).resolve().parent
FIGURE = HERE / "paper_figures.png"
DATA = HERE / "paper_figures.json"
DEMO_UNCERTAINTIES = (0.05, 0.10, 0.15)
"""``make demo``'s ``--mass-uncertainty``."""
COMMAND = "exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15"


def curves_digest(data: dict[str, Any]) -> str:
    """sha256 of the curves (each run's mass uncertainty and per-trial max |e|), canonical
    JSON: what the PNG's ``Description`` names."""
    curves = [[run["mass_uncertainty"], run["true_max_abs_error"]] for run in data["runs"]]
    return hashlib.sha256(json.dumps(curves, sort_keys=True).encode()).hexdigest()


def demo_runs() -> tuple[list[str], list[RunSummary]]:
    """The joint names and ``make demo``'s three runs, as ``exo-ilc simulate`` makes them."""
    config = load_config()
    runs = [RunSummary.from_result(run_trials(config, delta, config["max_trials"]))
            for delta in DEMO_UNCERTAINTIES]
    return config["joint_names"], runs


def main() -> None:
    names, runs = demo_runs()
    data = {"command": COMMAND, "joint_names": names,
            "runs": [{"law": run.law, "mass_uncertainty": run.mass_uncertainty,
                      "error_bound": run.error_bound,
                      "true_max_abs_error": [[float(x) for x in row]
                                             for row in run.true_errors]}
                     for run in runs]}
    DATA.write_text(json.dumps(data, indent=1) + "\n")
    figure = convergence_figure(runs, names)
    figure.savefig(FIGURE, dpi=110, metadata={"Description": "curves sha256 "
                                              + curves_digest(data)})
    print(f"wrote {FIGURE} and {DATA}")


if __name__ == "__main__":
    main()
