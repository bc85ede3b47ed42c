"""Reading a run back from any rosbag2 bag (MCAP or sqlite3, ours or ``ros2 bag record``'s).

MCAP files are read only after their CRCs are checked (:mod:`.mcap_messages`): a damaged file
is refused by name with what failed; files written before exo_ilc_ros wrote CRCs read with a
note. sqlite3 bags are read with rosbags' ``AnyReader``.

Trials are cut out of ``/joint_states`` by the header stamps of the trial start/end events
(falling back to the summaries' stamps when the events were not recorded); each sample goes to
index ``round((stamp - start) / period)``, so a dropped message leaves a NaN row, never a shift.
The reference and the learned feed-forward come from ``/ilc/feedforward`` (or the bag's config),
the effort commands are matched to the last joint state received before them.

``aborted`` events are told apart by their ``reason``: ``error_envelope`` marks a trial that is
kept as recorded, with ``aborted_at`` (:attr:`TrialData.aborted_at`); any other reason
(``watchdog``, a stuck protocol step) means that attempt was dropped and the trial run again
(:attr:`TrialData.reruns`; the last start counts). A ``resumed`` event (no trial number) says the
run continued from its store (:attr:`BagRun.resumed_after`): the earlier trials are in the
interrupted run's bag, not this one.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..core.protocol.timing import STEP_TIMEOUT
from ..core.reference.build import build_reference
from ..core.session.summary import RunSummary, law_segments
from ..wire import protocol, topics
from ..wire.cdr import joint_states
from . import messages
from .errors import BagReadError
from .mcap_messages import McapReadError, read_mcap_topics
from .provenance import ParameterChange, Provenance, read_provenance


@dataclass
class TrialData:
    """One trial as recorded, sampled at t_i = i * period (NaN rows where a sample is missing)."""

    trial: int
    time: np.ndarray
    reference_position: np.ndarray
    reference_velocity: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    """Effort the plant applied over the period that *ended* at each sample (JointState)."""
    summary: dict[str, str] = field(default_factory=dict)
    ended: bool = False
    """An ``end`` event (or a summary) was recorded for the trial."""
    aborted_at: int | None = None
    """Sample at which the error envelope aborted the trial (safe hold from there on; the trial
    is kept and the law did not learn from it; -1 if the bag does not say at which sample);
    None if it was not aborted."""
    reruns: list[str] = field(default_factory=list)
    """Why each earlier attempt of the trial was aborted and run again (e.g. ``watchdog``)."""
    command_messages: list[bytes] = field(default_factory=list, repr=False)
    """The trial's effort commands (CDR), one per sample when all were recorded."""
    feedforward_message: bytes | None = field(default=None, repr=False)
    decode: Callable[[bytes, str], Any] | None = field(default=None, repr=False)

    @cached_property
    def command(self) -> np.ndarray:
        """Effort the controller commanded at each sample (NaN where not recorded); decoded
        on first use."""
        samples, joints = np.shape(self.position)
        rows = np.full((samples, joints), np.nan)
        if self.decode is not None and len(self.command_messages) == samples:
            msgtype = topics.TYPES[topics.EFFORT_COMMANDS]
            for i, raw in enumerate(self.command_messages):
                data = self.decode(raw, msgtype).data
                if len(data) == joints:
                    rows[i] = data
        return rows

    @cached_property
    def feedforward(self) -> np.ndarray | None:
        """u_ff of the trial (from its /ilc/feedforward profile; None if not recorded)."""
        if self.decode is None or self.feedforward_message is None:
            return None
        msg = self.decode(self.feedforward_message, topics.TYPES[topics.FEEDFORWARD])
        if len(msg.points) != self.position.shape[0]:
            return None
        return np.array([p.accelerations for p in msg.points], dtype=float)

    @property
    def missing_samples(self) -> int:
        """Samples of the trial with no JointState."""
        return int(np.count_nonzero(np.isnan(self.position[:, 0])))

    @property
    def complete(self) -> bool:
        """Ended, with every sample recorded."""
        return self.ended and self.missing_samples == 0

    @property
    def error(self) -> np.ndarray:
        """e = q_d - q."""
        return np.asarray(self.reference_position - self.position)

    @property
    def max_abs_error(self) -> np.ndarray:
        """max_t |e_j| per joint over the recorded samples."""
        return np.asarray(np.nanmax(np.abs(self.error), axis=0))


