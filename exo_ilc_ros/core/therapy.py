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
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .config import Config
from .errors import ProfileError
from .experiment import Experiment, build_reference
from .laws import TrialRecord
from .metrics import SessionMetrics, TrialMetrics, config_metrics, session_metrics
from .profiles import Profile, ProfileBook, ProfileWriter, check_name
from .session import RunResult, TrialConclusion, run_trials


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
                "session": None if summary is None else summary.to_json()}


def prepare(config: Config, book: ProfileBook, patient: str, exercise: str,
            new_patient: bool = False) -> PreparedExercise:
    """Every check before an exercise runs (module docstring): ProfileError or ConfigError
    naming the unknown patient or exercise, the corrupt file or what differs."""
    check_name("patient", patient)
    if not new_patient:
        book.require_patient(patient)
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
    writer: ProfileWriter = book.begin(prepared.patient, prepared.exercise, cfg,
                                       build_reference(cfg), prepared.start, session)
    cfg = writer.config
    experiment = Experiment(cfg)
    metrics: list[TrialMetrics] = []

    def conclude(conclusion: TrialConclusion) -> None:
        record = conclusion.record
        measured = config_metrics(record, cfg)
        metrics.append(measured)
        true_error = getattr(record, "true_max_abs_error", record.max_abs_error)
        writer.save(record.trial, conclusion.update, true_error,
                    complete=conclusion.stop is not None, metrics=measured.to_json())

    memory = load_patient_memory(writer.directory, experiment.reference.samples)
    result = run_trials(cfg, on_trial=on_trial, on_conclusion=conclude, patient_memory=memory)
    if result.patient_memory is not None:
        save_patient_memory(writer.directory, result.patient_memory)
    return ExerciseResult(prepared.patient, prepared.exercise, cfg, result, metrics,
                          None if prepared.start is None else prepared.start.version,
                          writer.version if metrics else None)


def profiles_root(given: str | None) -> Path:
    """``--profiles DIR`` or the default root (:func:`.profiles.default_root`)."""
    from .profiles import default_root

    return Path(given) if given else default_root()


VIRTUAL_PATIENT = "virtual_patient.npz"
"""Beside a profile: what a *learning virtual patient* (``patient.learning.*``) had learned at
the end of the last in-process session, so that the next session simulates the same patient
(simulation only; a real patient keeps it themselves)."""


def load_patient_memory(directory: Path, samples: int) -> tuple[Any, Any] | None:
    """The virtual patient's (fast, slow) states saved beside the profile (None: none, or
    of another movement)."""
    import numpy as np

    path = directory / VIRTUAL_PATIENT
    if not path.is_file():
        return None
    try:
        with np.load(path) as data:
            fast, slow = np.array(data["fast"]), np.array(data["slow"])
    except (OSError, ValueError, KeyError) as exc:
        raise ProfileError(f"{path}: unreadable virtual patient state: {exc}") from None
    return (fast, slow) if fast.shape[0] == samples == slow.shape[0] else None


def save_patient_memory(directory: Path, memory: tuple[Any, Any]) -> None:
    """Save the virtual patient's (fast, slow) states beside the profile, atomically."""
    import io

    import numpy as np

    from .profiles import write_bytes_atomic

    buffer = io.BytesIO()
    np.savez(buffer, fast=memory[0], slow=memory[1])
    write_bytes_atomic(directory / VIRTUAL_PATIENT, buffer.getvalue())
