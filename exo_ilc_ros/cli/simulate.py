"""``exo-ilc simulate``: the experiment in-process (no ROS), with a table and optional JSON."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from ..core.errors import ConfigError
from ..core.params.config import Config
from .arguments import (
    add_config_argument,
    add_mass_uncertainty_argument,
    add_scenario_argument,
    config_with_flags,
    directory,
    integer,
    json_file,
    parameter,
)
from .progress import progress_bar
from .therapy import add_therapy_arguments, simulate_session, uses_therapy

if TYPE_CHECKING:
    from ..core.session.result import RunResult
    from ..core.session.summary import RunSummary


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """--config, --scenario, --mass-uncertainty, --trials, --law: shared by simulate and
    run."""
    add_config_argument(parser)
    add_scenario_argument(parser)
    add_mass_uncertainty_argument(parser, "plant mass uncertainty delta, one run each (default: "
                                  "the config's plant_simulator mass_uncertainty)")
    parser.add_argument("--trials", type=parameter("max_trials"),
                        help="trials per run (default: max_trials)")
    parser.add_argument("--law", choices=("sign", "linear", "norm_optimal"), help="learning law "
                        "(default: the config's law)")
    parser.add_argument("--json", metavar="OUT", type=json_file,
                        help="write the per-trial table as JSON")


def config_from_args(args: argparse.Namespace) -> Config:
    """The config the arguments name, with --law and --trials applied."""
    flags: dict[str, tuple[str, Any]] = {}
    if args.law:
        flags["law"] = ("--law", args.law)
    if args.trials is not None:
        flags["max_trials"] = ("--trials", args.trials)
    return config_with_flags(args.config, flags, args.scenario or [])


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser("simulate", help="run the experiment in-process (no ROS)",
                            description="Run K trials per mass uncertainty in-process and print "
                            "max |e| per trial and joint, and iterations to the bound.")
    add_config_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no per-trial table")
    parser.add_argument("--learned", action="store_true", help="also print per-trial tables "
                        "of max |u_ff| (learned feed-forward) and max |effort| per joint")
    parser.add_argument("--metrics", action="store_true", help="also compute every trial's "
                        "therapy metrics (required torque, SPARC smoothness ...) into --json's "
                        "runs[].metrics (a --patient session always computes them)")
    parser.add_argument("--bag-dir", dest="bag", metavar="DIR", type=directory,
                        help="also write each run as a rosbag2 bag DIR/<run-name>/ with the "
                        "graph's topics (what bag_recorder records; the flag of run and paper)")
    parser.add_argument("--bag", dest="bag_deprecated", metavar="DIR", type=directory,
                        help=argparse.SUPPRESS)  # the old name of --bag-dir
    parser.add_argument("--store", metavar="DIR", type=directory, help="save every trial and "
                        "the learned feed-forward to DIR (atomic writes, keyed by trajectory + "
                        "config)")
    parser.add_argument("--resume", action="store_true", help="with --store: continue each "
                        "run after the last trial stored (bit-identical to an uninterrupted run)")
    parser.add_argument("--spread", metavar="N", type=integer(2), help="also run each mass "
                        "uncertainty N times from initial states perturbed by 1e-12 rad and "
                        "print the iterations to the bound as median [min-max] (the sign law "
                        "amplifies last-bit differences; 20 is a good N)")
    parser.add_argument("--replay", metavar="BAG", help="run a recorded run again in-process: "
                        "the bag's config, mass uncertainty, trial count and live parameter "
                        "changes (at the trials they took effect), then compare every trial "
                        "with the bag (exit 1 if any differs)")

    add_therapy_arguments(parser)
    parser.set_defaults(func=simulate)


REPLAY_EXCLUDES = ("config", "scenario", "mass_uncertainty", "trials", "law", "store", "bag",
                   "patient", "spread")


def replay_bag(args: argparse.Namespace) -> int:
    """--replay BAG: the recorded run again, the report, and the comparison with the bag."""
    from ..bag import BagError, read_bag
    from ..bag.replay import replay
    from ..core.session.summary import RunSummary

    given = [f"--{name.replace('_', '-')}" for name in REPLAY_EXCLUDES
             if getattr(args, name) not in (None, False)]
    if given:
        print(f"exo-ilc simulate: error: --replay takes the run from the bag; drop "
              f"{', '.join(given)}", file=sys.stderr)
        return 2
    try:
        run = read_bag(args.replay)
        with progress_bar(total=max(run.completed, default=0), desc=f"replay {run.path.name}",
                          unit="trial") as bar:
            replayed = replay(run, on_trial=lambda record: bar.update(1))
    except BagError as exc:
        print(f"exo-ilc simulate: error: --replay {args.replay}: {exc}", file=sys.stderr)
        return 2
    plan = replayed.plan
    for note in plan.notes:
        print(f"note: {note}", file=sys.stderr)
    for trial, values in sorted(plan.changes.items()):
        print(f"live change from trial {trial}: " + ", ".join(
            f"{name} = {value}" for name, value in sorted(values.items())), file=sys.stderr)
    print_report(args, plan.config, [RunSummary.from_result(replayed.result)])
    print()
    if replayed.identical:
        print(f"replay of {run.path}: {replayed.compared} trials compared, identical to the "
              "recording (max |e|, max |u_ff|, max |effort| of every trial)")
        return 0
    print(f"replay of {run.path}: differs from the recording from trial "
          f"{replayed.first_different} on (largest difference {replayed.worst:.3e})")
    return 1


def simulate(args: argparse.Namespace) -> int:
    """Run and report (the bag writer and the therapy metrics imported only when asked for)."""
    from ..core.programs.divergences import add_divergences
    from ..core.session.learning_session import run_trials
    from ..core.session.summary import RunSummary
    if args.bag_deprecated is not None:
        if args.bag is not None:
            raise ConfigError("--bag", "is the old name of --bag-dir; give one of them")
        print("exo-ilc simulate: note: --bag is deprecated, use --bag-dir (the name run and "
              "paper use)", file=sys.stderr)
        args.bag = args.bag_deprecated
    if args.replay:
        return replay_bag(args)
    if args.resume and not args.store:
        print("exo-ilc simulate: error: --resume needs --store DIR", file=sys.stderr)
        return 2
    config = config_from_args(args)

    if uses_therapy(args):
        if args.spread:
            raise ConfigError("--spread", "runs the experiment again from perturbed states; a "
                              "therapy session (--patient) runs once")
        _, runs = simulate_session(args, config)
        print_report(args, config, runs)
        return aborted_exit(runs, "simulate")
    deltas = args.mass_uncertainty or [config["mass_uncertainty"]]
    trials = config["max_trials"]
    runs = []
    for delta in deltas:
        measured = config.with_mass_uncertainty(delta)  # the run's config, validated once
        with progress_bar(total=trials, desc=f"{config['law']} delta={delta:g}",
                          unit="trial") as bar:
            def progress(record: Any, bar: Any = bar) -> None:
                bar.update(1)
                bar.set_postfix_str("max|e| " + " ".join(f"{x:.1e}"
                                                         for x in record.max_abs_error))
            result = run_trials(measured, delta, trials, on_trial=progress, store=args.store,
                                resume=args.resume)
        runs.append(RunSummary.from_result(result))
        add_cuff_aborts(runs[-1], result, measured)
        add_identified(runs[-1], result, config["joint_names"])
        add_divergences(runs[-1], result, measured)
        if args.spread:
            runs[-1].extra["spread"] = _spread(config, delta, trials, args.spread)
        if args.metrics:  # the therapy metrics of every trial (core/programs/metrics.py)
            from ..core.programs.metrics import config_metrics

            runs[-1].extra["metrics"] = [config_metrics(r, measured).to_json()
                                         for r in result.records]
        for trial, notes in result.notes.items():
            for note in notes:
                print(f"delta {delta:g}, learning from trial {trial}: {note}", file=sys.stderr)
        if args.bag:
            from ..bag import run_name, unique_path, write_run

            path = unique_path(args.bag, run_name("sim", result.law, delta))
            print(f"bag: {write_run(path, config, result)}", file=sys.stderr)
    print_report(args, config, runs)
    return aborted_exit(runs, "simulate")


def format_cuff_forces(cuffs: Any, title: str) -> str:
    """The cuff forces of a run with a person strapped in: per cuff, the peak |force| of the
    first and the last trial and the highest of the run (N), and the last trial's RMS."""
    lines = [f"{title}: cuff forces on the person (N; peak |F| per trial)"]
    for c, cuff in enumerate(("upper arm", "forearm")):
        peaks = cuffs[:, c, 0]
        worst = int(peaks.argmax())
        lines.append(f"  {cuff:9}: trial 1 {peaks[0]:.1f}, trial {len(peaks)} {peaks[-1]:.1f} "
                     f"(RMS {cuffs[-1, c, 1]:.1f}), highest {peaks[worst]:.1f} (trial "
                     f"{worst + 1})")
    return "\n".join(lines)