@dataclass
class BagRun:
    """A run read from one bag."""

    path: Path
    storage: str
    joint_names: list[str]
    period: float
    provenance: Provenance
    trials: dict[int, TrialData]
    summaries: dict[int, dict[str, str]]
    parameter_changes: list[ParameterChange]
    notes: list[str] = field(default_factory=list)
    """What the reader had to work around (missing topics, incomplete trials, ...)."""
    resumed_after: int | None = None
    """The run was resumed from its store after this trial (``resumed`` event): trials
    1..resumed_after ran before this recording (another bag) and are not in this bag."""

    @property
    def aborted(self) -> list[int]:
        """Trials the error envelope aborted (kept, marked, not learned from), in order."""
        return sorted(k for k, t in self.trials.items() if t.aborted_at is not None)

    @property
    def completed(self) -> list[int]:
        """Trials that ended, in order."""
        return sorted(k for k, t in self.trials.items() if t.ended)

    @property
    def incomplete(self) -> list[int]:
        """Trials that started but have no end (the run was stopped or the recorder killed)."""
        return sorted(k for k, t in self.trials.items() if not t.ended)

    @property
    def mass_uncertainty(self) -> float:
        """From the provenance, else the summaries (NaN if neither has it)."""
        if self.provenance.mass_uncertainty is not None:
            return self.provenance.mass_uncertainty
        for values in self.summaries.values():
            if "mass_uncertainty" in values:
                return float(values["mass_uncertainty"])
        return math.nan

    @property
    def law(self) -> str:
        """From the provenance, else the summaries."""
        if self.provenance.law:
            return self.provenance.law
        for values in self.summaries.values():
            if "law" in values:
                return values["law"]
        return "?"

    @property
    def error_bound(self) -> float:
        """The config's bound (0.005 rad, the paper's, if the bag has no config)."""
        values = self.provenance.config_values or {}
        return float(values.get("error_bound", 0.005))

    def live_changes(self, count: int | None = None) -> list[dict[str, Any]]:
        """The run's live parameter changes, each with the first trial run with it: the
        supervisor's own record (its summaries' ``parameters_changed``, as ``simulate --replay``
        uses it) where the bag has it, the other nodes' from the recorder's
        ``/parameter_events`` (whose trial a change sent near a boundary may be one off)."""
        applied: list[dict[str, Any]] = []
        for k in range(1, (max(self.completed, default=0) if count is None else count) + 1):
            text = self.summaries.get(k, {}).get(protocol.PARAMETERS_CHANGED)
            try:
                values = json.loads(text) if text else {}
            except ValueError:
                values = {}
            applied += [{"trial": k + 1, "node": "ilc_supervisor", "parameter": name,
                         "value": value} for name, value in sorted(values.items())]
        recorded = [{"trial": c.effective_trial, "node": c.node.lstrip("/"), "parameter": c.name,
                     "value": c.value} for c in self.parameter_changes
                    if not (applied and c.node.lstrip("/") == "ilc_supervisor")]
        return sorted(applied + recorded, key=lambda c: int(c["trial"]))

    def summary(self) -> RunSummary:
        """The per-trial table of the ended trials 1..K: max |e| from the recorded samples, or
        from the trial's summary where samples are missing; NaN rows for trials not recorded."""
        count = max(self.completed, default=0)
        joints = len(self.joint_names)
        errors = np.full((count, joints), np.nan)
        ff = np.full((count, joints), np.nan)
        effort = np.full((count, joints), np.nan)
        sources: list[str] = []
        for k in range(1, count + 1):
            trial = self.trials.get(k)
            values = self.summaries.get(k, {})
            recorded = protocol.per_joint(values, "max_abs_error", self.joint_names)
            if trial is not None and trial.ended and trial.missing_samples == 0:
                errors[k - 1] = trial.max_abs_error
                sources.append("samples")
            elif recorded is not None:
                errors[k - 1] = recorded
                sources.append("summary")
            else:
                sources.append("missing")
            recorded_ff = protocol.per_joint(values, "max_abs_feedforward", self.joint_names)
            if recorded_ff is not None:
                ff[k - 1] = recorded_ff
            elif trial is not None and trial.feedforward is not None:
                ff[k - 1] = np.max(np.abs(trial.feedforward), axis=0)
            v = protocol.per_joint(values, "max_abs_effort", self.joint_names)
            if v is not None:
                effort[k - 1] = v
            elif trial is not None and not np.all(np.isnan(trial.command)):
                effort[k - 1] = np.nanmax(np.abs(trial.command), axis=0)
        true_rows = [protocol.per_joint(self.summaries.get(k, {}), "true_max_abs_error",
                                        self.joint_names) for k in range(1, count + 1)]
        true = np.array(true_rows) if count and all(r is not None for r in true_rows) \
            else None  # the virtual patient's true max |e|, from the summaries
        extra: dict[str, Any] = {"bag": str(self.path), "sources": sources}
        if self.incomplete:
            extra["incomplete_trials"] = self.incomplete
        if self.aborted:
            extra["aborted_trials"] = self.aborted
        if self.resumed_after is not None:
            extra["resumed_after"] = self.resumed_after
        changes = self.live_changes(count)
        if changes:
            extra["live_changes"] = changes
        again = [{"trial": k, "reason": reason} for k, t in sorted(self.trials.items())
                 for reason in t.reruns]
        if again:
            extra["reruns"] = again
        laws = law_segments(self.law, changes)
        if laws:
            extra["laws"] = laws
        return RunSummary(self.mass_uncertainty, self.law, self.error_bound, errors,
                          None if np.isnan(ff).all() else ff,
                          None if np.isnan(effort).all() else effort, extra, true)


