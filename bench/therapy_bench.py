"""Therapy sessions, measured (issue #16's "done when"): prints numbers, writes the figure of
docs/therapy.md.

1. Assist-as-needed against the plain law over a session with a virtual patient (scenario,
   default the learning patient if shipped, else ``voluntary``): the robot's assistance (RMS
   torque beyond gravity compensation, and the learned feed-forward) over the trials, and the
   true max |e| against the safety envelope and the deadband.
2. A second session of the same patient and exercise from the stored profile: its trial-1
   max |e| over the first session's final max |e|.

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST .venv/bin/python -m bench.therapy_bench \
        [--scenario NAME] [--trials 100] [--figure docs/therapy-aan.png]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

from exo_ilc_ros.core.params.config import load_config, scenario_names, scenario_path
from exo_ilc_ros.core.persistence.profiles import ProfileBook
from exo_ilc_ros.core.programs.therapy import ExerciseResult, prepare, run_exercise

ROOT = Path(__file__).resolve().parents[1]
AAN = {"assist_as_needed.enabled": True}


def default_scenario() -> str:
    """The learning patient if the scenarios have one, else the voluntary patient."""
    names = scenario_names()
    learning = [n for n in names if "learn" in n]
    return learning[0] if learning else "voluntary"


def session(config: Any, root: Path, patient: str, trials: int, new: bool) -> ExerciseResult:
    book = ProfileBook(root)
    return run_exercise(prepare(config, book, patient, "paper_quintic", new), book, trials)


def table(done: ExerciseResult, name: str) -> np.ndarray:
    return np.array([getattr(m, name) for m in done.metrics])


def describe(label: str, done: ExerciseResult, config: Any) -> dict[str, float]:
    assist = table(done, "assistance_rms").sum(axis=1)
    uff = table(done, "feedforward_rms").sum(axis=1)
    error = table(done, "max_error")
    share = np.array([m.patient_share_total for m in done.metrics])
    k = min(10, len(assist) // 2)
    envelope = np.asarray(config["safety.error_envelope"])
    deadband = config["assist_as_needed.deadband_sigmas"] * \
        np.asarray(config["assist_as_needed.variability"])
    out = {"assist_first": float(assist[:k].mean()), "assist_last": float(assist[-k:].mean()),
           "uff_first": float(uff[:k].mean()), "uff_last": float(uff[-k:].mean()),
           "uff_peak": float(uff.max()), "error_last": float(error[-k:].max()),
           "error_after_first": float(error[k:].max()), "share_first": float(share[:k].mean()),
           "share_last": float(share[-k:].mean())}
    print(f"{label}:")
    print(f"  assistance, RMS torque beyond gravity (sum over joints, N m): trials 1-{k} "
          f"{out['assist_first']:.4f} -> last {k} {out['assist_last']:.4f} "
          f"({100 * (out['assist_last'] / out['assist_first'] - 1):+.1f} %)")
    print(f"  learned feed-forward RMS (sum over joints, rad/s^2): trials 1-{k} "
          f"{out['uff_first']:.4f}, peak {out['uff_peak']:.4f}, last {k} {out['uff_last']:.4f}")
    print(f"  true max |e| (rad), worst joint: after trial {k} at most "
          f"{out['error_after_first']:.4g}, last {k} at most {out['error_last']:.4g}; safety "
          f"envelope {envelope.min():g}, deadband 3 sigma {deadband.max():g}")
    print(f"  patient's share of the work: {100 * out['share_first']:.2f} % -> "
          f"{100 * out['share_last']:.2f} %")
    return out


def figure(plain: ExerciseResult, aan: ExerciseResult, path: Path, scenario: str) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9.0, 3.4), layout="constrained")
    left, mid, right = fig.subplots(1, 3)
    for done, label, style in ((plain, "plain law", "-"), (aan, "assist-as-needed", "-")):
        trials = np.arange(1, len(done.metrics) + 1)
        left.plot(trials, table(done, "assistance_rms").sum(axis=1), style, label=label)
        mid.plot(trials, table(done, "feedforward_rms").sum(axis=1), style, label=label)
        right.semilogy(trials, table(done, "max_error").max(axis=1), style, label=label)
    left.set_ylabel("assistance: RMS torque beyond gravity (N m)")
    mid.set_ylabel("learned feed-forward RMS (rad/s²)")
    right.set_ylabel("true max |e|, worst joint (rad)")
    for ax in (left, mid, right):
        ax.set_xlabel("trial")
        ax.grid(True, linewidth=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"Assist-as-needed vs the plain law, scenario {scenario}", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    print(f"wrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default=None)
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                        help="assist-as-needed overrides, e.g. assist_as_needed.forgetting=0.97")
    parser.add_argument("--variability-from-plain", action="store_true",
                        help="assist_as_needed.variability = sigma of the plain session's last "
                        "20 trials (core.learning.assist.estimate_variability)")
    args = parser.parse_args()
    scenario = args.scenario or default_scenario()
    overrides: dict[str, Any] = dict(AAN)
    for item in args.set:
        key, _, value = item.partition("=")
        overrides[key] = [float(v) for v in value.split(",")] if "," in value else float(value)
    base = load_config(ROOT / "config" / "robust.yaml", overlays=[scenario_path(scenario)])
    print(f"scenario {scenario}, config/robust.yaml, {args.trials} trials, exercise "
          f"paper_quintic; assist-as-needed: "
          + ", ".join(f"{k} = {v}" for k, v in overrides.items()))
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        plain = session(base, Path(tmp) / "a", "plain", args.trials, True)
        if args.variability_from_plain:  # sigma measured on the plain session's last trials
            from exo_ilc_ros.core.learning.assist import estimate_variability

            sigma = estimate_variability(plain.result.records[-20:])
            overrides["assist_as_needed.variability"] = [float(x) for x in sigma]
            print("variability measured on the plain session's last 20 trials: sigma = "
                  + " ".join(f"{x:.4g}" for x in sigma) + " rad")
        aan_config = base.replace(overrides)
        aan = session(aan_config, Path(tmp) / "b", "aan", args.trials, True)
        describe("plain law (robust.yaml)", plain, aan_config)
        describe("assist-as-needed", aan, aan_config)
        second = session(aan_config, Path(tmp) / "b", "aan", 10, False)
        final = float(np.max(aan.result.records[-1].true_max_abs_error))
        start = float(np.max(second.result.records[0].true_max_abs_error))
        print(f"second session from the stored profile: trial-1 true max |e| {start:.4g} rad, "
              f"first session's final {final:.4g} rad: ratio {start / final:.3f} (<= 1.5 "
              f"asked; from zero it is {np.max(aan.result.records[0].true_max_abs_error):.3g})")
        print(f"({time.perf_counter() - t0:.1f} s)")
        if args.figure:
            figure(plain, aan, args.figure, scenario)


if __name__ == "__main__":
    main()
