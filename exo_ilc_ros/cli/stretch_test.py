"""``exo-ilc stretch-test``: ramp-and-hold extension of the person's elbow per MAS preset and
velocity (McPherson et al. 2018), printing resistance, reflex stiffness and threshold angle."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from ..core.params.schema import MAS_GRADES
from .arguments import add_config_argument, figure_path, json_file, number

MODELS = ("myoelbow", "myoarm")
"""The person models the test runs on (core/person/model.py): MyoSuite's small elbow (two
degrees of freedom, six muscles) and MyoArm's pruned right arm."""


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "stretch-test", help="stretch the person's elbow per MAS preset and velocity: "
        "resistance, reflex stiffness, threshold angle",
        description="Ramp-and-hold extension of the musculoskeletal person's elbow (120 -> 20 "
        "deg flexion, arm supported, no exoskeleton) at each velocity, as McPherson et al. "
        "2018 did, with each MAS grade's neural drive: the peak resistance torque, the reflex "
        "torque's peak, its torque-angle slope (reflex stiffness) and the reflex threshold "
        "angle. The reflex delay and spastic muscles come from the config (person.drive.*); "
        "custom runs the config's own drive. See docs/stretch-test.md.")
    add_config_argument(parser, "ROS parameter YAML over the shipped config: its person.drive "
                        "keys (delay, spastic muscles; custom: the whole drive)")
    parser.add_argument("--model", choices=MODELS, default="myoelbow",
                        help="the person's model: myoelbow (MyoSuite's small elbow, the "
                        "default, fast) or myoarm (MyoArm's right arm, shoulder held)")
    parser.add_argument("--grades", nargs="+", choices=MAS_GRADES,
                        default=["0", "1", "1+", "2", "3"], metavar="GRADE",
                        help="MAS presets to stretch (0 1 1+ 2 3; custom: the config's drive; "
                        "default: all five presets)")
    parser.add_argument("--velocities", nargs="+", metavar="DEG_S",
                        type=number(strictly_positive=True, why=" (deg/s)"),
                        default=[15.0, 30.0, 60.0, 90.0, 120.0, 150.0],
                        help="stretch velocities in deg/s (default: 15 30 60 90 120 150)")
    parser.add_argument("--json", metavar="OUT", type=json_file,
                        help="also write the measures as JSON")
    parser.add_argument("--plot", metavar="OUT.png", type=figure_path,
                        help="figure: reflex stiffness and threshold angle against velocity, "
                        "one line per grade")
    parser.set_defaults(func=stretch_test_command)


def stretch_test_command(args: argparse.Namespace) -> int:
    """Run the test, print the table, write the JSON and the figure."""
    from ..core.params.config import load_config
    from ..core.person.neural_drive import drive_settings
    from ..core.person.stretch_test import stretch_person, stretch_test
    config = load_config(args.config)
    base = drive_settings(config)
    person = stretch_person(args.model)
    result = stretch_test(person, base, args.grades, args.velocities)
    measures = result.measures
    print(f"stretch test: {person.name}, 120 -> 20 deg flexion, reflex delay {base.delay:g} s, "
          f"spastic muscles {', '.join(base.spastic_muscles) or 'none'}")
    print(f"{'MAS':>6} {'deg/s':>6} {'resist N m':>10} {'reflex N m':>10} "
          f"{'K N m/rad':>10} {'threshold deg':>13} {'onset - crossing s':>18}")
    for m in measures:
        threshold = "-" if m.threshold_angle is None else f"{m.threshold_angle:.1f}"
        lag = "-" if m.onset_time is None or m.crossing_time is None else \
            f"{m.onset_time - m.crossing_time:.3f}"
        print(f"{m.grade:>6} {m.velocity:6.0f} {m.resistance:10.2f} {m.reflex_peak:10.2f} "
              f"{m.stiffness:10.2f} {threshold:>13} {lag:>18}")
    print("spring-damper over each grade's stretches (McCrea et al. 2003: tau = K (theta - "
          "theta_0) + B thetadot)")
    print(f"{'MAS':>6} {'K N m/rad':>10} {'B N m s/rad':>12} {'theta_0 deg':>12} {'r2':>6}")
    for grade, fit in result.spring_dampers.items():
        print(f"{grade:>6} {fit.stiffness:10.2f} {fit.damping:12.3f} {fit.offset_angle:12.1f} "
              f"{fit.r2:6.3f}")
    if args.json:
        document = {"model": person.name, "reflex_delay": base.delay,
                    "spastic_muscles": list(base.spastic_muscles),
                    "start_deg": 120.0, "end_deg": 20.0,
                    "measures": [m.as_dict() for m in measures],
                    "spring_dampers": {grade: fit.__dict__
                                       for grade, fit in result.spring_dampers.items()}}
        Path(args.json).write_text(json.dumps(document, indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        from ..analysis.figures import save
        from ..analysis.stretch_figure import stretch_figure
        save(stretch_figure(measures), args.plot)
        print(f"wrote {args.plot}")
    return 0

