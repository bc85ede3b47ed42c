"""Automatic tuning of the sign law's step schedules, eqs (22)-(24), with Optuna (ROS-free).

The paper found its thresholds and levels "by trial and error". Here an Optuna study searches
them per joint and per term (M, M', M''): 3 terms x joints x 5 numbers. The parametrisation
always satisfies the schema's rules (:mod:`.tuning_space`): ``threshold_low`` log-uniform and
``threshold_high = threshold_low * ratio`` with ``ratio > 1``; levels log-uniform and positive
(:data:`.tuning_space.THRESHOLD_RANGES`, :data:`.tuning_space.RATIO_RANGE`,
:data:`.tuning_space.LEVEL_RANGES`).

Objective (minimised), for every mass uncertainty delta of the problem, from one K-trial run:

* ``settled``: the trial from which *every* joint stays within the bound (1-based); if some joint is
  not within it at trial K, ``K + K * share`` where ``share`` is the fraction of (trial, joint)
  entries above the bound (so never settling always costs more than settling at K, and being
  nearer costs less);
* ``peak_weight * max(0, peak / first - 1)``: the patient-comfort penalty. ``first`` is the largest
  error of trial 1 (zero feed-forward, the same for every schedule), ``peak`` the largest error of
  any trial. A schedule that makes the arm track worse than it did before learning pays
  ``peak_weight`` iterations per 100 % of overshoot (default 20: 10 % worse costs 2 iterations).

The per-delta scores are aggregated by ``max`` (worst case over the uncertainties; default) or
``mean``. A run whose error grows beyond ``DIVERGENCE_FACTOR`` times its trial-1 error, or becomes
non-finite, is stopped early and its missing trials count as outside the bound.

Studies live in an Optuna storage: a journal file (a path; works across processes, and across
machines on a shared file system) or an RDB URL (``sqlite:///...``, ``postgresql://...``). The
study name defaults to a digest of the problem, so the same command resumes the same study and a
changed problem starts a new one. Parallel jobs are worker processes on the same storage.
"""

from __future__ import annotations

import hashlib
import json
import math
import multiprocessing
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import optuna

from ..core.errors import ExoIlcError
from ..core.loop.record import TrialRecord
from ..core.params.config import Config
from ..core.params.redact import redact
from ..core.session.learning_session import run_trials
from .tuning_space import (
    NORM_OPTIMAL_KEYS,
    SPACE_VERSION,
    space_params,
    suggest,
    tuned_values,
    values_from_params,
)

DIVERGENCE_FACTOR = 10.0
"""A run stops early once max |e| exceeds this multiple of its trial-1 max |e|."""


class TuningError(ExoIlcError):
    """A study cannot be created, loaded or used (wrong problem, empty study, bad storage)."""


@dataclass(frozen=True)
class TuningProblem:
    """What is tuned and how it is scored: the base config, the uncertainties, trials per run
    and the objective's weighting. Picklable, so worker processes receive it whole."""

    config_values: dict[str, Any]
    mass_uncertainties: tuple[float, ...]
    trials: int
    peak_weight: float = 20.0
    aggregate: str = "max"
    law: str = "sign"
    """sign: the step schedules; norm_optimal: its input-change weights and model delta_m."""

    def __post_init__(self) -> None:
        if self.aggregate not in ("max", "mean"):
            raise TuningError(f"aggregate must be max or mean, got {self.aggregate!r}")
        if not self.mass_uncertainties:
            raise TuningError("at least one mass uncertainty is needed")
        if self.trials < 2:
            raise TuningError(f"trials per run must be >= 2, got {self.trials}")

    @classmethod
    def from_config(cls, config: Config, mass_uncertainties: Sequence[float], trials: int,
                    peak_weight: float = 20.0, aggregate: str = "max",
                    law: str = "sign") -> TuningProblem:
        """The problem of tuning ``config``'s sign-law schedules (or ``law``'s values)."""
        return cls(config.values, tuple(float(d) for d in mass_uncertainties), int(trials),
                   float(peak_weight), aggregate, law)

    @property
    def config(self) -> Config:
        """The base config (its schedules are the starting point, trial 0 of a new study)."""
        return Config(self.config_values, "tuning problem")

    def fixed_values(self) -> dict[str, Any]:
        """The config values the objective depends on, except the schedules being tuned."""
        unused = ("law", "max_trials", "mass_uncertainty", "stop_when_settled")
        other = ("norm_optimal.",) if self.law == "sign" else NORM_OPTIMAL_KEYS
        return {k: v for k, v in self.config_values.items()
                if not k.startswith(("schedule.", "linear.", *other)) and k not in unused}

    def settings(self) -> dict[str, Any]:
        """Uncertainties, trials, weighting and search-space version."""
        return {"mass_uncertainties": list(self.mass_uncertainties), "trials": self.trials,
                "peak_weight": self.peak_weight, "aggregate": self.aggregate,
                "space": SPACE_VERSION, **({"law": self.law} if self.law != "sign" else {})}

    def digest(self) -> str:
        """A stable hash of everything the objective depends on except the schedules."""
        blob = json.dumps({"config": self.fixed_values(), **self.settings()},
                          sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:12]

    def conflicts(self, fixed: Mapping[str, Any], settings: Mapping[str, Any]) -> list[str]:
        """Names whose value differs from a stored problem's. Parameters only one side knows
        (added to or removed from the schema since) are not conflicts."""
        ours = self.fixed_values()
        names = [k for k in sorted(fixed.keys() & ours.keys()) if fixed[k] != ours[k]]
        names += [k for k, v in self.settings().items() if settings.get(k) != v]
        return names

    def default_study_name(self) -> str:
        """``exo-ilc-tune-<digest>``: the same problem resumes the same study."""
        return f"exo-ilc-tune-{self.digest()}"


