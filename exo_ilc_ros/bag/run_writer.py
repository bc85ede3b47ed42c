"""A bag of an in-process run (``exo-ilc simulate --bag``): the messages the graph would have
published, on the same topics and types, so users without the graph get the same record.

Simulated time is the plant simulator's: trial k's sample i is stamped
``((k - 1) (N + 1) + 1 + i) * period`` (each reset puts the next t0 one period after the last
sample). The order per trial is the graph's: feed-forward, the controller's ``loaded`` and
``start`` at t0, the samples (``/clock`` as the plant sends it: every ``clock_every``-th sample
and the first and last; with a person strapped in each cuff's wrench just before its
sample), the controller's ``done``, the summary, the trial metrics and ``end`` at the last
sample; ``finished`` after the last trial. The arm's view
(:class:`~.view.ArmView`, as the live view shows it): ``/robot_description`` and
``/reference/robot_description`` once, at the start (log time 0), and per sample a ``/tf`` at
its stamp; with a person strapped in the person's display URDF once (log time 0) and per
sample the person's joints and their ``/tf``, as the graph's recorder holds them. The same
topics and types as the recorder's bag, one storage file per trial
(``split_every``), each file's metadata with the run's configuration. Log and publish times
equal the sim stamps (the recorder's rule, see ``nodes/bag_recorder.py``). Not written (the
graph's, not the run's): the nodes' once-a-second health on ``/diagnostics`` and
``/parameter_events``, declared with no message.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from datetime import datetime
from pathlib import Path

import numpy as np

from ..core.params.config import Config
from ..core.person.cuffs import cuff_summary_values
from ..core.programs.identified import Identified
from ..core.programs.metrics import TrialMetrics, metric_summary_values
from ..core.session.result import RunResult
from ..wire import protocol, topics
from ..wire.qos import offered_qos
from . import messages
from . import view as view_module
from .provenance import TRIALS_COMPLETED, provenance_data
from .view import ArmView
from .writer import BagWriter

NS = 1_000_000_000


def run_name(source: str, law: str, mass_uncertainty: float,
             when: datetime | None = None) -> str:
    """``<source>_<law>_d<delta>_<YYYYmmdd-HHMMSS>`` (source: ``sim`` or ``graph``): the
    directory name of a run's bag."""
    stamp = (when or datetime.now()).strftime("%Y%m%d-%H%M%S")
    return re.sub(r"[^A-Za-z0-9_.-]", "_", f"{source}_{law}_d{mass_uncertainty:g}_{stamp}")


def unique_path(parent: Path | str, name: str) -> Path:
    """``parent/name``, or ``parent/name-2``, ... if taken."""
    parent = Path(parent)
    candidate, n = parent / name, 1
    while candidate.exists():
        n += 1
        candidate = parent / f"{name}-{n}"
    return candidate


def declare_topics(writer: BagWriter, person: bool = False) -> None:
    """Every topic of :data:`topics.BAG_TYPES` (and with a ``person`` strapped in
    :data:`topics.PERSON_TYPES`: the cuffs' wrenches, the person's joints and display URDF),
    with the QoS their publishers offer."""

    for topic, msgtype in {**topics.BAG_TYPES,
                           **(topics.PERSON_TYPES if person else {})}.items():
        writer.add_topic(topic, msgtype, offered_qos(topic))


