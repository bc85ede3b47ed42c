"""A recorded run reproduced in-process: the bag's effective config, its mass uncertainty, its
trial count and the live parameter changes the run made, replayed through
:func:`core.session.run_trials`, then compared with the bag's trial summaries number for number.

The changes come from the summaries: the supervisor's session writes the changes it applied at
a trial's end into that trial's summary (``parameters_changed``), so the trial they took effect
at is exact. A bag recorded before that key existed falls back on the recorder's
``parameter_changes`` (the trial is the recorder's view of the boundary, which a change sent
between two trials can miss by one; the replay says so).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..core.loop.patient import PatientModel
from ..core.loop.record import TrialRecord
from ..core.params.config import Config
from ..core.params.schema import SUPERVISOR
from ..core.persistence.patient_states import session_start
from ..core.session.learning_session import LIVE, run_trials
from ..core.session.result import RunResult
from ..wire import protocol
from .errors import BagReadError
from .provenance import PROFILE_VERSION
from .run import BagRun
from .storage import read_metadata

COMPARED = ("max_abs_error", "max_abs_feedforward", "max_abs_effort")
"""The summary quantities a replay must reproduce."""


@dataclass
class ReplayPlan:
    """What a bag says to run again."""

    config: Config
    trials: int
    changes: dict[int, dict[str, Any]]
    """Effective trial (the first run with the new values) -> changed values."""
    notes: list[str] = field(default_factory=list)


def replay_plan(run: BagRun) -> ReplayPlan:
    """The run recorded in ``run``, as arguments of :func:`run_trials`."""
    config = run.provenance.config
    if config is None:
        raise BagReadError(run.path, "no effective config in its provenance (not recorded by "
                           "exo-ilc, or by an incompatible version): cannot replay it")
    trials = max(run.completed, default=0)
    if trials == 0:
        raise BagReadError(run.path, "no completed trial to replay")
    notes = list(run.provenance.problems)  # e.g. parameters added since: today's defaults
    changes: dict[int, dict[str, Any]] = {}
    if any(protocol.PARAMETERS_CHANGED in values for values in run.summaries.values()):
        for k, values in sorted(run.summaries.items()):
            changed = protocol.parameters_changed(values)
            if changed:
                changes[k + 1] = changed
    else:
        for change in run.parameter_changes:
            if change.node.lstrip("/") != SUPERVISOR or change.name not in LIVE:
                continue
            changes.setdefault(change.effective_trial, {})[change.name] = change.value
        if changes:
            notes.append("the bag's summaries do not say when each change was applied; using "
                         "the recorder's trial numbers (a change sent between two trials may "
                         "be placed one trial off)")
    ignored = [c for c in run.parameter_changes if c.node.lstrip("/") != SUPERVISOR]
    for change in ignored:
        notes.append(f"{change.node} {change.name} changed from trial {change.effective_trial}: "
                     "not replayed (only the supervisor's learning parameters are)")
    return ReplayPlan(config.replace({"max_trials": trials}), trials, changes, notes)


@dataclass
class Replay:
    """A replayed run and how it compares with the recording."""

    plan: ReplayPlan
    result: RunResult
    compared: int
    """Trials whose summary the bag holds and the replay was compared on."""
    worst: float
    """Largest absolute difference of any compared quantity (0.0: identical)."""
    first_different: int | None
    """The first trial that differs (None: none)."""

    @property
    def identical(self) -> bool:
        """Every compared number equal, bit for bit."""
        return self.first_different is None


def _patient_start(run: BagRun, plan: ReplayPlan) -> tuple[np.ndarray, np.ndarray] | None:
    """A therapy session's learning virtual patient starts from the state stored with its
    profile version (:mod:`..core.patient_states`; None: from zero). The bag says it is a
    session (custom data ``profile_version``); ``profile.initial`` names the profile's
    directory (empty: the session started from no version, so from zero)."""
    from pathlib import Path


    config = plan.config
    if not PatientModel(config).learns:
        return None
    custom = read_metadata(run.path).get("custom_data") or {}
    version = str(custom.get(PROFILE_VERSION) or "")
    if not version or not config["profile.initial"]:
        return None
    state = session_start(Path(config["profile.initial"]).parent, int(version))
    if state is None:
        plan.notes.append(f"the learning patient's state session {version} started from is "
                          "not stored with its profile (written before states were kept per "
                          "version): replayed from zero")
        return None
    return state.fast, state.slow


def replay(run: BagRun, on_trial: Callable[[TrialRecord], None] | None = None) -> Replay:
    """Run the bag's experiment again in-process and compare it with the bag's summaries."""
    plan = replay_plan(run)
    memory = _patient_start(run, plan)
    result = run_trials(plan.config, trials=plan.trials, changes=plan.changes,
                        on_trial=on_trial, patient_memory=memory)
    tables = {"max_abs_error": result.max_abs_errors,
              "max_abs_feedforward": result.max_abs_feedforward,
              "max_abs_effort": result.max_abs_effort}
    worst, first, compared = 0.0, None, 0
    for k, values in sorted(run.summaries.items()):
        if not 1 <= k <= len(result.records):
            continue
        rows = [protocol.per_joint(values, key, run.joint_names) for key in COMPARED]
        if any(row is None for row in rows):
            continue
        compared += 1
        for key, row in zip(COMPARED, rows, strict=True):
            difference = float(np.max(np.abs(tables[key][k - 1] - np.asarray(row))))
            worst = max(worst, difference)
            if difference != 0.0 and first is None:
                first = k
    return Replay(plan, result, compared, worst, first)