# --- search space -------------------------------------------------------------------------------


# --- objective ----------------------------------------------------------------------------------

@dataclass
class RunScore:
    """How one K-trial run of a schedule scored at one mass uncertainty."""

    mass_uncertainty: float
    first: list[int | None]
    settled: list[int | None]
    settled_cost: float
    first_error: float
    """max |e| of trial 1 over joints (rad)."""
    peak_error: float
    """max |e| over every trial and joint (rad)."""
    floor: float
    """max |e| of the last trial over joints (rad)."""
    peak_penalty: float
    diverged: bool = False

    @property
    def score(self) -> float:
        """settled_cost + peak_penalty."""
        return self.settled_cost + self.peak_penalty


class _DivergedError(Exception):
    pass


def score_errors(max_abs_errors: np.ndarray, trials: int, bound: float, peak_weight: float,
                 mass_uncertainty: float, diverged: bool = False) -> RunScore:
    """Score a (k <= K, joints) table of max |e| per trial; missing trials count as outside."""
    errors = np.asarray(max_abs_errors, dtype=float)
    errors = np.where(np.isfinite(errors), errors, np.inf)
    joints = errors.shape[1]
    within = errors <= bound
    first: list[int | None] = []
    settled: list[int | None] = []
    for j in range(joints):
        hits = np.flatnonzero(within[:, j])
        first.append(int(hits[0]) + 1 if hits.size else None)
        misses = np.flatnonzero(~within[:, j])
        complete = errors.shape[0] == trials and not diverged
        if not complete or not within[-1, j]:
            settled.append(None)
        else:
            settled.append(int(misses[-1]) + 2 if misses.size else 1)
    if all(s is not None for s in settled):
        settled_cost = float(max(s for s in settled if s is not None))
    else:
        outside = int(np.count_nonzero(~within)) + (trials - errors.shape[0]) * joints
        settled_cost = trials + trials * outside / (trials * joints)
    first_error = float(np.max(errors[0]))
    peak = float(np.max(errors))
    overshoot = peak / first_error - 1.0 if first_error > 0 else 0.0
    penalty = peak_weight * max(0.0, overshoot) if math.isfinite(overshoot) else 1e6
    return RunScore(mass_uncertainty, first, settled, settled_cost, first_error,
                    peak if math.isfinite(peak) else float("inf"), float(np.max(errors[-1])),
                    penalty, diverged)


def evaluate(config: Config, problem: TuningProblem) -> tuple[float, list[RunScore]]:
    """The objective of ``config``'s schedules on ``problem``, with the score of each run."""
    scores = []
    bound = float(config["error_bound"])
    for delta in problem.mass_uncertainties:
        rows: list[np.ndarray] = []

        def guard(record: TrialRecord, rows: list[np.ndarray] = rows) -> None:
            rows.append(record.true_max_abs_error)
            worst = float(np.max(record.true_max_abs_error))
            if not math.isfinite(worst) or worst > DIVERGENCE_FACTOR * float(np.max(rows[0])):
                raise _DivergedError

        diverged = False
        try:
            run_trials(config, delta, problem.trials, law=problem.law, on_trial=guard)
        except (_DivergedError, FloatingPointError, ArithmeticError):
            diverged = True
        scores.append(score_errors(np.array(rows), problem.trials, bound, problem.peak_weight,
                                   delta, diverged))
    values = [s.score for s in scores]
    total = max(values) if problem.aggregate == "max" else float(np.mean(values))
    return total, scores


