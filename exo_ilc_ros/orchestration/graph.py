"""Run the node graph for one configuration and collect its trial summaries.

:class:`GraphSession` starts the processes of :data:`launcher.GRAPH_NODES` (plus any ``extra``)
on a domain of their own (the one given, else a free one claimed: a caller that honours an
exported ``ROS_DOMAIN_ID`` passes :func:`launcher.exported_domain_id`, as ``exo-ilc run`` and
the benches do) and a monitor node in this process that follows
``/ilc/trial_summary`` and ``/ilc/trial_events``; :func:`run_graph` runs it to the end and
returns a :class:`report.RunSummary`, the same as ``exo-ilc simulate`` reports.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from ..core.loop.divergence import DIVERGED
from ..core.loop.rate import with_control_rate
from ..core.params.config import Config
from ..core.persistence.store import RunStore
from ..core.person.cuffs import cuff_table
from ..core.programs.identified import Identified
from ..core.reference.build import build_reference
from ..core.session.abort import ABORT_STOP_KEY
from ..core.session.summary import CUFF_LIMIT_ABORTS, RunSummary, live_changes
from ..nodes.common import EVENTS_QOS
from ..wire import topics
from ..wire.protocol import PARAMETERS_CHANGED, int_value, per_joint, summary_values
from .launcher import (
    GRAPH_NODES,
    DomainClaim,
    GraphError,
    GraphProcesses,
    NodeSpec,
    claim_domain_id,
    graph_environment,
)


@dataclass
class TrialSummary:
    """One ``/ilc/trial_summary`` status, parsed (floats exactly as the supervisor had them)."""

    trial: int
    values: dict[str, str]
    received: float = field(default_factory=time.monotonic)

    def row(self, key: str, joints: Sequence[str]) -> np.ndarray:
        """``key/<joint>`` for every joint (NaN where absent)."""
        row = per_joint(self.values, key, joints)
        return np.full(len(joints), np.nan) if row is None else row

    def levels(self, joints: Sequence[str]) -> np.ndarray | None:
        """M, M', M'' (rows) per joint, or None if the trial had none (trial 1, linear law)."""
        if f"level/M/{joints[0]}" not in self.values:
            return None
        levels = np.array([self.row(f"level/{symbol}", joints)
                           for symbol in topics.LEVEL_SYMBOLS])
        return None if np.all(np.isnan(levels)) else levels  # trial 1's are nan


def summaries_to_run(summaries: Sequence[TrialSummary], config: Config) -> RunSummary:
    """The :class:`RunSummary` of a graph run, as ``RunSummary.from_result`` gives in-process."""
    joints = config["joint_names"]
    first = summaries[0].values if summaries else {}
    summary = RunSummary(float(first.get("mass_uncertainty", config["mass_uncertainty"])),
                      str(first.get("law", config["law"])), float(config["error_bound"]),
                      np.array([s.row("max_abs_error", joints) for s in summaries]),
                      np.array([s.row("max_abs_feedforward", joints) for s in summaries]),
                      np.array([s.row("max_abs_effort", joints) for s in summaries]),
                      true_max_abs_error=np.array([s.row("true_max_abs_error", joints)
                                                   for s in summaries])
                      if f"true_max_abs_error/{joints[0]}" in first else None)
    summary.cuff_forces = cuff_table([s.values for s in summaries])  # a person strapped in
    applied = {s.trial + 1: json.loads(s.values[PARAMETERS_CHANGED]) for s in summaries
               if s.values.get(PARAMETERS_CHANGED)}
    summary.extra.update(live_changes(applied, str(config["law"])))
    aborted = [s.trial for s in summaries if "aborted_at" in s.values]
    if aborted:
        summary.extra["aborted_trials"] = aborted
    diverged = [json.loads(s.values[DIVERGED]) for s in summaries if s.values.get(DIVERGED)]
    if diverged:  # the plant's state stopped being finite (simulate's plant_diverged)
        summary.extra[DIVERGED] = diverged
    stopped = summaries[-1].values.get(ABORT_STOP_KEY) if summaries else None
    if stopped:  # the session's one message (core/session/abort.py), as simulate's
        summary.extra[ABORT_STOP_KEY] = stopped
    identified = Identified.from_summary(summaries[-1].trial, summaries[-1].values, joints) \
        if summaries else None
    if identified is not None:  # the last estimate, as simulate reports it
        summary.extra["identified"] = identified.to_json()
    return summary


def reruns(events: Sequence[tuple[str, dict[str, str], float]]) -> list[dict[str, Any]]:
    """The trials run again (an ``aborted`` event for another reason than the error envelope
    or a plant that diverged: a watchdog trip, lost samples, a timeout), each with its
    reason, in order."""
    out: list[dict[str, Any]] = []
    for message, values, _ in events:
        if message == "aborted" and values.get("reason") not in topics.KEPT_REASONS:
            trial = int_value(values, "trial")
            if trial is not None:
                out.append({"trial": trial,
                            "reason": values.get("reason") or values.get("phase") or "?"})
    return out


