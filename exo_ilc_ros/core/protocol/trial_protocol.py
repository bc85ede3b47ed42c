"""The trial protocol of a graph run, ROS-free: how a :class:`LearningSession`'s trials are run
on a plant that is reached through messages and services (the ``ilc_supervisor`` node is its
ROS binding; tests drive it by hand).

Per trial: reset the plant (it answers with the stamp t0 of the trial's first sample), push the
session's feed-forward, wait for the controller's acknowledgement, start the plant, collect the
N+1 samples (:class:`TrialSamples`), and, once the controller reported the trial ``done``,
conclude it in the session. A trial with a watchdog trip, lost samples or a step that made no
progress for :data:`STEP_TIMEOUT` is discarded and run again with the same feed-forward. A plant
whose state stopped being finite reports ``diverged`` instead of that sample
(:meth:`TrialProtocol.on_plant_diverged`): the trial ends there as the trial kernel ends it
in-process (every sample from it on NaN, aborted there unless the envelope aborted it before),
and the session stops on it with its one message. With a
recorder (``wait_for_recorder``) a concluded trial is stored only once the recorder filed it;
the next trial is prepared meanwhile and started after the store (``WAIT_RECORDER``), so a
stored trial is always in a bag.

With a person strapped in (``musculoskeletal.model``) the plant also sends every sample's
cuff wrenches (:meth:`TrialProtocol.on_cuff_sample`); a trial ends once they are in too, its
record carries them (``TrialRecord.cuff_wrench``), and the first sample a cuff pressed past
``safety.cuff_force_limit`` (:func:`~..person.cuffs.first_beyond_cuff_limit`, the in-process
rule) aborts it there unless the envelope aborted it before: the plant held the arm safe from
that sample on, and the record is rebuilt with the safe hold from it, as in-process.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from enum import Enum
from typing import Any, Protocol

import numpy as np

from ..errors import ExoIlcError
from ..loop.controller import outside_envelope
from ..loop.divergence import PlantDivergence
from ..loop.rate import with_control_rate
from ..loop.trial import record_from_samples, sample_index
from ..params.config import Config
from ..persistence.store import RunStore
from ..person.cuffs import CUFFS, first_beyond_cuff_limit
from ..reference.build import build_reference
from ..session.abort import ABORT_STOP_KEY
from ..session.learning_session import LIVE, LearningSession, TrialConclusion
from ..sim.experiment import Experiment
from .samples import CuffSamples, TrialSamples
from .timing import ACK_RETRY, LATE_RERUNS, RECORDER_TIMEOUT, STEP_TIMEOUT


class Phase(Enum):
    """Where the protocol is."""

    WAIT_GRAPH = "wait_graph"
    RESETTING = "resetting"
    WAIT_ACK = "wait_ack"
    STARTING = "starting"
    HOMING = "homing"
    """Protocol homing: the controller brings the arm to q_d(0)
    (core/protocol/homing_protocol.py)."""
    RUNNING = "running"
    WAIT_RECORDER = "wait_recorder"
    FINISHED = "finished"


class GraphPort(Protocol):
    """What the protocol asks of the graph; answers come back as ``on_*`` calls."""

    def reset(self) -> None:
        """Put the plant at x_d(0); answered by :meth:`TrialProtocol.on_reset`."""

    def start(self) -> None:
        """Release the plant; answered by :meth:`TrialProtocol.on_started`."""

    def push_feedforward(self, trial: int, t0_ns: int, feedforward: np.ndarray,
                         joint_force: np.ndarray | None = None) -> None:
        """Send the trial's feed-forward (and the identified joint forces computed torque adds,
        None: none) to the controller (it acknowledges it)."""

    def publish_conclusion(self, conclusion: TrialConclusion, end_ns: int) -> None:
        """The trial summary and the ``end`` event (and ``aborted`` for an envelope abort)."""

    def event(self, message: str, values: Sequence[tuple[str, str]],
              stamp_ns: int | None = None) -> None:
        """A trial event (start, aborted, resumed, finished)."""

    def log(self, error: bool, text: str) -> None:
        """A line for the user (``error``: something went wrong)."""


class TrialProtocol:
    """The protocol's state; every input is a method call, every output a port call."""

    def __init__(self, config: Config, port: GraphPort,
                 live: Callable[[], Config] | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.config = config = with_control_rate(config)  # the period the nodes run
        self.port = port
        self.live = live or (lambda: config)
        """The node's parameters now (accepted live changes are staged at the boundary)."""
        self.seen = config
        self.clock = clock
        self.reference = build_reference(config)
        self.samples = TrialSamples(self.reference)
        self.truth = TrialSamples(self.reference)
        """The plant's true state of the running trial (/ground_truth/joint_states), collected
        when the virtual patient's sensors make it differ from the measured samples."""
        self.expects_truth = False
        self.session: LearningSession | None = None
        """Created by :meth:`open` once the plant's parameters are known."""
        self.experiment: Experiment | None = None
        self.store: RunStore | None = None
        self.phase = Phase.WAIT_GRAPH
        self.phase_since = clock()
        self.done_report: Mapping[str, str] | None = None
        self.starting = False
        """A start request is out."""
        self.refused = False
        """The plant refused a start of this trial (logged once)."""
        self.recorder_filed = 0
        self.recorder_lost = False
        self.unsaved: TrialConclusion | None = None
        self.unsaved_since = 0.0
        self.after_save = ""
        """In WAIT_RECORDER: ``start`` or ``finish``."""
        self.end_ns = 0
        self.real_time = False
        """The plant runs on a wall-clock timer (its ``mode``): a trial ends with the plant's
        report of late commands too, and the run's first attempt is a warm-up."""
        self.warmed_up = False
        self.plant_report: Mapping[str, str] | None = None
        """The real-time plant's ``done`` of the running trial (late commands)."""
        self.late_reruns = 0
        """Consecutive runs of this trial discarded for late commands."""
        self.pushed_at = 0.0
        """When the feed-forward was last pushed (WAIT_ACK: pushed again after ACK_RETRY)."""
        self.ack_retries = 0
        """Feed-forwards pushed again for want of an acknowledgement (whole run)."""
        self.error: str | None = None
        self.exit_code: int | None = None
        self.diverged: tuple[int, Mapping[str, str]] | None = None
        """The running trial's plant diverged: (the first non-finite sample, the plant's
        report); the trial ends once every sample before it is in."""
        self.divergence: PlantDivergence | None = None
        """The concluded trial's divergence (None: its plant stayed finite), for its summary."""
        self.cuffs: CuffSamples | None = None
        """A person strapped in: the running trial's cuff wrenches (None: no person)."""
        self.cuff_limit: list[float] = []
        self.cuff_abort: int | None = None
        """The concluded trial's sample a cuff pressed past its limit at, when that aborted
        it (None: it did not), for its ``aborted`` event."""

    @property
    def trial(self) -> int:
        """The trial running or next."""
        return 1 if self.session is None else self.session.trial

    @property
    def completed(self) -> int:
        """Trials concluded."""
        return 0 if self.session is None else self.session.completed

    def _enter(self, phase: Phase) -> None:
        self.phase = phase
        self.phase_since = self.clock()

    # --- start-up -----------------------------------------------------------------------------
    def open(self, plant: Mapping[str, Any]) -> None:
        """The plant's parameters are known (they label the summaries and key the store): the
        session, resumed from the store if the config asks. A store error stops the run."""
        config = self.config.replace(dict(plant))
        try:
            session = LearningSession(config)
            if config["store.directory"]:
                self.store, _ = session.open_store(config["store.directory"],
                                                   config["store.resume"])
        except ExoIlcError as exc:
            self.fail(str(exc), code=2)
            return
        self.experiment = Experiment(config)
        if self.experiment.patient.learns and session.completed:
            self.fail("a learning patient (patient.learning.gain) cannot be resumed through the "
                      "graph: its adaptation lives in the plant node; resume in-process "
                      "(exo-ilc simulate --store DIR --resume)", code=2)
            return
        self.expects_truth = self.experiment.patient.measures
        if str(config["musculoskeletal.model"]) != "none":  # the plant sends the cuffs
            self.cuffs = CuffSamples(self.reference, len(CUFFS))
            self.cuff_limit = [float(x) for x in config["safety.cuff_force_limit"]]
        self.real_time = config["mode"] == "real_time"
        self.session = session
        if not session.finished:
            try:
                session.rehearse(self.experiment)  # the kernels now, not after trial 1
            except Exception as exc:  # a warm-up only: the real conclusion reports errors
                self.port.log(False, f"warm-up of the trial conclusion skipped: {exc}")
        if self.store is not None:
            if session.completed:
                self.port.log(False, f"resumed from {self.store.directory}: trials 1.."
                              f"{session.completed} restored, continuing with trial "
                              f"{session.trial}")
                self.port.event("resumed", [("trials", str(session.completed))])
            else:
                self.port.log(False, f"saving every trial to {self.store.directory}")
        if session.finished:
            self._finish()

    # --- inputs ---------------------------------------------------------------------------------
    def tick(self, graph_ready: bool) -> None:
        """Periodic: start once the graph is up; store without a silent recorder; discard a
        stuck trial; retry a refused start."""
        now = self.clock()
        if self.phase is Phase.WAIT_GRAPH:
            if graph_ready and self.session is not None and not self.session.finished:
                self._reset()
        elif self.unsaved is not None and now - self.unsaved_since > RECORDER_TIMEOUT:
            self.port.log(True, f"the recorder has not filed trial {self.unsaved.record.trial} "
                          f"for {RECORDER_TIMEOUT:g} s; going on without waiting for it")
            self.recorder_lost = True
            self._store_unsaved()
        elif self.phase is not Phase.FINISHED and now - self.phase_since > STEP_TIMEOUT:
            self.port.log(True, f"trial {self.trial}: no progress in {self.phase.value} for "
                          f"{STEP_TIMEOUT:g} s; discarding the trial and running it again "
                          "with the same feed-forward")
            self._retry("timeout", [("phase", self.phase.value)])
        elif self.phase is Phase.STARTING and not self.starting:
            self._start()
        elif self.phase is Phase.WAIT_ACK and now - self.pushed_at > ACK_RETRY:
            self.ack_retries += 1
            self._push()

    def on_reset(self, t0_ns: int | None, message: str = "") -> None:
        """The plant is at x_d(0), its next sample stamped ``t0_ns`` (None: refused)."""
        if self.phase is not Phase.RESETTING or self.session is None:
            return
        if t0_ns is None:
            self.port.log(True, f"plant reset failed: {message}")
            return
        self.samples.start(t0_ns)
        if self.expects_truth:
            self.truth.start(t0_ns)
        if self.cuffs is not None:
            self.cuffs.start(t0_ns)
        self.done_report = None
        self.plant_report = None
        self._enter(Phase.WAIT_ACK)
        self._push()

    def on_acknowledged(self, trial: int, t0_ns: int) -> None:
        """The controller loaded the feed-forward of ``trial`` at ``t0_ns``."""
        if self.phase is not Phase.WAIT_ACK or (trial, t0_ns) != (self.trial,
                                                                  self.samples.t0_ns):
            return
        if self.unsaved is not None:  # the previous trial is not filed yet
            self.after_save = "start"
            self._enter(Phase.WAIT_RECORDER)
        else:
            self._begin_trial()

    def on_started(self, success: bool, message: str = "") -> None:
        """The plant's answer to :meth:`GraphPort.start` (refused: retried by :meth:`tick`).
        The reply may come after the trial's samples and ``done`` (a reliable reply resent
        after a lost packet): those are kept, and the trial ends here then."""
        self.starting = False
        if self.phase is not Phase.STARTING:
            return
        if success:
            self._enter(Phase.RUNNING)
            self._maybe_end_trial()
        elif not self.refused:
            self.refused = True
            self.port.log(False, f"plant refused start: {message}; retrying")

    def on_sample(self, stamp_ns: int, position: np.ndarray, velocity: np.ndarray) -> None:
        """A checked sample of the arm; the trial's last one may end it."""
        if not self.samples.add(stamp_ns, position, velocity):
            return
        if self.diverged is not None:  # a sample before the divergence came after its report
            self._maybe_end_diverged()
            return
        if self.phase is Phase.STARTING and self.samples.received[1:].any():
            self._enter(Phase.RUNNING)  # the plant steps: it started, whatever its reply
        self.phase_since = self.clock()  # progress: a slow real-time trial is not stuck
        if not self.samples.last_in:
            return
        if self.samples.missing:
            missing = self.samples.missing
            self.port.log(True, f"trial {self.trial}: {missing} samples lost; running the "
                          "trial again")
            self._retry("lost", [("lost", str(missing))])
            return
        self._maybe_end_trial()

    def on_true_sample(self, stamp_ns: int, position: np.ndarray,
                       velocity: np.ndarray) -> None:
        """A sample of the plant's true state (/ground_truth/joint_states); the trial ends once
        both its measured and its true samples are in."""
        if not self.expects_truth or not self.truth.add(stamp_ns, position, velocity):
            return
        if self.diverged is not None:
            self._maybe_end_diverged()
            return
        if self.truth.last_in and self.samples.last_in and not self.samples.missing:
            self._maybe_end_trial()

    def on_cuff_sample(self, cuff: int, stamp_ns: int, wrench: np.ndarray) -> None:
        """Cuff ``cuff``'s wrench (force, torque) at the sample stamped ``stamp_ns``; the trial
        ends once its samples and every cuff's wrenches are in."""
        if self.cuffs is None or not self.cuffs.add(cuff, stamp_ns, wrench):
            return
        if self.diverged is not None:
            self._maybe_end_diverged()
            return
        if self.samples.last_in and not self.samples.missing and \
                self.cuffs.complete_before(self.cuffs.received.shape[0]):
            self._maybe_end_trial()

    def on_done(self, trial: int, t0_ns: int, report: Mapping[str, str]) -> None:
        """The controller's end of ``trial`` (abort index, watchdog trips); kept until the
        plant's start is confirmed (by its reply or its samples)."""
        if self.phase in (Phase.STARTING, Phase.RUNNING) and \
                (trial, t0_ns) == (self.trial, self.samples.t0_ns):
            self.done_report = report
            self._maybe_end_trial()

    def on_plant_done(self, t0_ns: int, report: Mapping[str, str]) -> None:
        """The real-time plant's end of the trial that started at ``t0_ns`` (late commands)."""
        if self.phase in (Phase.STARTING, Phase.RUNNING) and t0_ns == self.samples.t0_ns:
            self.plant_report = report
            self._maybe_end_trial()

    def on_plant_diverged(self, report: Mapping[str, str]) -> None:
        """The plant's state stopped being finite at the sample stamped ``stamp_ns`` (its
        report: ``stamp_ns``, ``joint``, ``joint_name``, ``cause``): the plant sent no sample
        from it on and stopped; the trial ends there once the samples before it are in."""
        stamp = report.get("stamp_ns", "")
        if self.phase not in (Phase.STARTING, Phase.RUNNING) or not self.samples.running or \
                not stamp.lstrip("-").isdigit() or self.diverged is not None:
            return
        i = self._sample_of(int(stamp))
        if i is None:
            return
        self.diverged = (i, dict(report))
        self.port.log(True, f"trial {self.trial}: the plant reported a non-finite state at "
                      f"sample {i}: {report.get('cause', '')}")
        self._enter(Phase.RUNNING)
        self._maybe_end_diverged()

    def _sample_of(self, stamp_ns: int) -> int | None:
        """The running trial's sample stamped ``stamp_ns`` (None: not one of its samples)."""
        s = self.samples
        return sample_index(stamp_ns, s.t0_ns, s.step_ns, s.received.shape[0])

    def _samples_before(self, sample: int) -> bool:
        """Every sample before ``sample`` is in (measured, and true ones if expected)."""
        return bool(self.samples.received[:sample].all() and
                    (not self.expects_truth or self.truth.received[:sample].all()) and
                    (self.cuffs is None or self.cuffs.complete_before(sample)))

    def _maybe_end_diverged(self) -> None:
        """End the trial whose plant diverged at sample i, as the trial kernel ends it: NaN
        from i on, aborted at the first sample before i outside the envelope, else at i."""
        assert self.diverged is not None and self.experiment is not None
        sample, report = self.diverged
        if not self._samples_before(sample):
            return
        for samples in (self.samples, self.truth) if self.expects_truth else (self.samples,):
            samples.position[sample:] = np.nan
            samples.velocity[sample:] = np.nan
            samples.received[:] = True
        if self.cuffs is not None:  # the plant sent no wrench from the divergence on
            self.cuffs.wrench[sample:] = np.nan
            self.cuffs.received[:] = True
        ref, envelope = self.experiment.reference.position, self.experiment.error_envelope
        aborted = next((k for k in range(sample)
                        if outside_envelope(ref[k], self.samples.position[k], envelope)), sample)
        names = list(self.config["joint_names"])
        joint = int(report.get("joint", "0")) if report.get("joint", "").isdigit() else 0
        self.divergence = PlantDivergence(
            self.trial, sample, sample * self.experiment.period, joint,
            report.get("joint_name") or names[min(joint, len(names) - 1)],
            report.get("cause", "the plant's state is not finite"))
        self.diverged = None
        self._end_trial(aborted)

    def on_recorder_filed(self, trials: int) -> None:
        """The recorder's count of trials filed (in the bag, files closed)."""
        self.recorder_filed = max(self.recorder_filed, trials)
        if self.unsaved is not None and self.recorder_filed >= self.unsaved.record.trial:
            self._store_unsaved()

    # --- steps ----------------------------------------------------------------------------------
    def _reset(self) -> None:
        self._enter(Phase.RESETTING)
        self.diverged = None
        self.samples.stop()
        self.truth.stop()
        self.port.reset()

    def _push(self) -> None:
        assert self.session is not None
        self.pushed_at = self.clock()
        self.port.push_feedforward(self.trial, self.samples.t0_ns, self.session.feedforward,
                                   self.session.joint_force)

    def _begin_trial(self) -> None:
        self.port.event("start", [("trial", str(self.trial))], self.samples.t0_ns)
        self.refused = False
        self._enter(Phase.STARTING)
        self._start()

    def _start(self) -> None:
        self.starting = True
        self.port.start()

    def _retry(self, reason: str, values: Sequence[tuple[str, str]]) -> None:
        assert self.session is not None
        self.session.discard(reason)
        self.port.event("aborted", [("trial", str(self.trial)), ("reason", reason), *values])
        self._reset()

    def _maybe_end_trial(self) -> None:
        report = self.done_report
        if self.diverged is not None:  # ends with the samples before it (_maybe_end_diverged)
            return
        if self.phase is not Phase.RUNNING or not self.samples.running or report is None \
                or not self.samples.last_in or (self.real_time and self.plant_report is None):
            return
        if self.cuffs is not None and \
                not self.cuffs.complete_before(self.cuffs.received.shape[0]):
            return  # the last cuff wrenches are on their way (a lost one: the step timeout)
        if self.expects_truth:
            if not self.truth.last_in:
                return
            if self.truth.missing:
                self.port.log(True, f"trial {self.trial}: {self.truth.missing} true-state "
                              "samples lost; running the trial again")
                self._retry("lost", [("lost_true", str(self.truth.missing))])
                return
        trips = int(report.get("watchdog_trips", "0"))
        if trips:
            self.port.log(True, f"trial {self.trial}: the controller's watchdog tripped "
                          f"{trips}x (safe hold); running the trial again")
            self._retry("watchdog", [("watchdog_trips", str(trips))])
            return
        if self.real_time and self._late():
            return
        self._end_trial(int(report.get("aborted_at", "-1")))

    def _late(self) -> bool:
        """Real time: the run's first attempt warms the graph up (every path once: DDS, the
        kernels, the first messages) and is run again; a trial with more than
        ``max_late_commands`` of its periods on a late command is run again, not learned
        from (LATE_RERUNS times in a row stop the run). True: not concluded."""
        if not self.warmed_up:
            self.warmed_up = True
            self.port.log(False, f"trial {self.trial}: warm-up attempt done; running it again")
            self._retry("warm_up", [])
            return True
        report = self.plant_report or {}
        late, periods = int(report.get("late_commands", "0")), int(report.get("periods", "0"))
        if late <= self.config["max_late_commands"] * max(periods, 1):
            self.late_reruns = 0
            return False
        self.late_reruns += 1
        share = f"{late} of {periods} periods ran on a late command"
        if self.late_reruns >= LATE_RERUNS:
            self.fail(f"trial {self.trial}: {share}, {LATE_RERUNS} times in a row (more than "
                      f"max_late_commands = {self.config['max_late_commands']:g}): this machine "
                      "does not keep the control rate; stopped (stored trials are kept)")
            return True
        self.port.log(True, f"trial {self.trial}: {share}; running the trial again")
        self._retry("late_commands", [("late_commands", str(late)), ("periods", str(periods))])
        return True

    def _end_trial(self, aborted: int) -> None:
        """Conclude the trial in the session; store it (once the recorder filed it) and go on
        with the next one, or finish."""
        session, experiment = self.session, self.experiment
        assert session is not None and experiment is not None
        self.end_ns = self.samples.end_ns
        self.samples.stop()
        self.truth.stop()
        truth = self.expects_truth
        self.cuff_abort = None
        if self.cuffs is not None:  # the cuff-force limit: the plant held from that sample on
            pressed = first_beyond_cuff_limit(self.cuffs.wrench, self.cuff_limit)
            if pressed >= 0 and (aborted < 0 or pressed < aborted):
                aborted = self.cuff_abort = pressed
        record = record_from_samples(experiment, session.trial, session.feedforward,
                                     self.samples.position, self.samples.velocity,
                                     session.levels, experiment.reference,
                                     aborted if aborted >= 0 else None,
                                     self.truth.position if truth else None,
                                     self.truth.velocity if truth else None,
                                     session.joint_force)
        if self.cuffs is not None:
            record = replace(record, cuff_wrench=self.cuffs.wrench.copy())
        self._stage_live_changes()
        try:
            conclusion = session.conclude(record)
        except ExoIlcError as exc:
            self.fail(str(exc))
            return
        if conclusion.applied:
            changed = ", ".join(f"{k} = {v}" for k, v in sorted(conclusion.applied.items()))
            self.port.log(False, f"parameters changed; applied from trial {session.trial}: "
                          f"{changed}")
        for note in conclusion.update.notes if conclusion.learned else ():
            self.port.log(False, f"learning from trial {record.trial}: {note}")
        if conclusion.trip is not None:
            self.port.log(True, f"{conclusion.trip.describe()}: aborted, learned from up to "
                          f"sample {aborted}")
        if conclusion.stop_message:
            self.port.log(True, conclusion.stop_message)
        self.port.publish_conclusion(conclusion, self.end_ns)
        self.divergence = None
        self.unsaved, self.unsaved_since = conclusion, self.clock()
        if self.config["wait_for_recorder"] and not self.recorder_lost \
                and self.recorder_filed < record.trial:
            # Stored once the bag holds it; the next trial is prepared meanwhile.
            if session.finished:
                self.after_save = "finish"
                self._enter(Phase.WAIT_RECORDER)
            else:
                self._reset()
        elif self._save():
            if session.finished:
                self._finish()
            else:
                self._reset()

    def _stage_live_changes(self) -> None:
        assert self.session is not None
        live = self.live()
        if live is self.seen:
            return
        changed = {name: live[name] for name in sorted(LIVE) if live[name] != self.seen[name]}
        self.seen = live
        try:
            self.session.stage(changed)
        except (ExoIlcError, ValueError) as exc:  # the node checked them; the session disagrees
            self.port.log(True, f"live change {changed} not applied: {exc}")

    def _save(self) -> bool:
        """The concluded trial into the store (False: it could not be saved; run stopped)."""
        assert self.unsaved is not None
        conclusion, self.unsaved = self.unsaved, None
        if self.store is not None:
            try:
                self.store.save(conclusion.record, conclusion.update, conclusion.config)
            except (ExoIlcError, OSError) as exc:
                trial = conclusion.record.trial
                self.fail(f"trial {trial}: cannot save to the store: {exc}", trial - 1)
                return False
        return True

    def _store_unsaved(self) -> None:
        if not self._save() or self.phase is not Phase.WAIT_RECORDER:
            return
        if self.after_save == "finish":
            self._finish()
        else:
            self._begin_trial()

    def _finish(self, completed: int | None = None,
                values: Sequence[tuple[str, str]] = ()) -> None:
        trials = self.completed if completed is None else completed
        self._enter(Phase.FINISHED)
        if self.session is not None and self.session.stop_message:  # also on a resumed stop
            values = [*values, (ABORT_STOP_KEY, self.session.stop_message)]
        self.port.event("finished", [("trials", str(trials)), *values], self.end_ns or None)
        self.port.log(False, f"finished after {trials} trials")

    def fail(self, message: str, completed: int | None = None, code: int = 1) -> None:
        """Stop running trials: ``finished`` with the error after ``completed`` trials
        (default: those concluded); the node exits with ``code``."""
        self.error = message
        self.port.log(True, message)
        self._finish(completed, [("error", message)])
        self.exit_code = code
