"""``exo-ilc run``: the experiment through the ROS 2 node graph (one process per node, real DDS)."""

from __future__ import annotations

import argparse
import contextlib
import os
import shlex
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..core.errors import ConfigError
from ..core.params.config import Config
from ..orchestration.launcher import exported_domain_id
from ..wire import topics
from ..wire.relay import DISPLAY_RATE
from .arguments import directory, domain_id, shown_command
from .progress import progress_bar
from .simulate import aborted_exit, add_config_arguments, config_from_args, print_report
from .therapy import add_therapy_arguments, run_session_graph, uses_therapy

if TYPE_CHECKING:
    from ..core.session.summary import RunSummary
    from ..orchestration.graph import TrialSummary


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "run", help="run the experiment through the ROS 2 node graph",
        description="Start plant_simulator, computed_torque_controller and ilc_supervisor as "
        "separate processes (bag_recorder in the supervisor's) on a ROS domain of their own "
        "(discovery limited to this machine unless ROS_AUTOMATIC_DISCOVERY_RANGE is set), run "
        "K trials per mass uncertainty and print the same table and JSON as `exo-ilc "
        "simulate`.")
    add_config_arguments(parser)
    parser.add_argument("--domain-id", type=domain_id, help="ROS domain id of the graph (default: "
                        "an exported ROS_DOMAIN_ID, else a free one, claimed with a lock "
                        "file)")
    parser.add_argument("--quiet", action="store_true", help="no per-trial table")
    parser.add_argument("--learned", action="store_true", help="also print per-trial tables "
                        "of max |u_ff| (learned feed-forward) and max |effort| per joint")
    parser.add_argument("--no-bag", action="store_true",
                        help="do not start bag_recorder (default: each run is recorded to "
                        "<bag-dir>/<run-name>/, rosbag2 MCAP)")
    parser.add_argument("--bag-dir", metavar="DIR", type=directory,
                        help="where the bags go (default: bags)")
    parser.add_argument("--isolated-recorder", action="store_true",
                        help="run bag_recorder in a process of its own (default: in "
                        "ilc_supervisor's process, which costs the control loop less; a "
                        "process of its own survives the supervisor and vice versa)")
    parser.add_argument("--store", metavar="DIR", type=directory,
                        help="save every completed trial and the feed-forward it led to under "
                        "DIR (default: a new .exo-ilc/runs/<date-time>-<pid>/store per run)")
    parser.add_argument("--resume", nargs="?", const=True, default=False, metavar="SESSION",
                        help="with --store DIR: continue after the last trial stored there "
                        "(after a crash or a killed node), bit-identical to an uninterrupted "
                        "run; with --patient, SESSION (the id the stopped run printed, or vN) "
                        "says which unfinished session to continue")
    parser.add_argument("--no-store", action="store_true", help="do not save the trials")

    add_therapy_arguments(parser)
    parser.add_argument("--plant", choices=("simulator", "mujoco"), default="simulator",
                        help="the arm: our simulator (default) or MuJoCo (mujoco_plant, no "
                        "reset service: sets protocol homing)")
    parser.add_argument("--live", action="store_true",
                        help="serve the running graph to the Foxglove app (foxglove_bridge, a "
                        "process of its own; docs/live-view.md): open ws://127.0.0.1:8765")
    parser.add_argument("--live-port", type=port_number, default=None, metavar="PORT",
                        help="with --live: the WebSocket port (default 8765; 0: any free one)")
    parser.add_argument("--live-host", default=None, metavar="HOST",
                        help="with --live: the address to bind (default 127.0.0.1, this "
                        "machine only; 0.0.0.0 lets anyone who can reach this machine watch "
                        "the run, without a password: docs/live-view.md)")
    parser.add_argument("--live-rate", type=display_rate, default=None, metavar="HZ",
                        help="with --live: samples shown per second of wall time, per topic "
                        f"(default {DISPLAY_RATE:g}: every sample of a real-time loop up to "
                        "that rate; a faster lock-step run is shown at it; 0: every sample)")
    parser.add_argument("--live-pace", type=display_rate, default=None, metavar="RATE",
                        help="with --live, lock-step: at most RATE simulated seconds per wall "
                        "second (1: real time, to watch it learn); the numbers do not change "
                        "(the plant's pace)")
    parser.add_argument("--live-param", action="append", default=[], metavar="NAME:=VALUE",
                        type=bridge_parameter,
                        help="with --live: a foxglove_bridge parameter, e.g. "
                        "sample_reliability:=reliable or message_backlog:=10000 (repeatable)")
    parser.set_defaults(func=run)