class Objective:
    """Optuna objective: sample schedules, run every uncertainty, return the aggregate score."""

    def __init__(self, problem: TuningProblem) -> None:
        self.problem = problem
        self.base = problem.config

    def __call__(self, trial: optuna.Trial) -> float:
        """Score one sampled schedule set; per-run details go to the trial's user attrs."""
        config = self.base.replace(suggest(trial, self.base.joints, self.problem.law))
        total, scores = evaluate(config, self.problem)
        trial.set_user_attr("runs", [asdict(s) for s in scores])
        return total


# --- storage and studies ------------------------------------------------------------------------

DRIVER_PACKAGES = {"psycopg": "'psycopg[binary]' (or pip install -e '.[postgres]')",
                   "psycopg2": "psycopg2-binary", "pymysql": "pymysql",
                   "MySQLdb": "mysqlclient"}
"""What to ``pip install`` for a database driver SQLAlchemy names (by its module)."""


def check_database_driver(url: str) -> None:
    """Raise TuningError (one line, no traceback) when the RDB URL is not one SQLAlchemy can
    use or its driver is not installed. SQLAlchemy 2.1 opens ``postgresql://`` with psycopg 3
    (``postgresql+psycopg2://`` asks for psycopg2)."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    try:
        dialect = make_url(url).get_dialect()
    except (ArgumentError, NoSuchModuleError, ValueError) as exc:
        raise TuningError(f"--storage {redact(url)}: not a database URL SQLAlchemy knows ({exc})") \
            from None
    try:
        dialect.import_dbapi()
    except ImportError as exc:
        module = exc.name or str(exc)
        package = DRIVER_PACKAGES.get(module.split(".")[0], module)
        raise TuningError(f"--storage {redact(url)}: the database driver {module!r} "
                          f"({dialect.name}+{dialect.driver}) is not installed; install it "
                          f"with: pip install {package}") from None


def open_storage(url: str) -> optuna.storages.BaseStorage | str:
    """An RDB URL (contains ``://``) as is, once its driver is known to be installed; anything
    else is a journal file path."""
    if "://" in url:
        check_database_driver(url)
        return url
    path = Path(url)
    path.parent.mkdir(parents=True, exist_ok=True)
    return optuna.storages.JournalStorage(optuna.storages.journal.JournalFileBackend(str(path)))


def make_sampler(seed: int | None) -> optuna.samplers.BaseSampler:
    """Multivariate TPE; constant liar keeps parallel workers from sampling the same point."""
    return optuna.samplers.TPESampler(seed=seed, multivariate=True, constant_liar=True,
                                      n_startup_trials=10)


CREATE_ATTEMPTS = 5
"""Tries at creating/loading a study on a database: processes starting together on an empty
one race to create Optuna's tables (PostgreSQL: 'duplicate key value violates unique
constraint "pg_type_typname_nsp_index"'); the loser retries and finds them."""


def _create_study(storage: str, name: str, seed: int | None) -> optuna.Study:
    """``optuna.create_study(..., load_if_exists=True)``; a database error other than a lost
    race is one line (TuningError), not a traceback."""
    for attempt in range(1, CREATE_ATTEMPTS + 1):
        try:
            return optuna.create_study(storage=open_storage(storage), study_name=name,
                                       direction="minimize", sampler=make_sampler(seed),
                                       load_if_exists=True)
        except ImportError as exc:  # a driver's own dependency (check_database_driver)
            raise TuningError(f"--storage {redact(storage)}: {exc}") from None
        except Exception as exc:
            from sqlalchemy.exc import IntegrityError, ProgrammingError, SQLAlchemyError

            if not isinstance(exc, SQLAlchemyError):
                raise
            if isinstance(exc, IntegrityError | ProgrammingError) and \
                    attempt < CREATE_ATTEMPTS:
                time.sleep(0.2 * attempt)  # another process is creating the tables
                continue
            reason = str(getattr(exc, "orig", None) or exc).strip().splitlines()[0]
            raise TuningError(f"--storage {redact(storage)}: cannot open the database ({reason})") \
                from None
    raise AssertionError("unreachable")  # pragma: no cover


def open_study(problem: TuningProblem, storage: str, study_name: str | None = None,
               seed: int | None = None) -> optuna.Study:
    """Create or resume the study; a new one gets the base config's schedules as trial 0.

    Raises TuningError when an existing study of that name was made for another problem.
    """
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    name = study_name or problem.default_study_name()
    study = _create_study(storage, name, seed)
    stored = study.user_attrs.get("problem_fixed")
    if stored is None:
        # "problem_fixed" last: a process starting on the same study meanwhile (docs/tuning.md's
        # "same command on every machine") reads either none of these or all of them.
        study.set_user_attr("problem_digest", problem.digest())
        study.set_user_attr("problem", problem.settings())
        study.set_user_attr("base_schedules", tuned_values(problem.config, problem.law))
        study.set_user_attr("problem_fixed", problem.fixed_values())
    else:
        conflicts = problem.conflicts(stored, study.user_attrs.get("problem", {}))
        if conflicts:
            raise TuningError(f"study {name!r} in {redact(storage)} was made for another problem "
                              f"({', '.join(conflicts[:5])} differ); use another --study-name "
                              "or the original options")
    if not study.trials:
        study.enqueue_trial(space_params(problem.config, problem.law),
                            user_attrs={"baseline": True})
    return study


def _worker(problem: TuningProblem, storage: str, study_name: str, n_trials: int,
            seed: int | None) -> None:
    """One worker process: load the study and run ``n_trials`` trials of it."""
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.load_study(study_name=study_name, storage=open_storage(storage),
                              sampler=make_sampler(seed))
    study.optimize(Objective(problem), n_trials=n_trials)


def _shares(total: int, jobs: int) -> list[int]:
    return [total // jobs + (1 if i < total % jobs else 0) for i in range(jobs)]


def optimize(problem: TuningProblem, storage: str, budget: int, jobs: int = 1,
             study_name: str | None = None, seed: int | None = None,
             progress: Callable[[optuna.Study], None] | None = None) -> optuna.Study:
    """Run ``budget`` more trials of the study, spread over ``jobs`` worker processes.

    ``jobs == 1`` runs in this process. ``progress(study)`` is called after each trial (one job)
    or every second while the workers run (several jobs).
    """
    study = open_study(problem, storage, study_name, seed)
    if budget <= 0:
        return study
    if jobs <= 1:
        callbacks = [lambda s, _t: progress(s)] if progress else None
        study.optimize(Objective(problem), n_trials=budget, callbacks=callbacks)
        return study
    context = multiprocessing.get_context("spawn")
    workers = [context.Process(target=_worker, args=(problem, storage, study.study_name, share,
                                                     None if seed is None else seed + i + 1),
                               name=f"exo-ilc-tune-{i}")
               for i, share in enumerate(_shares(budget, jobs)) if share > 0]
    for worker in workers:
        worker.start()
    try:
        while any(w.is_alive() for w in workers):
            if progress:
                progress(study)
            time.sleep(1.0)
    finally:
        for worker in workers:
            if worker.is_alive():
                worker.terminate()
            worker.join()
    if progress:
        progress(study)
    failed = [w.name for w in workers if w.exitcode not in (0, None)]
    if failed:
        raise TuningError(f"tuning worker(s) {', '.join(failed)} failed; see the messages above")
    return study


# --- results ------------------------------------------------------------------------------------

@dataclass
class TuningResult:
    """The best schedules found, with the scores of the baseline (trial 0) and of the best."""

    study_name: str
    config: Config
    """The base config with the best schedules."""
    best_value: float
    baseline_value: float | None
    best_runs: list[RunScore]
    baseline_runs: list[RunScore] = field(default_factory=list)
    completed: int = 0


def _runs(attrs: Mapping[str, Any]) -> list[RunScore]:
    return [RunScore(**r) for r in attrs.get("runs", [])]


def _rank(trial: optuna.trial.FrozenTrial) -> tuple[float, float, float]:
    """Objective first; ties go to the lower mean score, then the lower worst final error."""
    runs = _runs(trial.user_attrs)
    value = float(trial.value if trial.value is not None else math.inf)
    if not runs:
        return value, math.inf, math.inf
    return (value, float(np.mean([r.score for r in runs])), max(r.floor for r in runs))


def best_result(study: optuna.Study, problem: TuningProblem) -> TuningResult:
    """The study's best trial as a config, beside its baseline trial (if any).

    Among trials with the same objective the lower mean score over the uncertainties wins, then
    the lower worst final error."""
    complete = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.COMPLETE,))
    if not complete:
        raise TuningError(f"study {study.study_name!r} has no completed trial yet")
    best = min(complete, key=_rank)
    base = problem.config
    config = base.replace(values_from_params(best.params, base.joints, problem.law))
    baseline = next((t for t in complete if t.user_attrs.get("baseline")), None)
    return TuningResult(study.study_name, config, float(best.value or 0.0),
                        None if baseline is None else float(baseline.value or 0.0),
                        _runs(best.user_attrs),
                        [] if baseline is None else _runs(baseline.user_attrs), len(complete))
