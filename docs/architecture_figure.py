"""Draws docs/architecture.png: the package's layers and the data flow of one trial, in-process and
through the ROS 2 graph. Run from the checkout: ``.venv/bin/python docs/architecture_figure.py``.

The picture is drawn from the lists below, not from the code: when a room or a topic changes,
change it here and run the script again."""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

OUT = Path(__file__).resolve().parent / "architecture.png"

TOP_LEVEL = [  # top to bottom: each imports only those below it
    ("cli/", "exo-ilc: simulate run param analyze paper tune study ..."),
    ("orchestration/", "the graph's processes, its domain, its recorder"),
    ("nodes/", "thin rclpy nodes: translate messages and parameters"),
    ("analysis/", "tables, figures, tuning, the study, reports"),
    ("bag/", "rosbag2 (MCAP) writing, CRC check, reading, replay"),
    ("wire/", "topics, QoS, CDR fast paths, who may publish"),
]
CORE_ROOMS = [  # top to bottom, the rooms of core/ (exo_ilc_ros.core.ROOMS, reversed)
    ("programs/", "therapy, metrics, study cells"),
    ("protocol/", "graph and homing protocol, samples"),
    ("session/", "LearningSession, run_trials, summary"),
    ("persistence/", "store, profiles, patient states"),
    ("sim/", "Experiment, MuJoCo arm"),
    ("convergence/", "iterations to bound, loop factors, growth"),
    ("learning/", "laws, Q-filter, norm-optimal, assist"),
    ("loop/", "compiled plant, controller rule, hold, trial"),
    ("reference/", "quintic, exercises"),
    ("arm/", "model, dynamics, geometry, URDF"),
    ("params/", "schema, config, validation"),
]
ROS_FREE = "#e8f1fb"
ROS = "#fdf0e0"
EDGE = "#44546a"


def box(ax: Axes, x: float, y: float, w: float, h: float, title: str, text: str,
        colour: str, text_x: float, size: float = 8.5) -> None:
    ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.004,rounding_size=0.008",
                                facecolor=colour, edgecolor=EDGE, linewidth=0.9))
    ax.text(x + 0.012, y + h / 2, title, va="center", ha="left", fontsize=size,
            fontweight="bold", family="monospace")
    ax.text(text_x, y + h / 2, text, va="center", ha="left", fontsize=size - 0.5)


def arrow(ax: Axes, start: tuple[float, float], end: tuple[float, float], label: str = "",
          offset: tuple[float, float] = (0.0, 0.012), colour: str = EDGE,
          style: str = "-|>", rad: float = 0.0) -> None:
    ax.add_patch(FancyArrowPatch(start, end, arrowstyle=style, mutation_scale=11,
                                 color=colour, linewidth=1.1,
                                 connectionstyle=f"arc3,rad={rad}"))
    if label:
        ax.text((start[0] + end[0]) / 2 + offset[0], (start[1] + end[1]) / 2 + offset[1], label,
                ha="center", va="bottom", fontsize=7.5, family="monospace", color="#222")


def layers(ax: Axes) -> None:
    ax.set_title("Layers: each imports only those below it", fontsize=11, loc="left")
    h, gap, x, w = 0.045, 0.012, 0.02, 0.96
    y = 0.965
    for title, text in TOP_LEVEL:
        y -= h
        colour = ROS if title in ("nodes/", "orchestration/", "cli/") else ROS_FREE
        box(ax, x, y, w, h, "exo_ilc_ros/" + title, text, colour, x + 0.30)
        y -= gap
    y -= 0.01
    top = y
    inner_h = 0.039
    bottom = top - len(CORE_ROOMS) * (inner_h + 0.008) - 0.045
    ax.add_patch(FancyBboxPatch((x, bottom), w, top - bottom,
                                boxstyle="round,pad=0.004,rounding_size=0.01",
                                facecolor="#f5f9fe", edgecolor=EDGE, linewidth=1.2))
    ax.text(x + 0.012, top - 0.022, "exo_ilc_ros/core/", fontsize=9, fontweight="bold",
            family="monospace", va="center")
    ax.text(x + 0.20, top - 0.022, "the mathematics and the learning session: numpy/numba, "
            "never rclpy;\nimported through its face, exo_ilc_ros.core", fontsize=7.5,
            va="center")
    y = top - 0.045
    for title, text in CORE_ROOMS:
        y -= inner_h
        box(ax, x + 0.03, y, w - 0.06, inner_h, title, text, ROS_FREE, x + 0.20, size=8)
        y -= 0.008
    ax.text(x, bottom - 0.03, "blue: ROS-free (no rclpy import)   orange: ROS 2 (rclpy)",
            fontsize=7.5, color="#333")


