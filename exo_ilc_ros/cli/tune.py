"""``exo-ilc tune``: search the sign law's thresholds and levels with Optuna, write a ROS YAML."""

from __future__ import annotations

import argparse
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..analysis.wording import count_phrase
from ..core.errors import ConfigError
from ..core.params.config import load_config
from ..core.params.redact import redact
from .arguments import (
    add_config_argument,
    add_mass_uncertainty_argument,
    add_scenario_argument,
    at_least_two_trials,
    integer,
    nonempty,
    number,
    parameter,
    seed,
    shown_command,
    storage,
    yaml_out,
)
from .progress import progress_bar

if TYPE_CHECKING:
    import optuna

    from ..analysis.tuning import RunScore, TuningResult

DEFAULT_STORAGE = ".exo-ilc/tune.journal"
DEFAULT_OUT_DIR = ".exo-ilc/tuned"
"""Where a tuning result goes without ``--out``: under the git-ignored ``.exo-ilc/``, never over
the tracked ``config/tuned.yaml`` (which ``exo-ilc compare`` shows by default)."""


def default_out(study_name: str) -> Path:
    """``.exo-ilc/tuned/<study-name>.yaml`` (characters other than letters, digits, ``._-``
    replaced by ``_``)."""
    safe = re.sub(r"[^A-Za-z0-9._-]", "_", study_name).lstrip(".") or "study"
    return Path(DEFAULT_OUT_DIR) / f"{safe}.yaml"


