"""A therapy session in-process: for one patient, each exercise of the session starts from the
patient's latest profile of it (:mod:`.profiles`), learns over its trials, saves the profile
after every trial and measures every trial (:mod:`.metrics`).

The order of the checks is what keeps bad input from overwriting anything: the patient, the
exercise, the stored profile (its file and index) and its compatibility with the config's model
and reference are all checked before the first trial runs and before a new version is begun.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..arm.build import build_arm
from ..errors import ProfileError
from ..learning.patient_model import JointForceModel
from ..loop.patient import PatientLearning, PatientModel
from ..loop.rate import with_control_rate
from ..loop.record import TrialRecord
from ..params.config import Config
from ..persistence.patient_states import PatientState, read_legacy
from ..persistence.profile_format import Profile
from ..persistence.profile_writer import ProfileWriter
from ..persistence.profiles import ProfileBook, check_name, default_root
from ..reference.build import build_reference
from ..session.learning_session import TrialConclusion, run_trials
from ..session.result import RunResult
from .identified import Identified
from .metrics import SessionMetrics, TrialMetrics, config_metrics, session_metrics

IDENTIFICATION = "identification"
"""The key of a trial's metrics (a profile version's ``metrics``) holding the identified
patient after it (:meth:`.identified.Identified.to_json`; absent without identification)."""


def session_id() -> str:
    """``<UTC date-time>-<pid>``: names a session's profile versions and bags."""
    return f"{time.strftime('%Y%m%dT%H%M%SZ', time.gmtime())}-{os.getpid()}"


@dataclass
class PreparedExercise:
    """An exercise checked and ready to run: its config (``exercise.name`` and
    ``profile.initial`` set) and the profile it starts from (None: from the law's start)."""

    patient: str
    exercise: str
    config: Config
    start: Profile | None


@dataclass
class ExerciseResult:
    """One exercise of a session: the run, its metrics and the profile version it wrote."""

    patient: str
    exercise: str
    config: Config
    result: RunResult
    metrics: list[TrialMetrics] = field(default_factory=list)
    started_from: int | None = None
    """The profile version the session started from (None: no profile yet)."""
    version: int | None = None
    """The profile version this session wrote."""
    identified: list[Identified] = field(default_factory=list)
    """The identified patient after each trial (``identification.enabled``; empty: off)."""

    @property
    def session(self) -> SessionMetrics | None:
        """The session's summary of the metrics."""
        return session_metrics(self.metrics)

    def to_json(self) -> dict[str, Any]:
        """The ``therapy`` entry of a run in the JSON export."""
        summary = self.session
        return {"patient": self.patient, "exercise": self.exercise,
                "profile_started_from": self.started_from, "profile_version": self.version,
                "patient_session": self.config["patient.session"],
                "metrics": [m.to_json() for m in self.metrics],
                "session": None if summary is None else summary.to_json(),
                IDENTIFICATION: self.identified[-1].to_json() if self.identified else None}


def prepare(config: Config, book: ProfileBook, patient: str, exercise: str,
            new_patient: bool = False) -> PreparedExercise:
    """Every check before an exercise runs (module docstring): ProfileError or ConfigError
    naming the unknown patient or exercise, the corrupt file or what differs."""
    check_name("patient", patient)
    if not new_patient:
        try:
            book.require_patient(patient)
        except ProfileError as exc:
            raise ProfileError(f"{exc}; for the patient's first session add --new-patient") \
                from None
    elif patient in book.patients():
        raise ProfileError(f"patient {patient!r} already has profiles under {book.root}; drop "
                           "--new-patient to continue their therapy")
    cfg = config.replace({"exercise.name": exercise, "profile.initial": ""})
    reference = build_reference(cfg)  # ConfigError naming an unknown exercise
    start = book.latest(patient, exercise)
    if start is not None:
        start.check_compatible(cfg, reference)
        cfg = cfg.replace({"profile.initial": str(start.path.resolve())})
    return PreparedExercise(patient, exercise, cfg, start)


def run_exercise(prepared: PreparedExercise, book: ProfileBook, trials: int | None = None,
                 on_trial: Callable[[TrialRecord], None] | None = None,
                 session: str = "") -> ExerciseResult:
    """Run ``prepared``: trial 1 from its profile, the profile saved after every trial (a
    killed session keeps what it learned up to its last trial), metrics per trial. The
    session's version is allocated first (:meth:`.ProfileBook.begin`, under the profile's
    lock) and is the virtual patient's session (``patient.session``): its own noise."""
    cfg = prepared.config
    if trials is not None:
        cfg = cfg.replace({"max_trials": int(trials)})
    reference = build_reference(cfg)
    patient = None
    if PatientModel(cfg).learns:  # the state it starts from, kept with the version
        patient = PatientLearning(PatientModel(cfg), reference.samples)
        start = patient_start_state(prepared, patient)
        patient.fast, patient.slow = start.fast.copy(), start.slow.copy()
        patient.torque = patient.fast + patient.slow
    writer: ProfileWriter = book.begin(
        prepared.patient, prepared.exercise, cfg, reference, prepared.start, session,
        patient_start=None if patient is None else PatientState(patient.fast, patient.slow))
    cfg = writer.config
    metrics: list[TrialMetrics] = []
    identified: list[Identified] = []

    def conclude(conclusion: TrialConclusion) -> None:
        record = conclusion.record
        measured = config_metrics(record, cfg)
        metrics.append(measured)
        filed = measured.to_json()
        if conclusion.joint_forces is not None:  # the version keeps the last estimate
            identified.append(Identified.from_step(conclusion.joint_forces,
                                                   cfg["joint_names"]))
            filed[IDENTIFICATION] = identified[-1].to_json()
        true_error = getattr(record, "true_max_abs_error", record.max_abs_error)
        writer.save(record.trial, conclusion.update, true_error,
                    complete=conclusion.stop is not None, metrics=filed,
                    patient_state=None if patient is None else
                    PatientState(patient.fast, patient.slow))

    result = run_trials(cfg, on_trial=on_trial, on_conclusion=conclude, patient=patient)
    return ExerciseResult(prepared.patient, prepared.exercise, cfg, result, metrics,
                          None if prepared.start is None else prepared.start.version,
                          writer.version if metrics else None, identified)


def identified_of_records(config: Config,
                          records: Sequence[TrialRecord]) -> Identified | None:
    """The identified patient after ``records`` (a graph run's stored trials, in order),
    replayed as the session identified them (None: ``identification.enabled`` is off or no
    record)."""
    if not config["identification.enabled"] or not records:
        return None
    config = with_control_rate(config)  # the period the records were run at
    model = JointForceModel(config, build_arm(config), build_reference(config))
    steps = [model.conclude(record) for record in records]
    return Identified.from_step(steps[-1], config["joint_names"])


def patient_start_state(prepared: PreparedExercise, patient: PatientLearning) -> PatientState:
    """The learning virtual patient's state a session starts from: the state stored with the
    profile version it starts from, else (a version written before states were kept per
    version) the exercise's ``virtual_patient.npz``, else zeros (:mod:`.patient_states`)."""
    samples, joints = patient.fast.shape
    start = prepared.start
    if start is not None:
        if start.patient_state is not None and start.patient_state.fast.shape == (samples,
                                                                                  joints):
            return start.patient_state
        legacy = read_legacy(start.path.parent, samples)
        if legacy is not None:
            return legacy
    return PatientState.zeros(samples, joints)


def profiles_root(given: str | None) -> Path:
    """``--profiles DIR`` or the default root (:func:`.profiles.default_root`)."""

    return Path(given) if given else default_root()


