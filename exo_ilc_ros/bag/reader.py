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

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core.protocol.timing import STEP_TIMEOUT
from ..core.reference.build import build_reference
from ..wire import protocol, topics
from ..wire.cdr import joint_states
from . import messages
from .errors import BagReadError
from .provenance import read_provenance
from .run import BagRun, TrialData
from .storage import Stream, frame_id, read_metadata, read_topics, statuses

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
    streams, decode, read_notes = read_topics(
        path, info, skip_damaged, [topics.JOINT_STATES, topics.EFFORT_COMMANDS, topics.FEEDFORWARD,
                     topics.TRIAL_EVENTS, topics.TRIAL_SUMMARY, *topics.CUFF_WRENCHES],
        raw_topics=[topics.EFFORT_COMMANDS, topics.FEEDFORWARD, topics.JOINT_STATES])
    notes.extend(read_notes)
    events = _trial_events(streams, notes)
    profiles = _profiles(streams[topics.FEEDFORWARD], decode, notes)
    js = streams[topics.JOINT_STATES]
    if not js.msgs:
        raise BagReadError(path, f"no {topics.JOINT_STATES} messages")
    decoded = joint_states(js.msgs, decode, config["joint_names"] if config else ())
    if not decoded.names:
        raise BagReadError(path, f"{topics.JOINT_STATES} has no joint names and the bag no "
                           "config")
    reference = _reference(path, profiles, decode, config, notes)
    period = _period(path, config, reference[0])
    _complete_boundaries(path, events, len(reference[0]), period * 1e9, notes)
    trials = _cut_trials(events, profiles, reference, period * 1e9, decoded,
                         np.asarray(js.log, dtype=np.int64), streams[topics.EFFORT_COMMANDS],
                         decode, notes)
    _cut_cuffs(events, trials, [streams[t] for t in topics.CUFF_WRENCHES], period * 1e9)
    if not provenance.parameter_changes and provenance.recorded_by is None:
        notes.append("no exo_ilc_ros provenance in custom_data (recorded by another tool?)")
    return BagRun(path, str(info.get("storage_identifier", "?")), decoded.names, period,
                  provenance, trials, events.summaries, provenance.parameter_changes, notes,
                  events.resumed_after)


@dataclass
class _Events:
    """What the trial events and summaries say: each trial's start (stamp and log time), end,
    summary, envelope abort and re-runs, and where a resumed run continued."""

    starts: dict[int, int] = field(default_factory=dict)
    start_logs: dict[int, int] = field(default_factory=dict)
    ends: dict[int, int] = field(default_factory=dict)
    summaries: dict[int, dict[str, str]] = field(default_factory=dict)
    summary_stamps: dict[int, int] = field(default_factory=dict)
    aborted_at: dict[int, int] = field(default_factory=dict)
    reruns: dict[int, list[str]] = field(default_factory=dict)
    resumed_after: int | None = None


