"""Benchmark of the live view: what ``exo-ilc run --live`` with a Foxglove client connected costs
the graph's control loop.

Run with ``.venv/bin/python -m bench.live_bench [--trials K] [--repeats R]``. Prints figures;
asserts nothing (wall-clock timing is noisy on a shared 2-core machine).

The graph's lock-step control steps per second within trials (graph_bench's measure: start to
end events, trials 4 on, median), recorded as ``exo-ilc run`` records it (the recorder in the
supervisor's process), without ``--live`` and with it (foxglove_bridge, its own process, and
a headless WebSocket client in a process of its own, subscribed to every channel:
test/live_client.py), in turn (ABBA)
in one run. Also: what the client received (messages, /tf messages, per second) and the other
tenants' load per round. Target: the view costs at most 10 % within trials.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.bag_bench import _bootstrap_interval, graph_steps_per_second
from bench.graph_bench import graph_rate
from exo_ilc_ros.core.config import Config, load_config
from exo_ilc_ros.orchestration.live import LiveView
from exo_ilc_ros.orchestration.recording import Recording
from exo_ilc_ros.wire.tf import TF

CLIENT = Path(__file__).resolve().parents[1] / "test" / "live_client.py"
"""The headless client, run as a process of its own (as the Foxglove app would be)."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def live_steps_per_second(config: Config, bag_dir: Path) -> dict[str, float]:
    """One recorded run with the live view and a client subscribed to everything."""
    recorded = config.replace({"wait_for_recorder": True})
    port = _free_port()
    client = subprocess.Popen([sys.executable, str(CLIENT), f"ws://127.0.0.1:{port}", "120"],
                              stdout=subprocess.PIPE, stdin=subprocess.DEVNULL, text=True)
    try:
        with Recording(recorded, bag_dir) as recording, LiveView(recorded, port) as live:
            rates = graph_rate(recorded, [*recording.graph_nodes(), live.spec])
        out, _ = client.communicate(timeout=60)
    finally:
        if client.poll() is None:
            client.kill()
            client.wait()
    counts = json.loads(out.strip().splitlines()[-1]) if out.strip() else {}
    return {**rates, "client_messages": float(sum(counts.values())),
            "client_tf": float(counts.get(TF, 0))}


def bench_live(trials: int, repeats: int, bag_dir: Path) -> None:
    """The two modes in turn, ``repeats`` rounds; the cost from the medians and per round."""
    config = load_config(overrides={"max_trials": trials})
    without: list[dict[str, float]] = []
    live: list[dict[str, float]] = []
    for round_ in range(repeats):
        order = ("without", "live") if round_ % 2 == 0 else ("live", "without")
        for mode in order:
            if mode == "without":
                without.append(graph_steps_per_second(config, "supervisor", bag_dir))
            else:
                live.append(live_steps_per_second(config, bag_dir))
        print(f"  round {round_ + 1}: steps/s within trials without --live "
              f"{without[-1]['steps_per_s_in_trial']:.0f} [other tenants "
              f"{without[-1]['others']:.2f} cores], with --live and a client "
              f"{live[-1]['steps_per_s_in_trial']:.0f}; the client got "
              f"{live[-1]['client_messages']:.0f} messages ({live[-1]['client_tf']:.0f} /tf)",
              flush=True)
    key = "steps_per_s_in_trial"
    base = float(np.median([r[key] for r in without]))
    with_view = float(np.median([r[key] for r in live]))
    costs = [1 - a[key] / b[key] for a, b in zip(live, without, strict=True)]
    low, high = _bootstrap_interval(costs)
    print(f"live view, lock-step graph within trials, {trials} trials, medians of {repeats} "
          f"ABBA rounds: without --live {base:.0f} steps/s, with --live and a client "
          f"{with_view:.0f} steps/s: costs {100 * (1 - with_view / base):.1f} % (median of the "
          f"rounds' costs {100 * float(np.median(costs)):.1f} %, 90 % interval "
          f"{100 * low:.1f} to {100 * high:.1f} %; target <= 10 %)")


def main() -> None:
    """Parse the options and run."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=4, help="ABBA rounds")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="live_bench_") as tmp:
        bench_live(args.trials, args.repeats, Path(tmp))


if __name__ == "__main__":
    main()
