"""The package's controller and learning session driven from outside on MuJoCo, as a lab
drives its own arm: MuJoCo's native joint damping, dry friction (``frictionloss``, a hard
Coulomb law) and stiffness are the patient; the loop sees them only through the measured
position (optionally a 14-bit encoder with differenced velocity). Reports, per trial, the
estimates the loop uses against MuJoCo's true values and max |e|.

    python -m bench.mujoco_identification_bench [--trials 12] [--encoder] [--exercise NAME]
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import yaml

from exo_ilc_ros.core import Experiment, load_config
from exo_ilc_ros.core.loop.controller import GuardedControlStep
from exo_ilc_ros.core.loop.record import TrialRecord
from exo_ilc_ros.core.loop.trial import record_from_samples
from exo_ilc_ros.core.params.config import Config, config_dir
from exo_ilc_ros.core.session.learning_session import LearningSession, TrialConclusion
from exo_ilc_ros.core.sim.mujoco_arm import MujocoArm

COUNT = 2.0 * np.pi / 2 ** 14
"""rad: one count of a 14-bit joint encoder."""


@dataclass
class LabRun:
    """What a run driven from outside left: every record and conclusion."""

    records: list[TrialRecord] = field(default_factory=list)
    conclusions: list[TrialConclusion] = field(default_factory=list)

    def first_within(self, bound: float) -> int | None:
        """The first trial whose max |e| on every joint (the arm's true state) is within."""
        for record in self.records:
            truth = record.position if record.true_position is None else record.true_position
            if record.aborted_at is None and np.max(np.abs(record.reference.position
                                                           - truth)) <= bound:
                return record.trial
        return None


def lab_config(damping: float, frictionloss: float, stiffness: float,
               rest: tuple[float, float, float] = (0.0, 0.0, 0.3),
               overlay: str | None = "patient_aware.yaml", delta: float = 0.1,
               **overrides: Any) -> Config:
    """The shipped config (+ ``overlay``) with the patient as MuJoCo joint attributes (every
    joint: ``damping``, ``frictionloss``, ``stiffness`` toward ``rest``)."""
    values: dict[str, Any] = {
        "mass_uncertainty": delta,
        "patient.friction.viscous": [damping] * 3,
        "patient.friction.coulomb": [frictionloss] * 3,
        "patient.passive.stiffness": [stiffness] * 3,
        "patient.passive.rest_position": list(rest)}
    values.update(overrides)
    overlays = [config_dir() / overlay] if overlay else []
    return load_config(overlays=overlays, overrides=values)


def run_lab(config: Config, trials: int, encoder: bool = False) -> LabRun:
    """``trials`` trials of the session of ``config`` on MuJoCo: each from rest at q_d(0), the
    controller's effort at every sample from the measured (q, qdot) (``encoder``: q quantised
    to 14 bits, qdot its difference over one period, as most arms measure it)."""
    experiment = Experiment(config)
    session = LearningSession(config)
    arm = MujocoArm.from_config(config)
    control = GuardedControlStep(experiment)
    ref = experiment.reference
    samples, n = ref.position.shape
    period = experiment.period
    run = LabRun()
    while not session.finished and session.trial <= trials:
        feedforward = session.feedforward
        force = session.joint_force
        arm.set_state(ref.position[0], ref.velocity[0])
        control.begin_trial()
        q_log = np.empty((samples, n))
        qd_log = np.empty((samples, n))
        q_true = np.empty((samples, n))
        qd_true = np.empty((samples, n))
        aborted: int | None = None
        previous = ref.position[0]
        for i in range(samples):
            q_true[i], qd_true[i] = arm.position, arm.velocity
            if encoder:
                q = np.round(q_true[i] / COUNT) * COUNT
                qd = (q - previous) / period if i else np.zeros(n)
                previous = q
            else:
                q, qd = q_true[i], qd_true[i]
            q_log[i], qd_log[i] = q, qd
            if control.sample(i, feedforward[i], ref.position[i], ref.velocity[i], q, qd,
                              False, None if force is None else force[i]) and aborted is None:
                aborted = i
            if i + 1 < samples:
                arm.step(control.effort.copy())
        record = record_from_samples(experiment, session.trial, feedforward, q_log, qd_log,
                                     session.levels, aborted_at=aborted,
                                     true_position=q_true, true_velocity=qd_true,
                                     joint_force=force)
        run.records.append(record)
        run.conclusions.append(session.conclude(record))
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--trials", type=int, default=12)
    parser.add_argument("--encoder", action="store_true")
    parser.add_argument("--exercise", default="")
    parser.add_argument("--damping", type=float, default=0.4)
    parser.add_argument("--frictionloss", type=float, default=0.3)
    parser.add_argument("--stiffness", type=float, default=1.0)
    parser.add_argument("--delta", type=float, default=0.1)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=YAML",
                        help="config overrides, e.g. identification.in_loop=false")
    args = parser.parse_args()
    extra: dict[str, Any] = {"exercise.name": args.exercise} if args.exercise else {}
    for item in args.set:
        key, _, value = item.partition("=")
        extra[key] = yaml.safe_load(value)
    config = lab_config(args.damping, args.frictionloss, args.stiffness, delta=args.delta,
                        **extra)
    run = run_lab(config, args.trials, args.encoder)
    truth = {"viscous": args.damping, "coulomb": args.frictionloss, "stiffness": args.stiffness}
    for record, conclusion in zip(run.records, run.conclusions, strict=True):
        step = conclusion.joint_forces
        line = f"trial {record.trial:3d} max|e| {np.max(np.abs(record.error)):.2e}"
        if step is not None:
            est = step.estimate
            for name in truth:
                got = est.values(name)
                line += f"  {name} " + " ".join(f"{v:.3f}" for v in got)
            line += "  used " + "".join("1" if u else "0" for u in step.used)
            line += "  q0 " + " ".join(f"{v:.3f}" for v in est.values("rest_position"))
            print(line, truth)
            print("   ", [j.reasons for j in est.joints])
        else:
            print(line)
    print("first within 0.005:", run.first_within(0.005))
    if run.records:
        print(f"control period {run.records[0].reference.period * 1e3:g} ms "
              f"(control.period_rule {config['control.period_rule']})")


if __name__ == "__main__":
    main()
