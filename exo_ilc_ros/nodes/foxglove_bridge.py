"""foxglove_bridge: the running graph, live, in the Foxglove app (Foxglove WebSocket protocol,
served by ``foxglove-sdk``; subprotocol ``foxglove.sdk.v1``).

A process of its own beside the graph (``exo-ilc run --live``, ``ros2 run exo_ilc_ros
foxglove_bridge``, the launch file's ``live:=true``). It reads the graph's topics through an
:class:`~.common.Inbox` (raw CDR, drained in batches: no executor wake-up per message) and
forwards the bytes untouched, each logged at its sim time
(:class:`~exo_ilc_ros.wire.sim_time.SimClock`, the bags' rule), on channels advertised with
their ``ros2msg`` schema:
``/joint_states``, ``/effort_controller/commands``, ``/ilc/feedforward``, ``/clock``,
``/ilc/trial_events``, ``/ilc/trial_summary``, ``/ilc/trial_metrics``, ``/diagnostics``, and
with a person strapped in (``musculoskeletal.model``) each cuff's ``/cuffs/<cuff>/wrench``,
``/person/joint_states`` and ``/person/robot_description`` (the person's display URDF, kept
and sent again to a late subscriber; ``/tf`` then also carries the person's frames per person
sample, :meth:`~exo_ilc_ros.bag.view.ArmView.person_tf`). It
adds the arm's view (:class:`~exo_ilc_ros.bag.view.ArmView`, the same messages every bag
holds): ``/robot_description`` (``std_msgs/String``, the arm's URDF from the run's config),
``/reference/robot_description`` (the same arm, links prefixed ``reference/``) and ``/tf``
(``tf2_msgs/TFMessage``: per sample one transform per joint of the measured arm, stamped with
the JointState stamp, and the reference pose q_d(t_i) of the trial's feed-forward on the
``reference/`` tree, placed beside the arm). ``/clock`` drives the app's clock
(``Capability.Time``). The protocol has no latching: what was logged before a client
subscribed (the URDFs, the last feed-forward, every trial's summary, metrics and events) is
logged again to a client that subscribes to a channel (to that client only), and the
current trial's samples from its start.

Beside ``exo-ilc run``'s recorder it is no DDS reader at all (parameter ``relay``): the
recorder, which takes every topic for the bag anyway, hands it the messages over a local socket
(:mod:`~exo_ilc_ros.wire.relay`), in the bag's order, so the loop's writers serve no extra
reader and the view's log times are the bag's.

It never slows the control loop: its own process; ``log()`` never blocks; a client that
reads too slowly loses its oldest messages (``message_backlog_size`` per client, the SDK's
rule), not the graph its rate; /tf is computed only while someone subscribes to it; the
per-sample topics are shown at a display rate (:class:`~exo_ilc_ros.wire.relay.SampleGate`,
default 200 per second of wall time: every sample of a real-time loop up to 200 Hz, a sample
every 5 ms of a lock-step simulation that runs faster), so its cost does not grow with the
graph's speed. Trial events, results, the feed-forward and /diagnostics are always shown.

Parameters: ``host`` (default 127.0.0.1: this machine only), ``port`` (8765; 0 = any free
port), ``config_file`` (the run's parameter YAML, for the arm; default the shipped one),
``message_backlog`` (per client, default 4096), ``sample_reliability`` (``best_effort``, the
default, or ``reliable``: how the per-sample topics are read, :func:`reader_qos`),
``relay`` (a Unix socket path to listen at for the recorder's feed instead of reading DDS;
default none; the recorder's ``relay_rate`` then sets the display rate), ``sample_rate`` (the
display rate, per-sample messages per second of wall time; 0: every sample), ``scheduling``
(``idle``, the default: the process runs at ``SCHED_IDLE``, on CPU the loop leaves free;
``batch``; ``normal``).
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

import foxglove
from foxglove import Channel, Schema
from foxglove.websocket import Capability, ServerListener
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ..bag.messages import typestore
from ..bag.view import ArmView
from ..core.arm.assets import AssetResolver, urdf_packages
from ..core.errors import ConfigError
from ..core.loop.rate import with_control_rate
from ..core.params.config import Config, load_config, urdf_source
from ..wire import topics
from ..wire.relay import DISPLAY_RATE, RelayReceiver, SampleGate
from ..wire.sim_time import SimClock
from ..wire.tf import TF
from .bag_recorder import message_class
from .common import Inbox, run_nodes
from .parameters import command_line_parameters
from .realtime import own_threads

NAME = "foxglove_bridge"
FORWARDED = topics.LIVE_TOPICS
"""The graph's topics the view forwards as they are."""
LATCHED = frozenset({topics.FEEDFORWARD, topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY,
                     topics.TRIAL_METRICS, topics.DIAGNOSTICS, topics.PERSON_DESCRIPTION})
