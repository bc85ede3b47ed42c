"""bag_recorder: records every topic of the graph into a rosbag2 MCAP bag, as received.

Subscribes with ``raw=True`` to each topic of :data:`exo_ilc_ros.wire.topics.TYPES` (and, when
the run's config straps a person in, :data:`~exo_ilc_ros.wire.topics.CUFF_TYPES`: the cuffs'
wrenches per sample) (QoS per topic: :func:`subscription_qos`, documented in docs/live-view.md)
and stores the CDR bytes untouched. Log time = simulated time, as ``ros2 bag record
--use-sim-time`` logs it: the recorder's sim clock at receipt
(:class:`~exo_ilc_ros.wire.sim_time.SimClock`: every sample and /clock message at its own stamp,
a message without one at the sim time of the last stamped message received before it). Publish
time = the wall-clock time (ns since the epoch) DDS received the message (kept for latency
analysis). The subscriptions are :class:`~.common.Inbox` es, so the recorder does not wake once
per message next to the control loop. Within a trial it stays out of the loop's way: it reads
only the trial events every ``INBOX_PERIOD``, and takes and writes the other topics (the
samples, commands, /clock) at the next trial event, or after :data:`DATA_PERIOD` at the latest;
DDS holds them meanwhile (``RECORDER_DEPTH``). The samples between two trial events go to the
bag as one batch (``BagWriter.write_many``).
The bag also holds the arm as the live view shows it (:class:`~exo_ilc_ros.bag.view.ArmView`,
the view's own code): ``/robot_description`` and ``/reference/robot_description`` once, at the
start, and a ``/tf`` per recorded JointState at its stamp (publish time: the JointState's).
With a person strapped in, also the person's display URDF and joints (recorded as the plant
publishes them) and a ``/tf`` of the person's frames per ``/person/joint_states`` sample
(:meth:`~exo_ilc_ros.bag.view.ArmView.person_tf`).
The transforms are computed when a trial's file is finished (:meth:`BagRecorder._split`),
between trials, never within one.
``exo-ilc run`` starts it in the supervisor's process (``container ilc_supervisor
bag_recorder``), where it shares the supervisor's /joint_states subscription.
A new storage file starts after each trial (``split_every`` trials), so a SIGKILL loses at most
the trial being recorded; Ctrl-C / SIGTERM close the bag normally. ``custom_data`` holds the
run's provenance and every parameter change with the trial it took effect at.

Parameters (the recorder's own, not part of the experiment's schema):
``bag_path`` (default ``bags/<run_name>``), ``run_name`` (default ``run_<date>-<time>``),
``config_file`` (the run's effective parameter YAML, for the provenance), ``split_every``
(trials per storage file, default 1; 0: one file), ``storage`` (``mcap`` or ``sqlite3``),
``relay`` (a Unix socket path: hand every message of ``topics.LIVE_TOPICS`` (and of
``topics.PERSON_LIVE_TOPICS``) it takes to the
live view listening there, at the bag's log time, :mod:`~exo_ilc_ros.wire.relay`; then the
other topics are also taken every :data:`RELAY_PERIOD`, and written when they would be
without a view; default none) and ``relay_rate`` (the
view's display rate, per-sample messages per second of wall time, 0: every one;
:class:`~exo_ilc_ros.wire.relay.SampleGate`).
"""

from __future__ import annotations

import importlib
import json
import sys
import time
from datetime import datetime
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import ParameterEvent
from rclpy.node import Node
from rclpy.parameter import parameter_value_to_python
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from .. import __version__
from ..bag.provenance import (
    RECORDED_BY,
    RUN_NAME,
    TRIALS_COMPLETED,
    VERSION,
    ParameterChange,
    parameter_changes_data,
    provenance_data,
)
from ..bag.view import ArmView
from ..bag.writer import BagWriter
from ..core.errors import ConfigError
from ..core.loop.rate import with_control_rate
from ..core.params.config import load_config
from ..wire import topics
from ..wire.protocol import int_value, key_values
from ..wire.qos import RECORDER_DEPTH, TRANSIENT_LOCAL_TOPICS, offered_qos
from ..wire.relay import DISPLAY_RATE, RelaySender, SampleGate
from ..wire.sim_time import SimClock
from .common import EVENTS_QOS, CountingPublisher, Inbox, receive_time, run_nodes, wall_clock
from .diagnostics import diagnostic_array, status

