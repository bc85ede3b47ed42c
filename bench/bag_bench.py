"""Benchmark of bags: what recording costs the graph, and how fast a big bag is analysed.

Run with ``.venv/bin/python -m bench.bag_bench [--trials K] [--analysis-trials N]``. Prints
figures; asserts nothing (wall-clock timing is noisy on a shared 2-core machine).

(a) The graph's lock-step control steps per second, within trials and overall, without
    bag_recorder, with it in the supervisor's process (``exo-ilc run``'s default) and in a
    process of its own (``--isolated-recorder``), in turn (ABBA) in one run; the medians, with
    a bootstrap interval, of all rounds and of the rounds in which the machine's other tenants
    used fewer than ``--quiet`` cores (from /proc/stat less this process's tree). Target: the
    recorder costs at most 5 % within trials, 10 % overall.
(b) Analysing a 150-trial bag at 100 Hz (written in-process by ``write_run``, the same topics
    and messages as the recorder's): ``read_bag`` + the table. Target: under 5 s.
(c) Why a recorder process of its own costs more: the raw ping-pong of graph_bench with and
    without one more, silent subscriber process on both topics (what such a process adds to
    the round trip).
(e) The CPU time the graph's processes spend per control step within trials (start to end
    event, trial 4 on), without and with the composed recorder, read from /proc (CPU time,
    unlike a rate, barely moves when other tenants load the machine): the difference is what
    recording costs per step, shown as a share of the in-trial time at ``--rate`` (an upper
    bound of the rate's loss: only the part on the plant-controller round trip slows it).
    ``--cpu-only`` runs only (e).
(d) The writer alone, in-process (steadier than (a) on a shared machine): the recorder's
    message mix (per control step a JointState and an effort command, a /clock every tenth)
    written in the batches of a 10 ms drain, a file finished per 501-sample trial; CPU time
    (process time, less sensitive than wall time to the other tenants of the machine) per
    step and per finished file, and the in-trial share it takes at (a)'s rate without the
    recorder (or ``--rate``). Run it on an older tree too (``PYTHONPATH=<tree>``) for a before
    and after; ``--writer-only`` runs only (d).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from bench.graph_bench import graph_rate, middleware_floor
from exo_ilc_ros.bag import read_bag, write_run
from exo_ilc_ros.core.params.config import Config, load_config
from exo_ilc_ros.core.session.learning_session import run_trials
from exo_ilc_ros.orchestration.launcher import exported_domain_id

MODES = {"without": "no recorder", "supervisor": "recorder in the supervisor's process",
         "isolated": "recorder in a process of its own"}
"""(a)'s runs: what ``exo-ilc run --no-bag``, ``exo-ilc run`` and ``exo-ilc run
--isolated-recorder`` start."""


def _machine_busy_seconds() -> float:
    """CPU seconds every process of the machine spent so far (``/proc/stat``, all CPUs)."""
    fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]
    user, nice, system, _, _, irq, softirq, steal = (int(x) for x in fields[:8])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


def _own_seconds() -> float:
    """CPU seconds of this process and its reaped children (the graph's processes)."""
    times = os.times()
    return times.user + times.system + times.children_user + times.children_system


def graph_steps_per_second(config: Config, mode: str, bag_dir: Path) -> dict[str, float]:
    """Lock-step control steps per second within trials and overall (graph_bench's measure:
    trial start to end events, the first three trials skipped), in one of :data:`MODES`; and
    ``others``: the cores the machine's other tenants used meanwhile (everything but this
    process and the graph it started)."""
    from exo_ilc_ros.orchestration.recording import Recording

    busy, own, start = _machine_busy_seconds(), _own_seconds(), time.monotonic()
    if mode == "without":
        rates = graph_rate(config)
    else:
        recorded = config.replace({"wait_for_recorder": True})
        with Recording(recorded, bag_dir) as recording:
            rates = graph_rate(recorded, recording.graph_nodes(isolated=mode == "isolated"))
    others = (_machine_busy_seconds() - busy) - (_own_seconds() - own)
    return {**rates, "others": max(others, 0.0) / (time.monotonic() - start)}


def bench_recording(trials: int, repeats: int, bag_dir: Path,
                    modes: tuple[str, ...] = tuple(MODES), quiet: float = 0.15) -> float:
    """(a): the ``modes`` in turn (always with ``without``), ``repeats`` times; the cost of
    each recording mode from the medians, of all rounds and of the quiet ones (other tenants
    below ``quiet`` cores in each of the round's runs). Returns the median in-trial rate
    without the recorder."""
    config = load_config(overrides={"max_trials": trials})
    modes = ("without", *(m for m in modes if m != "without"))
    recorded = [m for m in modes if m != "without"]
    rates: dict[str, list[dict[str, float]]] = {mode: [] for mode in modes}
    for round_ in range(repeats):  # ABBA: alternate the order, so a drift costs both alike
        for mode in modes if round_ % 2 == 0 else modes[::-1]:
            rates[mode].append(graph_steps_per_second(config, mode, bag_dir))
        print("  steps/s within trials (overall) [other tenants' cores]: " + ", ".join(
            f"{MODES[mode]} {runs[-1]['steps_per_s_in_trial']:.0f} "
            f"({runs[-1]['steps_per_s_overall']:.0f}) [{runs[-1]['others']:.2f}]"
            for mode, runs in rates.items()), flush=True)
    _report_recording(rates, recorded, trials, "")
    calm = [i for i in range(repeats) if max(runs[i]["others"] for runs in rates.values()) < quiet]
    if calm and len(calm) < repeats:
        _report_recording({mode: [runs[i] for i in calm] for mode, runs in rates.items()},
                          recorded, trials, f" (the {len(calm)} rounds with other tenants below "
                          f"{quiet:g} cores)")
    elif not calm:
        print(f"(a) no round had the other tenants below {quiet:g} cores")
    return float(np.median([r["steps_per_s_in_trial"] for r in rates["without"]]))


def _report_recording(rates: dict[str, list[dict[str, float]]], recorded: Sequence[str],
                      trials: int, which: str) -> None:
    repeats = len(rates["without"])
    for key, label in (("steps_per_s_in_trial", "within trials"),
                       ("steps_per_s_overall", "overall")):
        median = {mode: float(np.median([r[key] for r in runs])) for mode, runs in rates.items()}
        paired = {mode: float(np.median([1 - r[key] / b[key] for r, b in
                                         zip(rates[mode], rates["without"], strict=True)]))
                  for mode in recorded}
        spread = {mode: _bootstrap_interval([1 - r[key] / b[key] for r, b in
                                             zip(rates[mode], rates["without"], strict=True)])
                  for mode in recorded}
        costs = ", ".join(f"{MODES[mode]} {median[mode]:.0f} steps/s, costs "
                          f"{100 * (1 - median[mode] / median['without']):.1f} % (median of "
                          f"the rounds' costs {100 * paired[mode]:.1f} %, 90 % interval "
                          f"{100 * spread[mode][0]:.1f} to {100 * spread[mode][1]:.1f} %)"
                          for mode in recorded)
        print(f"(a) lock-step graph {label}, {trials} trials x 501 samples, medians of "
              f"{repeats}{which}: no recorder {median['without']:.0f} steps/s; {costs} "
              f"(target <= {5 if key == 'steps_per_s_in_trial' else 10} %)")


def _bootstrap_interval(costs: Sequence[float], draws: int = 10_000) -> tuple[float, float]:
    """The 5th and 95th percentiles of the median of ``costs`` resampled with replacement
    (how far the rounds' median cost could move with other rounds on this machine)."""
    rng = np.random.default_rng(0)
    values = np.asarray(costs, dtype=float)
    medians = np.median(rng.choice(values, size=(draws, values.size)), axis=1)
    return float(np.percentile(medians, 5)), float(np.percentile(medians, 95))


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


def _cpu_seconds(pid: int) -> float:
    """CPU time of every thread of process ``pid`` so far (``/proc/<pid>/task/*/schedstat``,
    nanoseconds; ``/proc/<pid>/stat`` counts 10 ms ticks, too coarse for one trial)."""
    total = 0
    for task in Path(f"/proc/{pid}/task").iterdir():
        with contextlib.suppress(FileNotFoundError, ProcessLookupError):
            total += int((task / "schedstat").read_text().split()[0])
    return total * 1e-9


class _InTrialCpu:
    """The CPU time each process spends between a trial's start and end events (as the
    monitor receives them), summed over trials 4 to the last."""

    def __init__(self, pids: dict[str, int]) -> None:
        self.pids = pids
        self.used = dict.fromkeys(pids, 0.0)
        self.trials = 0
        self._seen = 0
        self._at_start: dict[str, float] | None = None

    def watch(self, events: Sequence[tuple[str, dict[str, str], float]]) -> None:
        """Called after every executor event: snapshot at each new start, add at its end."""
        for message, values, _ in events[self._seen:]:
            if message == "start" and int(values.get("trial", 0)) > 3:
                self._at_start = {name: _cpu_seconds(pid) for name, pid in self.pids.items()}
            elif message == "end" and self._at_start is not None:
                for name, pid in self.pids.items():
                    self.used[name] += _cpu_seconds(pid) - self._at_start[name]
                self.trials += 1
                self._at_start = None
        self._seen = len(events)


def graph_cpu_per_step(config: Config, recorded: bool, bag_dir: Path) -> dict[str, float]:
    """(e): CPU seconds per control step within trials (start to end event, trials 4 to the
    end) of each of the graph's processes (by name) and of all of them (``total``)."""
    from exo_ilc_ros.orchestration.graph import GraphSession
    from exo_ilc_ros.orchestration.launcher import GRAPH_NODES
    from exo_ilc_ros.orchestration.recording import Recording

    samples = int(round(config["trajectory.duration"] / config["control.period"])) + 1
    trials = int(config["max_trials"])
    with contextlib.ExitStack() as stack:
        nodes: Sequence[Any] = GRAPH_NODES
        if recorded:
            config = config.replace({"wait_for_recorder": True})
            nodes = stack.enter_context(Recording(config, bag_dir)).graph_nodes()
        session = stack.enter_context(GraphSession(config, exported_domain_id(), nodes=nodes))
        session.spin_until(lambda: len(session.summaries) >= 3, timeout=600.0)
        cpu = _InTrialCpu({name: p.pid for name, p in session.processes.processes.items()})

        def done() -> bool:
            cpu.watch(session.events)
            return len(session.summaries) >= trials

        session.spin_until(done, timeout=1800.0, stall_timeout=120.0)
    steps = max(cpu.trials, 1) * samples
    per_step = {name: seconds / steps for name, seconds in cpu.used.items()}
    per_step["total"] = sum(cpu.used.values()) / steps
    return per_step


def bench_cpu(trials: int, repeats: int, rate: float, bag_dir: Path) -> None:
    """(e): without and with the composed recorder in turn (ABBA), ``repeats`` times."""
    config = load_config(overrides={"max_trials": trials})
    without: list[float] = []
    with_recorder: list[float] = []
    for round_ in range(repeats):
        order = (False, True) if round_ % 2 == 0 else (True, False)
        runs = dict(zip(order, (graph_cpu_per_step(config, recorded, bag_dir)
                                for recorded in order), strict=True))
        without.append(runs[False]["total"])
        with_recorder.append(runs[True]["total"])
        print("  graph CPU per control step within trials (us): " + "; ".join(
            f"{label} {1e6 * run['total']:.1f} (" + ", ".join(
                f"{name} {1e6 * value:.1f}" for name, value in run.items() if name != "total")
            + ")" for label, run in (("no recorder", runs[False]),
                                     ("recorder in the supervisor's process", runs[True]))),
            flush=True)
    bare, recorded = float(np.median(without)), float(np.median(with_recorder))
    cost = recorded - bare
    print(f"(e) graph CPU per control step within trials 4-{trials}, medians of {repeats}: no "
          f"recorder {1e6 * bare:.1f} us, with the recorder {1e6 * recorded:.1f} us: recording "
          f"costs {1e6 * cost:.1f} us per step, {100 * cost * rate:.2f} % of the in-trial time "
          f"at {rate:.0f} steps/s (target <= 5 %)")


def bench_writer(rate: float, trials: int, bag_dir: Path, repeats: int = 5) -> dict[str, float]:
    """(d): the recorder's writing at ``rate`` control steps/s, in-process; the best of
    ``repeats`` runs of ``trials`` trials of 501 samples."""
    from exo_ilc_ros.bag import BagWriter, messages
    from exo_ilc_ros.wire import topics
    from exo_ilc_ros.wire.qos import offered_qos

    names = ["shoulder_flexion", "shoulder_abduction", "elbow_flexion"]
    samples, period_ns = 501, 10_000_000
    per_drain = max(1, int(round(rate * 0.01)))  # control steps between two 10 ms drains
    zeros = np.zeros(3)
    state = messages.joint_state(0, names, zeros, zeros, zeros)
    command = messages.effort_command(zeros)
    clock = messages.clock(0)
    best_step, best_split = np.inf, np.inf
    for repeat in range(repeats):
        path = bag_dir / f"writer_{repeat}"
        writing = splitting = 0.0
        with BagWriter(path) as writer:
            for topic, msgtype in topics.TYPES.items():
                writer.add_topic(topic, msgtype, offered_qos(topic))
            ns = 0
            for _ in range(trials):
                for first in range(0, samples, per_drain):
                    batch = []
                    for i in range(first, min(samples, first + per_drain)):
                        ns += period_ns
                        batch.append((ns, topics.JOINT_STATES, state))
                        batch.append((ns + 1, topics.EFFORT_COMMANDS, command))
                        if i % 10 == 0:
                            batch.append((ns, topics.CLOCK, clock))
                    start = time.process_time()
                    writer.write_many(batch)
                    writing += time.process_time() - start
                start = time.process_time()
                writer.split()
                splitting += time.process_time() - start
        shutil.rmtree(path, ignore_errors=True)
        best_step = min(best_step, writing / (trials * samples))
        best_split = min(best_split, splitting / trials)
    in_trial = best_step * rate
    overall = (best_step * samples + best_split) / (samples / rate)
    print(f"(d) writer alone ({trials} trials x {samples} samples, batches of {per_drain} "
          f"steps, best of {repeats}): {1e6 * best_step:.2f} us CPU per control step (2.1 "
          f"messages), {1e3 * best_split:.2f} ms per finished file; at {rate:.0f} steps/s "
          f"that is {100 * in_trial:.2f} % of the time within trials, {100 * overall:.2f} % "
          "with the file finished after each trial")
    return {"us_per_step": 1e6 * best_step, "ms_per_split": 1e3 * best_split,
            "in_trial": in_trial, "overall": overall}


def main() -> None:
    """Measure and print."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=20, help="graph trials per run (a)")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each kind (a, c)")
    parser.add_argument("--analysis-trials", type=int, default=150, help="trials of (b)")
    parser.add_argument("--skip-graph", action="store_true", help="only (b) and (d)")
    parser.add_argument("--writer-only", action="store_true", help="only (d)")
    parser.add_argument("--cpu-only", action="store_true", help="only (e)")
    parser.add_argument("--modes", nargs="+", choices=tuple(MODES), default=tuple(MODES),
                        help="(a)'s runs (default: all three)")
    parser.add_argument("--quiet", type=float, default=0.15, help="(a) also reports the rounds "
                        "in which the machine's other tenants used fewer cores than this")
    parser.add_argument("--rate", type=float, default=3500.0, help="(d)'s in-trial rate, "
                        "steps/s, when (a) does not run (default: docs/bags.md's 3,501)")
    args = parser.parse_args()
    bag_dir = Path(tempfile.mkdtemp(prefix="exo_ilc_bag_bench_"))
    try:
        if args.writer_only:
            bench_writer(args.rate, 20, bag_dir)
            return
        if args.cpu_only:
            bench_cpu(args.trials, args.repeats, args.rate, bag_dir)
            return
        bench_analysis(args.analysis_trials, bag_dir)
        rate = args.rate
        if not args.skip_graph:
            rate = bench_recording(args.trials, args.repeats, bag_dir, args.modes,
                                   args.quiet) or rate
        bench_writer(rate, 20, bag_dir)
        if not args.skip_graph and "isolated" in args.modes:
            bench_listener_floor(args.repeats)
    finally:
        shutil.rmtree(bag_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
