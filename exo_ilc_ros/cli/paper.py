"""``exo-ilc paper``: the paper's whole experiment (5/10/15 % mass uncertainty), one bag per
run, then one figure and one table beside the paper's numbers, all from the bags."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError
from .analyze import analyze, analyze_arguments
from .arguments import (
    add_config_argument,
    config_with_flags,
    directory,
    domain_id,
    figure_path,
    json_file,
    parameter,
)
from .progress import progress_bar
from .run import graph_domain

PAPER_UNCERTAINTIES = (0.05, 0.10, 0.15)


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "paper", help="the paper's experiment through the graph: 3 bags, 1 figure, 1 table",
        description="Run the experiment at 5, 10 and 15 % mass uncertainty through the ROS 2 "
        "graph (each run recorded by bag_recorder), then analyse the three bags: the "
        "per-trial table, iterations to the bound beside the paper's, Figures 5-7.")
    add_config_argument(parser, "ROS parameter YAML laid over the shipped config")
    parser.add_argument("--trials", type=parameter("max_trials"),
                        help="trials per run (default: max_trials)")
    parser.add_argument("--bag-dir", default="bags", metavar="DIR", type=directory,
                        help="default: bags")
    parser.add_argument("--plot", default="paper_figures.png", metavar="OUT.png",
                        type=figure_path,
                        help="the figure (default: paper_figures.png)")
    parser.add_argument("--json", metavar="OUT", type=json_file, help="the tables as JSON")
    parser.add_argument("--csv", metavar="OUT", type=json_file, help="the per-trial table as CSV")
    parser.add_argument("--in-process", action="store_true",
                        help="run in-process (exo-ilc simulate --bag) instead of the graph; "
                        "the bags hold the same topics")
    parser.add_argument("--domain-id", type=domain_id, help="ROS domain id of the graph (default: "
                        "an exported ROS_DOMAIN_ID, else a free one)")
    parser.add_argument("--quiet", action="store_true", help="no per-trial table")
    parser.set_defaults(func=paper)


def paper(args: argparse.Namespace) -> int:
    """Three runs, three bags, then ``analyze`` on them."""
    from ..bag import run_name, unique_path, write_run
    from ..core.session.learning_session import run_trials
    from ..orchestration.graph import run_graph
    from ..orchestration.recording import Recording
    if args.in_process and args.domain_id is not None:  # an exported ROS_DOMAIN_ID is fine
        raise ConfigError("--in-process", "starts no graph: --domain-id would be ignored; drop "
                          "one")
    config = config_with_flags(args.config, {} if args.trials is None else
                               {"max_trials": ("--trials", args.trials)})
    trials = config["max_trials"]
    bags: list[Path] = []
    for delta in PAPER_UNCERTAINTIES:
        run_config = config.with_mass_uncertainty(delta)
        with progress_bar(total=trials, desc=f"{'in-process' if args.in_process else 'graph'} "
                                        f"delta={delta:g}", unit="trial") as bar:
            def progress(_: Any, bar: Any = bar) -> None:
                bar.update(1)

            if args.in_process:
                result = run_trials(run_config, delta, trials, on_trial=progress)
                path = unique_path(args.bag_dir, run_name("sim", result.law, delta))
                bags.append(write_run(path, run_config, result))
            else:
                run_config = run_config.replace({"wait_for_recorder": True})
                with Recording(run_config, args.bag_dir) as recording:
                    run_graph(run_config, graph_domain(args.domain_id), on_summary=progress,
                              nodes=recording.graph_nodes())
                bags.append(recording.path)
        print(f"bag: {bags[-1]}", file=sys.stderr)
    analysis = [str(b) for b in bags] + ["--plot", str(args.plot)]
    analysis += ["--csv", str(args.csv)] if args.csv else []
    analysis += ["--json", str(args.json)] if args.json else []
    analysis += ["--quiet"] if args.quiet else []
    return analyze(analyze_arguments(analysis))
