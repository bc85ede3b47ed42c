"""One learning session: which trial runs next, with which feed-forward, and what a trial's
record does to it. The in-process runner (:func:`run_trials`) and the ``ilc_supervisor`` node
are both loops over a :class:`LearningSession`; neither holds a rule of its own.

The rules, in the order :meth:`LearningSession.conclude` applies them at a trial boundary:

1. Live parameter changes staged during the trial (:meth:`~LearningSession.stage`) take effect:
   the law is rebuilt from the new values and learns the next feed-forward with them (the first
   trial *run* with them is the next one, the ``effective_trial`` a bag records).
2. A completed trial is learned from with the law, eq (11). A trial the error envelope aborted
   at sample a is kept, marked and learned from over the samples it has (variable pass length,
   :mod:`.abort`): the law's update on [0, a), the aborted feed-forward kept from a on, the change
   on the tripping joints scaled by ``abort.backoff``. An aborted feed-forward is never run again
   unchanged: ``abort.max_consecutive`` aborts in a row, or an abort that left nothing to learn,
   or a plant that diverged, stop the session (:attr:`StopReason.ABORTS`,
   :attr:`LearningSession.stop_message` says why, once). A learned feed-forward that is not
   finite or of the wrong shape stops the session (:class:`SafetyError`), nothing of it used.
3. The "within the bound" streak counts consecutive completed trials with every joint's
   max |e_j| <= ``error_bound``; the session is finished after ``max_trials`` trials, once the
   streak reaches ``stop_when_settled`` (> 0), or by rule 2's aborts.

A trial that must be run again (a watchdog trip, lost samples, a protocol step that made no
progress) is :meth:`~LearningSession.discard`-ed: nothing is learned, the same trial number and
feed-forward run again. A session resumes from the trials a :class:`RunStore` holds; it runs at
``control.period_rule``'s period (:func:`..loop.rate.with_control_rate`).
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..arm.build import build_arm, view_urdf
from ..errors import SafetyError, StoreError
from ..learning.averaging import AveragingGain, averaging_of
from ..learning.factory import build_law
from ..learning.laws import FeedforwardUpdate, LearningLaw
from ..learning.norm_optimal_model import PatientLinearisation
from ..learning.patient_model import JointForceModel, JointForceStep
from ..learning.progress_gain import progress_gain_of
from ..learning.qfilter import feedforward_limit_of
from ..loop.gains import feedback_gains, velocity_observer_gains
from ..loop.observer import fed_back_velocity
from ..loop.patient import PatientLearning, PatientModel, true_error
from ..loop.rate import with_control_rate
from ..loop.record import TrialRecord, position_velocity_record
from ..loop.trial import record_from_samples
from ..loop.wire_input import Rejection, check_feedforward_array
from ..params import schema
from ..params.config import Config
from ..persistence.profiles import load_initial
from ..persistence.store import RunStore, StoredTrial
from ..person.experiment import StrappedExperiment, experiment_for
from ..reference.build import build_reference
from ..sim.experiment import Experiment
from .abort import AbortTrip, partial_update, pass_length_record, stop_message, trip_of
from .result import RunResult, StopReason

LIVE = frozenset(p.name for p in schema.PARAMETERS if p.live)
"""Parameters that may change at a trial boundary."""
EXPERIMENT_KEYS = frozenset({"safety.error_envelope"})
"""Live parameters that change how a trial runs in-process (the rest change what is learned)."""


def refuse_stored(store: RunStore, resume: bool) -> int:
    """The trials ``store`` already holds; without ``resume``, holding any is an error (nothing
    is overwritten). The one rule for the in-process runner, the supervisor and ``exo-ilc run``
    (which checks before any node starts, :func:`stored_trials`)."""
    if store.completed and not resume:
        raise StoreError(f"{store.directory}: already holds {store.completed} trials of this "
                         "run; add --resume (store.resume) to continue it or use another store")
    return store.completed


def stored_trials(config: Config, resume: bool) -> int:
    """:func:`refuse_stored` for the store a config names (``store.directory``)."""
    return refuse_stored(RunStore(config["store.directory"], config, build_reference(config)),
                         resume)


@dataclass(frozen=True)
class TrialConclusion:
    """What a trial's record did to the session."""

    record: TrialRecord
    update: FeedforwardUpdate
    """The feed-forward (and levels) the next trial uses."""
    learned: bool
    """False only for an aborted trial that left nothing to learn (then the session stops);
    an aborted trial is learned from over the samples it has (:mod:`.abort`)."""
    within_bound: bool
    applied: dict[str, Any]
    """Live changes that took effect at this boundary (learned with; empty: none)."""
    config: Config
    """The configuration in effect after this boundary (what the store records)."""
    stop: StopReason | None
    """Set when this was the session's last trial."""
    joint_forces: JointForceStep | None = None
    """The identification of the trial and the joint forces the next trial adds
    (``identification.enabled``; None: off)."""
    trip: AbortTrip | None = None
    """Where an aborted trial left the envelope (None: completed)."""
    stop_message: str = ""
    """Why aborts stopped the session (``stop`` is ABORTS); empty otherwise."""