def write_run(path: Path | str, config: Config, result: RunResult, *, storage: str = "mcap",
              split_every: int = 1, name: str = "",
              extra_custom_data: Mapping[str, str] | None = None,
              metrics: Sequence[TrialMetrics] | None = None) -> Path:
    """Write ``result`` (a run of ``config``) as a bag at ``path``; ``split_every`` > 0 starts a
    new storage file every that many trials (as the recorder does); ``metrics`` (one per
    record; default: measured here) go into the trial summaries. Returns ``path``."""
    path = Path(path)
    names = list(config["joint_names"])
    measured = config.replace({"law": result.law}).with_mass_uncertainty(result.mass_uncertainty)
    custom = provenance_data(measured, recorded_by="exo-ilc simulate",
                             run_name=name or path.name)
    custom.update(extra_custom_data or {})
    period_ns = int(round(float(config["control.period"]) * NS))
    clock_every = max(1, int(config["clock_every"]))
    view = ArmView(config)
    with BagWriter(path, storage=storage, custom_data=custom) as writer:
        declare_topics(writer, any(r.cuff_wrench is not None for r in result.records))
        for topic, raw in view.descriptions().items():
            writer.write(topic, 0, raw)
        person_names: list[str] = []
        if result.person_description:  # as the plant publishes it, before the trials
            raw = view_module.string_message(result.person_description)
            writer.write(topics.PERSON_DESCRIPTION, 0, raw)
            view.load_person(raw)
            person_names = list(view.person.moving) if view.person is not None else []
        for k, record in enumerate(result.records, start=1):
            ref = record.reference
            samples = ref.samples
            t0 = ((k - 1) * samples + 1) * period_ns
            ff = messages.feedforward(t0, k, names, ref.time, ref.position, ref.velocity,
                                      record.feedforward)
            writer.write(topics.FEEDFORWARD, t0, ff)
            view.load_reference(ff)
            writer.write(topics.DIAGNOSTICS, t0, messages.controller_status(
                t0, "loaded", [("trial", str(k)), ("t0_ns", str(t0))]))
            writer.write(topics.TRIAL_EVENTS, t0, messages.trial_event(t0, "start", k))
            applied = np.vstack([np.zeros((1, record.effort.shape[1])), record.effort[:-1]])
            for i in range(samples):
                ns = t0 + i * period_ns
                if i % clock_every == 0 or i == samples - 1:  # as plant_simulator sends it
                    writer.write(topics.CLOCK, ns, messages.clock(ns))
                if record.cuff_wrench is not None:  # a person: as the plant, before the sample
                    for c, topic in enumerate(topics.CUFF_WRENCHES):
                        writer.write(topic, ns, messages.cuff_wrench(ns, c,
                                                                     record.cuff_wrench[i, c]))
                if record.person_position is not None and record.person_velocity is not None \
                        and person_names:  # as the plant: the person's joints, then the arm's
                    person = messages.joint_state(
                        ns, person_names, record.person_position[i], record.person_velocity[i],
                        np.full(len(person_names), np.nan))
                    writer.write(topics.PERSON_JOINT_STATES, ns, person)
                    person_tf = view.person_tf(person)
                    if person_tf is not None:
                        writer.write(topics.TF, ns, person_tf[1])
                state = messages.joint_state(ns, names, record.position[i],
                                             record.velocity[i], applied[i])
                writer.write(topics.JOINT_STATES, ns, state)
                tf = view.tf(state)
                if tf is not None:
                    writer.write(topics.TF, ns, tf[1])
                writer.write(topics.EFFORT_COMMANDS, ns,
                             messages.effort_command(record.effort[i]))
            end = t0 + (samples - 1) * period_ns
            values = protocol.summary_values(
                k, result.mass_uncertainty, result.law, names, record.max_abs_error,
                np.max(np.abs(record.feedforward), axis=0), np.max(np.abs(record.effort), axis=0),
                record.levels, record.aborted_at, result.applied.get(k + 1),
                None if record.true_position is None else record.true_max_abs_error,
                result.notes.get(k, ()))
            if metrics is not None:
                values += metrics[k - 1].summary_values(names)
            else:  # as the supervisor files them (core/programs/metrics.py)
                values += metric_summary_values(record, measured, names)
            values += cuff_summary_values(record.cuff_wrench)  # as the supervisor files them
            step = result.joint_forces.get(k)
            if step is not None:  # as the supervisor files it (core/programs/identified.py)
                values += Identified.from_step(step, names).summary_values()
            within = bool(np.all(record.max_abs_error <= result.error_bound))
            aborted = -1 if record.aborted_at is None else int(record.aborted_at)
            writer.write(topics.DIAGNOSTICS, end, messages.controller_status(
                end, "done", [("trial", str(k)), ("t0_ns", str(t0)),
                              ("aborted_at", str(aborted)), ("watchdog_trips", "0")]))
            writer.write(topics.TRIAL_SUMMARY, end, messages.trial_summary(end, values, within))
            writer.write(topics.TRIAL_METRICS, end, messages.trial_metrics(values, names, within))
            writer.write(topics.TRIAL_EVENTS, end, messages.trial_event(end, "end", k, values))
            writer.set_custom_data(TRIALS_COMPLETED, str(k))
            if split_every > 0 and k % split_every == 0:
                writer.split()
        if result.records:
            count = len(result.records)
            end = (count * result.records[-1].reference.samples) * period_ns
            writer.write(topics.TRIAL_EVENTS, end, messages.trial_event(
                end, "finished", count, [("trials", str(count))]))
    return path