def _trial_events(streams: dict[str, Stream], notes: list[str]) -> _Events:
    """Trial boundaries from the start/end events, else the summaries; aborts, re-runs, a
    resume (module docstring)."""
    out = _Events()
    for stamp, log, status in statuses(streams[topics.TRIAL_EVENTS], topics.TRIAL_STATUS):
        values = protocol.key_values(status)
        if status.message == "finished":
            continue
        if status.message == "resumed":  # no trial number: trials 1..N came from the store
            out.resumed_after = protocol.int_value(values, "trials")
            notes.append(f"the run was resumed from its store after trial {out.resumed_after}: "
                         "the trials before were recorded in the interrupted run's bag"
                         if out.resumed_after is not None else "the run was resumed from its "
                         "store")
            continue
        k = protocol.int_value(values, "trial")
        if k is None:
            notes.append(f"trial event {status.message!r} at {stamp} ns without a trial number")
            continue
        if status.message == "aborted":
            if values.get("reason") in topics.KEPT_REASONS:
                at = protocol.int_value(values, "aborted_at")
                out.aborted_at[k] = -1 if at is None else at
                notes.append(f"trial {k} was aborted by the error envelope at sample "
                             f"{values.get('aborted_at', '?')} (safe hold from there; kept, "
                             "learned from up to the abort)"
                             if values.get("reason") == topics.ENVELOPE_REASON else
                             f"trial {k} was aborted at sample {values.get('aborted_at', '?')}: "
                             "a cuff pressed past safety.cuff_force_limit (safe hold from "
                             "there; kept, learned from up to the abort)"
                             if values.get("reason") == topics.CUFF_LIMIT_REASON else
                             f"trial {k}: the plant diverged at sample "
                             f"{values.get('aborted_at', '?')} (kept; the run stopped there)")
            else:
                reason = values.get("reason") or values.get("phase") or "?"
                out.reruns.setdefault(k, []).append(reason)
                notes.append(rerun_note(k, values))
        if status.message == "start":
            out.starts[k] = stamp  # a retried trial starts again: the last start counts
            out.start_logs[k] = log
        elif status.message == "end":
            out.ends[k] = stamp
            out.summaries.setdefault(k, {}).update(values)
    for stamp, _, status in statuses(streams[topics.TRIAL_SUMMARY], topics.SUMMARY_STATUS):
        values = protocol.key_values(status)
        k = protocol.int_value(values, "trial")
        if k is not None:
            out.summaries.setdefault(k, {}).update(values)
            out.summary_stamps[k] = stamp
    for k, values in out.summaries.items():  # a bag without the events: the summary marks it
        at = protocol.int_value(values, "aborted_at")
        if at is not None and out.aborted_at.get(k, -1) < 0:
            out.aborted_at[k] = at
    return out


def _profiles(stream: Stream, decode: Callable[[bytes, str], Any], notes: list[str]
              ) -> dict[int, bytes]:
    """The feed-forward profiles (raw) by trial."""
    profiles: dict[int, bytes] = {}
    for raw in stream.msgs:
        try:
            frame = frame_id(raw, decode)
        except Exception:  # CDR-framed junk: not a profile
            notes.append(f"an undecodable message on {topics.FEEDFORWARD} left out")
            continue
        trial = protocol.trial_of_frame(frame)
        if trial is not None:
            profiles[trial] = raw
        elif frame.startswith(topics.FEEDFORWARD_FRAME_PREFIX):
            notes.append(f"feed-forward with frame_id {frame!r}")
    return profiles