def read_metadata(path: Path) -> dict[str, Any]:
    """``rosbag2_bagfile_information`` of the bag at ``path``."""
    meta = path / "metadata.yaml"
    try:
        document = yaml.safe_load(meta.read_text())
    except OSError as exc:
        raise BagReadError(path, f"no readable metadata.yaml ({exc.strerror}); is it a "
                           "rosbag2 bag directory?") from None
    except yaml.YAMLError as exc:
        raise BagReadError(meta, f"invalid YAML: {exc}") from None
    if not isinstance(document, dict) or "rosbag2_bagfile_information" not in document:
        raise BagReadError(meta, "no rosbag2_bagfile_information")
    info = document["rosbag2_bagfile_information"]
    return info if isinstance(info, dict) else {}


def trials_filed(path: Path | str) -> int:
    """Trials the recorder has finished files for, from ``metadata.yaml`` (rewritten after each
    trial); 0 while there is no readable metadata yet (a live or just-started recording)."""
    try:
        info = read_metadata(Path(path))
    except BagReadError:
        return 0
    return read_provenance(info.get("custom_data")).trials_completed or 0


@dataclass
class _Stream:
    """Messages of one topic: log times, and the decoded messages (or the raw ones, for the
    topics decoded lazily)."""

    log: list[int] = field(default_factory=list)
    msgs: list[Any] = field(default_factory=list)


def _read_topics(path: Path, info: dict[str, Any], skip_damaged: bool, wanted: Sequence[str],
                 raw_topics: Iterable[str]
                 ) -> tuple[dict[str, _Stream], Callable[[bytes, str], Any], list[str]]:
    """The ``wanted`` topics' messages in log-time order (deserialised, or raw for
    ``raw_topics``), the deserialiser, and notes. MCAP files are read by
    :mod:`.mcap_messages` after their CRCs are checked; other storages by rosbags."""
    if info.get("storage_identifier") == "mcap":
        return _read_mcap(path, info, wanted, set(raw_topics), skip_damaged)
    return (*_read_with_rosbags(path, wanted, raw_topics), [])


