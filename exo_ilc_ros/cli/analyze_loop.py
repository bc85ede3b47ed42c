"""``exo-ilc analyze-loop``: the trial-to-trial factor of the learning law in the sampled loop."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..core.params.config import Config, load_config
from .arguments import (
    add_config_argument,
    add_mass_uncertainty_argument,
    config_with_flags,
    figure_file,
    integer,
    parameter,
    scenario,
)


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "analyze-loop", help="trial-to-trial convergence factor per joint and frequency",
        description="Linearise the closed loop (computed torque + PD + zero-order hold at the "
        "control period) around the reference and print, per joint, the worst trial-to-trial "
        "factor |F| of the learning law and the band where |F| > 1 (the learned input grows "
        "there), without and with the Q-filter. See docs/convergence.md.")
    add_config_argument(parser)
    parser.add_argument("--law", choices=("sign", "linear", "norm_optimal"),
                        help="learning law (default: the config's law)")
    add_mass_uncertainty_argument(parser, "plant mass uncertainty delta, one analysis each "
                                  "(default: the config's)")
    parser.add_argument("--cutoff", type=parameter("q_filter.cutoff_hz"), metavar="HZ",
                        help="analyse with this Q-filter cut-off (Hz) instead of the config's, "
                        "enabling the filter")
    parser.add_argument("--lifted", type=integer(0), metavar="K", default=0,
                        help="also check the finite trial exactly: spectral radius and growth "
                        "over K trials of the lifted (N+1)x(N+1) map (slower)")
    parser.add_argument("--scenarios", type=scenario, nargs="+", metavar="NAME|FILE",
                        help="also analyse against these virtual patients' arms (their linear "
                        "joint forces: stiffness and damping, passive, spastic and their own "
                        "pull; shipped names or files) and say which the law is robust to; "
                        "with the config's identification in the loop its update inverts them "
                        "(taken as identified exactly)")
    parser.add_argument("--plot", metavar="OUT.png", type=figure_file, help="plot |F| against "
                        "frequency (PNG); with several uncertainties, one file each "
                        "(OUT_d0.05.png, ...)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Analyse, print and plot."""
    from ..analysis.loop import format_analysis, format_robustness, plot_analysis
    from ..core.convergence.factors import analyze_loop
    from ..core.convergence.norm_optimal_robustness import robustness
    flags: dict[str, tuple[str, Any]] = {}
    if args.cutoff is not None:
        flags.update({"q_filter.enabled": ("--cutoff", True),
                      "q_filter.cutoff_hz": ("--cutoff", args.cutoff)})
    config = config_with_flags(args.config, flags)
    deltas = args.mass_uncertainty or [config["mass_uncertainty"]]
    worst = 0.0
    for i, delta in enumerate(deltas):
        analysis = analyze_loop(config.with_mass_uncertainty(delta), args.law,
                                lifted_trials=args.lifted)
        if i:
            print()
        print(format_analysis(analysis))
        worst = max(worst, analysis.worst(filtered=analysis.qfilter is not None))
        if args.plot:
            path = args.plot
            if len(deltas) > 1:
                stem, dot, ext = path.rpartition(".")
                path = f"{stem}_d{delta:g}.{ext}" if dot else f"{path}_d{delta:g}"
            plot_analysis(analysis, path)
            print(f"wrote {path}")
    label = "with the configured Q-filter" if config["q_filter.enabled"] or args.cutoff \
        else "(Q-filter off)"
    print(f"\nworst trial-to-trial factor {label}: {worst:.5f} -> "
          + ("learning stays bounded" if worst <= 1.0 + 1e-9 else "the learned input can grow"))
    if (args.law or config["law"]) == "norm_optimal" and config["assist_as_needed.enabled"]:
        print("note: assist-as-needed is on, but the norm-optimal factor above does not include "
              "it (its forgetting multiplies the memory term: inside the deadband |F| = f)")
    if (args.law or config["law"]) == "norm_optimal":
        report = robustness(config)
        print()
        print(format_robustness(report))
    if args.scenarios:
        print()
        print(_patients(args, config, deltas))
    return 0


def _patients(args: argparse.Namespace, config: Config, deltas: list[float]) -> str:
    """One line per scenario and delta: the worst factor against that patient's arm."""
    from ..core.convergence.factors import analyze_loop
    from ..core.convergence.patient_load import patient_load
    inverted = config["identification.enabled"] and config["identification.in_loop"]
    how = (", the model rebuilt about them" if (args.law or config["law"]) == "norm_optimal"
           else ", the update inverting them") if inverted else ""
    lines = ["against the patients' arms (their linear joint forces; Coulomb friction and the "
             f"reflex left out: `exo-ilc study` has the nonlinear answer){how}:"]
    robust: list[str] = []
    not_robust: list[str] = []
    for path in args.scenarios:
        label = Path(path).stem
        load = patient_load(load_config(args.config, overlays=[path]), label)
        worst = 0.0
        for delta in deltas:
            analysis = analyze_loop(config.with_mass_uncertainty(delta), args.law, patient=load,
                                    lifted_trials=args.lifted)
            factor = analysis.worst(filtered=analysis.qfilter is not None)
            worst = max(worst, factor)
            lines.append(f"  {label:<12} delta {delta:<5g} worst |F| {factor:.5f}"
                         + ("" if factor <= 1.0 + 1e-9 else "  the learned input can grow"))
        (robust if worst <= 1.0 + 1e-9 else not_robust).append(label)
    lines.append("bounded for: " + (", ".join(robust) or "none") + "; can grow for: "
                 + (", ".join(not_robust) or "none"))
    return "\n".join(lines)