NAME = "bag_recorder"
READY_TOPICS = (topics.JOINT_STATES, topics.CLOCK, topics.EFFORT_COMMANDS, topics.FEEDFORWARD,
                topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY, topics.TRIAL_METRICS)
"""Topics whose subscriptions must be matched with a publisher before the recorder reports
``ready`` (the supervisor starts trial 1 only then). Matched, not merely known to the graph:
each reader-writer pair is discovered on its own, and a volatile topic published before its
pair matched is lost to the recorder (/clock was not waited for, and once its first 26
messages of trial 1 were missing)."""
LIVE = frozenset((*topics.LIVE_TOPICS, *topics.PERSON_LIVE_TOPICS))
"""Topics relayed to the live view (``relay``; the person's only where recorded: a person's
run)."""
VIEWED = frozenset({topics.JOINT_STATES, topics.FEEDFORWARD, topics.PERSON_JOINT_STATES,
                    topics.PERSON_DESCRIPTION})
"""Topics the arm's view (/tf) is computed from (and, a person strapped in, the person's)."""
PROTOCOL_TOPICS = frozenset({topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY, topics.PARAMETER_EVENTS})
"""Topics the recorder reads as well as writes (trial boundaries, parameter changes); the rest
are written in batches."""
RELAY_PERIOD = 0.05
"""s: with a relay to the live view, the other topics are also taken this often (what the
view shows is at most this late); they are still written every :data:`DATA_PERIOD` and at
trial events, as without a view (so the bag's writing stays out of the trials)."""
DATA_PERIOD = 1.0
"""s: the other topics are taken and written at least this often (and at every trial event).
Within it DDS holds them: at most ``RECORDER_DEPTH`` (10 000) messages per topic, 10 000 / s,
four times the lock-step graph's fastest rate seen here and ten times 1 kHz."""


def message_class(msgtype: str) -> Any:
    """The rclpy message class of ``pkg/msg/Name``."""
    package, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


def subscription_qos(topic: str) -> QoSProfile:
    """Reliable, ``RECORDER_DEPTH`` deep; transient local where the publisher latches."""
    durable = topic in TRANSIENT_LOCAL_TOPICS
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RECORDER_DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if durable
                      else DurabilityPolicy.VOLATILE)