"""Topics read transient local (their publishers keep a history for late joiners)."""
REPLAYED = {topics.FEEDFORWARD: 1, topics.TRIAL_EVENTS: None, topics.TRIAL_SUMMARY: None,
            topics.TRIAL_METRICS: None, topics.PERSON_DESCRIPTION: 1}
"""Topic -> how many of its last messages a new subscriber gets again (None: all)."""
TRIAL_SAMPLES = 100_000
"""Per-sample messages of the current trial kept per topic for a late viewer (at most; the
view's display rate keeps far fewer of a fast lock-step run): a viewer that subscribes within
a trial gets its samples from its start. A new trial's feed-forward starts the next
trial's; the run's earlier trials keep only their per-trial data (:data:`REPLAYED`)."""
READER_DEPTH = 10000
SCHEDULING = ("idle", "batch", "normal")
DEFAULT_SCHEDULING = "idle"
"""The view yields to the control loop (:func:`yield_to_the_loop`): on a busy machine it falls
behind (its readers hold 10 000 messages per topic; a client then sees the run late, or loses
the oldest), never the loop."""


def forwarded_topics(config: Config) -> tuple[str, ...]:
    """The graph's topics the view forwards for the run of ``config``: :data:`FORWARDED`, and
    with a person strapped in (``musculoskeletal.model``) :data:`topics.PERSON_LIVE_TOPICS`
    (the cuffs' wrenches and the person's joints per sample, the person's display URDF)."""
    person = str(config["musculoskeletal.model"]) != "none"
    return (*FORWARDED, *(topics.PERSON_LIVE_TOPICS if person else ()))


SAMPLED = topics.PER_SAMPLE
"""The control loop's per-sample topics."""
VIEWED_SAMPLES = (topics.JOINT_STATES, topics.PERSON_JOINT_STATES)
"""The per-sample topics /tf is computed from (the arm's, the person's)."""
SAMPLE_RELIABILITY = ("best_effort", "reliable")


def reader_qos(topic: str, samples: str = "best_effort") -> QoSProfile:
    """10 000 deep (between two drains). The per-sample topics (:data:`SAMPLED`) best effort
    by default (``samples``): the loop's writers then never repair a sample for the view, which
    runs at ``SCHED_IDLE`` and may fall behind; a sample it misses is lost to the view only.
    The rest reliable, and transient local where the publisher keeps a history (a view started
    late still gets the trials so far)."""
    best_effort = topic in SAMPLED and samples == "best_effort"
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=READER_DEPTH,
                      reliability=ReliabilityPolicy.BEST_EFFORT if best_effort
                      else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if topic in LATCHED
                      else DurabilityPolicy.VOLATILE)


def ros2_channel(topic: str, msgtype: str) -> Channel:
    """A CDR channel advertised with the full ``ros2msg`` definition of ``msgtype``."""
    text = typestore().generate_msgdef(msgtype, ros_version=2)[0]
    return Channel(topic, message_encoding="cdr",
                   schema=Schema(name=msgtype, encoding="ros2msg", data=text.encode()))


