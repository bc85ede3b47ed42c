"""The live view's layout made for the run's arm: a Foxglove or Lichtblick layout (JSON, the
apps' ``configById`` format, "Import from file") and a PlotJuggler one (XML), generated from
the config: the arm's joints (names, count, order: the order the graph publishes them in
``/joint_states`` and the commands), its root link (the 3D panel follows it), and which
per-trial numbers the run has (``/ilc/trial_metrics``; the identified B only with
``identification.enabled``, the step gain M only under the sign law) and, with a person
strapped in (``musculoskeletal.model``), the cuff forces: per sample the force components of
each cuff (``/cuffs/<cuff>/wrench``) and per trial each cuff's peak and RMS |F| (the metrics'
cuff block, :func:`cuff_index`), and the 3D panel draws the person from its own URDF
(``/person/robot_description``, a URDF layer) on the /tf the view computes.

Per-trial series are placed by the layout the metrics message declares
(:func:`~exo_ilc_ros.wire.trial_metrics.index`: ``data_offset`` + row x joints + joint, the
rows and joints named in its ``layout.dim`` labels), for the run's joints; every series is
labelled with its joint's name and every panel titled under the app's own key
(:data:`TITLE_KEYS`). ``exo-ilc layout`` writes them; ``exo-ilc run --live`` writes the run's
and prints its path. No ROS import.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from typing import Any, NamedTuple

from ..core.arm.build import view_urdf
from ..core.params.config import Config
from ..core.person.cuffs import CUFF_METRICS, CUFFS
from ..wire import topics
from ..wire.trial_metrics import HEADER_SIZE, ROW_NAMES, index

APPS = ("foxglove", "lichtblick")
TITLE_KEYS = {"foxglove": "foxglovePanelTitle", "lichtblick": "lichtblickPanelTitle"}
"""The config key each app reads a panel's title from (Lichtblick's
``PANEL_TITLE_CONFIG_KEY``; Foxglove's own)."""
COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2",
          "#7f7f7f", "#bcbd22", "#17becf")
SCRIPT_TOPIC = "/studio_script/tracking_error"
REFERENCE_PREFIX = "reference/"


class ArmLayout(NamedTuple):
    """What a layout is made from."""

    joint_names: tuple[str, ...]
    root_link: str
    per_trial_rows: tuple[str, ...]
    """The ``/ilc/trial_metrics`` rows drawn per trial (:data:`PER_TRIAL_PLOTS`)."""
    cuffs: tuple[str, ...] = ()
    """A person strapped in: the cuffs (``core.person.cuffs.CUFFS``) whose forces are drawn,
    per sample (``/cuffs/<cuff>/wrench``) and per trial (:data:`CUFF_PLOTS`); empty: none."""


class PerTrialPlot(NamedTuple):
    """A per-trial plot: its panel id, the metrics row and the title."""

    panel: str
    row: str
    title: str


PER_TRIAL_PLOTS = (
    PerTrialPlot("max_error", "max_abs_error", "max |e| per trial, rad"),
    PerTrialPlot("rms_error", "rms_error", "RMS e per trial, rad"),
    PerTrialPlot("level_M", "level/M", "step gain M per trial (eq. (11))"),
    PerTrialPlot("identified_damping", "identified/viscous",
                 "identified damping B per trial, N m s/rad"),
)
"""Every per-trial plot a run may have. A plot of a row :mod:`~exo_ilc_ros.wire.trial_metrics`
gains (the cuff forces, when they are measured) joins here with one line; it shows where
:func:`per_trial_rows` says the run has that row."""


CUFF_PLOTS = (
    PerTrialPlot("cuff_peak_force", "peak_force_N", "peak cuff force |F| per trial, N"),
    PerTrialPlot("cuff_rms_force", "rms_force_N", "RMS cuff force |F| per trial, N"),
)
"""The per-trial cuff plots of a person's run: one series per cuff, the entry of the metrics'
cuff block (:func:`cuff_index`) whose metric is ``row`` (a ``CUFF_METRICS`` name)."""
FORCE_AXES = ("x", "y", "z")


def cuff_index(cuff: str, metric: str, joints: int) -> int:
    """Position in ``/ilc/trial_metrics``' data of ``cuff``'s ``metric`` (the cuff block after
    the joints' matrix, :mod:`~exo_ilc_ros.wire.trial_metrics`: cuffs in ``CUFFS`` order, each
    its ``CUFF_METRICS``)."""
    return (HEADER_SIZE + len(ROW_NAMES) * joints + CUFFS.index(cuff) * len(CUFF_METRICS)
            + CUFF_METRICS.index(metric))


def cuff_topic(cuff: str) -> str:
    """The per-sample wrench topic of ``cuff``."""
    return topics.CUFF_WRENCHES[CUFFS.index(cuff)]