class BagRecorder(Node):
    """Writes the graph's topics into a bag, one storage file per trial."""

    DRAINS_ON_STOP = True
    """On SIGINT/SIGTERM :func:`~.common.run_nodes` polls on until the last messages are in
    (a :class:`~.common.DrainingNode`)."""

    def __init__(self) -> None:
        super().__init__(NAME)
        stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
        self.run_name = str(self.declare_parameter("run_name", f"run_{stamp}").value)
        bag_path = str(self.declare_parameter("bag_path", "").value)
        config_file = str(self.declare_parameter("config_file", "").value)
        self.split_every = int(self.declare_parameter("split_every", 1).value)
        storage = str(self.declare_parameter("storage", "mcap").value)
        relay = str(self.declare_parameter("relay", "").value)
        rate = float(self.declare_parameter("relay_rate", DISPLAY_RATE).value)
        self.relay = RelaySender(relay, topics.PER_SAMPLE) if relay else None
        """The live view's feed (:mod:`~exo_ilc_ros.wire.relay`), when it runs beside us."""
        try:
            self.relay_gate = SampleGate(rate, topics.PER_SAMPLE)
        except ValueError as exc:
            raise ConfigError("relay_rate", str(exc), NAME) from None
        path = Path(bag_path) if bag_path else Path("bags") / self.run_name

        custom = {VERSION: "", RECORDED_BY: NAME, RUN_NAME: self.run_name}
        if config_file:
            config = with_control_rate(load_config(config_file))
            custom = provenance_data(config, recorded_by=NAME, run_name=self.run_name)
        else:
            config = load_config()
            custom[VERSION] = __version__
            self.get_logger().warning("no config_file given: the bag will not hold the run's "
                                      "config (its /robot_description is the shipped arm)")
        self.view: ArmView | None = None
        try:
            self.view = ArmView(config)
        except Exception as exc:  # the recording goes on: only the arm's view is missing
            self.get_logger().error(f"no /robot_description or /tf in the bag: {exc}")
        self.view_pending: list[tuple[int, str, bytes]] = []
        """The samples and feed-forwards since the last file, for their /tf (:meth:`_split`)."""
        self.writer = BagWriter(path, storage=storage, custom_data=custom)
        self.writer.open()
        self.started = 0
        """The last trial that started (0: none yet)."""
        self.running: int | None = None
        """The trial between its start and end events, else None."""
        self.completed = 0
        """The last trial whose end event is recorded (``trials_received``)."""
        self.filed = 0
        """The last trial filed: its end event and summary written and its storage file
        finished (``trials_filed``; the supervisor stores a trial only once it is filed)."""
        self.ended: int | None = None
        """A trial that ended but whose summary has not arrived yet."""
        self.summarised: set[int] = set()
        self.changes: list[ParameterChange] = []
        self.messages = 0
        self.sim_clock = SimClock()
        """The recorder's sim clock: every message's log time."""
        self.exit_code: int | None = None
        """Never set: the recorder has no fatal error of its own (a bag error raises)."""

        self.events = Inbox(self, "events")  # PROTOCOL_TOPICS, read at every poll
        self.inbox = Inbox(self)  # every other topic, taken at events (see poll)
        self.subscriptions_by_topic: dict[str, Any] = {}
        recorded = {**topics.TYPES, **(topics.PERSON_TYPES if str(
            config["musculoskeletal.model"]) != "none" else {})}  # a person: its topics too
        for topic, msgtype in recorded.items():
            self.writer.add_topic(topic, msgtype, offered_qos(topic))
            inbox = self.events if topic in PROTOCOL_TOPICS else self.inbox
            self.subscriptions_by_topic[topic] = inbox.subscribe(
                message_class(msgtype), topic, subscription_qos(topic))
        self.ready_topics = (*READY_TOPICS, *sorted(topic for topic in topics.PER_SAMPLE
                                                    if topic in topics.PERSON_TYPES
                                                    and topic in recorded))
        """:data:`READY_TOPICS`, and a person's per-sample topics when recorded (volatile as
        the samples: a reader matched late would miss the first)."""
        for topic, msgtype in topics.VIEW_TYPES.items():  # computed here, not subscribed to
            self.writer.add_topic(topic, msgtype, offered_qos(topic))
        for topic, raw in (self.view.descriptions() if self.view else {}).items():
            self.writer.write(topic, self.sim_clock.ns, raw, time.time_ns())
            self.messages += 1
        self.data_due = 0.0
        """Monotonic time by which the other topics are taken and written again
        (:data:`DATA_PERIOD`)."""
        self.relay_due = 0.0
        """With a relay: monotonic time by which the other topics are taken again for the
        view (:data:`RELAY_PERIOD`)."""
        self.unwritten: list[tuple[int, str, bytes, int]] = []
        """Messages taken for the view but not written yet (log time, topic, CDR, receive
        time), in receive order: written before anything taken after them."""
        self.status_pub = self.create_publisher(
            message_class(topics.TYPES[topics.DIAGNOSTICS]), topics.DIAGNOSTICS, EVENTS_QOS,
            publisher_class=CountingPublisher)
        self.create_timer(0.2, self.on_status_timer, clock=wall_clock())
        self.get_logger().info(f"recording {len(recorded)} topics to {path}")

    def on_status_timer(self) -> None:
        """``ready`` on /diagnostics once the subscription of every :attr:`ready_topics` is
        matched with a publisher (the supervisor waits for it when ``wait_for_recorder`` is
        set)."""
        missing = [topic for topic in self.ready_topics
                   if self.subscriptions_by_topic[topic].get_publisher_count() < 1]
        message = "waiting" if missing else "ready"
        values = [*self.status_values(), *(("waiting_for", topic) for topic in missing)]
        self.status_pub.publish(diagnostic_array(
            self, [status(topics.RECORDER_STATUS, message, values, hardware_id=NAME)]))

    def status_values(self) -> list[tuple[str, str]]:
        """The status key-values (:data:`topics.RECORDER_STATUS`): the bag, messages written,
        the last trial whose end was recorded and the last trial filed."""
        return [("bag", str(self.writer.path)), ("messages", str(self.messages)),
                ("trials_received", str(self.completed)), ("trials_filed", str(self.filed))]

    def poll(self, everything: bool = False) -> int:
        """Write what waits, in the order DDS received it; returns how many messages. The
        other topics only with a trial event or parameter change, after :data:`DATA_PERIOD`,
        or with ``everything``; else only the (mostly empty) protocol topics are looked at.
        With a relay, the other topics are also taken every :data:`RELAY_PERIOD` for the
        view; what is taken then is written with the next batch (:attr:`unwritten`), when it
        would be written without a view (between trials), not within a trial."""
        taken = self.events.take()
        now = time.monotonic()
        write = bool(taken) or everything or now >= self.data_due
        if write:
            self.data_due = now + DATA_PERIOD
        if write or (self.relay is not None and now >= self.relay_due):
            self.relay_due = now + RELAY_PERIOD
            data = self.inbox.take()
            taken = sorted([*taken, *data], key=receive_time) if taken else data
        samples, self.unwritten = self.unwritten, []  # one batch up to an event
        shown: list[tuple[int, str, bytes]] = []  # for the live view (relay)
        relay, admit, advance = self.relay, self.relay_gate.admit, self.sim_clock.advance
        for received, topic, raw in taken:
            log_time = advance(topic, raw)
            if relay is not None and topic in LIVE and admit(topic, received):
                shown.append((log_time, topic, raw))
            if topic in PROTOCOL_TOPICS:  # (only when ``write``: taken with the events)
                self.messages += self.writer.write_many(samples)
                samples = []
                self.on_message(topic, raw, received)
            else:
                samples.append((log_time, topic, raw, received))
                if topic in VIEWED and self.view is not None:
                    self.view_pending.append((received, topic, raw))
        if write:
            self.messages += self.writer.write_many(samples)
        else:
            self.unwritten = samples
        if relay is not None:
            relay.send(shown)
        return len(taken)

    def write_view(self) -> int:
        """The /tf of every sample taken since the last call, in receive order (a feed-forward
        sets the reference of the samples after it), each at its sample's stamp; returns how
        many."""
        pending, self.view_pending = self.view_pending, []
        view = self.view
        if view is None:
            return 0
        batch: list[tuple[int, str, bytes, int]] = []
        for received, topic, raw in sorted(  # the person's URDF before its samples
                pending, key=lambda m: m[1] != topics.PERSON_DESCRIPTION):
            if topic == topics.PERSON_DESCRIPTION:
                try:
                    view.load_person(raw)
                except ValueError as exc:
                    self.get_logger().warning(f"/tf without the person: {exc}", once=True)
                continue
            if topic == topics.FEEDFORWARD:
                try:
                    view.load_reference(raw)
                except ValueError as exc:
                    self.get_logger().warning(f"/tf without the reference arm: {exc}",
                                              once=True)
                continue
            tf = view.sample_tf(topic, raw)
            if tf is not None:
                batch.append((tf[0], topics.TF, tf[1], received))
        written = self.writer.write_many(batch)
        self.messages += written
        return written

    def drain(self) -> int:
        """Write everything waiting (after a stop; see :class:`~.common.DrainingNode`)."""
        return self.poll(everything=True)

    def on_message(self, topic: str, raw: bytes, received_ns: int) -> None:
        """Store the bytes at the sim clock (publish time: the DDS receive time, wall clock,
        ns); follow the trial protocol to split the bag at trial boundaries."""
        if topic == topics.TRIAL_EVENTS:
            self._before_event(raw)
        self.writer.write(topic, self.sim_clock.ns, raw, received_ns)
        self.messages += 1
        if topic == topics.TRIAL_EVENTS:
            self._after_event(raw)
        elif topic == topics.TRIAL_SUMMARY:
            self.on_summary(raw)
        elif topic == topics.PARAMETER_EVENTS:
            self.on_parameter_event(raw)

    def _events(self, raw: bytes) -> list[tuple[str, int | None]]:
        msg = deserialize_message(raw, message_class(topics.TYPES[topics.TRIAL_EVENTS]))
        out = []
        for item in msg.status:
            if item.name == topics.TRIAL_STATUS:
                out.append((item.message, int_value(key_values(item), "trial")))
        return out

    def _before_event(self, raw: bytes) -> None:
        """A trial starting while the previous one awaits its summary: split first."""
        if self.ended is not None and any(e == "start" for e, _ in self._events(raw)):
            self._split()

    def _after_event(self, raw: bytes) -> None:
        for event, trial in self._events(raw):
            if event == "start" and trial is not None:
                self.started, self.running = trial, trial
            elif event == "end" and trial is not None:
                self.running = None
                self.completed = max(self.completed, trial)
                self.ended = trial
                if trial in self.summarised:
                    self._split()
            elif event == "aborted":
                self.running = None
            elif event == "finished" and self.ended is not None:
                self._split()

    def on_summary(self, raw: bytes) -> None:
        """The summary of trial k: split if its end event is in already."""
        msg = deserialize_message(raw, message_class(topics.TYPES[topics.TRIAL_SUMMARY]))
        for item in msg.status:
            trial = int_value(key_values(item), "trial")
            if item.name == topics.SUMMARY_STATUS and trial is not None:
                self.summarised.add(trial)
                if self.ended == trial:
                    self._split()

    def on_parameter_event(self, raw: bytes) -> None:
        """Note every changed parameter with the trial it applies from (the next boundary)."""
        event = deserialize_message(raw, ParameterEvent)
        stamp = int(event.stamp.sec) * 1_000_000_000 + int(event.stamp.nanosec)
        for parameter in event.changed_parameters:
            value = parameter_value_to_python(parameter.value)
            if isinstance(value, (list, tuple)) or type(value).__name__ == "array":
                value = list(value)
            self.changes.append(ParameterChange(event.node, parameter.name, value, stamp,
                                                self.running, self.started + 1))
            self.get_logger().info(f"parameter {event.node} {parameter.name} = "
                                   f"{json.dumps(value)}, from trial {self.started + 1}")
        if event.changed_parameters:
            for key, text in parameter_changes_data(self.changes).items():
                self.writer.set_custom_data(key, text)

    def _split(self) -> None:
        """The trial's /tf (:meth:`write_view`), then its file is finished and filed."""
        trial, self.ended = self.ended, None
        self.write_view()
        self.writer.set_custom_data(TRIALS_COMPLETED, str(self.completed))
        for key, text in parameter_changes_data(self.changes).items():
            self.writer.set_custom_data(key, text)
        if self.split_every > 0 and trial is not None and trial % self.split_every == 0:
            self.writer.split()
        if trial is not None:
            # Only now (the trial's file is finished and listed) tell the supervisor, which
            # waits for this before the next trial: a kill -9 from here on loses no ended trial.
            self.filed = max(self.filed, trial)
            self.on_status_timer()

    def destroy_node(self) -> None:
        """Close the bag (writes the last file and metadata.yaml), then the node."""
        self.poll(everything=True)
        if self.relay is not None:  # the view waits for this before it stops
            self.relay.close()
            if self.relay.dropped:
                print(f"[{NAME}] the live view did not keep up: {self.relay.dropped} samples "
                      "not shown (the bag has them)", file=sys.stderr, flush=True)
        self.write_view()
        self.events.destroy()
        self.inbox.destroy()
        self.writer.set_custom_data(TRIALS_COMPLETED, str(self.completed))
        for key, text in parameter_changes_data(self.changes).items():
            self.writer.set_custom_data(key, text)
        self.writer.close()
        print(f"[{NAME}] bag {self.writer.path} closed: {self.messages} messages, "
              f"{self.completed} trials", file=sys.stderr, flush=True)  # rclpy may be shut down
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros bag_recorder``. SIGINT and SIGTERM stop it cleanly:
    what was published before is still taken and written, then the bag is closed."""
    return run_nodes([BagRecorder], args)


if __name__ == "__main__":
    raise SystemExit(main())