@dataclass
class LearningSession:
    """The state of one learning run between trials (module docstring for the rules).
    ``config`` is the run's whole configuration, the plant's parameters included (it keys the
    store). ``law`` replaces the config's law (then live changes cannot rebuild it)."""

    config: Config
    law: LearningLaw | None = None
    trial: int = 1
    """The next trial to run."""
    completed: int = 0
    """Trials concluded (stored or restored)."""
    within_streak: int = 0
    aborted_trials: list[int] = field(default_factory=list)
    retried: list[tuple[int, str]] = field(default_factory=list)
    stop: StopReason | None = None
    consecutive_aborts: int = 0
    """Aborted trials in a row up to the last concluded one (``abort.max_consecutive``)."""
    stop_message: str = ""
    """Why aborts stopped the session (rule 2; empty: they did not)."""
    _custom_law: bool = field(default=False, init=False, repr=False)
    _staged: dict[str, Any] = field(default_factory=dict, init=False, repr=False)
    _patient: PatientLinearisation | None = field(default=None, init=False, repr=False)
    _lowest_error: np.ndarray | None = field(default=None, init=False, repr=False)
    """Per joint the lowest max |e| of the completed trials so far (``progress_gain``)."""
    _averaging: AveragingGain | None = field(default=None, init=False, repr=False)
    """The step gain from the trials' statistics (``averaging``; None: off)."""

    def __post_init__(self) -> None:
        self.config = with_control_rate(self.config)  # the period the experiment runs
        self._custom_law = self.law is not None
        self.active_law: LearningLaw = self.law or build_law(self.config)
        self.reference = build_reference(self.config)
        self._averaging = averaging_of(self.config)
        if self.config["profile.initial"]:  # a patient's learned profile (persistence/profiles.py)

            self.next_update = load_initial(self.config["profile.initial"], self.config,
                                            self.reference)
        else:
            first = self.active_law.initial_feedforward(self.reference)
            self.next_update = FeedforwardUpdate(first, None)
        self.joint_forces: JointForceModel | None = None
        """The identified patient (``identification.enabled``, :mod:`..learning.patient_model`)."""
        self.replayed: dict[int, JointForceStep] = {}
        """The identification of each trial :meth:`resume` restored, by trial."""
        if self.config["identification.enabled"]:
            self.joint_forces = JointForceModel(self.config, build_arm(self.config),
                                                self.reference)
            if self.config["identification.in_loop"]:
                self.next_update = dataclasses.replace(
                    self.next_update, joint_force=self.joint_forces.joint_force.copy())
        self.stop = self._stop_reason()

    # --- what runs next ---------------------------------------------------------------------
    @property
    def feedforward(self) -> np.ndarray:
        """The feed-forward of the next trial."""
        return self.next_update.feedforward

    @property
    def joint_force(self) -> np.ndarray | None:
        """The identified joint forces (N m per sample) computed torque adds in the next trial;
        None: none (:mod:`..learning.patient_model`)."""
        return self.next_update.joint_force

    @property
    def levels(self) -> np.ndarray | None:
        """The M, M', M'' (rows) per joint that formed the next trial's feed-forward."""
        return self.next_update.levels

    @property
    def finished(self) -> bool:
        """No trial is left to run (``stop`` says why)."""
        return self.stop is not None

    @property
    def staged(self) -> dict[str, Any]:
        """Live changes waiting for the next trial boundary."""
        return dict(self._staged)

    def _stop_reason(self) -> StopReason | None:
        if self.stop_message:
            return StopReason.ABORTS
        if self.completed >= self.config["max_trials"]:
            return StopReason.MAX_TRIALS
        settled = self.config["stop_when_settled"]
        if settled > 0 and self.within_streak >= settled:
            return StopReason.SETTLED
        return None

    # --- inputs ------------------------------------------------------------------------------
    def stage(self, values: Mapping[str, Any]) -> None:
        """Live parameter changes for the next trial boundary (validated now: ConfigError
        names the key and the rule; nothing is staged then). Only ``live`` parameters."""
        fixed = sorted(set(values) - LIVE)
        if fixed:
            raise ValueError(f"not live parameters (cannot change during a run): {fixed}")
        if self._custom_law and values:
            raise ValueError("a session with a custom learning law cannot take live changes")
        self.config.replace({**self._staged, **values})  # validates the whole combination
        self._staged.update(values)

    def conclude(self, record: TrialRecord) -> TrialConclusion:
        """The trial ``record`` ran to its end: apply staged changes, learn (or keep the
        feed-forward after an envelope abort), update the streak; rules in the module
        docstring."""
        if self.finished:
            raise SafetyError(f"trial {record.trial}: the session is already finished "
                              f"({self.stop.value if self.stop else ''})")
        if record.trial != self.trial:
            raise SafetyError(f"trial {record.trial} concluded, but trial {self.trial} is the "
                              "one running")
        applied = self._apply_staged()
        learned_from = self._learned_from(record)
        trip = None
        if record.aborted:
            self.aborted_trials.append(record.trial)
            self.consecutive_aborts += 1
            trip = trip_of(record, self.config)
            update = self._learn_through_abort(record, trip)
        else:
            self.consecutive_aborts = 0
            update = self.active_law.update(learned_from)
        checked = check_feedforward_array(update.feedforward, self.feedforward.shape,
                                          "learned feed-forward")
        if isinstance(checked, Rejection):
            raise SafetyError(f"trial {record.trial}: the learning law produced a bad "
                              f"feed-forward ({checked}); it was not stored or used")
        forces = None
        shift = None
        if self.joint_forces is not None:
            forces = self.joint_forces.conclude(learned_from)
            if forces.joint_force is not None:
                update, shift = self._with_patient(update, learned_from, forces,
                                                   self.joint_forces)
        if not record.aborted:
            update = self._with_averaging(update, record, shift)
            update = self._with_progress(update, record)
        update = self._within_limit(update)
        within = self._within(record)
        self.within_streak = self.within_streak + 1 if within else 0
        self.completed = record.trial
        self.trial = record.trial + 1
        self.next_update = update
        nothing_learned = self._abort_stop(record, trip, update)
        self.stop = self._stop_reason()
        return TrialConclusion(record, update, not nothing_learned, within, applied,
                               self.config, self.stop, forces, trip,
                               self.stop_message if self.stop is StopReason.ABORTS else "")

    def _learn_through_abort(self, record: TrialRecord, trip: AbortTrip) -> FeedforwardUpdate:
        """Rule 2 for aborted ``record``: the law's update from its valid samples
        (:func:`.abort.pass_length_record`) on [0, a), the rest kept, the back-off on the
        tripping joints (``abort.backoff``)."""
        law_record = pass_length_record(record)
        if self.config["learning_velocity"] == "position":
            law_record = position_velocity_record(law_record, self._feedback_kd(),
                                                  self._fed_back(law_record))
        backoff = float(self.config["abort.backoff"])
        return partial_update(self.active_law.update(law_record), record, trip.tripped, backoff)

    def _abort_stop(self, record: TrialRecord, trip: AbortTrip | None,
                    update: FeedforwardUpdate) -> bool:
        """Rule 2's stop after aborted ``record`` led to ``update``: sets :attr:`stop_message`
        after ``abort.max_consecutive`` aborts in a row, a diverged plant or an update that left
        the aborted feed-forward as it was (returned: True, nothing learned)."""
        if trip is None:
            return False
        nothing_learned = bool(np.array_equal(update.feedforward, record.feedforward))
        if trip.diverged or nothing_learned or \
                self.consecutive_aborts >= self.config["abort.max_consecutive"]:
            self.stop_message = stop_message(trip, self.consecutive_aborts, nothing_learned,
                                             PatientModel(self.config).enabled)
        return nothing_learned

    def rehearse(self, experiment: Experiment) -> None:
        """Run a conclusion's kernels once on a throwaway record (the reference tracked
        exactly, this session's feed-forward) and a copy of the law: the graph's first trial
        then does not pay numba's cache load (0.2-0.3 s measured in the supervisor after
        trial 1). Nothing of this session changes."""
        ref = self.reference
        record = record_from_samples(experiment, self.trial, self.feedforward, ref.position,
                                     ref.velocity, self.levels, ref)
        copy.deepcopy(self.active_law).update(record)

    def discard(self, reason: str) -> None:
        """The running trial must be run again (``reason``: watchdog, lost, timeout, ...):
        nothing is learned, the same trial and feed-forward run next."""
        self.retried.append((self.trial, reason))

    def resume(self, stored: Sequence[StoredTrial]) -> None:
        """Continue after the trials ``stored`` (1..n, as a :class:`RunStore` loads them):
        their streak, aborts and the feed-forward the last one led to."""
        if self.completed:
            raise StoreError("resume: the session has already concluded trials")
        for k, item in enumerate(stored, start=1):
            if item.record.trial != k:
                raise StoreError(f"resume: stored trial {item.record.trial} where trial {k} "
                                 "was expected")
            within = self._within(item.record)
            self.stop_message = ""  # a stop a later stored trial went past (a larger limit)
            self.within_streak = self.within_streak + 1 if within else 0
            if item.record.aborted:
                self.aborted_trials.append(item.record.trial)
                self.consecutive_aborts += 1
                self._abort_stop(item.record, trip_of(item.record, self.config),
                                 item.next_update)  # the stop is replayed too
            else:  # progress_gain's lowest error so far
                self.consecutive_aborts = 0
                self._lowest_error = self._lowest_after(item.record)
            learned_from = self._learned_from(item.record)
            target = None if self._averaging is None or item.record.aborted else \
                self.active_law.update(learned_from)
            shift = None
            if self.joint_forces is not None:  # the identification is replayed, exactly
                self.replayed[k] = step = self.joint_forces.conclude(learned_from)
                if step.joint_force is not None:  # and norm-optimal's model with it
                    if target is not None:
                        target, shift = self._with_patient(target, learned_from, step,
                                                           self.joint_forces)
                    self._rebuild_about_patient()
            if self._averaging is not None and target is not None:  # and averaging's sums
                self._averaging.observe(target.feedforward + self._shift_or_zero(shift),
                                        shift)
        if stored and self.joint_forces is not None:
            stored_force = stored[-1].next_update.joint_force
            if stored_force is not None:
                self.joint_forces.joint_force = np.array(stored_force, dtype=float)
        if stored:
            self.next_update = stored[-1].next_update
            self.completed = stored[-1].record.trial
            self.trial = self.completed + 1
        self.stop = self._stop_reason()

    def open_store(self, root: Path | str, resume: bool) -> tuple[RunStore, list[StoredTrial]]:
        """The store of this run under ``root`` (its learning key); with ``resume`` the session
        continues after the trials it holds (up to ``max_trials``), which are returned. A store
        that holds trials without ``resume`` is an error: nothing is overwritten."""
        store = RunStore(root, self.config, self.reference)
        refuse_stored(store, resume)
        restored = store.load()[:self.config["max_trials"]]
        self.resume(restored)
        return store, restored

    # --- rules --------------------------------------------------------------------------------
    def _learned_from(self, record: TrialRecord) -> TrialRecord:
        """The record the law and the identified patient learn from: ``record`` itself, or
        with ``learning_velocity: position`` its velocity from the measured position
        (:func:`..loop.record.position_velocity_record`; not an aborted trial's, which is not
        learned from)."""
        if self.config["learning_velocity"] != "position" or record.aborted:
            return record
        return position_velocity_record(record, self._feedback_kd(), self._fed_back(record))

    def _feedback_kd(self) -> np.ndarray:
        """The K_D the controller ran (control.kd with its floor, :mod:`..loop.gains`), for
        the config in force (computed once per config)."""
        held = getattr(self, "_kd_of", None)
        if held is None or held[0] is not self.config:
            held = (self.config, feedback_gains(self.config)[1],
                    velocity_observer_gains(self.config))
            self._kd_of = held
        return held[1]

    def _fed_back(self, record: TrialRecord) -> np.ndarray | None:
        """The velocity fed back in ``record`` (:func:`..loop.observer.fed_back_velocity`);
        None where no joint has the velocity observer (the measured velocity)."""
        self._feedback_kd()  # computes self._kd_of for the config in force
        if not np.any((gains := self._kd_of[2])[0]):
            return None
        return fed_back_velocity(record.position, record.velocity, record.control_input,
                                 gains)

    def _rebuild_about_patient(self) -> str:
        """Norm-optimal's model rebuilt about the identified plant once the linearised forces
        moved by more than ``identification.rebuild_threshold`` (relative, any joint and
        sample, against the last model's) since it was built (cached as every model is); the
        note says so ("": not rebuilt)."""
        if self.joint_forces is None or self._custom_law or self.config["law"] != "norm_optimal":
            return ""
        patient = self.joint_forces.linearisation()
        if patient is None:
            return ""
        last = self._patient
        if last is not None:
            scale = np.maximum(np.abs(last.stiffness) + np.abs(last.damping), 1e-9)
            moved = np.max(np.maximum(np.abs(patient.stiffness - last.stiffness),
                                      np.abs(patient.damping - last.damping)) / scale)
            if moved <= self.config["identification.rebuild_threshold"]:
                return ""
        self._patient = patient
        self.active_law = build_law(self.config, patient=patient)
        return "norm-optimal model rebuilt about the identified patient"

    def _with_patient(self, update: FeedforwardUpdate, record: TrialRecord,
                      forces: JointForceStep, model: JointForceModel
                      ) -> tuple[FeedforwardUpdate, np.ndarray]:
        """The law's update with the identified forces in the loop: the learned feed-forward
        after the adoption rule, plus the inverse with the patient (not for norm-optimal, whose
        model is rebuilt about the patient instead, with a note), and the forces; and what the
        adoption rule took from the law's feed-forward (the hand-over, ``averaging``'s shift)."""
        feedforward = self._adopt(update, forces)
        shift = update.feedforward - feedforward
        correction = None if self.config["law"] == "norm_optimal" else \
            model.learning_correction(record)
        if correction is not None:
            feedforward = feedforward + correction
        update = dataclasses.replace(update, feedforward=feedforward,
                                     joint_force=forces.joint_force)
        rebuilt = self._rebuild_about_patient()
        if rebuilt:
            update = dataclasses.replace(update, notes=(*update.notes, rebuilt))
        return update, shift

    @staticmethod
    def _shift_or_zero(shift: np.ndarray | None) -> np.ndarray | float:
        return 0.0 if shift is None else shift

    def _with_averaging(self, update: FeedforwardUpdate, record: TrialRecord,
                        shift: np.ndarray | None) -> FeedforwardUpdate:
        """``averaging`` (:mod:`..learning.averaging`, (KG)): u_ff,k+1 = u_ff,k + K (T_k -
        u_ff,k) - shift, T_k the law's target (its update plus the inverse with the patient,
        before the hand-over ``shift`` moved it into the next trial's coordinates), u_ff,k the
        feed-forward completed trial ``record`` ran with; K = 1: the update as it is."""
        if self._averaging is None:
            return update
        target = update.feedforward + self._shift_or_zero(shift)
        gain = self._averaging.observe(target, shift)
        if np.all(gain >= 1.0):
            return update
        previous = np.asarray(record.feedforward, dtype=float)
        feedforward = previous + gain * (target - previous) - self._shift_or_zero(shift)
        return dataclasses.replace(update, feedforward=feedforward)

    def _lowest_after(self, record: TrialRecord) -> np.ndarray:
        """The lowest max |e| per joint once completed trial ``record`` is counted."""
        m = np.asarray(record.max_abs_error, dtype=float)
        return m.copy() if self._lowest_error is None else np.minimum(self._lowest_error, m)

    def _with_progress(self, update: FeedforwardUpdate, record: TrialRecord) -> FeedforwardUpdate:
        """``progress_gain`` (:mod:`..learning.progress_gain`): Q[G e] added on the joints whose
        error in completed trial ``record`` is a new low; the lowest error follows."""
        rule = progress_gain_of(self.config)
        active = None if rule is None else rule.active(record.max_abs_error,
                                                       self._lowest_error)
        self._lowest_error = self._lowest_after(record)
        step = None if rule is None or active is None else rule.step(record.error, active)
        if step is None:
            return update
        feedforward = update.feedforward + step
        limit = feedforward_limit_of(self.config)  # the law's sat_U holds for the sum too
        if limit is not None:
            feedforward = np.clip(feedforward, -limit, limit)
        return dataclasses.replace(update, feedforward=feedforward)

    def _within_limit(self, update: FeedforwardUpdate) -> FeedforwardUpdate:
        """The next trial's feed-forward within ``feedforward_limit`` (the law's sat_U), after
        everything added to the law's update (the inverse with the identified patient, the
        hand-over, averaging, progress gain) and after a live change of the limit: no learned
        input runs, is stored or is printed above its limit. The same array when it is
        within."""
        limit = feedforward_limit_of(self.config)
        if limit is None or np.all(np.abs(update.feedforward) <= limit):
            return update
        return dataclasses.replace(update, feedforward=np.clip(update.feedforward, -limit,
                                                               limit))

    def _adopt(self, update: FeedforwardUpdate, forces: JointForceStep) -> np.ndarray:
        """The learned feed-forward once the identified forces changed
        (``identification.adoption``): ``restart`` starts a joint whose forces are adopted for
        the first time from the law's first feed-forward (what the law had learned of the
        patient would count twice); ``handover`` gives up a_N(q_d)^-1 times the change;
        ``keep`` leaves it."""
        feedforward = update.feedforward
        if forces.handover is not None:
            return feedforward - forces.handover
        mode = self.config["identification.adoption"]
        if mode == "restart" and forces.adopted is not None and np.any(forces.adopted):
            first = self.active_law.initial_feedforward(self.reference)
            feedforward = np.where(forces.adopted[None, :], first, feedforward)
        return feedforward

    def _within(self, record: TrialRecord) -> bool:
        return not record.aborted and \
            bool(np.all(record.max_abs_error <= self.config["error_bound"]))

    def _apply_staged(self) -> dict[str, Any]:
        changed = {k: v for k, v in self._staged.items() if self.config[k] != v}
        self._staged.clear()
        if not changed:
            return {}
        self.config = self.config.replace(changed)
        if not self._custom_law:
            self.active_law = build_law(self.config, patient=self._patient)
        return changed