class _Listener(ServerListener):
    """Re-logs the messages a channel had before its new subscriber came (on an SDK thread)."""

    def __init__(self, bridge: FoxgloveBridge) -> None:
        self.bridge = bridge

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self.bridge.replay(str(channel.topic), int(client.id))


class FoxgloveBridge(Node):
    """Serves the graph's topics, the URDF and /tf over the Foxglove WebSocket protocol."""

    DRAINS_ON_STOP = True
    """On SIGINT/SIGTERM the last messages of the run are still forwarded
    (:class:`~.common.DrainingNode`), then the server stops."""
    FLUSH = 0.5
    """s given to the server to send what it holds before it stops."""
    RELAY_WAIT = 10.0
    """s at most to wait for the recorder's last messages after a stop."""

    def __init__(self) -> None:
        super().__init__(NAME)
        host = str(self.declare_parameter("host", "127.0.0.1").value)
        port = int(self.declare_parameter("port", 8765).value)
        config_file = str(self.declare_parameter("config_file", "").value)
        backlog = int(self.declare_parameter("message_backlog", 4096).value)
        samples = str(self.declare_parameter("sample_reliability", "best_effort").value)
        if samples not in SAMPLE_RELIABILITY:
            raise ConfigError("sample_reliability", f"use one of {', '.join(SAMPLE_RELIABILITY)}",
                              NAME)
        policy = str(self.declare_parameter("scheduling", DEFAULT_SCHEDULING).value)
        if policy not in SCHEDULING:
            raise ConfigError("scheduling", f"use one of {', '.join(SCHEDULING)}", NAME)
        config = with_control_rate(load_config(config_file or None))
        self.view = ArmView(config)
        self.assets = AssetResolver(
            Path(urdf_source(config.values)[1]) if config["model.source"] == "urdf" else None,
            urdf_packages(self.view.urdf))
        """The URDF's meshes, served on the client's ``fetchAsset`` (the assets capability)."""
        self.exit_code: int | None = None
        self.sim_clock = SimClock()
        self._lock = threading.Lock()
        self._kept: dict[str, list[tuple[int, bytes]]] = {
            topic: [(0, raw)] for topic, raw in self.view.descriptions().items()}
        self._trial: dict[str, list[tuple[int, bytes]]] = {topic: [] for topic in SAMPLED}
        """The current trial's per-sample messages shown so far (for a late viewer)."""
        forwarded = forwarded_topics(config)
        types = {**topics.BAG_TYPES, **topics.PERSON_TYPES}
        self.channels: dict[str, Channel] = {
            topic: ros2_channel(topic, types[topic]) for topic in (*forwarded,
                                                                   *topics.VIEW_TYPES)}
        try:
            self.server = foxglove.start_server(
                name="exo_ilc_ros", host=host, port=port, capabilities=[Capability.Time],
                server_listener=_Listener(self), message_backlog_size=backlog,
                asset_handler=self.assets.fetch)
        except Exception as exc:  # the SDK's own error type: a port in use, a bad address
            raise ConfigError("port", f"cannot serve on {host}:{port}: {exc} (another "
                              "program on that port? choose another with --live-port)",
                              NAME) from None
        relay = str(self.declare_parameter("relay", "").value)
        rate = float(self.declare_parameter("sample_rate", DISPLAY_RATE).value)
        try:
            self.gate = SampleGate(rate, SAMPLED)
        except ValueError as exc:
            raise ConfigError("sample_rate", str(exc), NAME) from None
        self.relay = RelayReceiver(relay) if relay else None
        self.inbox = Inbox(self)
        for topic in forwarded if self.relay is None else ():
            self.inbox.subscribe(message_class(types[topic]), topic, reader_qos(topic, samples))
        self.forwarded = 0
        feed = f"fed by the recorder at {relay}" if relay else "reading the graph's topics"
        # started at the priority it was given (imports, middleware, server: a few s of CPU
        # that SCHED_IDLE on a busy machine left it without for over a minute), serving from
        # now on below the loop, every thread of it
        print(f"[{NAME}] scheduling: {yield_to_the_loop(policy)}", file=sys.stderr, flush=True)
        self.get_logger().info(f"Foxglove WebSocket server on ws://{host}:{self.server.port} "
                               f"(subprotocol foxglove.sdk.v1; {feed}): open it in the "
                               "Foxglove app")
        print(json.dumps({"foxglove_port": self.server.port}), flush=True)

    def replay(self, topic: str, client: int | None = None) -> None:
        """Log ``topic``'s kept messages again to the ``client`` that just subscribed to it
        (its id is its sink's: the clients already subscribed get no copy; None: to all): the
        URDFs, the run's per-trial data, and the current trial's samples from its start (/tf
        computed again from its JointStates)."""
        channel = self.channels.get(topic)
        with self._lock:
            if topic == TF:  # the arm's and the person's, in sample order
                samples = sorted((log_time, sampled, raw) for sampled in VIEWED_SAMPLES
                                 for log_time, raw in self._trial.get(sampled, ()))
                kept = [out for out in (self.view.sample_tf(sampled, raw)
                                        for _, sampled, raw in samples) if out is not None]
            else:
                kept = list(self._kept.get(topic, ())) + list(self._trial.get(topic, ()))
        if channel is not None:
            for log_time, raw in kept:
                channel.log(raw, log_time=log_time, sink_id=client)

    def poll(self) -> int:
        """Forward what waits, in receive order; returns how many messages."""
        if self.relay is not None:  # already at the display rate, at the bag's log times
            taken = self.relay.take()
        else:  # every message advances the sim clock; the display rate picks the samples
            taken = []
            for received, topic, raw in self.inbox.take():
                log_time = self.sim_clock.advance(topic, raw)
                if self.gate.admit(topic, received):
                    taken.append((log_time, topic, raw))
        for log_time, topic, raw in taken:
            channel = self.channels[topic]
            if topic == topics.FEEDFORWARD:  # a new trial: its samples start here
                with self._lock:
                    self._load_reference(raw)
                    for samples in self._trial.values():
                        samples.clear()
            if topic in REPLAYED:
                self._keep(topic, log_time, raw)
            elif topic in SAMPLED:
                with self._lock:
                    samples = self._trial[topic]
                    if len(samples) < TRIAL_SAMPLES:
                        samples.append((log_time, raw))
            if channel.has_sinks():
                channel.log(raw, log_time=log_time)
            if topic in VIEWED_SAMPLES:
                self._transforms(topic, raw)
            elif topic == topics.PERSON_DESCRIPTION:
                with self._lock:
                    self._load_person(raw)
            elif topic == topics.CLOCK:
                self.server.broadcast_time(log_time)
        self.forwarded += len(taken)
        return len(taken)

    def drain(self) -> int:
        """Forward everything waiting (after a stop)."""
        return self.poll()

    def _keep(self, topic: str, log_time: int, raw: bytes) -> None:
        limit = REPLAYED[topic]
        with self._lock:
            kept = self._kept.setdefault(topic, [])
            kept.append((log_time, raw))
            if limit is not None and len(kept) > limit:
                del kept[:-limit]

    def _load_reference(self, raw: bytes) -> None:
        try:
            self.view.load_reference(raw)
        except ValueError as exc:  # a foreign profile: no reference pose, the rest goes on
            self.get_logger().warning(f"feed-forward not shown as the reference: {exc}")

    def _load_person(self, raw: bytes) -> None:
        try:
            self.view.load_person(raw)
        except ValueError as exc:  # no person drawn, the rest goes on
            self.get_logger().warning(f"the person not shown: {exc}")

    def _transforms(self, topic: str, raw: bytes) -> None:
        """/tf of one sample (:meth:`ArmView.sample_tf`: the arm's or the person's), while
        someone subscribes to it."""
        channel = self.channels[TF]
        if not channel.has_sinks():
            return
        out = self.view.sample_tf(topic, raw)
        if out is not None:
            channel.log(out[1], log_time=out[0])

    def destroy_node(self) -> None:
        """Stop the server (after :data:`FLUSH`), leave the subscriptions, then the node. Fed
        by the recorder, first forward what it still sends until it closes the relay (it
        sends the run's last messages once it has drained DDS, after we were told to stop;
        at most :data:`RELAY_WAIT` s)."""
        self.poll()
        if self.relay is not None:
            deadline = time.monotonic() + self.RELAY_WAIT
            while not self.relay.finished and time.monotonic() < deadline:
                time.sleep(0.01)
                self.poll()
        time.sleep(self.FLUSH)
        self.server.stop()
        self.inbox.destroy()
        if self.relay is not None:
            self.relay.close()
        print(f"[{NAME}] stopped: {self.forwarded} messages forwarded", file=sys.stderr,
              flush=True)
        super().destroy_node()