def per_trial_rows(config: Config) -> tuple[str, ...]:
    """The rows the run fills: max |e| and RMS e always, M under the sign law (the only law
    with step gains), the identified B with ``identification.enabled``."""
    rows = ["max_abs_error", "rms_error"]
    if config["law"] == "sign":
        rows.append("level/M")
    if config["identification.enabled"]:
        rows.append("identified/viscous")
    return tuple(r for r in rows if r in ROW_NAMES)


def arm_layout(config: Config) -> ArmLayout:
    """The layout's inputs from the run's config."""
    _, _, root = view_urdf(config)
    person = str(config["musculoskeletal.model"]) != "none"
    return ArmLayout(tuple(config["joint_names"]), root, per_trial_rows(config),
                     CUFFS if person else ())


def _series(path: str, label: str, j: int, stamp: str, line: bool = False) -> dict[str, Any]:
    out: dict[str, Any] = {"value": path, "enabled": True, "timestampMethod": stamp,
                           "label": label, "color": COLORS[j % len(COLORS)]}
    if line:
        out["showLine"] = True
    return out


def _plot(app: str, title: str, paths: list[dict[str, Any]],
          x_path: str | None = None) -> dict[str, Any]:
    out: dict[str, Any] = {TITLE_KEYS[app]: title, "paths": paths, "showLegend": True,
                           "legendDisplay": "floating"}
    if x_path is None:
        out["xAxisVal"] = "timestamp"
    else:
        out["xAxisVal"] = "custom"
        out["xAxisPath"] = {"value": x_path, "enabled": True}
    return out


TRACKING_ERROR_SCRIPT = """\
// Tracking error e = q_d - q per joint and sample (rad): q_d from the trial's
// /ilc/feedforward (point i = (stamp - t0) / period, positions = q_d(t_i)), q from
// /joint_states. Works on the live view and on bags alike (both carry the two topics).
import { Input } from "./types";

export const inputs = ["/ilc/feedforward", "/joint_states"];
export const output = "/studio_script/tracking_error";

type Time = { sec: number; nsec: number };
type Output = { header: { stamp: Time; frame_id: string }; name: string[]; error: number[] };

let t0 = 0;
let period = 0;
let names: string[] = [];
let reference: number[][] = [];

function nanoseconds(t: any): number {
  return t.sec * 1e9 + (t.nsec ?? t.nanosec ?? 0);
}

export default function script(
  event: Input<"/ilc/feedforward"> | Input<"/joint_states">,
): Output | undefined {
  const msg: any = event.message;
  if (event.topic === "/ilc/feedforward") {
    t0 = nanoseconds(msg.header.stamp);
    names = Array.from(msg.joint_names);
    reference = msg.points.map((p: any) => Array.from(p.positions as number[]));
    period = msg.points.length > 1
      ? nanoseconds(msg.points[1].time_from_start) - nanoseconds(msg.points[0].time_from_start)
      : 0;
    return undefined;
  }
  if (period <= 0 || reference.length === 0) {
    return undefined;
  }
  const i = Math.round((nanoseconds(msg.header.stamp) - t0) / period);
  if (i < 0 || i >= reference.length) {
    return undefined;
  }
  const error = (msg.name as string[]).map(
    (n: string, j: number) => reference[i][names.indexOf(n)] - msg.position[j]);
  return { header: msg.header, name: msg.name, error };
}
"""


def _three_d(app: str, root_link: str) -> dict[str, Any]:
    return {
        TITLE_KEYS[app]: "the arm (measured) and the reference q_d (orange)",
        "cameraState": {"distance": 2.2, "perspective": True, "phi": 60, "thetaOffset": 30,
                        "targetOffset": [0, 0.3, -0.3], "target": [0, 0, 0],
                        "targetOrientation": [0, 0, 0, 1], "fovy": 45, "near": 0.01,
                        "far": 5000},
        "followMode": "follow-pose",
        "followTf": root_link,
        "scene": {"transforms": {"labelSize": 0.03, "axisSize": 0.08}},
        "transforms": {},
        "topics": {topics.ROBOT_DESCRIPTION: {"visible": True}},
        "layers": {
            "grid": {"layerId": "foxglove.Grid", "instanceId": "grid", "label": "Grid",
                     "visible": True, "frameLocked": True, "size": 4, "divisions": 20,
                     "lineWidth": 1, "color": "#248eff", "position": [0, 0, -1],
                     "rotation": [0, 0, 0], "order": 1},
            "reference": {"layerId": "foxglove.Urdf", "instanceId": "reference",
                          "label": "reference q_d (reference/ frames)", "visible": True,
                          "frameLocked": True, "sourceType": "topic",
                          "topic": topics.ROBOT_DESCRIPTION, "framePrefix": REFERENCE_PREFIX,
                          "displayMode": "auto", "fallbackColor": "#ff9900", "order": 2},
        },
        "publish": {"type": "point", "poseTopic": "/move_base_simple/goal",
                    "pointTopic": "/clicked_point", "poseEstimateTopic": "/initialpose",
                    "poseEstimateXDeviation": 0.5, "poseEstimateYDeviation": 0.5,
                    "poseEstimateThetaDeviation": 0.26179939},
        "imageMode": {},
    }