def run_trials(config: Config, mass_uncertainty: float | None = None,
               trials: int | None = None, law: str | None = None,
               on_trial: Callable[[TrialRecord], None] | None = None,
               learning_law: LearningLaw | None = None,
               store: Path | str | None = None, resume: bool = False,
               changes: Mapping[int, Mapping[str, Any]] | None = None,
               on_conclusion: Callable[[TrialConclusion], None] | None = None,
               patient_memory: tuple[np.ndarray, np.ndarray] | None = None,
               patient: PatientLearning | None = None) -> RunResult:
    """Run the experiment in-process, learning between trials: a loop over a
    :class:`LearningSession` (its rules, including ``stop_when_settled``, are the graph's).

    ``trials`` overrides ``max_trials``, ``law`` the config's law (``sign``/``linear``);
    ``learning_law`` passes any other :class:`LearningLaw`. ``on_trial`` is called after each
    trial run now (progress, logging). ``changes`` replays live parameter changes: effective
    trial -> values, as a bag records them (the first trial run with the new values). With
    ``store`` (a root directory, :class:`RunStore`) every trial and the feed-forward it led to
    are saved before the next trial starts; with ``resume`` the trials already stored under
    this run's learning key are restored (bit for bit) and the run continues after the last
    one. A store that already holds trials without ``resume`` is an error (nothing is
    overwritten). ``on_conclusion`` sees each trial's conclusion (what the next trial uses)
    once the store holds it (a patient's profile is saved from it, core/persistence/profiles.py).
    ``patient_memory`` (fast, slow) starts a learning patient with what an earlier session left
    (core/programs/therapy.py); ``result.patient_memory`` is what this run leaves. ``patient``: the
    learning patient itself (its state read by ``on_conclusion``: the state after the trial
    concluded), instead of a new one. Over 10 parameters because it is the in-process runner's
    public entry point: every option is a keyword with a default that leaves the config's
    behaviour, as the CLI, benches and tests pass them.
    """
    overrides: dict[str, Any] = {}
    if trials is not None:
        overrides["max_trials"] = int(trials)
    if law is not None:
        overrides["law"] = law
    if mass_uncertainty is not None:
        overrides["mass_uncertainty"] = float(mass_uncertainty)
    pending = {int(k): dict(v) for k, v in (changes or {}).items()}
    for k in sorted(k for k in pending if k <= 1):  # in effect from the start
        overrides.update(pending.pop(k))
    effective = with_control_rate(config.replace(overrides) if overrides else config)
    session = LearningSession(effective, learning_law)
    experiment = experiment_for(effective)
    result = RunResult(experiment.mass_uncertainty, effective["law"],
                       float(effective["error_bound"]))
    if isinstance(experiment, StrappedExperiment):  # how a view draws the person
        result.person_description = experiment.arm.person_description(
            view_urdf(effective)[2])
    if patient is None and experiment.patient.learns:
        patient = PatientLearning(experiment.patient, experiment.reference.samples)
    if patient is not None and patient_memory is not None:  # the same patient, a new session
        patient.fast, patient.slow = (np.array(x, dtype=float) for x in patient_memory)
        patient.torque = patient.fast + patient.slow
    run_store: RunStore | None = None
    if store is not None:
        run_store, restored = session.open_store(store, resume)
        result.records.extend(item.record for item in restored)
        result.resumed = len(restored)
        result.joint_forces.update(session.replayed)
        for item in restored:
            if patient is not None:
                patient.learn(item.record.trial, true_error(item.record))
    while not session.finished:
        record = experiment.run_trial(session.feedforward, session.trial, session.levels,
                                      None if patient is None else patient.torque,
                                      session.joint_force)
        if patient is not None:
            patient.learn(record.trial, true_error(record))
        if session.trial + 1 in pending:
            session.stage(pending.pop(session.trial + 1))
        conclusion = session.conclude(record)
        if conclusion.applied:
            result.applied[record.trial + 1] = conclusion.applied
            if EXPERIMENT_KEYS & conclusion.applied.keys():
                experiment = experiment_for(session.config)
        if run_store is not None:
            run_store.save(record, conclusion.update, conclusion.config)
        if on_conclusion is not None:
            on_conclusion(conclusion)
        result.records.append(record)
        if conclusion.learned and conclusion.update.notes:
            result.notes[record.trial] = conclusion.update.notes
        if conclusion.joint_forces is not None:
            result.joint_forces[record.trial] = conclusion.joint_forces
        if on_trial is not None:
            on_trial(record)
    result.final = session.next_update
    result.stop = session.stop
    result.stop_message = session.stop_message
    if patient is not None:
        result.patient_memory = (patient.fast.copy(), patient.slow.copy())
    return result
