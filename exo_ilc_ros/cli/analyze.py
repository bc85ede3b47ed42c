"""``exo-ilc analyze BAG [BAG ...]``: tables and the paper's figures from recorded runs."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..analysis.wording import count_phrase
from .arguments import figure_path, integer, json_file

if TYPE_CHECKING:
    from ..bag import BagRun
    from ..core.programs.identified import Identified
    from ..core.session.summary import RunSummary


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "analyze", help="tables and figures from recorded bags (MCAP or sqlite3)",
        description="Read rosbag2 bags of runs (recorded by bag_recorder, `exo-ilc simulate "
        "--bag`, or `ros2 bag record` of the same topics) and print per bag the max |e| per "
        "trial and joint and the iterations to the bound beside the paper's numbers.")
    parser.add_argument("bags", nargs="+", metavar="BAG", help="rosbag2 bag directories")
    parser.add_argument("--plot", metavar="OUT.png", type=figure_path,
                        help="the paper's Figures 5-7: max |e| per iteration, one curve per bag")
    parser.add_argument("--trial", type=integer(1), metavar="K",
                        help="also a tracking figure of trial K (q vs q_d, error, effort, "
                        "feed-forward), written beside --plot as <OUT>_trial<K>.png (default "
                        "trial<K>.png)")
    parser.add_argument("--csv", metavar="OUT", type=json_file,
                        help="write the per-trial table as CSV")
    parser.add_argument("--json", metavar="OUT", type=json_file,
                        help="write the tables as JSON (the shape of `exo-ilc simulate --json`)")
    parser.add_argument("--config-out", metavar="FILE", type=json_file,
                        help="write the first bag's effective config (rerun it with "
                        "`exo-ilc simulate --config FILE`)")
    parser.add_argument("--quiet", action="store_true", help="no per-trial table")
    parser.add_argument("--skip-damaged", action="store_true",
                        help="analyse a bag without its files whose checksums fail (named in a "
                        "note; their trials show as missing) instead of refusing it")
    parser.set_defaults(func=analyze)


def analyze_arguments(argv: Sequence[str]) -> argparse.Namespace:
    """``analyze``'s arguments parsed by its own parser (for commands that end in an analysis,
    like ``paper``), so a flag added to ``analyze`` can never be missing from them."""
    parser = argparse.ArgumentParser(prog="exo-ilc")
    register(parser.add_subparsers(dest="command", required=True))
    return parser.parse_args(["analyze", *argv])


def describe(run: BagRun) -> str:
    """A few lines about one bag: origin, provenance, trials, parameter changes, notes."""
    prov = run.provenance
    lines = [f"bag {run.path} ({run.storage}): {run.law}, mass uncertainty "
             f"{run.mass_uncertainty:g}; recorded by {prov.recorded_by or 'unknown'}"
             + (f" (exo_ilc_ros {prov.version})" if prov.version else "")
             + f"; {count_phrase(len(run.completed), 'trial')} completed"
             + (f", incomplete: {run.incomplete}" if run.incomplete else "")]
    if prov.options:
        lines.append("  options: " + ", ".join(f"{k}={v}" for k, v in prov.options.items()))
    for change in run.live_changes():
        lines.append(f"  parameter {change['node']} {change['parameter']} = "
                     f"{json.dumps(change['value'])} from trial {change['trial']}")
    lines += [f"  note: {note}" for note in run.notes]
    return "\n".join(lines)


def identified(run: BagRun) -> list[Identified]:
    """The identification each completed trial's summary carries (empty: none, a run
    without ``identification.enabled`` or a bag of an earlier version)."""
    from ..core.programs.identified import Identified
    found = (Identified.from_summary(k, run.summaries.get(k, {}), run.joint_names)
             for k in run.completed)
    return [item for item in found if item is not None]


def write_csv(path: Path | str, runs: Sequence[RunSummary], joint_names: Sequence[str]) -> None:
    """One row per bag and trial: max |e|, |u_ff| and |effort| per joint; with a person
    strapped in (any run) also ``cuff/<cuff>/<metric>`` per cuff (empty for a run without)."""
    from ..core.person.cuffs import CUFF_METRICS, CUFFS, cuff_key
    header = ["bag", "law", "mass_uncertainty", "trial"]
    for key in ("max_abs_error", "max_abs_feedforward", "max_abs_effort"):
        header += [f"{key}/{name}" for name in joint_names]
    person = any(r.cuff_forces is not None for r in runs)
    if person:
        header += [cuff_key(c, m) for c in CUFFS for m in CUFF_METRICS]
    with open(path, "w", newline="") as handle:
        out = csv.writer(handle)
        out.writerow(header)
        for run in runs:
            for k in range(len(run.max_abs_error)):
                row: list[Any] = [run.extra.get("bag", ""), run.law, repr(run.mass_uncertainty),
                                  k + 1]
                for table in (run.max_abs_error, run.max_abs_feedforward, run.max_abs_effort):
                    row += ([repr(float(x)) for x in table[k]] if table is not None
                            else [""] * len(joint_names))
                if person:
                    cuffs = run.cuff_forces
                    row += ([repr(float(x)) for x in cuffs[k].ravel()]
                            if cuffs is not None and k < len(cuffs)
                            else [""] * (len(CUFFS) * len(CUFF_METRICS)))
                out.writerow(row)


def trial_figure_path(plot: str | None, trial: int, bag: Path, several: bool) -> Path:
    """Where the tracking figure of ``trial`` goes."""
    if plot is None:
        base = Path(f"trial{trial}.png")
        return base.with_stem(f"{bag.name}_trial{trial}") if several else base
    out = Path(plot)
    middle = f"_{bag.name}" if several else ""
    return out.with_stem(f"{out.stem}{middle}_trial{trial}")


def bag_paths(paths: Sequence[str], command: str = "analyze") -> list[Path]:
    """The rosbag2 bag directories among ``paths`` (a directory with a ``metadata.yaml``);
    anything else (``bags/*`` also matches ``bags/README.md``) is skipped with a note. A
    recording killed before its first trial was filed has no ``metadata.yaml`` yet and is
    skipped too."""
    from ..bag import BagReadError
    found = []
    for given in paths:
        path = Path(given)
        if (path / "metadata.yaml").is_file():
            found.append(path)
            continue
        why = ("no such file or directory" if not path.exists() else
               "not a directory" if not path.is_dir() else "no metadata.yaml")
        print(f"exo-ilc {command}: note: skipping {given}: not a rosbag2 bag ({why})",
              file=sys.stderr)
    if not found:
        raise BagReadError(Path(paths[0]), "no rosbag2 bag directory among the arguments "
                           f"({', '.join(paths[:5])}{', ...' if len(paths) > 5 else ''})")
    return found


def bag_labels(runs: Sequence[BagRun]) -> list[str]:
    """One label per bag: its directory name, or its whole path where two names are equal."""
    names = [run.path.name for run in runs]
    return [str(run.path) if names.count(name) > 1 else name
            for run, name in zip(runs, names, strict=True)]


def analyze(args: argparse.Namespace) -> int:
    """Read every bag and check every request first, then report, export, plot."""
    from ..analysis import figures
    from ..analysis.identified import format_table
    from ..analysis.report import (
        format_cuff_table,
        format_iterations,
        format_run_events,
        format_trial_table,
        write_json,
    )
    from ..bag import BagReadError, read_bag
    bag_runs = [read_bag(path, skip_damaged=args.skip_damaged) for path in bag_paths(args.bags)]
    names = bag_runs[0].joint_names
    for run in bag_runs[1:]:
        if len(run.joint_names) != len(names):
            raise BagReadError(run.path, f"has {len(run.joint_names)} joints, "
                               f"{bag_runs[0].path} has {len(names)}")
    for run in bag_runs:
        print(describe(run))
    labels = bag_labels(bag_runs)
    runs = [run.summary() for run in bag_runs]
    for run, summary in zip(bag_runs, runs, strict=True):
        found = identified(run)
        if found:  # the last estimate, as simulate's JSON has it
            summary.extra["identified"] = found[-1].to_json()
    usable = [(r, label) for r, label in zip(runs, labels, strict=True)
              if len(r.max_abs_error)]
    if not usable:
        raise BagReadError(bag_runs[0].path, "no completed trial in any bag")
    # Every check before anything is written.
    config_text = bag_runs[0].provenance.config_yaml
    if args.config_out and not config_text:
        raise BagReadError(bag_runs[0].path, "has no config in custom_data (--config-out)")
    with_trial = bag_runs
    if args.trial is not None:
        with_trial = [run for run in bag_runs if args.trial in run.trials]
        if not with_trial:
            raise BagReadError(bag_runs[0].path if len(bag_runs) == 1 else
                               Path(args.bags[0]).parent,
                               f"no bag has trial {args.trial} (--trial; recorded: "
                               + "; ".join(f"{label}: {_trial_span(run)}" for run, label
                                           in zip(bag_runs, labels, strict=True)) + ")")
    summaries = [r for r, _ in usable]
    usable_labels = [label for _, label in usable]
    print()
    if not args.quiet:
        print(format_trial_table(summaries, names, labels=usable_labels))
        print()
    events = format_run_events(summaries, usable_labels)
    if events:
        print(events)
        print()
    print(format_iterations(summaries, names, labels=usable_labels))
    cuffs = format_cuff_table(summaries, usable_labels)
    if cuffs and not args.quiet:  # a person strapped in: the forces on it
        print()
        print(cuffs)
    if not args.quiet:
        for run, label in zip(bag_runs, labels, strict=True):
            table = format_table(identified(run), run.joint_names)
            if table:
                print(f"\n{label}: the identified patient per trial\n{table}")
    if args.csv:
        write_csv(args.csv, summaries, names)
        print(f"wrote {args.csv}")
    if args.json:
        config = bag_runs[0].provenance.config_values or {}
        write_json(args.json, config, summaries)
        print(f"wrote {args.json}")
    if args.config_out:
        Path(args.config_out).write_text(config_text or "")
        print(f"wrote {args.config_out}")
    if args.plot or args.trial is not None:
        if args.plot:
            plot_labels = [f"{label} ({r.law}, {100 * r.mass_uncertainty:g} %)"
                           for r, label in usable]
            figure = figures.convergence_figure(summaries, names, plot_labels)
            print(f"wrote {figures.save(figure, args.plot)}")
        if args.trial is not None:
            for run, label in zip(bag_runs, labels, strict=True):
                if run not in with_trial:
                    print(f"exo-ilc analyze: note: no tracking figure for {label}: it has no "
                          f"trial {args.trial} (recorded: {_trial_span(run)})", file=sys.stderr)
                    continue
                title = f"{label}: trial {args.trial}, {run.law}, mass uncertainty " \
                        f"{run.mass_uncertainty:g}"
                path = trial_figure_path(args.plot, args.trial, run.path, len(bag_runs) > 1)
                figure = figures.tracking_figure(run.trials[args.trial], run.joint_names, title,
                                         bound=run.error_bound)
                print(f"wrote {figures.save(figure, path)}")
    return 0


def _trial_span(run: BagRun) -> str:
    """``trials 1-5`` or ``no trial``."""
    trials = sorted(run.trials)
    if not trials:
        return "no trial"
    if trials == list(range(trials[0], trials[-1] + 1)):
        return f"trials {trials[0]}-{trials[-1]}" if len(trials) > 1 else f"trial {trials[0]}"
    return "trials " + ", ".join(map(str, trials))
