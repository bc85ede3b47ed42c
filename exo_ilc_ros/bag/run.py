"""A run read back from a bag (:class:`BagRun`), trial by trial (:class:`TrialData`): what
:func:`.reader.read_bag` returns and the report's tables read."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from ..core.person.cuffs import cuff_table
from ..core.session.summary import RunSummary, law_segments
from ..wire import protocol, topics
from .provenance import ParameterChange, Provenance


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
    cuff_wrench: np.ndarray | None = field(default=None, repr=False)
    """A person strapped in: per sample and cuff (upper arm, forearm) the force (N) and
    torque (N m) on the person (``/cuffs/<cuff>/wrench``), shape (N+1, 2, 6), NaN where a
    message is missing; None: the bag has none."""

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
        """Trials the error envelope aborted (kept, marked, learned from up to the abort), in
        order."""
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
                          None if np.isnan(effort).all() else effort, extra, true,
                          cuff_table([self.summaries.get(k, {}) for k in range(1, count + 1)]))
