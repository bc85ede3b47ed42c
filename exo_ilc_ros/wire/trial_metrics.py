"""``/ilc/trial_metrics``: one trial's numbers as numbers (``std_msgs/msg/Float64MultiArray``),
so a Plot panel draws them by message path; built from the trial summary's key-values.

Why this type: the summary (``/ilc/trial_summary``, a DiagnosticArray as ROS tools expect)
carries strings, which no Plot panel draws. A standard array type decodes in every ROS tool,
bag reader and the Foxglove app without a message package of ours (this ament_python package
generates none), and its layout names the entries, so the message explains itself:

* ``data[0]`` = trial k, ``data[1]`` = the summary's level (0 OK: every joint within the
  error bound, 1 WARN), so ``layout.data_offset`` = :data:`HEADER_SIZE` = 2;
* then a metrics x joints matrix, row-major: ``layout.dim[0]`` (label ``metric=`` and the
  comma-separated names of :data:`ROWS`, size 10, stride 10 J), ``layout.dim[1]`` (label
  ``joint=`` and the joint names, size J, stride J). Entry (metric r, joint j) is
  ``data[2 + r J + j]``; NaN where the trial has none (the levels of trial 1, which no
  update formed, and of laws without levels).

Rows: ``max |e|`` (rad), RMS e (rad, the summary's ``metric/rms_error``: of the true error),
``max |u_ff|`` (rad/s^2), ``max |effort|`` (N m), the step gains M, M', M'' of eq. (11)
that formed the trial's feed-forward, and the identified patient's damping B (N m s/rad),
Coulomb friction F_c (N m) and stiffness K (N m/rad) after the trial (``identified/viscous``,
``identified/coulomb``, ``identified/stiffness``; NaN without identification or where not
identifiable). With 3 joints: ``max |e|`` of joint 1 is ``data[2]``, RMS e ``data[5]``, M
``data[14]``, B ``data[23]``, F_c ``data[26]``, K ``data[29]`` (:func:`index`).

With a person strapped in (the summary's ``cuff/<cuff>/<metric>`` keys,
:mod:`exo_ilc_ros.core.person.cuffs`) the cuff metrics follow the matrix, and a third
``layout.dim`` names them: label ``cuff_metric=`` and the comma-separated
``<cuff>/<metric>`` names (upper_arm then forearm, each peak |F| (N), RMS |F| (N), peak |T|
(N m), RMS |T| (N m)), size 8, stride 8: the upper-arm cuff's peak force of 3 joints is
``data[32]``, the forearm's ``data[36]``. Without a person there is no
third dimension and nothing after the matrix (a reader of two dimensions reads the message as
before).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NamedTuple

from . import topics

IDENTIFIED_ROWS = ("viscous", "coulomb", "stiffness")
"""The identified parameters drawn per trial (``identified/<name>/<joint>`` of the summary,
core/programs/identified.py): NaN where the summary has none or calls it not identifiable."""
HEADER = ("trial", "level")
HEADER_SIZE = len(HEADER)
ROWS: tuple[tuple[str, str], ...] = (
    ("max_abs_error", "max_abs_error"),
    ("rms_error", "metric/rms_error"),
    ("max_abs_feedforward", "max_abs_feedforward"),
    ("max_abs_effort", "max_abs_effort"),
    *((f"level/{symbol}", f"level/{symbol}") for symbol in topics.LEVEL_SYMBOLS),
    *((f"identified/{name}", f"identified/{name}") for name in IDENTIFIED_ROWS),
)
"""(row name, summary key prefix ``<prefix>/<joint>``) of the matrix, in order."""
ROW_NAMES = tuple(name for name, _ in ROWS)
METRIC_LABEL = "metric="
JOINT_LABEL = "joint="
CUFF_LABEL = "cuff_metric="
CUFF_PREFIX = "cuff/"
"""The summary's keys of the cuff metrics (``cuff/<cuff>/<metric>``, written by
:func:`exo_ilc_ros.core.person.cuffs.cuff_summary_values`, which names them): the cuff block
carries every one, in the summary's order."""


class Dimension(NamedTuple):
    """One ``std_msgs/MultiArrayDimension``."""

    label: str
    size: int
    stride: int


class TrialMetricsArray(NamedTuple):
    """The fields of the ``Float64MultiArray``: ``layout.dim``, ``layout.data_offset``, data."""

    dims: tuple[Dimension, ...]
    data_offset: int
    data: list[float]


def index(row: str, joint: int, joints: int) -> int:
    """Position in ``data`` of ``row`` (a :data:`ROW_NAMES` entry) for joint ``joint``
    (0-based) of ``joints``."""
    return HEADER_SIZE + ROW_NAMES.index(row) * joints + joint


def _number(text: str | None) -> float:
    try:
        return float(text) if text is not None else float("nan")
    except ValueError:
        return float("nan")


def trial_metrics(values: Mapping[str, str], names: Sequence[str],
                  warn: bool) -> TrialMetricsArray:
    """The array of a trial summary's key-values (``warn``: its level is WARN)."""
    j = len(names)
    data = [_number(values.get("trial")), 1.0 if warn else 0.0]
    for _, prefix in ROWS:
        if prefix.startswith("identified/"):  # only what the trials determine
            data += [_number(values.get(f"{prefix}/{n}"))
                     if values.get(f"{prefix}/identifiable/{n}") == "true" else float("nan")
                     for n in names]
            continue
        data += [_number(values.get(f"{prefix}/{n}")) for n in names]
    dims: tuple[Dimension, ...] = (
        Dimension(METRIC_LABEL + ",".join(ROW_NAMES), len(ROWS), len(ROWS) * j),
        Dimension(JOINT_LABEL + ",".join(names), j, j))
    cuffs = [key for key in values if key.startswith(CUFF_PREFIX)]
    if cuffs:  # a person strapped in
        data += [_number(values[key]) for key in cuffs]
        dims += (Dimension(CUFF_LABEL + ",".join(k.removeprefix(CUFF_PREFIX) for k in cuffs),
                           len(cuffs), len(cuffs)),)
    return TrialMetricsArray(dims, HEADER_SIZE, data)


def decode(labels: Sequence[str], data_offset: int, data: Sequence[float]
           ) -> dict[str, object]:
    """Inverse of :func:`trial_metrics` from the message alone (its labels): ``trial``,
    ``level`` and ``{row: {joint: value}}``; with a person also ``cuff``:
    ``{<cuff>/<metric>: value}``."""
    rows = labels[0].removeprefix(METRIC_LABEL).split(",")
    joints = labels[1].removeprefix(JOINT_LABEL).split(",")
    out: dict[str, object] = {"trial": int(data[0]), "level": int(data[1])}
    for r, row in enumerate(rows):
        out[row] = {joint: float(data[data_offset + r * len(joints) + k])
                    for k, joint in enumerate(joints)}
    if len(labels) > 2 and labels[2].startswith(CUFF_LABEL):
        start = data_offset + len(rows) * len(joints)
        out["cuff"] = {name: float(data[start + k]) for k, name in
                       enumerate(labels[2].removeprefix(CUFF_LABEL).split(","))}
    return out
