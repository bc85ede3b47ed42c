"""``exo-ilc compare``: the paper's sign law, the tuned sign law and the linear law side by side."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.errors import ConfigError
from ..core.params.config import config_dir, read_yaml
from .arguments import (
    add_config_argument,
    add_mass_uncertainty_argument,
    add_scenario_argument,
    config_with_flags,
    figure_file,
    input_file,
    integer,
    json_file,
    parameter,
)
from .progress import progress_bar
from .tune import default_jobs

if TYPE_CHECKING:
    from ..core.session.summary import RunSummary

TUNED_NAME = "tuned.yaml"


def find_tuned() -> Path | None:
    """``config/tuned.yaml`` of the current directory, else of the shipped config directory."""
    for candidate in (Path("config") / TUNED_NAME, config_dir() / TUNED_NAME):
        if candidate.is_file():
            return candidate
    return None


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "compare", help="compare the paper's, the tuned sign law and the linear law",
        description="Run the paper's hand-tuned sign law, the tuned sign law (from --tuned, or "
        "config/tuned.yaml if there is one), the linear law and the norm-optimal law at each "
        "mass uncertainty; print one table and write one figure.")
    add_config_argument(parser, "ROS parameter YAML laid over the shipped config (the "
                        "paper's law and the linear law run with it)")
    add_scenario_argument(parser)
    parser.add_argument("--tuned", type=input_file, help="tuned YAML laid over --config "
                        "(default: config/tuned.yaml if found)")
    parser.add_argument("--no-tuned", action="store_true", help="leave the tuned law out")
    parser.add_argument("--no-norm-optimal", action="store_true",
                        help="leave the norm-optimal law (law: norm_optimal) out")
    add_mass_uncertainty_argument(parser, "default: 0.05 0.10 0.15", [0.05, 0.10, 0.15])
    parser.add_argument("--trials", type=parameter("max_trials"),
                        help="trials per run (default: max_trials)")
    parser.add_argument("--plot", default="compare.png", type=figure_file,
                        help="figure (default: compare.png)")
    parser.add_argument("--json", metavar="OUT", type=json_file,
                        help="also write the per-trial tables as JSON")
    parser.add_argument("--jobs", type=integer(1), default=default_jobs(),
                        help="parallel worker processes (default: the CPUs available)")
    parser.set_defaults(func=compare)


def compare(args: argparse.Namespace) -> int:
    """Run the variants, print the table, write the figure."""
    from ..analysis.comparison import Variant, format_comparison, plot_comparison, run_comparison
    from ..analysis.report import write_json
    if args.no_tuned and args.tuned:
        raise ConfigError("--no-tuned", f"cannot be combined with --tuned {args.tuned}")
    base = config_with_flags(args.config, {} if args.trials is None else
                             {"max_trials": ("--trials", args.trials)},
                             args.scenario or [])
    trials = int(base["max_trials"])
    variants = [Variant("sign (paper)", base.replace({"law": "sign"}), "sign")]
    tuned_path = None if args.no_tuned else (Path(args.tuned) if args.tuned else find_tuned())
    if tuned_path is not None:
        if not tuned_path.is_file():
            raise ConfigError("--tuned", "no such file", str(tuned_path))
        tuned_values = read_yaml(tuned_path)
        tuned_values.pop("max_trials", None)
        try:
            tuned = base.replace(tuned_values)
        except ConfigError as exc:  # the tuned file's fault, not --config's
            raise ConfigError(exc.key, exc.rule, str(tuned_path)) from None
        variants.append(Variant("sign (tuned)", tuned.replace({"law": "sign"}), "sign"))
    variants.append(Variant("linear", base.replace({"law": "linear"}), "linear"))
    if not args.no_norm_optimal:
        variants.append(Variant("norm-optimal", base.replace({"law": "norm_optimal"}),
                                "norm_optimal"))
    deltas = args.mass_uncertainty
    print("compare: " + ", ".join(v.label for v in variants) + " at delta = "
          + " ".join(f"{d:g}" for d in deltas) + f", {trials} trials"
          + (f"; tuned from {tuned_path}" if tuned_path else "; no tuned file"))
    with progress_bar(total=len(variants) * len(deltas), desc="compare", unit="run") as bar:
        runs = run_comparison(variants, deltas, trials, args.jobs, lambda: bar.update(1))
    names = base["joint_names"]
    print(format_comparison(runs, names))
    plot_comparison(runs, names, args.plot)
    print(f"wrote {args.plot}")
    if args.json:
        summaries = []
        for r in runs:
            s: RunSummary = r.summary
            s.law = r.label
            summaries.append(s)
        write_json(args.json, base.values, summaries)
        print(f"wrote {args.json}")
    return 0