def _read_mcap(path: Path, info: dict[str, Any], wanted: Sequence[str], keep_raw: set[str],
               skip_damaged: bool
               ) -> tuple[dict[str, _Stream], Callable[[bytes, str], Any], list[str]]:
    """Every file of the bag in turn: refused by name if a checksum fails (or left out with a
    note, ``skip_damaged``); a note for files without CRCs (written before exo_ilc_ros wrote
    bags with ``mcap``: damage to them cannot be seen). Each topic's messages are then put in
    log-time order (stable), as rosbags does."""
    streams = {t: _Stream() for t in wanted}
    types: dict[str, str] = {}
    unchecked: list[str] = []
    notes: list[str] = []
    for name in info.get("relative_file_paths") or []:
        file = path / str(name)
        if not file.is_file():
            raise BagReadError(file, "is listed in metadata.yaml but missing")
        try:
            found = read_mcap_topics(file, wanted)
        except OSError as exc:
            raise BagReadError(file, f"cannot be read ({exc.strerror or exc})") from None
        except McapReadError as exc:
            raise BagReadError(file, f"is damaged ({exc}); it carries no CRCs that would say "
                               "where") from None
        check = found.check
        if not check.intact:
            damage = "is corrupt, its checksums do not match: " + "; ".join(check.problems)
            if not skip_damaged:
                raise BagReadError(file, f"{damage}. The bag's other files are checked on "
                                   "their own: `exo-ilc analyze --skip-damaged` (read_bag(..., "
                                   "skip_damaged=True)) analyses them without this one.")
            notes.append(f"{file.name} left out: it {damage}")
            continue
        if check.chunks and check.chunk_crcs < check.chunks:
            unchecked.append(file.name)
        for topic, msgtype in found.types.items():
            expected = topics.TYPES.get(topic)
            if topic in streams and expected and msgtype != expected:
                raise BagReadError(file, f"topic {topic} has type {msgtype}, expected "
                                   f"{expected}")
            types.setdefault(topic, msgtype)
        for topic, log in found.log.items():
            streams[topic].log.extend(log)
            streams[topic].msgs.extend(found.data[topic])
    deserialize = messages.typestore().deserialize_cdr
    for topic, stream in streams.items():
        times = np.asarray(stream.log, dtype=np.int64)
        if times.size > 1 and np.any(np.diff(times) < 0):
            order = np.argsort(times, kind="stable")
            stream.log = [stream.log[i] for i in order]
            stream.msgs = [stream.msgs[i] for i in order]
        _keep_decodable(topic, stream, deserialize, types.get(topic, ""),
                        topic not in keep_raw, notes)
    if unchecked:
        notes.append(f"{len(unchecked)} of the bag's files ({unchecked[0]}"
                     f"{', ...' if len(unchecked) > 1 else ''}) carry no chunk CRCs (written "
                     "before exo_ilc_ros wrote bags with mcap): damage to them could not be "
                     "detected")
    return streams, deserialize, notes


CDR_HEADERS = (b"\x00\x00", b"\x00\x01")
"""The encapsulations a rosbag2 CDR message starts with (big- and little-endian plain CDR)."""