def add_cuff_aborts(summary: RunSummary, result: RunResult, config: Config) -> None:
    """A person strapped in: the trials the cuff-force limit aborted (the first sample a cuff
    pressed past ``safety.cuff_force_limit`` is the abort sample) as
    ``summary.extra["cuff_limit_aborts"]`` (the JSON's and the warning's; nothing without)."""
    from ..core.person.cuffs import first_beyond_cuff_limit
    from ..core.session.summary import CUFF_LIMIT_ABORTS
    limit = [float(x) for x in config["safety.cuff_force_limit"]]
    pressed = [r.trial for r in result.records if r.aborted_at is not None and
               r.cuff_wrench is not None and
               first_beyond_cuff_limit(r.cuff_wrench, limit) == r.aborted_at]
    if pressed:
        summary.extra[CUFF_LIMIT_ABORTS] = pressed


def add_identified(summary: RunSummary, result: RunResult, names: list[str]) -> None:
    """The identification after the run's last trial as ``summary.extra["identified"]`` (the
    JSON's and the report's; nothing without ``identification.enabled``)."""
    from ..core.programs.identified import Identified
    if result.joint_forces:
        last = result.joint_forces[max(result.joint_forces)]
        summary.extra["identified"] = Identified.from_step(last, names).to_json()


