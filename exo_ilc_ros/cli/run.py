"""``exo-ilc run``: the experiment through the ROS 2 node graph (one process per node, real DDS)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from tqdm import tqdm

from ..report import (
    RunSummary,
    format_iterations,
    format_long_run,
    format_trial_table,
    write_json,
)
from .simulate import add_config_arguments, config_from_args


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "run", help="run the experiment through the ROS 2 node graph",
        description="Start plant_simulator, computed_torque_controller and ilc_supervisor as "
        "separate processes on a ROS domain of their own (discovery limited to this machine "
        "unless ROS_AUTOMATIC_DISCOVERY_RANGE is set), run K trials per mass uncertainty and "
        "print the same table and JSON as `exo-ilc simulate`.")
    add_config_arguments(parser)
    parser.add_argument("--domain-id", type=int, help="ROS domain id of the graph (default: "
                        "a free one, claimed with a lock file)")
    parser.add_argument("--quiet", action="store_true", help="no per-trial table")
    parser.add_argument("--learned", action="store_true", help="also print per-trial tables "
                        "of max |u_ff| (learned feed-forward) and max |effort| per joint")
    parser.add_argument("--no-bag", action="store_true",
                        help="do not start bag_recorder (default: each run is recorded to "
                        "<bag-dir>/<run-name>/, rosbag2 MCAP)")
    parser.add_argument("--bag-dir", default="bags", metavar="DIR",
                        help="where the bags go (default: bags)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the graph once per mass uncertainty and report."""
    from ..bag.recording import Recording
    from ..graph import TrialSummary, run_graph

    config = config_from_args(args)
    deltas = args.mass_uncertainty or [config["mass_uncertainty"]]
    trials = config["max_trials"]
    runs: list[RunSummary] = []
    for delta in deltas:
        run_config = config.replace({"mass_uncertainty": delta})
        with tqdm(total=trials, desc=f"graph {config['law']} delta={delta:g}", unit="trial",
                  file=sys.stderr, disable=None) as bar:
            def progress(summary: TrialSummary, bar: Any = bar) -> None:
                bar.update(1)
                errors = summary.row("max_abs_error", config["joint_names"])
                bar.set_postfix_str("max|e| " + " ".join(f"{x:.1e}" for x in errors))
            if args.no_bag:
                result = run_graph(run_config, args.domain_id, on_summary=progress,
                               on_start=lambda s: print(f"graph on ROS_DOMAIN_ID={s.domain_id}",
                                                        file=sys.stderr, flush=True))
            else:
                run_config = run_config.replace({"wait_for_recorder": True})
                with Recording(run_config, args.bag_dir) as recording:
                    result = run_graph(run_config, args.domain_id, extra=[recording.spec],
                                       on_summary=progress)
                bar.write(f"bag: {recording.path}", file=sys.stderr)
        runs.append(result.summary)
    names = config["joint_names"]
    if not args.quiet:  # the same report as `exo-ilc simulate`
        print(format_trial_table(runs, names))
        print()
        if args.learned:
            for quantity in ("feedforward", "effort"):
                print(format_trial_table(runs, names, quantity))
                print()
    print(format_iterations(runs, names))
    print()
    print(format_long_run(runs, names))
    if args.json:
        write_json(args.json, config.values, runs)
        print(f"wrote {args.json}")
    return 0