def _keep_decodable(topic: str, stream: _Stream, deserialize: Callable[[bytes, str], Any],
                    msgtype: str, decode: bool, notes: list[str]) -> None:
    """Drop (with a note) the messages of ``stream`` that are not CDR of ``msgtype``: the
    recorder keeps whatever was published, a foreign publisher's junk included (the nodes
    refused it live); ``decode``: replace the others by their deserialised messages, else
    keep them raw after a check of their encapsulation only."""
    kept_log, kept = [], []
    for log, raw in zip(stream.log, stream.msgs, strict=True):
        if bytes(raw[:2]) not in CDR_HEADERS or len(raw) < 4:
            continue
        if decode:
            try:
                raw = deserialize(raw, msgtype)
            except Exception:  # any decoding failure: junk, dropped
                continue
        kept_log.append(log)
        kept.append(raw)
    dropped = len(stream.msgs) - len(kept)
    if dropped:
        notes.append(f"{dropped} message(s) on {topic} are not {msgtype or 'CDR'} and were "
                     "left out (another publisher's junk: the nodes refused it live)")
    stream.log, stream.msgs = kept_log, kept


def _read_with_rosbags(path: Path, wanted: Sequence[str], raw_topics: Iterable[str]
                       ) -> tuple[dict[str, _Stream], Callable[[bytes, str], Any]]:
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag2 import ReaderError

    streams = {t: _Stream() for t in wanted}
    keep_raw = set(raw_topics)
    try:
        with AnyReader([path], default_typestore=messages.typestore()) as reader:
            connections = [c for c in reader.connections if c.topic in streams]
            for conn in connections:
                expected = topics.TYPES.get(conn.topic)
                if expected and conn.msgtype != expected:
                    raise BagReadError(path, f"topic {conn.topic} has type {conn.msgtype}, "
                                       f"expected {expected}")
            deserialize = reader.typestore.deserialize_cdr
            for conn, log_time, raw in reader.messages(connections=connections):
                stream = streams[conn.topic]
                stream.log.append(log_time)
                stream.msgs.append(raw if conn.topic in keep_raw
                                   else deserialize(raw, conn.msgtype))
    except (AnyReaderError, ReaderError) as exc:
        raise BagReadError(path, f"rosbags cannot read it: {exc}") from None
    return streams, deserialize


def _frame_id(raw: bytes, decode: Callable[[bytes, str], Any]) -> str:
    """header.frame_id of a CDR message without decoding the rest (a feed-forward profile is
    thousands of points)."""
    if len(raw) >= 16 and raw[:2] == b"\x00\x01":  # little-endian CDR: stamp, then the string
        (length,) = struct.unpack_from("<I", raw, 12)
        if 0 < length <= len(raw) - 16:
            return raw[16:16 + length - 1].decode(errors="replace")
    return str(decode(raw, topics.TYPES[topics.FEEDFORWARD]).header.frame_id)


def _statuses(stream: _Stream, name: str) -> Iterator[tuple[int, int, Any]]:
    for log, msg in zip(stream.log, stream.msgs, strict=True):
        for status in msg.status:
            if status.name == name:
                yield messages.time_ns(msg.header.stamp), log, status


"""``reason`` of the ``aborted`` event of a trial the error envelope aborted: unlike the other
``aborted`` events (watchdog, a stuck protocol step), that trial is not run again."""


PROTOCOL_STEPS = {
    "wait_graph": "waiting for the plant and the controller",
    "resetting": "moving the plant back to the start pose",
    "wait_ack": "waiting for the controller to take the trial's feed-forward",
    "starting": "starting the trial",
    "homing": "waiting for the controller to bring the arm to the start pose (protocol homing)",
    "running": "running the trial (no new joint sample arrived)",
    "wait_recorder": "waiting for bag_recorder to file the trial",
}
"""What the supervisor was doing in each protocol step (``core.protocol.Phase``)."""