def _column(panels: Sequence[Any]) -> Any:
    """A column of panels (a mosaic tree), equal heights."""
    if len(panels) == 1:
        return panels[0]
    half = len(panels) // 2
    return {"direction": "column", "splitPercentage": 100.0 * half / len(panels),
            "first": _column(panels[:half]), "second": _column(panels[half:])}


def foxglove_layout(arm: ArmLayout, app: str = "foxglove") -> dict[str, Any]:
    """The layout (Foxglove's or Lichtblick's ``configById`` format) for ``arm``."""
    if app not in APPS:
        raise ValueError(f"app {app!r}: use one of {', '.join(APPS)}")
    joints = arm.joint_names
    count = len(joints)
    metrics = topics.TRIAL_METRICS
    trial = f"{metrics}.data[0]"
    panels: dict[str, Any] = {"3D!arm": _three_d(app, arm.root_link)}
    if arm.cuffs:  # a person strapped in: drawn from its own URDF, on /tf as simulated
        three_d = panels["3D!arm"]
        three_d[TITLE_KEYS[app]] = ("the arm (measured), the reference q_d (orange) and the "
                                    "person")
        three_d["layers"]["person"] = {
            "layerId": "foxglove.Urdf", "instanceId": "person",
            "label": "the person (person/ frames)", "visible": True, "frameLocked": True,
            "sourceType": "topic", "topic": topics.PERSON_DESCRIPTION, "displayMode": "auto",
            "order": 3}
    panels["Plot!tracking_error"] = _plot(
        app, "tracking error e = q_d - q, rad (script tracking_error)",
        [_series(f"{SCRIPT_TOPIC}.error[{j}]", n, j, "headerStamp")
         for j, n in enumerate(joints)])
    panels["Plot!position"] = _plot(
        app, f"q position, rad ({topics.JOINT_STATES})",
        [_series(f"{topics.JOINT_STATES}.position[{j}]", n, j, "headerStamp")
         for j, n in enumerate(joints)])
    panels["Plot!commands"] = _plot(
        app, f"effort commands, N m ({topics.EFFORT_COMMANDS})",
        [_series(f"{topics.EFFORT_COMMANDS}.data[{j}]", n, j, "receiveTime")
         for j, n in enumerate(joints)])
    per_trial = []
    for plot in PER_TRIAL_PLOTS:
        if plot.row not in arm.per_trial_rows:
            continue
        panel = f"Plot!{plot.panel}"
        panels[panel] = _plot(
            app, f"{plot.title} ({metrics})",
            [_series(f"{metrics}.data[{index(plot.row, j, count)}]", n, j, "receiveTime",
                     line=True) for j, n in enumerate(joints)], x_path=trial)
        per_trial.append(panel)
    for plot in CUFF_PLOTS if arm.cuffs else ():
        panel = f"Plot!{plot.panel}"
        panels[panel] = _plot(
            app, f"{plot.title} ({metrics})",
            [_series(f"{metrics}.data[{cuff_index(c, plot.row, count)}]", c, k, "receiveTime",
                     line=True) for k, c in enumerate(arm.cuffs)], x_path=trial)
        per_trial.append(panel)
    samples = ["Plot!position", "Plot!commands"]
    if arm.cuffs:
        panels["Plot!cuff_force"] = _plot(
            app, "cuff force on the person, N (/cuffs/<cuff>/wrench, cuff frame: x "
            "mediolateral, y anteroposterior, z along the limb)",
            [_series(f"{cuff_topic(c)}.wrench.force.{axis}", f"{c} F{axis}",
                     k * len(FORCE_AXES) + a, "headerStamp")
             for k, c in enumerate(arm.cuffs) for a, axis in enumerate(FORCE_AXES)])
        samples.append("Plot!cuff_force")
    panels["DiagnosticSummary!diagnostics"] = {TITLE_KEYS[app]: "the nodes' health",
                                               "topicToRender": topics.DIAGNOSTICS,
                                               "sortByLevel": True}
    panels["RawMessages!summary"] = {TITLE_KEYS[app]: "the last trial's summary",
                                     "topicPath": f"{topics.TRIAL_SUMMARY}.status[0]",
                                     "diffEnabled": False, "expansion": "all"}
    return {
        "configById": panels,
        "globalVariables": {},
        "userNodes": {"tracking_error": {"name": "tracking_error",
                                         "sourceCode": TRACKING_ERROR_SCRIPT}},
        "playbackConfig": {"speed": 1},
        "layout": {
            "direction": "row", "splitPercentage": 62,
            "first": {"direction": "column", "splitPercentage": 55, "first": "3D!arm",
                      "second": {"direction": "row", "first": "Plot!tracking_error",
                                 "second": _column(samples) if arm.cuffs else
                                 {"direction": "column", "first": "Plot!position",
                                  "second": "Plot!commands"}}},
            "second": {"direction": "column", "splitPercentage": 60,
                       "first": _column(per_trial),
                       "second": {"direction": "column",
                                  "first": "DiagnosticSummary!diagnostics",
                                  "second": "RawMessages!summary"}},
        },
    }


