"""The key-values of the trial protocol's messages (``DiagnosticStatus`` values on
``/ilc/trial_summary``, ``/ilc/trial_events`` and ``/diagnostics``): written by the supervisor
and by bags made in-process, read by the monitor of ``exo-ilc run``, the bag reader and the
replay. Plain strings; floats as ``repr`` so they parse back exactly."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from . import topics

LAWS_WITH_LEVELS = frozenset({"sign"})
"""Laws whose update has step gains M, M', M'' (eq. (11)): their summaries carry ``level/``
keys in every trial."""
PARAMETERS_CHANGED = "parameters_changed"
"""Summary key: the live changes applied at the trial's end (JSON), in effect from the next."""


def summary_values(trial: int, mass_uncertainty: float, law: str, names: Sequence[str],
                   max_abs_error: Any, max_abs_feedforward: Any, max_abs_effort: Any,
                   levels: Any | None, aborted_at: int | None = None,
                   changed: Mapping[str, Any] | None = None,
                   true_max_abs_error: Any | None = None,
                   learning_notes: Sequence[str] = (),
                   has_levels: bool | None = None) -> list[tuple[str, str]]:
    """The key-values of a trial summary (floats as ``repr`` so they parse back exactly):
    ``aborted_at`` for a trial the envelope aborted, ``parameters_changed`` (JSON) for the
    live changes the session applied at this trial's end (in effect from the next trial),
    ``true_max_abs_error/<joint>`` when the plant's true state differs from the measured one,
    ``learning_notes`` when the law said something about its update (:data:`LEARNING_NOTES`);
    ``level/<M>/<joint>`` = ``nan`` where ``levels`` is None under a law that has levels
    (``has_levels``; default: the sign law, ``law`` ``sign``), so every trial has the same keys.
    Over 10 parameters because each group of summary keys is one argument (the optional ones
    keywords with defaults), so the one place that spells the keys takes them all."""
    if has_levels is None:
        has_levels = law in LAWS_WITH_LEVELS
    out = [("trial", str(trial)), ("mass_uncertainty", repr(float(mass_uncertainty))),
           ("law", law)]
    for key, row in (("max_abs_error", max_abs_error),
                     ("max_abs_feedforward", max_abs_feedforward),
                     ("max_abs_effort", max_abs_effort)):
        out += [(f"{key}/{n}", repr(float(x))) for n, x in zip(names, row, strict=True)]
    if true_max_abs_error is not None:
        out += [(f"true_max_abs_error/{n}", repr(float(x)))
                for n, x in zip(names, true_max_abs_error, strict=True)]
    if levels is None and has_levels:  # trial 1: the same keys as every other trial
        levels = np.full((len(topics.LEVEL_SYMBOLS), len(names)), np.nan)
    if levels is not None:
        for level_name, row in zip(topics.LEVEL_SYMBOLS, np.asarray(levels), strict=False):
            out += [(f"level/{level_name}/{n}", repr(float(x)))
                    for n, x in zip(names, row, strict=True)]
    if aborted_at is not None:
        out.append(("aborted_at", str(aborted_at)))
    if changed:
        out.append((PARAMETERS_CHANGED, json.dumps(dict(changed), sort_keys=True)))
    if learning_notes:
        out.append((topics.LEARNING_NOTES, "; ".join(learning_notes)))
    return out


def parameters_changed(values: Mapping[str, str]) -> dict[str, Any]:
    """The live changes a trial summary says took effect at its trial's end ({} if none or
    unparsable)."""
    try:
        changed = json.loads(values.get(PARAMETERS_CHANGED, "{}"))
    except ValueError:
        return {}
    return changed if isinstance(changed, dict) else {}


def int_value(values: Mapping[str, str], key: str) -> int | None:
    """``values[key]`` as an integer (None if absent or not one)."""
    text = values.get(key, "")
    try:
        return int(text)
    except ValueError:
        return None


def feedforward_frame(trial: int) -> str:
    """The ``trial:<k>`` frame id of trial ``trial``'s feed-forward."""
    return f"{topics.FEEDFORWARD_FRAME_PREFIX}{trial}"


def trial_of_frame(frame_id: str) -> int | None:
    """k of a feed-forward's ``trial:<k>`` frame id (None if it is not one)."""
    if not frame_id.startswith(topics.FEEDFORWARD_FRAME_PREFIX):
        return None
    text = frame_id[len(topics.FEEDFORWARD_FRAME_PREFIX):]
    return int(text) if text.isdigit() else None


def key_values(status: Any) -> dict[str, str]:
    """A DiagnosticStatus' values as a dict."""
    return {str(kv.key): str(kv.value) for kv in status.values}


def per_joint(values: Mapping[str, str], key: str, names: Sequence[str]) -> np.ndarray | None:
    """The ``<key>/<joint>`` floats in joint order (None if any is missing or unparsable)."""
    try:
        return np.array([float(values[f"{key}/{n}"]) for n in names])
    except (KeyError, ValueError):
        return None
