"""``exo-ilc study``: which law survives which patient. Every law x scenario x mass uncertainty x
seed is one cell, run in-process on a local process pool (or a Dask cluster with ``--dask``);
one table, optionally JSON and one figure."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from ..analysis.wording import count_phrase
from ..core.errors import ConfigError
from ..core.params.redact import redact
from ..core.programs.shipped_laws import SHIPPED_LAWS
from .arguments import (
    add_mass_uncertainty_argument,
    figure_path,
    integer,
    json_file,
    nonempty,
    parameter,
    seed,
)
from .progress import progress_bar
from .tune import default_jobs

if TYPE_CHECKING:
    from ..core.programs.study import StudyCell

DEFAULT_LAWS = ("sign", "tuned", "linear", "robust", "norm_optimal")
DEFAULT_TRIALS = 1000


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "study", help="robustness study: every law x patient scenario x uncertainty x seed",
        description="Run every law x scenario x mass uncertainty x seed in-process (one cell "
        "each) and print one table: first and settled trial within the bound, settled floor of "
        "the true error, bounded or growing, peak effort, share at the effort limit, envelope "
        "aborts. Cells run on a local process pool, or on a Dask cluster with --dask.")
    parser.add_argument("--laws", nargs="+", type=nonempty, default=list(DEFAULT_LAWS),
                        metavar="LAW", help="shipped names (" + ", ".join(SHIPPED_LAWS)
                        + "), config files laid over the shipped config, or LABEL=FILE "
                        "(default: " + " ".join(DEFAULT_LAWS) + ")")
    parser.add_argument("--scenarios", nargs="+", type=nonempty, metavar="SCENARIO",
                        help="shipped scenarios (config/scenarios/NAME.yaml), overlay files, "
                        "or LABEL=FILE (default: every shipped scenario)")
    add_mass_uncertainty_argument(parser, "default: 0.05 0.10 0.15", [0.05, 0.10, 0.15])
    parser.add_argument("--trials", type=parameter("max_trials"), default=DEFAULT_TRIALS,
                        metavar="K", help=f"trials per cell (default: {DEFAULT_TRIALS})")
    parser.add_argument("--seeds", type=integer(1), default=1, metavar="S",
                        help="patient seeds per cell: FIRST .. FIRST+S-1 (default: 1)")
    parser.add_argument("--first-seed", type=seed, default=0, metavar="FIRST",
                        help="the first patient seed (default: 0)")
    parser.add_argument("--json", metavar="OUT", type=json_file,
                        help="write the rows and every cell's per-trial tables as JSON")
    parser.add_argument("--figure", metavar="OUT.png", type=figure_path,
                        help="write the heatmap of the settled floor (format from the suffix)")
    parser.add_argument("--workers", type=integer(1), metavar="N",
                        help="local worker processes (default: the CPUs available)")
    parser.add_argument("--dask", metavar="ADDRESS", type=nonempty,
                        help="run the cells on a Dask distributed cluster, e.g. "
                        "tcp://host:8786 (docs/study.md: how to start a scheduler and workers)")
    parser.set_defaults(func=study)


def study(args: argparse.Namespace) -> int:
    """Build the cells, run them, print the table, write JSON and figure."""
    from ..analysis import figures
    from ..analysis.study import format_study_table, run_cells, write_study_json
    from ..analysis.study_figure import study_figure
    from ..core.programs.study import resolve_law, resolve_scenario, shipped_scenarios, study_cells
    from ..core.programs.study_rows import study_rows
    if args.dask and args.workers is not None:
        raise ConfigError("--workers", "applies to the local process pool; with --dask the "
                          "cluster's workers run the cells (start them with --nworkers)")
    laws = [resolve_law(text) for text in args.laws]
    scenarios = [resolve_scenario(text) for text in (args.scenarios or shipped_scenarios())]
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    cells = study_cells(laws, scenarios, args.mass_uncertainty, seeds, args.trials)
    workers = args.workers or default_jobs()
    where = f"the Dask cluster at {redact(args.dask)}" if args.dask else \
        f"{min(workers, len(cells))} local process(es)"
    print(f"study: {count_phrase(len(laws), 'law')} x {count_phrase(len(scenarios), 'scenario')} x "
          f"{count_phrase(len(args.mass_uncertainty), 'uncertainty')} x "
          f"{count_phrase(len(seeds), 'seed')} = {count_phrase(len(cells), 'cell')} of "
          f"{count_phrase(args.trials, 'trial')} on {where}", file=sys.stderr)
    for law in laws:
        print(f"  law {law.describe()}", file=sys.stderr)
    with progress_bar(total=len(cells), desc="study", unit="cell") as bar:
        def done(cell: StudyCell) -> None:
            bar.update(1)
            bar.set_postfix_str(cell.label)
        results = run_cells(cells, workers, args.dask, done)
    rows = study_rows(results, args.trials)
    print(format_study_table(rows))
    if args.json:
        setup = {"laws": {law.label: law.describe() for law in laws},
                 "scenarios": {s.label: str(s.path) for s in scenarios},
                 "mass_uncertainty": list(args.mass_uncertainty), "trials": args.trials,
                 "seeds": seeds}
        write_study_json(args.json, setup, rows, results)
        print(f"wrote {args.json}")
    if args.figure:
        print(f"wrote {figures.save(study_figure(rows), args.figure)}")
    return 0