def flow(ax: Axes) -> None:
    ax.set_title("One trial: in-process (simulate) and through the graph (run)", fontsize=11,
                 loc="left")
    # In-process
    ax.text(0.02, 0.93, "In-process: exo-ilc simulate, run_trials", fontsize=9.5,
            fontweight="bold")
    w, h = 0.27, 0.075
    nodes = {
        "config": (0.02, 0.80, "config", "YAML + overrides\n(core params)"),
        "trial": (0.365, 0.80, "Experiment.run_trial",
                  "compiled loop: plant RK4,\nPD + computed torque"),
        "session": (0.71, 0.80, "LearningSession", "learn / keep / rerun,\nstore every trial"),
        "law": (0.365, 0.655, "law.update", "sign, linear, norm-\noptimal, Q-filter"),
    }
    for x, y, title, text in nodes.values():
        ax.add_patch(FancyBboxPatch((x, y), w, h, boxstyle="round,pad=0.004",
                                    facecolor=ROS_FREE, edgecolor=EDGE))
        ax.text(x + w / 2, y + h - 0.018, title, ha="center", va="center", fontsize=8.5,
                fontweight="bold", family="monospace")
        ax.text(x + w / 2, y + 0.025, text, ha="center", va="center", fontsize=7.3)
    arrow(ax, (0.29, 0.8375), (0.365, 0.8375))
    arrow(ax, (0.635, 0.8375), (0.71, 0.8375), "TrialRecord", (0, 0.04))
    arrow(ax, (0.845, 0.80), (0.635, 0.6925), "record", (0.04, -0.02))
    arrow(ax, (0.365, 0.6925), (0.43, 0.80), "u_ff of trial k+1", (-0.13, -0.03))

    # Graph
    ax.text(0.02, 0.56, "Through the ROS 2 graph: exo-ilc run (DDS, one process per node)",
            fontsize=9.5, fontweight="bold")
    graph = {
        "sup": (0.02, 0.31, "ilc_supervisor", "the same LearningSession\nthrough core's protocol;"
                "\nrebuilds the TrialRecord\nfrom the samples"),
        "ctl": (0.365, 0.31, "computed_torque_\ncontroller", "PD + computed torque,\n"
                "error envelope, safe hold"),
        "plant": (0.71, 0.31, "plant_simulator", "the same compiled\nplant kernels\n"
                  "(or MuJoCo, or your arm)"),
        "bag": (0.02, 0.04, "bag_recorder", "every topic as received, in\nthe supervisor's process"
                "\n-> bags/<run>/"),
    }
    hh = 0.13
    for key, (x, y, title, text) in graph.items():
        ax.add_patch(FancyBboxPatch((x, y), w, hh, boxstyle="round,pad=0.004",
                                    facecolor=ROS, edgecolor=EDGE))
        top = y + hh - (0.028 if "\n" in title else 0.02)
        ax.text(x + w / 2, top, title, ha="center", va="center", fontsize=8.3,
                fontweight="bold", family="monospace")
        ax.text(x + w / 2, y + (0.045 if key != "bag" else 0.04), text, ha="center",
                va="center", fontsize=7.1)
    arrow(ax, (0.29, 0.40), (0.365, 0.40))
    ax.text(0.3275, 0.465, "/ilc/feedforward\n(u_ff, q_d)", ha="center", fontsize=7.2,
            family="monospace")
    arrow(ax, (0.635, 0.40), (0.71, 0.40))
    ax.text(0.6725, 0.465, "/effort_controller\n/commands", ha="center", fontsize=7.2,
            family="monospace")
    arrow(ax, (0.80, 0.31), (0.545, 0.31), rad=-0.4)
    arrow(ax, (0.80, 0.31), (0.20, 0.31), rad=-0.42)
    ax.text(0.86, 0.27, "/joint_states", fontsize=7.5, family="monospace", ha="left")
    arrow(ax, (0.29, 0.105), (0.40, 0.105))
    ax.text(0.41, 0.105, "exo-ilc analyze (analysis: tables, figures), simulate --replay",
            fontsize=7.2, va="center")
    ax.text(0.30, 0.01, "Graph == in-process: the same kernels and the same session, "
            "so the per-trial\nmax |e| agree bit for bit.", fontsize=7.8, style="italic")


def main() -> int:
    fig, (left, right) = plt.subplots(2, 1, figsize=(7.8, 12.6),
                                      gridspec_kw={"height_ratios": [1, 0.95]})
    for ax in (left, right):
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.axis("off")
    layers(left)
    flow(right)
    fig.tight_layout()
    fig.savefig(OUT, dpi=110, metadata={"Software": None})
    print(OUT)
    return 0


if __name__ == "__main__":
    sys.exit(main())