def bridge_parameter(text: str) -> tuple[str, str]:
    """``name:=value`` of ``--live-param``."""
    name, sep, value = text.partition(":=")
    if not sep or not name:
        raise argparse.ArgumentTypeError(f"not name:=value: {text!r}")
    return name, value


def display_rate(text: str) -> float:
    """Samples per second of wall time, >= 0 (0: every sample)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value >= 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"a rate is >= 0 samples/s (0: every sample), got "
                                         f"{text}")
    return value


def port_number(text: str) -> int:
    """A TCP port, 0 (any free one) to 65535."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= value <= 65535:
        raise argparse.ArgumentTypeError(f"a port is 0..65535, got {value}")
    return value


def _store_root(args: argparse.Namespace) -> Path | None:
    """The store root of this invocation (module docstring of core.persistence.store)."""
    if args.no_store:
        if args.resume or args.store:
            raise ConfigError("--no-store", "cannot be combined with --store or --resume")
        return None
    if args.store:
        return Path(args.store).resolve()
    if args.resume:
        raise ConfigError("--resume", "needs --store DIR (the store printed by the run to "
                          "continue)")
    stamp = f"{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    return (Path(".exo-ilc") / "runs" / stamp / "store").resolve()


def run(args: argparse.Namespace) -> int:
    """Run the graph once per mass uncertainty and report."""
    from ..analysis.therapy import format_filed_metrics
    from ..core.session.learning_session import stored_trials
    from ..orchestration.launcher import GraphError


    if args.no_bag and (args.bag_dir is not None or args.isolated_recorder):
        given = "--bag-dir" if args.bag_dir is not None else "--isolated-recorder"
        raise ConfigError("--no-bag", f"records nothing: {given} would be ignored; drop one")
    if not args.live and (args.live_port is not None or args.live_host is not None or
                          args.live_param or args.live_rate is not None or
                          args.live_pace is not None):
        given = "--live-port" if args.live_port is not None else \
            "--live-host" if args.live_host is not None else \
            "--live-rate" if args.live_rate is not None else \
            "--live-pace" if args.live_pace is not None else "--live-param"
        raise ConfigError(given, "needs --live")
    args.bag_dir = "bags" if args.bag_dir is None else args.bag_dir
    config = config_from_args(args)  # an invalid YAML fails here, before any node starts
    if args.live_pace is not None:
        config = config.replace({"pace": args.live_pace})
    if args.plant == "mujoco" and config["protocol"] != "homing":
        print("exo-ilc run: --plant mujoco offers no reset service: protocol homing",
              file=sys.stderr)
        config = config.replace({"protocol": "homing"})
    deltas = args.mass_uncertainty or [config["mass_uncertainty"]]
    trials = config["max_trials"]
    root = _store_root(args)

    if isinstance(args.resume, str) and not uses_therapy(args):
        raise ConfigError("--resume", f"takes a session ({args.resume!r}) only with --patient")

    if uses_therapy(args):  # each exercise from the patient's profile, saved from the store
        if root is None:
            raise ConfigError("--no-store", "cannot be combined with --patient (the profile "
                              "is written from the run's store)")
        try:
            exercises = run_session_graph(args, config, root, _run_one)
            print_report(args, config, exercises)
            for summary in exercises:
                print()
                print(format_filed_metrics(summary.extra.get("therapy") or {},
                                           config["joint_names"]))
            return aborted_exit(exercises, "run")
        except (GraphError, KeyboardInterrupt) as exc:
            interrupted = isinstance(exc, KeyboardInterrupt)
            print(f"exo-ilc run: {'interrupted' if interrupted else exc}\nexo-ilc run: the graph "
                  f"was stopped; the profile holds every completed trial (and the store "
                  f"{root})", file=sys.stderr)
            resume = getattr(exc, "resume", None)  # set by run_session_graph
            if resume:
                print(f"exo-ilc run: {resume}", file=sys.stderr)
            return EXIT_INTERRUPTED if interrupted else EXIT_GRAPH
    runs: list[RunSummary] = []
    for delta in deltas:
        run_config = config.with_mass_uncertainty(delta)
        if root is not None:
            run_config = run_config.replace({"store.directory": str(root),
                                             "store.resume": bool(args.resume)})
            done = stored_trials(run_config, args.resume)
            print(f"store: {root}" + (f" (resuming after trial {done})" if done else ""),
                  file=sys.stderr, flush=True)
        try:
            runs.append(_run_one(args, run_config, delta, trials))
        except (GraphError, KeyboardInterrupt) as exc:
            interrupted = isinstance(exc, KeyboardInterrupt)
            print(f"exo-ilc run: {'interrupted' if interrupted else exc}", file=sys.stderr)
            if root is not None:
                again = [a for a in args.argv if a not in ("--resume",)]
                if "--store" not in again:
                    again += ["--store", str(root)]
                if len(deltas) > 1:  # the runs still to do, this one first
                    again = _with_deltas(again, deltas[deltas.index(delta):])
                print(f"exo-ilc run: the graph was stopped; every completed trial is saved in "
                      f"{root}. Continue with:\n  {shown_command()} {shlex.join(again)} --resume",
                      file=sys.stderr)
            return EXIT_INTERRUPTED if interrupted else EXIT_GRAPH
    print_report(args, config, runs)
    return aborted_exit(runs, "run")