def _spread(config: Config, delta: float, trials: int, count: int) -> dict[str, Any]:
    """--spread: the iterations to the bound of ``count`` perturbed runs, as JSON."""
    from ..core.programs.spread import iteration_spread
    with progress_bar(total=count, desc=f"spread delta={delta:g}", unit="run") as bar:
        spread = iteration_spread(config, delta, trials, count,
                                  on_run=lambda _: bar.update(1))
    return spread.to_json()


EXIT_ABORTED = 4
"""Exit code of ``simulate`` and ``run``: every run completed, but the error envelope aborted
trials (listed on stderr; each was learned from over the samples it had): not a clean run."""
EXIT_ABORT_STOP = 5
"""Exit code of ``simulate`` and ``run``: a run was stopped by aborted trials in a row
(``abort.max_consecutive``), a diverged plant or an abort that left nothing to learn; one
message names the joint, the time, the error and the likely cause (core/session/abort.py)."""


def aborted_exit(runs: list[RunSummary], command: str) -> int:
    """Say loudly which trials the error envelope aborted and which the plant's divergence
    stopped (those are not called envelope aborts), and once why a run stopped on them;
    :data:`EXIT_ABORT_STOP` if one did, else :data:`EXIT_ABORTED` if any trial aborted or
    diverged, else 0."""
    from ..analysis.report import run_title
    from ..core.loop.divergence import DIVERGED
    from ..core.session.abort import ABORT_STOP_KEY
    from ..core.session.summary import CUFF_LIMIT_ABORTS
    any_aborted = stopped = False
    for run in runs:
        diverged = run.extra.get(DIVERGED, [])
        for d in diverged:
            print(f"exo-ilc {command}: ERROR: {run_title(run)}: {d['message']}",
                  file=sys.stderr)
        any_aborted = any_aborted or bool(diverged)
        gone = {int(d["trial"]) for d in diverged}
        pressed = {int(k) for k in run.extra.get(CUFF_LIMIT_ABORTS, [])}
        aborted = [int(k) for k in run.extra.get("aborted_trials", []) if int(k) not in gone]
        for by, which in (("the error envelope (safety.error_envelope", [
                k for k in aborted if k not in pressed]), ("the cuff-force limit "
                "(safety.cuff_force_limit: a cuff pressed past it", [
                k for k in aborted if k in pressed])):
            if not which:
                continue
            any_aborted = True
            count = len(run.max_abs_error)
            share = "ALL" if len(which) == count else f"{len(which)} of {count}"
            print(f"exo-ilc {command}: WARNING: {run_title(run)}: {share} trials ABORTED by "
                  f"{by}; the robot held the arm there; each was learned from up to its "
                  f"abort): trial{'s' if len(which) > 1 else ''} {_spans(which)}",
                  file=sys.stderr)
        message = run.extra.get(ABORT_STOP_KEY)
        if message:
            stopped = True
            print(f"exo-ilc {command}: {run_title(run)}: {message}", file=sys.stderr)
    if stopped:
        print(f"exo-ilc {command}: exit {EXIT_ABORT_STOP}: a run was stopped by aborted trials "
              "(every trial, and what was learned from it, is kept)", file=sys.stderr)
        return EXIT_ABORT_STOP
    if any_aborted:
        what = "the plant diverged" if any(run.extra.get(DIVERGED) for run in runs) else \
            "trials were aborted"
        print(f"exo-ilc {command}: exit {EXIT_ABORTED}: {what} (check the mass "
              "uncertainty, the gains, the envelope and the integration step)", file=sys.stderr)
        return EXIT_ABORTED
    return 0