def stored_summaries(config: Config) -> list[TrialSummary]:
    """The trials the store of ``config`` (``store.directory``, this run's learning key) holds,
    as trial summaries: what a resumed run restored rather than ran (empty without a store)."""
    if not config["store.directory"]:
        return []

    store = RunStore(config["store.directory"], config, build_reference(config))
    joints = config["joint_names"]
    out = []
    for entry in store.summaries:
        values = summary_values(entry["trial"], config["mass_uncertainty"],
                                str(entry["live"].get("law", config["law"])), joints,
                                entry["max_abs_error"], entry["max_abs_feedforward"],
                                entry["max_abs_effort"], entry.get("levels"),
                                entry.get("aborted_at"), None,
                                entry.get("true_max_abs_error")
                                if entry.get("true_max_abs_error") != entry["max_abs_error"]
                                else None)
        out.append(TrialSummary(int(entry["trial"]), dict(values)))
    return out


def merge_with_store(summaries: Sequence[TrialSummary], config: Config) -> list[TrialSummary]:
    """Trials 1..K: the live summaries, completed with the store's for trials restored on
    resume (or whose summary a crash swallowed after they were saved)."""
    by_trial = {s.trial: s for s in stored_summaries(config)}
    by_trial.update({s.trial: s for s in summaries})
    return [by_trial[k] for k in sorted(by_trial)]


class GraphSession:
    """The graph's processes plus a monitor node here; a context manager.

    ``node`` and ``executor`` are usable by callers (parameter clients, extra subscriptions);
    :meth:`spin_until` spins while watching the processes.
    """

    def __init__(self, config: Config, domain_id: int | None = None,
                 extra: Sequence[NodeSpec] = (), log_dir: Path | None = None,
                 on_summary: Callable[[TrialSummary], None] | None = None,
                 nodes: Sequence[NodeSpec] = GRAPH_NODES) -> None:
        self.config = config = with_control_rate(config)  # the period the nodes run
        self._claim: DomainClaim = claim_domain_id(domain_id)
        self.domain_id = self._claim.domain_id
        self._tmp = tempfile.TemporaryDirectory(prefix="exo_ilc_run_")
        self.params_file = Path(self._tmp.name) / "params.yaml"
        self.params_file.write_text(config.to_ros_yaml("written by exo-ilc run"))
        self.env = graph_environment(self.domain_id)
        self.processes = GraphProcesses([*nodes, *extra], self.params_file, self.env,
                                        log_dir or Path(self._tmp.name) / "logs")
        self.on_summary = on_summary
        self.summaries: list[TrialSummary] = []
        self.events: list[tuple[str, dict[str, str], float]] = []
        self._finished_after: int | None = None
        """The last trial named by the supervisor's ``finished`` event (None: not yet)."""
        self.error: str | None = None
        """The supervisor's ``finished`` event's error (the run stopped on a fault)."""
        self._resumed_after = 0
        self.started_at: float | None = None
        """Wall time of the first trial's start event."""
        self.finished_at: float | None = None
        self.context: Any = None
        self.node: Any = None
        self.executor: Any = None

    def __enter__(self) -> GraphSession:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.experimental import EventsExecutor


        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE",
                              self.env["ROS_AUTOMATIC_DISCOVERY_RANGE"])
        os.environ.setdefault("ROS_LOG_DIR", self.env["ROS_LOG_DIR"])
        try:
            self.context = rclpy.Context()
            rclpy.init(context=self.context, domain_id=self.domain_id)
            self.node = rclpy.create_node("exo_ilc_run", context=self.context)
            self.node.create_subscription(DiagnosticArray, topics.TRIAL_SUMMARY,
                                          self._on_summary, EVENTS_QOS)
            self.node.create_subscription(DiagnosticArray, topics.TRIAL_EVENTS,
                                          self._on_event, EVENTS_QOS)
            self.executor = EventsExecutor(context=self.context)
            self.executor.add_node(self.node)
            self.processes.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()

    def close(self) -> dict[str, int]:
        """Stop the processes (SIGINT, then SIGKILL), the monitor node, the domain claim."""
        codes = self.processes.stop() if self.processes.processes else {}
        if self.node is not None:  # the executor may be missing: __enter__ failed before it
            if self.executor is not None:
                self.executor.remove_node(self.node)
            self.node.destroy_node()
            self.node = None
        if self.context is not None:
            self.context.try_shutdown()
            self.context = None
        self._claim.release()
        self._tmp.cleanup()
        return codes

    def _on_summary(self, msg: Any) -> None:
        for item in msg.status:
            if item.name == topics.SUMMARY_STATUS:
                values = {kv.key: kv.value for kv in item.values}
                summary = TrialSummary(int(values["trial"]), values)
                self.summaries.append(summary)
                if self.on_summary is not None:
                    self.on_summary(summary)

    def _on_event(self, msg: Any) -> None:
        for item in msg.status:
            if item.name == topics.TRIAL_STATUS:
                values = {kv.key: kv.value for kv in item.values}
                self.events.append((item.message, values, time.monotonic()))
                if item.message == "start" and self.started_at is None:
                    self.started_at = time.monotonic()
                if item.message == "resumed":
                    self._resumed_after = int_value(values, "trials") or 0
                if item.message == "finished":
                    self._finished_after = int_value(values, "trials") or 0
                    self.error = values.get("error") or None
                    self.finished_at = time.monotonic()

    @property
    def finished(self) -> bool:
        """The supervisor finished and the summary of its last trial is here too. Summaries
        and events are two topics, matched and delivered independently: a fast run can
        report ``finished`` before this monitor received its summaries."""
        last = self._finished_after
        if last is None:
            return False
        return last <= self._resumed_after or any(s.trial == last for s in self.summaries)

    def spin_until(self, done: Callable[[], bool], timeout: float,
                   stall_timeout: float | None = None) -> None:
        """Spin until ``done()``; GraphError if a node exits, after ``timeout`` s, or when no
        summary arrived for ``stall_timeout`` s."""
        start = time.monotonic()
        last_check = 0.0
        while not done():
            now = time.monotonic()
            if now - start > timeout:
                raise GraphError(f"timed out after {timeout:g} s; supervisor log:\n"
                                 + self.processes.log_tail("ilc_supervisor"))
            if stall_timeout is not None:
                last = self.summaries[-1].received if self.summaries else start
                if now - last > stall_timeout:
                    raise GraphError(f"no trial summary for {stall_timeout:g} s; supervisor "
                                     "log:\n" + self.processes.log_tail("ilc_supervisor"))
            if now - last_check > 0.5:
                try:
                    self.processes.check()
                except GraphError:
                    if self._drained(done):  # its last messages said what we waited for
                        return
                    raise
                last_check = now
            self.executor.spin_once(timeout_sec=0.05)

    def _drained(self, done: Callable[[], bool], seconds: float = 3.0) -> bool:
        """Take what a node sent before it exited (its ``finished``, say) for up to
        ``seconds``; whether ``done()`` came true."""
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            if done():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return done()