EXIT_GRAPH = 3
"""Exit code: the graph stopped (a node died, a timeout); the store keeps what completed."""
EXIT_INTERRUPTED = 130
"""Exit code: Ctrl-C (the resume command is printed)."""


def _with_deltas(argv: list[str], deltas: list[float]) -> list[str]:
    """``argv`` with ``--mass-uncertainty`` naming only ``deltas``."""
    out: list[str] = []
    skipping = False
    for word in argv:
        if word == "--mass-uncertainty":
            skipping = True
            continue
        if skipping and not word.startswith("-"):
            continue
        skipping = False
        out.append(word)
    return [*out, "--mass-uncertainty", *(f"{d:g}" for d in deltas)]


def graph_domain(requested: int | None) -> int | None:
    """The domain id a graph runs on: ``--domain-id``, else an exported ``ROS_DOMAIN_ID`` (a ROS
    user's choice is honoured), else None (a free one is claimed)."""
    return requested if requested is not None else exported_domain_id()


def announce_graph(bar: Any, bag: Path | None) -> Callable[[Any], None]:
    """``on_start`` of a graph run: the domain id (for ``exo-ilc param`` from another terminal)
    and where the bag goes, printed once the nodes are up and before trial 1."""
    def on_start(session: Any) -> None:
        bar.write(f"graph on ROS_DOMAIN_ID={session.domain_id} (from another terminal: export "
                  f"ROS_DOMAIN_ID={session.domain_id}, then {shown_command()} param ...)",
                  file=sys.stderr)
        if bag is not None:
            bar.write(f"recording to bag: {bag}", file=sys.stderr)
        sys.stderr.flush()
    return on_start