def rerun_note(trial: int, values: dict[str, str]) -> str:
    """Plain words for an ``aborted`` event that was not the error envelope's: why the attempt
    was dropped, and why the results do not change."""
    reason = values.get("reason")
    if reason == "watchdog":
        cause = (f"watchdog: the controller went without /joint_states for longer than its "
                 f"watchdog allows and held the arm safe ({values.get('watchdog_trips', '?')}x)")
    elif reason == "homing":
        return (f"trial {trial} was not started: {values.get('detail', 'homing failed')}; the "
                "run stopped there with the arm in the safe hold (a resumed run starts it "
                "again). Nothing was learned from it.")
    elif reason == "lost":
        cause = f"lost: {values.get('lost', 'some')} joint samples of the attempt never arrived"
    elif reason and reason != "timeout":
        cause = reason
    else:  # "timeout" (older bags: no reason, only the phase)
        phase = values.get("phase", "?")
        cause = (f"stuck: the protocol step {phase!r} ({PROTOCOL_STEPS.get(phase, 'unknown')}) "
                 f"made no progress for {STEP_TIMEOUT:g} s, which happens when the machine is "
                 "busy")
    return (f"trial {trial} was aborted once and run again ({cause}); the supervisor "
            "discarded that attempt and ran the trial again from the same feed-forward. The "
            "results are unaffected: nothing is learned from a discarded attempt, and the "
            "tables and figures use the attempt that completed.")


def _assign_commands(windows: Sequence[tuple[int, int, TrialData]], cmd_log: np.ndarray,
                     commands: Sequence[bytes], decode: Callable[[bytes, str], Any],
                     notes: list[str]) -> None:
    """The controller answers every sample once, in order: trial k's commands are those
    logged from its start (event, else first sample) to the next trial's start, row i the i-th.
    Messages of different topics may be logged slightly out of order, so when the count is off
    the window is shifted to where command i equals the effort the plant reports at sample
    i + 1 (it applied exactly that)."""
    if not commands:
        return
    msgtype = topics.TYPES[topics.EFFORT_COMMANDS]
    bounds = sorted((log, k, trial) for k, log, trial in windows if log >= 0)
    for n, (log, k, trial) in enumerate(bounds):
        stop = bounds[n + 1][0] if n + 1 < len(bounds) else np.iinfo(np.int64).max
        picked: np.ndarray | None = np.flatnonzero((cmd_log >= log) & (cmd_log < stop))
        samples = trial.position.shape[0]
        if picked is not None and len(picked) != samples:
            picked = _matching_window(picked, samples, trial.effort, commands, decode, msgtype)
        if picked is None or len(picked) != samples:
            notes.append(f"trial {k}: effort commands do not line up with the {samples} "
                         "samples; commands not shown")
            continue
        trial.command_messages = [commands[int(c)] for c in picked]


def _matching_window(picked: np.ndarray, samples: int, applied: np.ndarray,
                     commands: Sequence[bytes], decode: Callable[[bytes, str], Any],
                     msgtype: str) -> np.ndarray | None:
    """``samples`` consecutive commands near ``picked`` whose first N equal the efforts the
    plant applied (``applied[1:]``), or None."""
    if not len(picked):
        return None
    slack = 3 + abs(len(picked) - samples)
    first = max(0, int(picked[0]) - slack)
    last = min(len(commands), int(picked[-1]) + 1 + slack)
    data = [np.asarray(decode(commands[c], msgtype).data, dtype=float)
            for c in range(first, last)]
    target = applied[1:]
    known = ~np.isnan(target).any(axis=1)
    for offset in range(0, len(data) - samples + 1):
        rows = data[offset:offset + samples - 1]
        if all(len(r) == target.shape[1] for r in rows) and \
                np.array_equal(np.array(rows)[known], target[known]):
            return np.arange(first + offset, first + offset + samples)
    return None


