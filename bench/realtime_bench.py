"""Real time: late commands and watchdog trips of the real-time graph (figures only, no asserts).

    .venv/bin/python -m bench.realtime_bench [--runs 10] [--trials 5] [--duration 1.0]
                                             [--rates 100 200 1000] [--priority 50 0]

For each control rate, ``--runs`` runs of ``--trials`` trials (real_time mode, real time,
``trajectory.duration`` shortened to keep it fast; ``max_late_commands: 1`` so that every trial is
measured, none re-run): per run the watchdog trips (a trial re-run for ``watchdog``), the trials
with a late command, the late commands of trial 1, the share of all periods run on a late
(held) command, and the warm-up attempt. Every run has a ROS domain of its own with discovery
kept on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``).
"""

from __future__ import annotations

import argparse
import os
import time

from exo_ilc_ros.core.params.config import load_config
from exo_ilc_ros.orchestration.graph import GraphSession
from exo_ilc_ros.orchestration.launcher import exported_domain_id

START_PERIODS = 10
"""A late command within a trial's first this many periods counts as "at start"."""


def one_run(rate_hz: float, trials: int, duration: float, priority: int
            ) -> dict[str, float]:
    """One real-time run: late commands per trial (from the summaries) and re-runs."""
    config = load_config(overrides={"mode": "real_time", "control.period": 1.0 / rate_hz,
                                    "trajectory.duration": duration, "max_trials": trials,
                                    "max_late_commands": 1.0, "law": "linear",
                                    "thread_priority": priority})
    started = time.monotonic()
    with GraphSession(config, exported_domain_id()) as session:
        session.spin_until(lambda: session.finished, timeout=60.0 + 4 * trials * duration,
                           stall_timeout=60.0)
        late = [int(s.values.get("late_commands", "-1")) for s in session.summaries]
        first = [int(s.values.get("first_late", "-1")) for s in session.summaries]
        periods = [int(s.values.get("periods", "0")) for s in session.summaries]
        reruns = [v.get("reason", "") for m, v, _ in session.events if m == "aborted"]
    return {"late_total": sum(late), "periods": sum(periods),
            "late_trial_1": late[0] if late else -1,
            "trials_late": sum(1 for x in late if x > 0),
            "late_at_start": sum(1 for f in first if 0 < f <= START_PERIODS),
            "watchdog": sum(1 for r in reruns if r == "watchdog"),
            "warm_up": sum(1 for r in reruns if r == "warm_up"),
            "wall": time.monotonic() - started}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--trials", type=int, default=5)
    parser.add_argument("--duration", type=float, default=1.0)
    parser.add_argument("--rates", type=float, nargs="+", default=[100.0, 200.0, 1000.0])
    parser.add_argument("--priority", type=int, nargs="+", default=[50],
                        help="thread_priority of the control loop (SCHED_FIFO; 0: the normal "
                        "scheduler); several: one pass each, to compare")
    args = parser.parse_args()
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    for priority, rate in ((p, r) for p in args.priority for r in args.rates):
        load = os.getloadavg()[0]
        runs = [one_run(rate, args.trials, args.duration, priority) for _ in range(args.runs)]
        late = sum(r["late_total"] for r in runs)
        periods = sum(r["periods"] for r in runs)
        print(f"thread_priority {priority} (root here: {os.geteuid() == 0}), load average "
              f"{load:.1f} -> {os.getloadavg()[0]:.1f}: "
              f"{rate:g} Hz, {args.runs} runs x {args.trials} trials of {args.duration:g} s: "
              f"watchdog trips {sum(r['watchdog'] for r in runs):g}, runs with a late command "
              f"in trial 1: {sum(1 for r in runs if r['late_trial_1'] > 0)}, trials with a "
              f"late command {sum(r['trials_late'] for r in runs):g} of "
              f"{args.runs * args.trials} ({sum(r['late_at_start'] for r in runs):g} within "
              f"the first {START_PERIODS} periods), late commands {late:g} of {periods:g} periods "
              f"({100 * late / max(periods, 1):.3f} %), warm-up attempts "
              f"{sum(r['warm_up'] for r in runs):g}, wall per run "
              f"{sum(r['wall'] for r in runs) / len(runs):.1f} s", flush=True)
        for k, r in enumerate(runs, 1):
            print(f"  run {k}: late {r['late_total']:g} / {r['periods']:g} periods, trial 1 "
                  f"{r['late_trial_1']:g}, at start {r['late_at_start']:g}, watchdog "
                  f"{r['watchdog']:g}", flush=True)


if __name__ == "__main__":
    main()
