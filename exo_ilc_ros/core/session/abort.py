"""Learning through an abort: variable pass length, the back-off and the stop after aborts in a
row (the session's rule 2, :mod:`.learning_session`).

**Variable pass length** (Seel, Schauer & Raisch, "Monotonic convergence of iterative learning
control systems with variable pass length", Int. J. Control 90(3), 2017; Shen & Xu, Syst. Control
Lett. 2016; Li, Xu & Huang, IEEE TAC 2015). A trial the error envelope aborted at sample a has
tracked the reference on samples 0..a (the abort sample's measurement is the last the trial's own
commands produced; from it on the safe hold acts). Every law learns from it in one way: from
:func:`pass_length_record`, the record with the samples after a set to "no information", i.e.
the reference tracked exactly there (zero error, zero error rate, the feed-forward as the whole
input), as the papers complete a shortened pass with zero error. The law's update is then taken
on the samples [0, a) only and the aborted trial's feed-forward is kept as it was from sample a
on (:func:`partial_update`): no law ever sees the hold, and nothing is changed where nothing was
measured. Laws that read sums over the trial (the sign law's schedule, eq (13)) sum over the
samples 0..a; laws with a model (norm-optimal) see a zero error after a.

**Back-off** (``abort.backoff``, b in (0, 1]): on the joints outside the envelope at the abort
sample (the tripping joints) the learned change is scaled by b in the update learned from the
aborted trial: u_next = u_ff + b (u_law - u_ff) there; the other joints take the law's update
as it is, and a completed trial is learned from at the law's full gain. With b = 0.5 the
tripping joint's learning gain is halved for that update: the next trial stays closer to the
input that kept it inside the envelope up to sample a; the samples from a on keep the aborted
trial's input either way. The factor does not compound over aborts in a row: b^n (n the aborts
in a row) shrank the step so fast that learning stalled before the abort moved (a 5 cm envelope
under PD: abort sample 19, 20, 21, 21, 22, 22, ... for 30 trials with the sign law, while a
constant 0.5 completed the trials after 18 aborts; docs/safety.md). We chose it over
restarting from the last completed trial's input: a restart drops what the aborted trials taught
(their partial learning) and runs again the input the law learned the aborting one from; and a
trial-1 abort has no completed trial to restart from.

**Stop** (``abort.max_consecutive``, N): N aborted trials in a row end the session; so does one
abort of a plant that diverged (a non-finite state: learning cannot help), or one whose learned
feed-forward equals the aborted one (nothing was measured before the abort: a deterministic
plant would abort the same way again). :func:`stop_message` says it once, naming
the joint, the time, the error against the envelope and the likely cause.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..learning.laws import FeedforwardUpdate
from ..loop.divergence import first_non_finite, trial_divergence
from ..loop.record import TrialRecord
from ..params.config import Config
from ..person.cuffs import CUFFS, beyond_cuff_limit
from ..sim.experiment import Experiment

STIFFNESS_CAUSE = ("the patient's stiffness or friction exceeds what the nominal model cancels "
                   "(a patient model, identification.enabled, or config/patient_aware.yaml; a "
                   "wider safety.error_envelope only if it is safe)")
DIVERGED_CAUSE = ("the plant diverged (a non-finite state: a joint's damping or stiffness too "
                  "stiff for the integration step)")
ABORT_STOP_KEY = "abort_stop"
"""The key of the stop message in the last trial's summary (the graph's ``/ilc/trial_summary``)
and in a run's JSON."""
MODEL_CAUSE = ("the nominal model's error (mass_uncertainty) or the gains take the arm out of "
               "the envelope faster than learning closes the error (smaller learning gains; a "
               "wider safety.error_envelope only if it is safe)")
CUFF_CAUSE = ("the learned input presses the exoskeleton against the person (its misalignment, "
              "the person's muscles): smaller learning gains or a better fit of the "
              "exoskeleton (strapping.misalignment.*); a higher safety.cuff_force_limit only "
              "if it is safe")
