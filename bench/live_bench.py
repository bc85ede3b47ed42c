"""Benchmark of the live view: what ``exo-ilc run --live`` with a Foxglove client connected costs
the graph's control loop.

Run with ``.venv/bin/python -m bench.live_bench [--trials K] [--repeats R]``. Prints figures;
asserts nothing (wall-clock timing is noisy on a shared 2-core machine).

The graph's lock-step control steps per second within trials (graph_bench's measure: start to
end events, trials 4 on, median), recorded as ``exo-ilc run`` records it (the recorder in the
supervisor's process), without ``--live`` and with it (foxglove_bridge, its own process, and
a headless WebSocket client in a process of its own, subscribed to every channel:
test/live_client.py), in turn (ABBA) in one run. ``--feed relay`` (default, as ``exo-ilc run``):
the recorder hands the view its messages; ``--feed dds``: the view reads DDS itself (as
``ros2 run exo_ilc_ros foxglove_bridge`` beside a recorder of its own does); ``--live-rate``
the view's display rate (default 200 samples/s of wall time, 0: every sample). Also, from trial
4's start to the end, the CPU time per control step of the loop's processes (plant and
controller: what one more reader of their topics costs them), of the supervisor's process
(which holds the recorder, so the relay's sending end), of the bridge and of the client
(steadier than a rate on a shared machine; the bridge's start-up, about 2 s of imports, left
out); what the client received; and the other tenants' load per round. Target: the view
costs at most 10 % within trials.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.bag_bench import _bootstrap_interval, _cpu_seconds, _machine_busy_seconds, _own_seconds
from bench.graph_bench import session_rates
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.nodes.registry import BRIDGE, CONTROLLER, PLANT, RECORDER, SUPERVISOR
from exo_ilc_ros.orchestration.graph import GraphSession
from exo_ilc_ros.orchestration.launcher import exported_domain_id
from exo_ilc_ros.orchestration.live import LiveView
from exo_ilc_ros.orchestration.recording import Recording
from exo_ilc_ros.wire.relay import DISPLAY_RATE
from exo_ilc_ros.wire.tf import TF

FIRST_MEASURED = 4
"""The first trial counted (graph_bench skips three to warm up)."""
CLIENT = Path(__file__).resolve().parents[1] / "test" / "live_client.py"
"""The headless client, run as a process of its own (as the Foxglove app would be)."""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_once(config: Config, bag_dir: Path, live: bool,
             bridge: dict[str, str] | None = None, relayed: bool = True,
             rate: float = DISPLAY_RATE, with_client: bool = True,
             feed: str = "relay") -> dict[str, float]:
    """One recorded run (as ``exo-ilc run`` records), with the live view and a client
    subscribed to everything or without: the in-trial rates (graph_bench's), the CPU time per
    control step of each process from trial 4's start to the end (``cpu_<name>``; the client
    as ``cpu_client``), the other tenants' load, and what the client received."""
    recorded = config.replace({"wait_for_recorder": True})
    port = _free_port()
    client = subprocess.Popen([sys.executable, str(CLIENT), f"ws://127.0.0.1:{port}", "120"],
                              stdout=subprocess.PIPE, stdin=subprocess.DEVNULL,
                              text=True) if live and with_client else None
    busy, own, began = _machine_busy_seconds(), _own_seconds(), time.monotonic()
    marks: list[dict[str, float]] = []
    try:
        with contextlib.ExitStack() as stack:
            view = stack.enter_context(LiveView(recorded, port, parameters=bridge,
                                                relayed=relayed, sample_rate=rate)) \
                if live else None
            recording = stack.enter_context(Recording(
                recorded, bag_dir, relay=view.relay if view is not None and feed != "none"
                else None,
                relay_rate=rate))
            nodes = list(recording.graph_nodes())
            if view is not None:
                nodes.append(view.spec)
            session = stack.enter_context(GraphSession(recorded, exported_domain_id(), nodes=nodes))
            pids = {name: p.pid for name, p in session.processes.processes.items()}
            if client is not None:
                pids["client"] = client.pid

            def done() -> bool:
                started = any(m == "start" and v.get("trial") == str(FIRST_MEASURED)
                              for m, v, _ in session.events)
                if (started and not marks) or (session.finished and len(marks) == 1):
                    marks.append({name: _cpu_seconds(pid) for name, pid in pids.items()})
                return session.finished

            session.spin_until(done, timeout=1800.0, stall_timeout=120.0)
        out = client.communicate(timeout=60)[0] if client is not None else ""
    finally:
        if client is not None and client.poll() is None:
            client.kill()
            client.wait()
    others = (_machine_busy_seconds() - busy) - (_own_seconds() - own)
    rates = session_rates(session, recorded)
    steps = (rates["trials"] - FIRST_MEASURED + 1) * rates["samples_per_trial"]
    cpu = {f"cpu_{name}": 1e3 * (marks[1][name] - marks[0][name]) / steps
           for name in marks[0]} if len(marks) == 2 else {}
    counts = json.loads(out.strip().splitlines()[-1]) if out.strip() else {}
    counts.pop("cpu_seconds", None)
    return {**rates, **cpu, "others": max(others, 0.0) / (time.monotonic() - began),
            "client_messages": float(sum(counts.values())),
            "client_tf": float(counts.get(TF, 0))}