def _reference(path: Path, profiles: dict[int, bytes], decode: Callable[[bytes, str], Any],
               config: Any, notes: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time, q_d and qdot_d: of any feed-forward profile (the reference is the same every
    trial), else rebuilt from the bag's config."""
    if profiles:
        msg = decode(profiles[min(profiles)], topics.TYPES[topics.FEEDFORWARD])
        return (np.array([messages.time_ns(p.time_from_start) for p in msg.points]) / 1e9,
                np.array([p.positions for p in msg.points], dtype=float),
                np.array([p.velocities for p in msg.points], dtype=float))
    if config is not None:
        ref = build_reference(config)
        notes.append(f"no {topics.FEEDFORWARD}: reference rebuilt from the bag's config")
        return ref.time, ref.position, ref.velocity
    raise BagReadError(path, f"neither {topics.FEEDFORWARD} nor a config in custom_data: "
                       "no reference to compute the errors against")


def _period(path: Path, config: Any, ref_time: np.ndarray) -> float:
    """The control period: the config's, else the reference's sample spacing."""
    if config is not None:
        return float(config["control.period"])
    if len(ref_time) > 1:
        return float(ref_time[1] - ref_time[0])
    raise BagReadError(path, "cannot tell the control period")


def _complete_boundaries(path: Path, events: _Events, samples: int, period_ns: float,
                         notes: list[str]) -> None:
    """Starts and ends where the events are missing: from the summaries' stamps (no events
    recorded), or a trial's tail (recording began during it)."""
    starts, ends = events.starts, events.ends
    if not starts:
        if events.summary_stamps:
            notes.append(f"no {topics.TRIAL_EVENTS}: trials cut at the summaries' stamps")
            for k, stamp in events.summary_stamps.items():
                starts[k] = int(round(stamp - (samples - 1) * period_ns))
                ends[k] = stamp
        else:
            raise BagReadError(path, f"neither {topics.TRIAL_EVENTS} nor "
                               f"{topics.TRIAL_SUMMARY}: cannot tell where trials are")
    for k, stamp in events.summary_stamps.items():
        ends.setdefault(k, stamp)
    for k, stamp in ends.items():
        if k not in starts:  # recording began during trial k: keep its tail
            starts[k] = int(round(stamp - (samples - 1) * period_ns))
            notes.append(f"trial {k}: no start event (recording began during it)")


def _cut_cuffs(events: _Events, trials: dict[int, TrialData], cuffs: Sequence[Stream],
               period_ns: float) -> None:
    """A person strapped in: each trial's cuff wrenches per sample (``TrialData.cuff_wrench``,
    NaN where one is missing) from the per-cuff streams, placed by their header stamps as
    the samples are; nothing for a bag without them."""
    if not any(stream.msgs for stream in cuffs):
        return
    for k, trial in trials.items():
        start = events.starts.get(k)
        if start is None:
            continue
        samples = trial.position.shape[0]
        wrench = np.full((samples, len(cuffs), 6), np.nan)
        for c, stream in enumerate(cuffs):
            for msg in stream.msgs:
                i = round((messages.time_ns(msg.header.stamp) - start) / period_ns)
                if 0 <= i < samples:
                    f, t = msg.wrench.force, msg.wrench.torque
                    wrench[i, c] = (f.x, f.y, f.z, t.x, t.y, t.z)
        trial.cuff_wrench = wrench


def _cut_trials(events: _Events, profiles: dict[int, bytes],
                reference: tuple[np.ndarray, np.ndarray, np.ndarray], period_ns: float,
                decoded: Any, js_log: np.ndarray, cmd: Stream,
                decode: Callable[[bytes, str], Any], notes: list[str]) -> dict[int, TrialData]:
    """Each trial's samples from ``/joint_states`` at index round((stamp - start) / period)
    (a dropped message leaves a NaN row), and its effort commands."""
    ref_time, ref_q, ref_qd = reference
    samples = len(ref_time)
    joints = len(decoded.names)
    stamps = decoded.stamps
    trials: dict[int, TrialData] = {}
    windows: list[tuple[int, int, TrialData]] = []
    sorted_starts = sorted(events.starts.items(), key=lambda kv: kv[1])
    for n, (k, start) in enumerate(sorted_starts):
        stop = sorted_starts[n + 1][1] if n + 1 < len(sorted_starts) else np.iinfo(np.int64).max
        if k in events.ends:
            stop = min(stop, events.ends[k] + 1)
        inside = np.flatnonzero((stamps >= start) & (stamps < stop))
        index = np.rint((stamps[inside] - start) / period_ns).astype(np.int64)
        keep = (index >= 0) & (index < samples)
        inside, index = inside[keep], index[keep]
        q = np.full((samples, joints), np.nan)
        qd = np.full((samples, joints), np.nan)
        eff = np.full((samples, joints), np.nan)
        q[index] = decoded.position[inside]
        qd[index] = decoded.velocity[inside]
        eff[index] = decoded.effort[inside]
        trials[k] = TrialData(k, ref_time.copy(), ref_q, ref_qd, q, qd, eff,
                              events.summaries.get(k, {}), k in events.ends,
                              aborted_at=events.aborted_at.get(k),
                              reruns=events.reruns.get(k, []),
                              feedforward_message=profiles.get(k), decode=decode)
        windows.append((k, events.start_logs.get(k, int(js_log[inside].min()) if inside.size
                                                else -1), trials[k]))
    _assign_commands(windows, np.asarray(cmd.log, dtype=np.int64), cmd.msgs, decode, notes)
    for k in sorted(trials):
        t = trials[k]
        if t.ended and t.missing_samples:
            notes.append(f"trial {k}: {t.missing_samples} of {samples} samples missing")
    return trials