NOTHING_LEARNED_CAUSE = ("nothing was measured before the abort, so nothing could be learned "
                         "(the arm starts outside the envelope?)")


@dataclass(frozen=True)
class AbortTrip:
    """Where an aborted trial left the error envelope."""

    trial: int
    sample: int
    """The abort sample a (the first outside the envelope)."""
    time: float
    """a times the control period (s)."""
    joint: int
    """The joint furthest outside its envelope (relative), or the first non-finite one."""
    joint_name: str
    error: float
    """|e| of that joint at the abort (rad; nan: not finite)."""
    envelope: float
    """Its envelope (rad)."""
    tripped: tuple[int, ...]
    """Every joint outside its envelope at the abort sample (the back-off's joints)."""
    cuff: str = ""
    """A person strapped in: the cuff that pressed past ``safety.cuff_force_limit`` at the
    abort sample, when that (not the envelope) aborted the trial ("": the envelope did)."""
    force: float = float("nan")
    """That cuff's |force| at the abort (N)."""
    limit: float = float("nan")
    """Its limit (N)."""

    @property
    def diverged(self) -> bool:
        """The abort was a non-finite state, not a large error."""
        return not np.isfinite(self.error)

    def describe(self) -> str:
        """``trial 4: elbow left the envelope at t = 1.234 s (|e| 0.2100 > 0.2000 rad)``."""
        if self.cuff:
            return (f"trial {self.trial}: the {self.cuff.replace('_', ' ')} cuff pressed "
                    f"{self.force:.1f} N into the person at t = {self.time:.3f} s (> "
                    f"{self.limit:g} N, safety.cuff_force_limit)")
        if self.diverged:
            return (f"trial {self.trial}: the plant diverged at t = {self.time:.3f} s on "
                    f"{self.joint_name} (a non-finite state)")
        return (f"trial {self.trial}: {self.joint_name} left the error envelope at "
                f"t = {self.time:.3f} s (|e| {self.error:.4f} > {self.envelope:.4f} rad)")


def abort_trip(trial: int, aborted_at: int, max_abs_error: Sequence[float] | np.ndarray,
               config: Config) -> AbortTrip:
    """The :class:`AbortTrip` of an aborted trial from its abort sample and its max |e| per joint
    (which, over samples 0..a, is the error at the abort sample for a joint that left a constant
    envelope there): the same from a record in-process and from the graph's trial summary."""
    error = np.asarray(max_abs_error, dtype=float)
    envelope = np.broadcast_to(np.asarray(config["safety.error_envelope"], dtype=float),
                               error.shape)
    bad = ~np.isfinite(error)
    if np.any(bad):
        tripped = tuple(int(j) for j in np.flatnonzero(bad))
        joint = tripped[0]
    else:
        ratio = error / envelope
        joint = int(np.argmax(ratio))
        outside = np.flatnonzero(error > envelope)
        tripped = tuple(int(j) for j in outside) or (joint,)
    names = list(config["joint_names"])
    return AbortTrip(int(trial), int(aborted_at), float(aborted_at) * config["control.period"],
                     joint, names[joint] if joint < len(names) else f"joint {joint}",
                     float(error[joint]), float(envelope[joint]), tripped)


def trip_of(record: TrialRecord, config: Config) -> AbortTrip:
    """:func:`abort_trip` of aborted ``record``; a plant that diverged names the joint the
    divergence report names (:func:`..loop.divergence.trial_divergence` on the plant of
    ``config``: the stiffest damping mode's joint over RK4's limit, else the one moving fastest
    before), not the first of its NaN joints: the stop message and the report agree."""
    if record.aborted_at is None:
        raise ValueError(f"trial {record.trial} was not aborted")
    trip = abort_trip(record.trial, record.aborted_at, record.max_abs_error, config)
    pressed = _pressed(record, config)
    if pressed is not None and not trip.diverged and trip.error <= trip.envelope:
        return dataclasses.replace(trip, cuff=pressed[0], force=pressed[1], limit=pressed[2])
    if not trip.diverged:
        return trip
    if first_non_finite(record.position, record.velocity) is None:
        return trip
    names = list(config["joint_names"])
    found = trial_divergence(Experiment(config), record, names)
    if found is None:
        return trip
    joint = found.joint
    return dataclasses.replace(trip, joint=joint, joint_name=names[joint] if joint < len(names)
                               else f"joint {joint}")