def bag_name(args: argparse.Namespace, config: Config) -> str:
    """``graph_<law>_d<delta>_<date>``, or for a therapy exercise
    ``graph_<patient>_<exercise>_<law>_d<delta>_<date>`` (as ``simulate --patient`` names its
    ``sim_<patient>_...`` bags: ``report bags/*_<patient>_*`` finds both)."""
    from ..bag.run_writer import run_name
    patient = getattr(args, "patient", None)
    source = f"graph_{patient}_{config['exercise.name']}" if patient else "graph"
    return run_name(source, config["law"], config["mass_uncertainty"])


def _run_one(args: argparse.Namespace, run_config: Config, delta: float,
             trials: int) -> RunSummary:
    """One graph run (one mass uncertainty), with the live view beside it (``--live``)."""
    from ..orchestration.launcher import graph_nodes
    from ..orchestration.live import DEFAULT_HOST, DEFAULT_PORT, LiveView

    config = run_config
    nodes = graph_nodes(args.plant, config["protocol"])
    with contextlib.ExitStack() as stack:
        extra: list[Any] = []
        relay, rate = None, DISPLAY_RATE
        if getattr(args, "live", False):
            live = stack.enter_context(LiveView(
                run_config, DEFAULT_PORT if args.live_port is None else args.live_port,
                args.live_host or DEFAULT_HOST, dict(args.live_param),
                relayed=not args.no_bag,  # the recorder feeds it
                sample_rate=DISPLAY_RATE if args.live_rate is None else args.live_rate))
            print(f"live view: {live.url} (Foxglove app: Open connection, Foxglove WebSocket; "
                  f"layout made for this arm, kept while it runs: {live.layouts['foxglove']}, "
                  f"Lichtblick's {live.layouts['lichtblick']})", file=sys.stderr, flush=True)
            extra.append(live.spec)
            relay = live.relay
            rate = live.sample_rate
        return _run_graph_once(args, run_config, delta, trials, nodes, extra, relay, rate)


def _run_graph_once(args: argparse.Namespace, run_config: Config, delta: float, trials: int,
                    nodes: Any, extra: list[Any], relay: Path | None = None,
                    relay_rate: float = DISPLAY_RATE) -> RunSummary:
    from ..core.programs.metrics import TrialMetrics
    from ..orchestration.graph import run_graph
    from ..orchestration.recording import Recording
    config = run_config
    with progress_bar(total=trials, desc=f"graph {config['law']} delta={delta:g}",
                      unit="trial") as bar:
        def progress(summary: TrialSummary, bar: Any = bar) -> None:
            bar.update(1)
            notes = summary.values.get(topics.LEARNING_NOTES)
            if notes:  # as simulate prints them (e.g. norm_optimal's active constraints)
                bar.write(f"delta {delta:g}, learning from trial {summary.trial}: {notes}",
                          file=sys.stderr)
            errors = summary.row("max_abs_error", config["joint_names"])
            bar.set_postfix_str("max|e| " + " ".join(f"{x:.1e}" for x in errors))
        domain = graph_domain(args.domain_id)
        if args.no_bag:
            result = run_graph(run_config, domain, on_summary=progress,
                               on_start=announce_graph(bar, None), nodes=nodes, extra=extra)
        else:
            run_config = run_config.replace({"wait_for_recorder": True})
            with Recording(run_config, args.bag_dir, name=bag_name(args, run_config),
                           relay=relay, relay_rate=relay_rate) as recording:
                result = run_graph(run_config, domain, on_summary=progress,
                                   nodes=recording.graph_nodes(args.isolated_recorder, nodes),
                                   on_start=announce_graph(bar, recording.path), extra=extra)
            bar.write(f"bag: {recording.path}", file=sys.stderr)
            result.summary.extra["bag"] = str(recording.path)

    names = config["joint_names"]
    filed = [TrialMetrics.from_summary(s.trial, s.values, names) for s in result.summaries]
    result.summary.extra["metrics"] = [m.to_json() for m in filed if m is not None]
    return result.summary