def foxglove_json(arm: ArmLayout, app: str = "foxglove") -> str:
    """:func:`foxglove_layout` as the file the app imports."""
    return json.dumps(foxglove_layout(arm, app), indent=1) + "\n"


def plotjuggler_xml(arm: ArmLayout) -> str:
    """PlotJuggler's layout (File > Load layout) for ``arm``: q, qdot, effort and the effort
    commands per joint, and the per-trial numbers (``/ilc/trial_metrics/data[i]``)."""
    root = ET.Element("root")
    tabs = ET.SubElement(root, "tabbed_widget", {"name": "Main Window", "parent": "main_window"})

    def tab(name: str, areas: list[tuple[str, list[str]]]) -> None:
        container = ET.SubElement(ET.SubElement(tabs, "Tab", containers="1", tab_name=name),
                                  "Container")
        splitter = ET.SubElement(container, "DockSplitter", orientation="-",
                                 count=str(len(areas)),
                                 sizes=";".join([f"{1 / len(areas):g}"] * len(areas)))
        for title, curves in areas:
            plot = ET.SubElement(ET.SubElement(splitter, "DockArea", name=title), "plot",
                                 mode="TimeSeries", flip_x="false", flip_y="false",
                                 style="Lines")
            ET.SubElement(plot, "range", left="0", right="5", top="1", bottom="-1")
            ET.SubElement(plot, "limitY")
            for j, curve in enumerate(curves):
                ET.SubElement(plot, "curve", name=curve, color=COLORS[j % len(COLORS)])

    joints = arm.joint_names
    js = topics.JOINT_STATES
    tab("joints", [(f"q {field}", [f"{js}/{n}/{field}" for n in joints])
                   for field in ("position", "velocity", "effort")]
        + [("effort commands",
            [f"{topics.EFFORT_COMMANDS}/data[{j}]" for j in range(len(joints))])])
    metrics = topics.TRIAL_METRICS
    tab("per trial", [(f"{plot.title} ({', '.join(joints)})",
                       [f"{metrics}/data[{index(plot.row, j, len(joints))}]"
                        for j in range(len(joints))])
                      for plot in PER_TRIAL_PLOTS if plot.row in arm.per_trial_rows]
        + [(f"{plot.title} ({', '.join(arm.cuffs)})",
            [f"{metrics}/data[{cuff_index(c, plot.row, len(joints))}]" for c in arm.cuffs])
           for plot in CUFF_PLOTS if arm.cuffs])
    if arm.cuffs:
        tab("cuffs", [(f"{c} cuff force, N (cuff frame)",
                       [f"{cuff_topic(c)}/wrench/force/{axis}" for axis in FORCE_AXES])
                      for c in arm.cuffs])
    ET.SubElement(tabs, "currentTabIndex", index="0")
    ET.SubElement(root, "use_relative_time_offset", enabled="1")
    plugins = ET.SubElement(root, "Plugins")
    ET.SubElement(plugins, "plugin", ID="DataLoad MCAP")
    ros2 = ET.SubElement(plugins, "plugin", ID="ROS2 Topic Subscriber")
    ET.SubElement(ros2, "use_header_stamp", value="true")
    ET.SubElement(ros2, "discard_large_arrays", value="true")
    ET.SubElement(ros2, "max_array_size", value="100")
    selected = ET.SubElement(ros2, "selected_topics")
    for topic in (js, topics.EFFORT_COMMANDS, metrics, topics.TRIAL_SUMMARY,
                  *(cuff_topic(c) for c in arm.cuffs)):
        ET.SubElement(selected, "topic", name=topic)
    ET.indent(root, " ")
    comment = (f"<!-- PlotJuggler layout for exo_ilc_ros (File > Load layout), with a bag (MCAP) "
               f"or live topics, made for the arm of joints {', '.join(joints)} (exo-ilc layout "
               "plotjuggler). /ilc/trial_metrics/data[i]: its layout.dim labels name each "
               "entry. -->\n")
    return ("<?xml version='1.0' encoding='UTF-8'?>\n" + comment
            + ET.tostring(root, encoding="unicode") + "\n")
