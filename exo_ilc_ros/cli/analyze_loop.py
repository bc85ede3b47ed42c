"""``exo-ilc analyze-loop``: the trial-to-trial factor of the learning law in the sampled loop."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.params import schema
from ..core.params.config import Config, load_config

if TYPE_CHECKING:
    from ..core.convergence.patient_ranges import RangeAnalysis

from .arguments import (
    add_mass_uncertainty_argument,
    config_with_flags,
    figure_file,
    input_file,
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
    parser.add_argument("--config", type=input_file, nargs="+", metavar="FILE",
                        help="ROS parameter YAML laid over the shipped config/exo_ilc.yaml "
                        "(any subset of keys); several are laid over in order (an arm file, "
                        "then a law: config/arms/ur5.yaml config/patient_aware.yaml)")
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
    parser.add_argument("--patient-ranges", action="store_true",
                        help="also the worst factor per joint over ranges of patients with the "
                        "patient in the loop (passive stiffness 0..--range-stiffness, viscous "
                        "0..--range-viscous, every MAS preset up to --range-mas, mass error "
                        "5 and 15 %%), each joint's inertia the lightest along the reference; "
                        "the law's own update, identification's inverse left out (the robust "
                        "case)")
    parser.add_argument("--range-stiffness", type=float, metavar="NM_PER_RAD",
                        help="largest passive stiffness (default: the ranges', 4 N m/rad)")
    parser.add_argument("--range-viscous", type=float, metavar="NMS_PER_RAD",
                        help="largest viscous friction (default: the ranges', 0.4 N m s/rad)")
    parser.add_argument("--range-mas", choices=schema.MAS_GRADES[1:], default="3",
                        help="highest MAS grade (its preset's stiffness and damping; default "
                        "%(default)s)")
    parser.add_argument("--range-reflex-delay", type=float, metavar="S", default=0.1,
                        help="the MAS presets' stretch reflex delay (s; default %(default)s, "
                        "SpasticMyoElbow's); a negative value leaves the reflex out")
    parser.add_argument("--plot", metavar="OUT.png", type=figure_file, help="plot |F| against "
                        "frequency (PNG); with several uncertainties, one file each "
                        "(OUT_d0.05.png, ...)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Analyse, print and plot."""
    from ..analysis.loop import format_analysis, format_robustness, plot_analysis
    from ..core.convergence.factors import analyze_loop
    from ..core.convergence.norm_optimal_robustness import robustness
    from ..core.convergence.patient_ranges import PatientRanges, analyze_patient_ranges
    from ..core.loop.patient import MAS_PRESETS
    flags: dict[str, tuple[str, Any]] = {}
    if args.cutoff is not None:
        flags.update({"q_filter.enabled": ("--cutoff", True),
                      "q_filter.cutoff_hz": ("--cutoff", args.cutoff)})
    files = args.config or [None]
    config = config_with_flags(files[0], flags, files[1:])
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
    if args.patient_ranges:
        grades = tuple(MAS_PRESETS)
        ranges = PatientRanges(
            PatientRanges.stiffness if args.range_stiffness is None else args.range_stiffness,
            PatientRanges.viscous if args.range_viscous is None else args.range_viscous,
            grades[:grades.index(args.range_mas) + 1],
            reflex_delay=max(0.0, args.range_reflex_delay),
            reflex=args.range_reflex_delay >= 0.0)
        print()
        print(format_ranges(analyze_patient_ranges(config, ranges)))
    return 0


def format_ranges(analysis: RangeAnalysis) -> str:
    """Per joint the worst factor over the ranges with the patient in the loop, its corner."""
    r = analysis.ranges
    lines = [f"with the patient in the loop, worst over passive stiffness 0-{r.stiffness:g} "
             f"N m/rad, viscous 0-{r.viscous:g} N m s/rad, MAS {', '.join(r.mas_grades)}, "
             f"mass error {', '.join(f'{d:g}' for d in r.mass_uncertainty)} (each joint's "
             "inertia the lightest along the reference, 1 / max (a_N^-1)_jj; the law's own "
             "update: identification's inverse and Coulomb friction left out; "
             + (f"the MAS presets' stretch reflex {r.reflex_delay:g} s late where the reference "
                "moves faster than its threshold):" if r.reflex else "the reflex left out):")]
    for j in analysis.joints:
        where = (f"K {j.stiffness:g} N m/rad, B {j.damping:g} N m s/rad"
                 + (f", reflex {j.reflex_gain:g} N m s/rad" if j.reflex_gain else "")
                 + f" (MAS {j.mas_grade}), delta {j.mass_uncertainty:g}") if j.patient else \
            f"no patient on this joint, delta {j.mass_uncertainty:g}"
        if j.unstable:
            lines.append(f"  {j.joint:<20} UNSTABLE within a trial: a pole at radius "
                         f"{j.radius:.4f}, {j.radius_hz:.2f} Hz ({where}; I >= "
                         f"{1.0 / j.inverse_inertia:.4g} kg m^2): the loop oscillates whatever "
                         "is learned" + (f"; G T / I {j.sampled_reflex:.2f} >= 1: no velocity "
                                         "feedback at this period holds it (a period below "
                                         f"I / G = {1e3 / (j.inverse_inertia * j.reflex_gain):.2g}"
                                         " ms, or damping inside the period, can; "
                                         "control.period_rule: reflex picks one)"
                                         if j.reflex_outruns_period else ""))
            continue
        lines.append(f"  {j.joint:<20} worst |F| {j.worst:.5f} at {j.frequency_hz:6.2f} Hz "
                     f"({where}; I >= {1.0 / j.inverse_inertia:.4g} kg m^2; without a patient "
                     f"{j.nominal:.5f})" + ("" if j.worst < 1.0 else "  the learned input can "
                                            "grow"))
    worst = analysis.worst()
    lines.append(f"worst over the ranges {worst:.5f} -> " + (
        "learning converges for every patient in the ranges" if worst < 1.0 else
        "some patient in the ranges makes the loop within a trial unstable"
        if any(j.unstable for j in analysis.joints) else
        "some patient in the ranges makes the learned input grow"))
    return "\n".join(lines)


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
        files = args.config or [None]
        load = patient_load(load_config(files[0], overlays=[*files[1:], path]), label)
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