@dataclass
class GraphRun:
    """What :func:`run_graph` returns."""

    summary: RunSummary
    """The run as ``exo-ilc simulate`` reports it."""
    summaries: list[TrialSummary]
    wall_time: float | None
    """Wall seconds from the first trial's start to the supervisor's ``finished``."""


def run_graph(config: Config, domain_id: int | None = None, extra: Sequence[NodeSpec] = (),
              on_summary: Callable[[TrialSummary], None] | None = None,
              timeout: float = 3600.0, stall_timeout: float = 90.0,
              on_start: Callable[[GraphSession], None] | None = None,
              nodes: Sequence[NodeSpec] = GRAPH_NODES) -> GraphRun:
    """Run the graph (``nodes`` plus ``extra`` processes) until the supervisor finishes,
    then stop every process."""
    with GraphSession(config, domain_id, extra, on_summary=on_summary, nodes=nodes) as session:
        if on_start is not None:
            on_start(session)
        session.spin_until(lambda: session.finished, timeout, stall_timeout)
        if session.error is not None:
            raise GraphError(f"ilc_supervisor stopped the run: {session.error}")
        wall = None
        if session.started_at is not None and session.finished_at is not None:
            wall = session.finished_at - session.started_at
        summaries = merge_with_store(session.summaries, config)
        summary = summaries_to_run(summaries, config)
        stopped = [v.get(ABORT_STOP_KEY) for m, v, _ in session.events if m == "finished"]
        if stopped and stopped[-1]:  # a resumed run the store's aborts had already stopped
            summary.extra[ABORT_STOP_KEY] = stopped[-1]
        pressed = [int(v["trial"]) for m, v, _ in session.events if m == "aborted" and
                   v.get("reason") == topics.CUFF_LIMIT_REASON and v.get("trial", "").isdigit()]
        if pressed:  # a person strapped in: the cuff-force limit's aborts, as simulate's
            summary.extra[CUFF_LIMIT_ABORTS] = sorted(set(pressed))
        again = reruns(session.events)
        if again:
            summary.extra["reruns"] = again
        return GraphRun(summary, summaries, wall)