def pass_length_record(record: TrialRecord) -> TrialRecord:
    """Aborted ``record`` as every law learns from it (module docstring): samples 0..a as
    measured, after a the reference tracked exactly (position and velocity the reference's, the
    whole input the feed-forward), not aborted. A completed record is returned as it is."""
    a = record.aborted_at
    if a is None:
        return record
    rows = np.arange(record.position.shape[0])[:, None]
    finite_at_abort = bool(np.all(np.isfinite(record.position[a])) and
                           np.all(np.isfinite(record.velocity[a])))
    valid = rows <= a if finite_at_abort else rows < a  # a diverged plant's sample a is not
    ref = record.reference

    def measured(values: np.ndarray, reference: np.ndarray) -> np.ndarray:
        return np.where(valid, values, reference)

    return dataclasses.replace(
        record, position=measured(record.position, ref.position),
        velocity=measured(record.velocity, ref.velocity),
        control_input=np.where(valid, record.control_input, record.feedforward),
        true_position=None if record.true_position is None
        else measured(record.true_position, ref.position),
        true_velocity=None if record.true_velocity is None
        else measured(record.true_velocity, ref.velocity), aborted_at=None)


def partial_update(update: FeedforwardUpdate, record: TrialRecord, tripped: Sequence[int],
                   backoff: float) -> FeedforwardUpdate:
    """The feed-forward after aborted ``record`` (module docstring): the law's ``update`` on
    samples [0, a), the aborted trial's feed-forward from a on; on the ``tripped`` joints the
    change scaled by ``backoff``."""
    a = record.aborted_at
    if a is None:
        raise ValueError(f"trial {record.trial} was not aborted")
    previous = np.asarray(record.feedforward, dtype=float)
    learned = np.asarray(update.feedforward, dtype=float)
    gain = np.ones(previous.shape[1])
    gain[list(tripped)] = backoff
    before = np.arange(previous.shape[0])[:, None] < a
    feedforward = np.where(before, previous + gain * (learned - previous), previous)
    return dataclasses.replace(update, feedforward=feedforward)


def _pressed(record: TrialRecord, config: Config) -> tuple[str, float, float] | None:
    """(cuff, |force| N, limit N) of the cuff that pressed past ``safety.cuff_force_limit``
    at the abort sample of ``record`` (a person strapped in), or None."""
    if record.cuff_wrench is None or record.aborted_at is None:
        return None
    wrench = np.asarray(record.cuff_wrench)[record.aborted_at]
    limit = [float(x) for x in config["safety.cuff_force_limit"]]
    cuff = beyond_cuff_limit(wrench, limit)
    if cuff < 0:
        return None
    return CUFFS[cuff], float(np.linalg.norm(wrench[cuff, :3])), limit[cuff]


def stop_message(trip: AbortTrip, consecutive: int, nothing_learned: bool = False,
                 patient: bool = True) -> str:
    """The one message of a session stopped by aborts: the last abort's joint, time and value,
    and its likely cause (``patient``: a virtual patient's forces act on the arm, else the
    nominal model's error is what computed torque does not cancel)."""
    cause = CUFF_CAUSE if trip.cuff else DIVERGED_CAUSE if trip.diverged else \
        NOTHING_LEARNED_CAUSE if nothing_learned else \
        STIFFNESS_CAUSE if patient else MODEL_CAUSE
    count = f"{consecutive} aborted trials in a row" if consecutive > 1 else "an aborted trial"
    return f"stopped after {count}: {trip.describe()}; likely cause: {cause}"