def _spans(trials: list[int]) -> str:
    """``1-5, 8`` from sorted trial numbers."""
    parts: list[str] = []
    start = previous = trials[0]
    for k in [*trials[1:], None]:
        if k is not None and k == previous + 1:
            previous = k
            continue
        parts.append(str(start) if start == previous else f"{start}-{previous}")
        if k is not None:
            start = previous = k
    return ", ".join(parts)


def print_report(args: argparse.Namespace, config: Config, runs: list[RunSummary]) -> None:
    """The per-trial table (unless --quiet; --learned adds max |u_ff| and max |effort|), the
    iterations to the bound, the long-run check, and --json: shared by simulate and run."""
    from ..analysis.report import (
        format_iterations,
        format_long_run,
        format_run_events,
        format_trial_table,
        run_title,
        write_json,
    )
    from ..core.learning.qfilter import feedforward_limit_of
    names = config["joint_names"]
    if not args.quiet:
        print(format_trial_table(runs, names))
        print()
    events = format_run_events(runs)
    if events:
        print(events)
        print()
    if args.learned:
        for quantity in ("feedforward", "effort"):
            print(format_trial_table(runs, names, quantity))
            print()
    print(format_iterations(runs, names))
    print()
    print(format_long_run(runs, names, limit=feedforward_limit_of(config)))
    for run in runs:
        if run.cuff_forces is not None:
            print()
            print(format_cuff_forces(run.cuff_forces, run_title(run)))
    for run in runs:
        if run.extra.get("identified"):  # (the identification's modules only for one)
            from ..analysis.identified import format_final
            from ..core.programs.identified import Identified

            print()
            print(format_final(Identified.from_json(run.extra["identified"]), run_title(run)))
    if args.json:
        write_json(args.json, config.values, runs)
        print(f"wrote {args.json}")