def default_jobs() -> int:
    """The CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "tune", help="auto-tune the sign law's thresholds and levels (Optuna)",
        description="Search the sign law's step schedules (eqs (22)-(24), per joint) to minimise "
        "the trial from which every joint stays within the bound, worst case over the mass "
        "uncertainties, plus a penalty for peak error. Resumable; several machines can share "
        "one study through --storage.")
    add_config_argument(parser, "ROS parameter YAML laid over the shipped config; its "
                        "schedules are the starting point (trial 0)")
    add_scenario_argument(parser)
    add_mass_uncertainty_argument(parser, "uncertainties scored at once (default: 0.05 0.10 "
                                  "0.15)", [0.05, 0.10, 0.15])
    parser.add_argument("--trials", type=parameter("max_trials", at_least_two_trials),
                        help="trials per run (default: max_trials)")
    parser.add_argument("--budget", type=integer(0), default=60,
                        help="Optuna trials to add to the study in this call (default: 60)")
    parser.add_argument("--out", metavar="FILE", type=yaml_out,
                        help="tuned ROS parameter YAML (default: "
                        f"{DEFAULT_OUT_DIR}/<study-name>.yaml, which git ignores; the shipped "
                        "config/tuned.yaml is only written when named here)")
    parser.add_argument("--storage", default=DEFAULT_STORAGE, type=storage,
                        help="Optuna storage: a journal file path (default: "
                        f"{DEFAULT_STORAGE}) or an RDB URL (sqlite:///f.db, "
                        "postgresql://user@host/db)")
    parser.add_argument("--study-name", type=nonempty, help="study to create or resume "
                        "(default: a digest of the problem, so the same command resumes the "
                        "same study)")
    parser.add_argument("--jobs", type=integer(1), default=default_jobs(),
                        help="parallel worker processes (default: the CPUs available)")
    parser.add_argument("--peak-weight", type=number(0.0), default=20.0,
                        help="iterations charged per 100%% of peak error above trial 1's "
                        "(default: 20)")
    parser.add_argument("--aggregate", choices=("max", "mean"), default="max",
                        help="combine the uncertainties' scores by worst case or mean")
    parser.add_argument("--seed", type=seed, help="sampler seed (reproducible with --jobs 1)")
    parser.add_argument("--law", choices=("sign", "norm_optimal"), default="sign",
                        help="what to tune: the sign law's schedules (default) or the "
                        "norm-optimal law's input-change weights and model delta_m")
    parser.set_defaults(func=tune)


def _fmt(x: int | None) -> str:
    return "-" if x is None else str(x)


def format_before_after(result: TuningResult, joint_names: Sequence[str]) -> str:
    """Scores of the starting schedules (trial 0) and of the best, per uncertainty."""
    cell = max([len(n) + 2 for n in joint_names] + [18])  # whole joint names
    header = (f"{'':<8}{'delta':>6}  " + "".join(f"{n:>{cell}}" for n in joint_names)
              + f"{'peak':>10}{'floor':>10}{'score':>8}")
    lines = ["First within / settled within the bound (trial, per joint), peak and final "
             "max |e| (rad), score", header, "-" * len(header)]

    def rows(label: str, runs: list[RunScore]) -> None:
        for r in runs:
            cells = "".join(f"{_fmt(f) + ' / ' + _fmt(s):>{cell}}"
                            for f, s in zip(r.first, r.settled, strict=True))
            lines.append(f"{label:<8}{r.mass_uncertainty:>6.2f}  {cells}{r.peak_error:>10.2e}"
                         f"{r.floor:>10.2e}{r.score:>8.1f}" + ("  diverged" if r.diverged else ""))

    rows("before", result.baseline_runs)
    rows("after", result.best_runs)
    before = "-" if result.baseline_value is None else f"{result.baseline_value:.1f}"
    lines.append(f"objective: before {before}, after {result.best_value:.1f} "
                 f"({result.completed} completed trials in study {result.study_name})")
    return "\n".join(lines)


def tune(args: argparse.Namespace) -> int:
    """Run the study, print before/after, write the tuned YAML."""
    from ..analysis.tuning import TuningProblem, best_result, optimize
    from ..core.loop.rate import with_control_rate
    config = with_control_rate(load_config(args.config, overlays=args.scenario or []))
    trials = int(args.trials if args.trials is not None else config["max_trials"])
    problem = TuningProblem.from_config(config, args.mass_uncertainty, trials,
                                        args.peak_weight, args.aggregate, args.law)
    name = args.study_name or problem.default_study_name()
    more = count_phrase(args.budget, "more trial")
    deltas = count_phrase(len(problem.mass_uncertainties), "uncertainty")
    print(f"study {name} in {redact(args.storage)}: {more} on {count_phrase(args.jobs, 'job')}, "
          f"{count_phrase(trials, 'trial')} x {deltas}"
          " each")
    with progress_bar(total=args.budget, desc="tune", unit="trial") as bar:
        start: list[int] = []

        def progress(study: optuna.Study) -> None:
            done = [t for t in study.get_trials(deepcopy=False) if t.state.is_finished()]
            if not start:
                start.append(len(done))
            bar.n = min(args.budget, len(done) - start[0])
            values = [t.value for t in done if t.value is not None]
            if values:
                bar.set_postfix_str(f"best {min(values):.1f}")
            bar.refresh()

        study = optimize(problem, args.storage, args.budget, args.jobs, name, args.seed,
                         progress)
    result = best_result(study, problem)
    print(format_before_after(result, config["joint_names"]))
    tuned = result.config.replace({"law": args.law})
    out = Path(args.out) if args.out else default_out(name)
    out.parent.mkdir(parents=True, exist_ok=True)
    deltas = " ".join(f"{d:g}" for d in problem.mass_uncertainties)
    what = "Sign-law schedules" if args.law == "sign" else "Norm-optimal weights and model"
    header = (f"{what} tuned by `exo-ilc tune` (Optuna study {name}, storage "
              f"{redact(args.storage)}).\n"
              f"Objective {result.best_value:.1f} (starting schedules: "
              f"{'-' if result.baseline_value is None else f'{result.baseline_value:.1f}'}): "
              f"worst trial from which every joint stays within the bound over delta = {deltas},"
              f" {trials} trials each, + {problem.peak_weight:g} per 100 % peak overshoot.\n"
              f"Use: {shown_command()} simulate --config THIS_FILE, or --params-file THIS_FILE "
              "for the nodes.")
    out.write_text(tuned.to_ros_yaml(header))
    if load_config(out).values != tuned.values:
        raise ConfigError("<file>", "the written tuned config does not read back unchanged",
                          str(out))
    print(f"wrote {out}")
    program = shown_command()
    print(f"use it with: {program} simulate --config {out}; {program} compare --tuned {out}")
    return 0
