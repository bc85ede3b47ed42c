"""``exo-ilc certify``: a law's certificate over a population of patients drawn from published
distributions (docs/every-patient.md), on any arm file, on the local process pool or a
Dask cluster like ``exo-ilc study``; optionally a falsification search for the worst patient."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from .arguments import (
    add_scenario_argument,
    figure_path,
    input_file,
    integer,
    json_file,
    nonempty,
    number,
    parameter,
    seed,
)
from .progress import progress_bar
from .tune import default_jobs

DEFAULT_TRIALS = 25
DEFAULT_WORST = 5
FAILED = 6
"""Exit status of a certificate that fails its criteria (docs/exit-codes.md)."""


def register(sub: Any) -> None:
    """Add the sub-command (no heavy imports here: the parser is built for every command)."""
    parser = sub.add_parser(
        "certify", help="a law's certificate over a population of patients (+ falsification)",
        description="Draw N patients from published distributions (passive stiffness and rest "
        "angle, friction, MAS grade, sensors, mass error, body size; with a person with "
        "muscles, musculoskeletal.model: MAS grade, misalignment, strap stiffness, mass error; "
        "docs/every-patient.md), "
        "run the law on each for K trials and print the certificate: shares bounded, within "
        "the bound by trial 10 / 25, with aborts; trials to the bound; the worst patients; "
        f"pass or fail against the certificate's criteria (exit status {FAILED} on fail). With "
        "--falsify, a CMA-ES search over the same ranges for the patient that fails worst.")
    parser.add_argument("--config", type=input_file, metavar="FILE",
                        help="the law or arm file laid over the shipped config (default: the "
                        "shipped config, the paper's arm and law)")
    add_scenario_argument(parser)
    parser.add_argument("--population", type=integer(1), default=48, metavar="N",
                        help="patients (default: 48)")
    parser.add_argument("--seed", type=seed, default=0, metavar="S",
                        help="the population's seed: patient i is drawn from (S, i) "
                        "(default: 0)")
    parser.add_argument("--trials", type=parameter("max_trials"), default=DEFAULT_TRIALS,
                        metavar="K", help=f"trials per patient (default: {DEFAULT_TRIALS})")
    parser.add_argument("--label", type=nonempty, metavar="NAME",
                        help="the law's name in the report (default: the last file's stem)")
    parser.add_argument("--encoder-share", type=number(0.0), metavar="P",
                        help="share of patients with a 14-bit encoder (default: 0.5; 0 with a "
                        "person with muscles, whose strapped plant has no sensor model)")
    parser.add_argument("--voluntary-share", type=number(0.0), default=0.0, metavar="P",
                        help="share of patients with voluntary effort and fatigue (default: 0)")
    parser.add_argument("--worst", type=integer(1), default=DEFAULT_WORST, metavar="W",
                        help=f"worst patients listed (default: {DEFAULT_WORST})")
    parser.add_argument("--rows", type=json_file, metavar="OUT.jsonl",
                        help="every patient's outcome, one line each as it finishes; run "
                        "again with the same file to run only the patients not yet in it "
                        "(default: OUT.rows.jsonl beside --json)")
    parser.add_argument("--json", metavar="OUT", type=json_file,
                        help="write the certificate as JSON")
    parser.add_argument("--figure", metavar="OUT.png", type=figure_path,
                        help="write the figure (trials to the bound, every patient's error)")
    parser.add_argument("--falsify", type=integer(0), default=0, metavar="BUDGET",
                        help="patients a CMA-ES search over the ranges runs for the worst "
                        "(default: 0, no search)")
    parser.add_argument("--falsify-dir", default="falsified", metavar="DIR",
                        help="where the worst patients found are written as scenario YAML "
                        "(default: falsified/)")
    parser.add_argument("--workers", type=integer(1), metavar="N",
                        help="local worker processes (default: the CPUs available)")
    parser.add_argument("--dask", metavar="ADDRESS", type=nonempty,
                        help="run the patients on a Dask distributed cluster, e.g. "
                        "tcp://host:8786 (docs/study.md)")
    parser.set_defaults(func=certify)


def certify(args: argparse.Namespace) -> int:
    """Draw the population, run it, print the certificate; JSON, figure, falsification."""
    from ..analysis import figures
    from ..analysis.certificate import (
        certificate_figure,
        certificate_json,
        format_certificate,
        run_population,
        write_scenario,
    )
    from ..analysis.falsification import Pool, Search, falsification_json, falsify
    from ..core.errors import ConfigError
    from ..core.loop.rate import with_control_rate
    from ..core.params.config import load_config
    from ..core.params.redact import redact
    from ..core.population.certificate import (
        PatientOutcome,
        certificate,
        patient_cell,
        patient_config,
    )
    from ..core.population.distributions import (
        PopulationSpec,
        draw_population,
        has_muscles,
        search_point,
    )

    if args.dask and args.workers is not None:
        raise ConfigError("--workers", "applies to the local process pool; with --dask the "
                          "cluster's workers run the patients")
    overlays = list(args.scenario or [])
    base = with_control_rate(load_config(args.config, overlays=overlays))
    muscles = has_muscles(base)
    if args.encoder_share is None:
        args.encoder_share = 0.0 if muscles else 0.5
    for flag in ("encoder_share", "voluntary_share"):
        if getattr(args, flag) > 1.0:
            raise ConfigError(f"--{flag.replace('_', '-')}", f"is a share in [0, 1], got "
                              f"{getattr(args, flag)}")
        if muscles and getattr(args, flag) > 0.0:
            raise ConfigError(f"--{flag.replace('_', '-')}", "is not drawn for a person with "
                              "muscles (musculoskeletal.model): the strapped plant has no "
                              "sensor model and the virtual patient's voluntary effort is "
                              "refused there; give 0")
    label = args.label or Path((overlays or [args.config or "exo_ilc.yaml"])[-1]).stem
    spec = PopulationSpec(encoder_share=args.encoder_share,
                          voluntary_share=args.voluntary_share)
    patients = draw_population(base, spec, args.population, args.seed)
    cells = [patient_cell(label, patient_config(base, p, args.trials), p)
             for p in patients]
    workers = args.workers or default_jobs()
    where = f"the Dask cluster at {redact(args.dask)}" if args.dask else \
        f"{min(workers, len(cells))} local process(es)"
    print(f"certify {label}: {args.population} patients (seed {args.seed}) x {args.trials} "
          f"trials on {base.joints} joints at {1e3 * base['control.period']:g} ms "
          f"(control.period_rule {base['control.period_rule']}), on {where}", file=sys.stderr)
    # The law's digest: a rows file of the same files after the law changed is refused, not
    # resumed with its patients run under another law.
    setup = {"label": label, "config": args.config, "overlays": overlays,
             "law": base.digest(), "population": args.population, "seed": args.seed,
             "trials": args.trials, "encoder_share": args.encoder_share,
             "voluntary_share": args.voluntary_share}
    rows = Path(args.rows) if args.rows else \
        (Path(args.json).with_suffix(".rows.jsonl") if args.json else None)
    with progress_bar(total=len(cells), desc="certify", unit="patient") as bar:
        def done(outcome: PatientOutcome) -> None:
            bar.update(1)
            bar.set_postfix_str(f"#{outcome.index}")
        outcomes = run_population(cells, args.trials, workers, args.dask, rows, setup, done)
    cert = certificate(label, args.population, args.trials, float(base["error_bound"]),
                       outcomes)
    by_index = {p.index: p for p in patients}
    print(format_certificate(cert, by_index, args.worst))
    if rows is not None:
        print(f"every patient's outcome: {rows}")
    falsification = None
    if args.falsify:
        worst = cert.worst(1)
        start = search_point(by_index[worst[0].index], spec) if worst else None
        with progress_bar(total=args.falsify, desc="falsify", unit="patient") as bar:
            found = falsify(base, spec, label, args.trials,
                            Search(args.falsify, args.seed, start), Pool(workers, args.dask),
                            lambda f: bar.update(1))
        written = []
        for rank, item in enumerate(found[:args.worst], start=1):
            path = Path(args.falsify_dir) / f"{label}_worst{rank}.yaml"
            header = (f"Found by exo-ilc certify --falsify {args.falsify} (seed {args.seed}) "
                      f"for {label}: score {item.score:.3f} over {args.trials} trials\n"
                      f"{item.patient.describe()}\n"
                      f"Outcome: {item.outcome.aborts} aborted trials, final true max |e| "
                      f"{item.outcome.final_error:.3e} rad, settled "
                      f"{item.outcome.settled}.\nA scenario overlay: laid over the same "
                      "config (docs/every-patient.md).")
            written.append(str(write_scenario(path, item.patient, header)))
        print(f"Falsification ({args.falsify} patients, CMA-ES from the worst of the "
              f"{len(cert.outcomes)} drawn patients):")
        for item in found[:args.worst]:
            o = item.outcome
            final = f"{o.final_error:.2e} rad" if o.finite else "not finite"
            print(f"  score {item.score:.3f}: {o.aborts} aborts, final {final}, settled "
                  f"{o.settled}; {item.patient.describe()}")
        for name in written:
            print(f"wrote {name}")
        falsification = falsification_json(found, args.falsify, args.trials, written,
                                           args.worst)
    if args.json:
        Path(args.json).write_text(json.dumps(certificate_json(
            cert, setup, by_index, args.worst, falsification)) + "\n")
        print(f"wrote {args.json}")
    if args.figure:
        print(f"wrote {figures.save(certificate_figure(cert), args.figure)}")
    return 0 if cert.passes else FAILED
