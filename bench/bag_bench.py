"""Benchmark of bags: what recording costs the graph, and how fast a big bag is analysed.

Run with ``.venv/bin/python -m bench.bag_bench [--trials K] [--analysis-trials N]``. Prints
figures; asserts nothing (wall-clock timing is noisy on a shared 2-core machine).

(a) The graph's lock-step control steps per second, within trials and overall, without
    bag_recorder, with it in the supervisor's process (``exo-ilc run``'s default) and in a
    process of its own (``--isolated-recorder``), in turn in one run; the medians. Target: the
    recorder costs at most 10 %.
(b) Analysing a 150-trial bag at 100 Hz (written in-process by ``write_run``, the same topics
    and messages as the recorder's): ``read_bag`` + the table. Target: under 5 s.
(c) Why a recorder process of its own costs more: the raw ping-pong of graph_bench with and
    without one more, silent subscriber process on both topics (what such a process adds to
    the round trip).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from bench.graph_bench import graph_rate, middleware_floor
from exo_ilc_ros.bag import read_bag, write_run
from exo_ilc_ros.core.config import Config, load_config
from exo_ilc_ros.core.session import run_trials

MODES = {"without": "no recorder", "supervisor": "recorder in the supervisor's process",
         "isolated": "recorder in a process of its own"}
"""(a)'s runs: what ``exo-ilc run --no-bag``, ``exo-ilc run`` and ``exo-ilc run
--isolated-recorder`` start."""


def graph_steps_per_second(config: Config, mode: str, bag_dir: Path) -> dict[str, float]:
    """Lock-step control steps per second within trials and overall (graph_bench's measure:
    trial start to end events, the first three trials skipped), in one of :data:`MODES`."""
    from exo_ilc_ros.orchestration.recording import Recording

    if mode == "without":
        return graph_rate(config)
    recorded = config.replace({"wait_for_recorder": True})
    with Recording(recorded, bag_dir) as recording:
        return graph_rate(recorded, recording.graph_nodes(isolated=mode == "isolated"))


def bench_recording(trials: int, repeats: int, bag_dir: Path) -> None:
    """(a): the three modes in turn, ``repeats`` times; the cost of each recording mode from
    the medians."""
    config = load_config(overrides={"max_trials": trials})
    rates: dict[str, list[dict[str, float]]] = {mode: [] for mode in MODES}
    for _ in range(repeats):
        for mode in MODES:
            rates[mode].append(graph_steps_per_second(config, mode, bag_dir))
        print("  steps/s within trials (overall): " + ", ".join(
            f"{MODES[mode]} {runs[-1]['steps_per_s_in_trial']:.0f} "
            f"({runs[-1]['steps_per_s_overall']:.0f})" for mode, runs in rates.items()),
            flush=True)
    for key, label in (("steps_per_s_in_trial", "within trials"),
                       ("steps_per_s_overall", "overall")):
        median = {mode: float(np.median([r[key] for r in runs])) for mode, runs in rates.items()}
        paired = {mode: float(np.median([1 - r[key] / b[key] for r, b in
                                         zip(rates[mode], rates["without"], strict=True)]))
                  for mode in ("supervisor", "isolated")}
        costs = ", ".join(f"{MODES[mode]} {median[mode]:.0f} steps/s, costs "
                          f"{100 * (1 - median[mode] / median['without']):.1f} % (median of "
                          f"the rounds' costs {100 * paired[mode]:.1f} %)"
                          for mode in ("supervisor", "isolated"))
        print(f"(a) lock-step graph {label}, {trials} trials x 501 samples, medians of "
              f"{repeats}: no recorder {median['without']:.0f} steps/s; {costs} "
              "(target <= 10 %)")


def bench_listener_floor(repeats: int, count: int = 8000) -> None:
    """(c): what one more subscriber process costs the middleware alone: the raw ping-pong
    with and without a third process subscribed to both topics (drained every 10 ms, no
    per-message wake-up, nothing written): the floor under (a)'s isolated recorder."""
    bare: list[float] = []
    heard: list[float] = []
    for _ in range(repeats):
        bare.append(middleware_floor(count, True)["round_trips_per_s"])
        heard.append(middleware_floor(count, True, listener=True)["round_trips_per_s"])
        print(f"  ping-pong round trips/s: alone {bare[-1]:.0f}, with a listener {heard[-1]:.0f}")
    cost = 1.0 - float(np.median(heard)) / float(np.median(bare))
    print(f"(c) middleware floor of (a)'s isolated recorder: one more subscriber process on "
          f"both topics costs the raw ping-pong {100 * cost:.1f} % (medians of {repeats})")


def bench_analysis(trials: int, bag_dir: Path) -> None:
    """(b): write a bag of ``trials`` trials at 100 Hz, then time its analysis."""
    config = load_config(overrides={"max_trials": trials})
    start = time.perf_counter()
    result = run_trials(config, 0.10)
    simulated = time.perf_counter() - start
    bag = bag_dir / "analysis"
    start = time.perf_counter()
    write_run(bag, config, result, split_every=1)
    written = time.perf_counter() - start
    size = sum(p.stat().st_size for p in bag.iterdir()) / 2**20
    times = []
    for _ in range(3):
        start = time.perf_counter()
        summary = read_bag(bag).summary()
        times.append(time.perf_counter() - start)
    assert summary.max_abs_error.shape[0] == trials
    print(f"(b) {trials}-trial bag at 100 Hz ({trials * 501} joint states, {size:.1f} MiB, "
          f"{trials + 1} files; simulated in {simulated:.1f} s, written in {written:.1f} s): "
          f"analysed in {min(times):.2f} s (best of 3; target < 5 s)")


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=20, help="graph trials per run (a)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each kind (a, c)")
    parser.add_argument("--analysis-trials", type=int, default=150, help="trials of (b)")
    parser.add_argument("--skip-graph", action="store_true", help="only (b)")
    args = parser.parse_args()
    bag_dir = Path(tempfile.mkdtemp(prefix="exo_ilc_bag_bench_"))
    try:
        bench_analysis(args.analysis_trials, bag_dir)
        if not args.skip_graph:
            bench_recording(args.trials, args.repeats, bag_dir)
            bench_listener_floor(args.repeats)
    finally:
        shutil.rmtree(bag_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