AUTOGROUP = Path("/proc/self/autogroup")
"""Linux's per-session scheduling group (``CONFIG_SCHED_AUTOGROUP``): its nice value weighs
the whole session against the others."""
AUTOGROUP_NICE = 19


def yield_to_the_loop(policy: str) -> str:
    """Run every thread of this process below the control loop (threads started later inherit
    it), once the view serves: ``idle`` (``SCHED_IDLE``: the view runs only on CPU the loop
    and everything else leave free), ``batch`` (``SCHED_BATCH`` at nice 10) or ``normal``.
    Returns what it runs at.

    With autogroups (most desktop kernels), each session is a scheduling group of its own, and
    a policy or nice value ranks a process only within its group: ``exo-ilc run`` starts every
    process of the graph in a session of its own (``launcher._die_with_parent``), so the view's
    ``SCHED_IDLE`` alone still took its group's full share of a core from the loop within
    trials (``bench/live_bench.py``). So when the process leads its own session (nothing else
    is in its group), the group's nice goes to 19 too (:func:`_nice_autogroup`); in a
    session it shares (a terminal, a launch file's) the group is left alone."""
    if policy == "normal":
        return "normal"
    idle = policy == "idle" and hasattr(os, "SCHED_IDLE")
    try:
        for tid in own_threads():
            try:
                if idle:
                    os.sched_setscheduler(tid, os.SCHED_IDLE, os.sched_param(0))
                    continue
                if hasattr(os, "SCHED_BATCH"):
                    os.sched_setscheduler(tid, os.SCHED_BATCH, os.sched_param(0))
                os.setpriority(os.PRIO_PROCESS, tid, max(10, os.getpriority(os.PRIO_PROCESS,
                                                                          tid)))
            except ProcessLookupError:  # a thread that ended meanwhile
                continue
    except OSError as exc:
        return f"normal ({exc.strerror})"
    return ("SCHED_IDLE" if idle else "SCHED_BATCH, nice 10") + _nice_autogroup()


def _nice_autogroup() -> str:
    """Lower this session's autogroup to :data:`AUTOGROUP_NICE` if the process leads the
    session (its group is its own); what was done, to append to the policy."""
    if os.getsid(0) != os.getpid():
        return ""
    try:
        AUTOGROUP.write_text(f"{AUTOGROUP_NICE}\n")
    except OSError:  # no autogroups (kernel, or sched_autogroup_enabled=0): nothing to do
        return ""
    return f", autogroup nice {AUTOGROUP_NICE}"


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros foxglove_bridge [--ros-args -p port:=8765]``; the
    process yields to the loop once it serves (``-p scheduling:=idle|batch|normal``, default
    idle)."""
    given = command_line_parameters(sys.argv if args is None else args, "/" + NAME)
    policy = str(given["scheduling"].value) if "scheduling" in given else DEFAULT_SCHEDULING
    if policy not in SCHEDULING:
        print(f"error: scheduling:={policy}: use one of {', '.join(SCHEDULING)}",
              file=sys.stderr)
        return 2
    return run_nodes([FoxgloveBridge], args)


if __name__ == "__main__":
    raise SystemExit(main())