LOOP = (PLANT.name, CONTROLLER.name)
"""The control loop's processes."""
SUPERVISING = f"{SUPERVISOR.name}+{RECORDER.name}"
"""The supervisor's process, which holds the recorder (and so the relay's sending end)."""


def _loop_cpu(run: dict[str, float]) -> float:
    return sum(run.get(f"cpu_{name}", float("nan")) for name in LOOP)


def _cpu(run: dict[str, float], name: str) -> float:
    return run.get(f"cpu_{name}", float("nan"))


def _median_cpu(runs: list[dict[str, float]], name: str) -> float:
    return float(np.median([_cpu(r, name) for r in runs]))


def bench_live(trials: int, repeats: int, bag_dir: Path,
               bridge: dict[str, str] | None = None, quiet: float = 0.15,
               relayed: bool = True, rate: float = DISPLAY_RATE,
               with_client: bool = True, feed: str = "relay") -> None:
    """The two modes in turn, ``repeats`` rounds; the cost from the medians and per round."""
    config = load_config(overrides={"max_trials": trials})
    without: list[dict[str, float]] = []
    live: list[dict[str, float]] = []
    for round_ in range(repeats):
        for mode in (False, True) if round_ % 2 == 0 else (True, False):
            (live if mode else without).append(run_once(config, bag_dir, mode, bridge,
                                                        relayed, rate, with_client, feed))
        a, b = without[-1], live[-1]
        print(f"  round {round_ + 1}: steps/s within trials without --live "
              f"{a['steps_per_s_in_trial']:.0f} [other tenants {a['others']:.2f} cores], with "
              f"--live and a client {b['steps_per_s_in_trial']:.0f} [{b['others']:.2f}]; the "
              f"client got {b['client_messages']:.0f} messages ({b['client_tf']:.0f} /tf); CPU "
              f"ms per control step: plant+controller {_loop_cpu(a):.3f} -> {_loop_cpu(b):.3f}, "
              f"supervisor+recorder {_cpu(a, SUPERVISING):.3f} -> {_cpu(b, SUPERVISING):.3f}, "
              f"foxglove_bridge {_cpu(b, BRIDGE.name):.3f}, client {_cpu(b, 'client'):.3f}",
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
    calm = [i for i in range(repeats) if max(without[i]["others"], live[i]["others"]) < quiet]
    if calm:
        calm_costs = [costs[i] for i in calm]
        print(f"  the {len(calm)} rounds with the other tenants below {quiet:g} cores: without "
              f"--live {float(np.median([without[i][key] for i in calm])):.0f} steps/s, with "
              f"{float(np.median([live[i][key] for i in calm])):.0f}: median of the rounds' "
              f"costs {100 * float(np.median(calm_costs)):.1f} % (each: "
              + ", ".join(f"{100 * c:.1f}" for c in calm_costs) + ")")
    else:
        print(f"  no round had the other tenants below {quiet:g} cores")
    loop_a = float(np.median([_loop_cpu(r) for r in without]))
    loop_b = float(np.median([_loop_cpu(r) for r in live]))
    print(f"CPU per control step within trials (medians): plant + controller {loop_a:.3f} ms "
          f"without --live, {loop_b:.3f} ms with it ({100 * (loop_b / loop_a - 1):+.1f} %); "
          f"supervisor + recorder {_median_cpu(without, SUPERVISING):.3f} -> "
          f"{_median_cpu(live, SUPERVISING):.3f} ms; foxglove_bridge "
          f"{_median_cpu(live, BRIDGE.name):.3f} ms, the client "
          f"{_median_cpu(live, 'client'):.3f} ms")


def main() -> None:
    """Parse the options and run."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trials", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=4, help="ABBA rounds")
    parser.add_argument("--bridge", nargs="*", default=[], metavar="NAME:=VALUE",
                        help="foxglove_bridge parameters, e.g. scheduling:=normal "
                        "sample_reliability:=reliable")
    parser.add_argument("--feed", choices=("relay", "dds", "none"), default="relay",
                        help="how the view gets the graph's topics: from the recorder (relay, "
                        "as exo-ilc run does) or as one more DDS reader (as ros2 run does); none: "
                        "the bridge gets nothing (what its process alone costs)")
    parser.add_argument("--live-rate", type=float, default=DISPLAY_RATE, metavar="HZ",
                        help="the view's display rate, as exo-ilc run --live-rate (0: every "
                        "sample)")
    parser.add_argument("--no-client", action="store_true",
                        help="the view without a client connected (what the bridge alone costs)")
    args = parser.parse_args()
    bridge = dict(item.split(":=", 1) for item in args.bridge)
    print(f"foxglove_bridge parameters: {bridge or 'defaults'}; feed: {args.feed}; display "
          f"rate: {args.live_rate:g} samples/s of wall time (0: every sample)", flush=True)
    with tempfile.TemporaryDirectory(prefix="live_bench_") as tmp:
        bench_live(args.trials, args.repeats, Path(tmp), bridge, relayed=args.feed != "dds",
                   rate=args.live_rate, with_client=not args.no_client, feed=args.feed)


if __name__ == "__main__":
    main()