def read_bag(path: Path | str, *, skip_damaged: bool = False) -> BagRun:
    """Read the run recorded in the rosbag2 bag directory ``path``. An MCAP file whose
    checksums fail is refused (:class:`BagReadError` naming it), or with ``skip_damaged``
    left out with a note (the trials it held then show as missing or incomplete)."""
    path = Path(path)
    info = read_metadata(path)
    provenance = read_provenance(info.get("custom_data"))
    config = provenance.config  # (its problems, e.g. parameters added since, are notes too)
    notes = list(provenance.problems)
    streams, decode, read_notes = _read_topics(
        path, info, skip_damaged, [topics.JOINT_STATES, topics.EFFORT_COMMANDS, topics.FEEDFORWARD,
                     topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY],
        raw_topics=[topics.EFFORT_COMMANDS, topics.FEEDFORWARD, topics.JOINT_STATES])
    notes.extend(read_notes)

    # Trial boundaries: start/end events, else the summaries.
    starts: dict[int, int] = {}
    start_logs: dict[int, int] = {}
    ends: dict[int, int] = {}
    summaries: dict[int, dict[str, str]] = {}
    aborted_at: dict[int, int] = {}
    reruns: dict[int, list[str]] = {}
    resumed_after: int | None = None
    for stamp, log, status in _statuses(streams[topics.TRIAL_EVENTS], topics.TRIAL_STATUS):
        values = protocol.key_values(status)
        if status.message == "finished":
            continue
        if status.message == "resumed":  # no trial number: trials 1..N came from the store
            resumed_after = protocol.int_value(values, "trials")
            notes.append(f"the run was resumed from its store after trial {resumed_after}: "
                         "the trials before were recorded in the interrupted run's bag"
                         if resumed_after is not None else "the run was resumed from its store")
            continue
        k = protocol.int_value(values, "trial")
        if k is None:
            notes.append(f"trial event {status.message!r} at {stamp} ns without a trial number")
            continue
        if status.message == "aborted":
            if values.get("reason") == topics.ENVELOPE_REASON:
                at = protocol.int_value(values, "aborted_at")
                aborted_at[k] = -1 if at is None else at
                notes.append(f"trial {k} was aborted by the error envelope at sample "
                             f"{values.get('aborted_at', '?')} (safe hold from there; kept, "
                             "not learned from)")
            else:
                reason = values.get("reason") or values.get("phase") or "?"
                reruns.setdefault(k, []).append(reason)
                notes.append(rerun_note(k, values))
        if status.message == "start":
            starts[k] = stamp  # a retried trial starts again: the last start counts
            start_logs[k] = log
        elif status.message == "end":
            ends[k] = stamp
            summaries.setdefault(k, {}).update(values)
    summary_stamps: dict[int, int] = {}
    for stamp, _, status in _statuses(streams[topics.TRIAL_SUMMARY], topics.SUMMARY_STATUS):
        values = protocol.key_values(status)
        k = protocol.int_value(values, "trial")
        if k is not None:
            summaries.setdefault(k, {}).update(values)
            summary_stamps[k] = stamp
    for k, values in summaries.items():  # a bag without the events: the summary marks it
        at = protocol.int_value(values, "aborted_at")
        if at is not None and aborted_at.get(k, -1) < 0:
            aborted_at[k] = at

    # Feed-forward profiles by trial.
    profiles: dict[int, bytes] = {}
    for raw in streams[topics.FEEDFORWARD].msgs:
        try:
            frame = _frame_id(raw, decode)
        except Exception:  # CDR-framed junk: not a profile
            notes.append(f"an undecodable message on {topics.FEEDFORWARD} left out")
            continue
        trial = protocol.trial_of_frame(frame)
        if trial is not None:
            profiles[trial] = raw
        elif frame.startswith(topics.FEEDFORWARD_FRAME_PREFIX):
            notes.append(f"feed-forward with frame_id {frame!r}")

    js = streams[topics.JOINT_STATES]
    if not js.msgs:
        raise BagReadError(path, f"no {topics.JOINT_STATES} messages")
    decoded = joint_states(js.msgs, decode, config["joint_names"] if config else ())
    names = decoded.names
    if not names:
        raise BagReadError(path, f"{topics.JOINT_STATES} has no joint names and the bag no "
                           "config")
    joints = len(names)
    stamps, position, velocity = decoded.stamps, decoded.position, decoded.velocity
    applied = decoded.effort

    # Reference: any feed-forward profile (the reference is the same every trial) or config.
    reference: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    if profiles:
        msg = decode(profiles[min(profiles)], topics.TYPES[topics.FEEDFORWARD])
        reference = (np.array([messages.time_ns(p.time_from_start) for p in msg.points]) / 1e9,
                     np.array([p.positions for p in msg.points], dtype=float),
                     np.array([p.velocities for p in msg.points], dtype=float))
    elif config is not None:
        ref = build_reference(config)
        reference = (ref.time, ref.position, ref.velocity)
        notes.append(f"no {topics.FEEDFORWARD}: reference rebuilt from the bag's config")
    if reference is None:
        raise BagReadError(path, f"neither {topics.FEEDFORWARD} nor a config in custom_data: "
                           "no reference to compute the errors against")
    ref_time, ref_q, ref_qd = reference
    samples = len(ref_time)
    if config is not None:
        period = float(config["control.period"])
    elif samples > 1:
        period = float(ref_time[1] - ref_time[0])
    else:
        raise BagReadError(path, "cannot tell the control period")
    period_ns = period * 1e9

    if not starts:
        if summary_stamps:
            notes.append(f"no {topics.TRIAL_EVENTS}: trials cut at the summaries' stamps")
            for k, stamp in summary_stamps.items():
                starts[k] = int(round(stamp - (samples - 1) * period_ns))
                ends[k] = stamp
        else:
            raise BagReadError(path, f"neither {topics.TRIAL_EVENTS} nor "
                               f"{topics.TRIAL_SUMMARY}: cannot tell where trials are")
    for k, stamp in summary_stamps.items():
        ends.setdefault(k, stamp)
    for k, stamp in ends.items():
        if k not in starts:  # recording began during trial k: keep its tail
            starts[k] = int(round(stamp - (samples - 1) * period_ns))
            notes.append(f"trial {k}: no start event (recording began during it)")

    js_log = np.asarray(js.log, dtype=np.int64)
    cmd = streams[topics.EFFORT_COMMANDS]
    cmd_log = np.asarray(cmd.log, dtype=np.int64)

    trials: dict[int, TrialData] = {}
    windows: list[tuple[int, int, TrialData]] = []
    sorted_starts = sorted(starts.items(), key=lambda kv: kv[1])
    for n, (k, start) in enumerate(sorted_starts):
        stop = sorted_starts[n + 1][1] if n + 1 < len(sorted_starts) else np.iinfo(np.int64).max
        if k in ends:
            stop = min(stop, ends[k] + 1)
        inside = np.flatnonzero((stamps >= start) & (stamps < stop))
        index = np.rint((stamps[inside] - start) / period_ns).astype(np.int64)
        keep = (index >= 0) & (index < samples)
        inside, index = inside[keep], index[keep]
        q = np.full((samples, joints), np.nan)
        qd = np.full((samples, joints), np.nan)
        eff = np.full((samples, joints), np.nan)
        q[index], qd[index], eff[index] = position[inside], velocity[inside], applied[inside]
        trials[k] = TrialData(k, ref_time.copy(), ref_q, ref_qd, q, qd, eff,
                              summaries.get(k, {}), k in ends,
                              aborted_at=aborted_at.get(k), reruns=reruns.get(k, []),
                              feedforward_message=profiles.get(k), decode=decode)
        windows.append((k, start_logs.get(k, int(js_log[inside].min()) if inside.size
                                         else -1), trials[k]))
    _assign_commands(windows, cmd_log, cmd.msgs, decode, notes)
    for k in sorted(trials):
        t = trials[k]
        if t.ended and t.missing_samples:
            notes.append(f"trial {k}: {t.missing_samples} of {samples} samples missing")
    if not provenance.parameter_changes and provenance.recorded_by is None:
        notes.append("no exo_ilc_ros provenance in custom_data (recorded by another tool?)")
    return BagRun(path, str(info.get("storage_identifier", "?")), names, period, provenance,
                  trials, summaries, provenance.parameter_changes, notes, resumed_after)
