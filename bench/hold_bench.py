"""The safe hold before and after ``safety.hold_*``: does the arm come to rest after an abort?

Run with ``.venv/bin/python -m bench.hold_bench`` (about 1-2 min on the shared machine). For
each law (sign, tuned, linear) x patient scenario at 10 % (and ``spastic`` at MAS 3) it runs
the study's cell up to its first envelope abort and replays that trial with the hold on the
controller's gains (``old``: the hold before ``safety.hold_*``) and with the shipped hold
(``new``); then the same for aborts provoked under ``spastic`` by a constant feed-forward on
one joint, and the hold's discrete-time decay rate at 0.001-0.01 s. Prints the numbers of
docs/safety.md "The safe hold"; asserts nothing.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from exo_ilc_ros.core.loop.hold import rest_after_abort
from exo_ilc_ros.core.loop.record import TrialRecord
from exo_ilc_ros.core.params.config import Config, load_config, scenario_path
from exo_ilc_ros.core.params.hold_rule import hold_radius
from exo_ilc_ros.core.programs.study import resolve_law, resolve_scenario, study_cells
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.core.sim.experiment import Experiment

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # no node here; house rule

OLD = {"safety.hold_kp": [16.0, 10.0, 10.0], "safety.hold_kd": [8.0, 5.0, 7.0],
       "safety.hold_ramp": 0.0}
"""The hold before ``safety.hold_*``: the controller's gains, no ramp."""


class _FirstAbortError(Exception):
    def __init__(self, record: TrialRecord) -> None:
        super().__init__(record.trial)
        self.record = record


def first_abort(values: dict[str, Any], trials: int) -> TrialRecord | None:
    """The first trial the envelope aborts in this cell (None: none within ``trials``)."""
    def on_trial(record: TrialRecord) -> None:
        if record.aborted:
            raise _FirstAbortError(record)
    try:
        run_trials(Config({**values, "max_trials": trials}, "hold bench"), on_trial=on_trial)
    except _FirstAbortError as stop:
        return stop.record
    return None


def line(label: str, ex: Experiment, record: TrialRecord) -> str:
    r = rest_after_abort(record, ex.period)
    rest = f"{r.time_to_rest:5.2f} s" if r.at_rest else "  never"
    return (f"{label:34s} abort {record.aborted_at:3d}  |qd| at abort {r.speed_at_abort:5.2f}  "
            f"peak {r.peak_speed:5.2f}  after 1 s {r.late_peak_speed:5.2f} rad/s  rest {rest}  "
            f"braking {r.braking:.2f}  end {r.final_offset:.2f} rad  effort {r.peak_effort:4.1f} "
            f"/ after 1 s {r.late_effort:4.1f} N m")


def replay(label: str, values: dict[str, Any], record: TrialRecord) -> None:
    for name, extra in (("old", OLD), ("new", {})):
        ex = Experiment(Config({**values, **extra}, "hold bench"))
        again = ex.run_trial(record.feedforward, record.trial)
        print(line(f"{label} {name}", ex, again))


def main() -> None:
    """Print the numbers."""
    print("Study cells at 10 %, their first envelope abort replayed with each hold "
          "(true state; rest: every |qdot| < 0.05 rad/s to the trial's end):")
    for law in ("sign", "tuned", "linear"):
        for scenario in ("spastic", "realistic", "voluntary", "friction", "sensor"):
            [cell] = study_cells([resolve_law(law)], [resolve_scenario(scenario)], [0.1], [0],
                                 1000)
            record = first_abort(cell.values, 1000)
            if record is None:
                print(f"{law} / {scenario}: no abort in 1000 trials")
                continue
            replay(f"{law}/{scenario} trial {record.trial}", cell.values, record)
    print("\nspastic at Modified Ashworth 3 (not covered by the shipped hold):")
    for law in ("sign", "linear"):
        [cell] = study_cells([resolve_law(law)], [resolve_scenario("spastic")], [0.1], [0], 1000)
        values = {**cell.values, "patient.spasticity.mas_grade": "3"}
        record = first_abort(values, 1000)
        if record is not None:
            replay(f"{law}/MAS 3 trial {record.trial}", values, record)
    print("\nspastic (MAS 2), 10 %: a constant feed-forward (rad/s^2) on one joint from t = 0:")
    spastic = load_config(overlays=[scenario_path("spastic")], overrides={
        "mass_uncertainty": 0.1}).values
    for joint, drive in ((0, 40.0), (0, 80.0), (0, 300.0), (2, 150.0), (2, -300.0)):
        for name, extra in (("old", OLD), ("new", {})):
            ex = Experiment(Config({**spastic, **extra}, "hold bench"))
            u_ff = np.zeros_like(ex.reference.position)
            u_ff[:, joint] = drive
            record = ex.run_trial(u_ff, 1)
            if record.aborted_at is not None:
                print(line(f"joint {joint + 1} {drive:+g} {name}", ex, record))
    shipped = load_config()
    print("\nDecay rate -ln(radius) / T of the hold's slowest mode (s^-1; negative: unstable), "
          "nominal double integrator, command d periods late:")
    for kp, kd in zip(shipped["safety.hold_kp"], shipped["safety.hold_kd"], strict=True):
        cells = []
        for period in (0.001, 0.002, 0.005, 0.01):
            rates = [-math.log(hold_radius(kp, kd, period, d)) / period for d in (0, 1, 2)]
            cells.append(f"T {period:g}: " + " / ".join(f"{r:5.1f}" for r in rates))
        print(f"  kp {kp:g}, kd {kd:g} (d = 0 / 1 / 2)  " + "   ".join(cells))


if __name__ == "__main__":
    main()
