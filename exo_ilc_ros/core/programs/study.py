"""The robustness study: which learning law survives which patient (issue 14).

A *cell* is one law x scenario x mass uncertainty x seed: a whole configuration, run for K
trials in-process by :func:`run_cell` and reduced where it ran to per-trial tables
(:class:`CellResult`, a few kB, whatever K's records weighed). :func:`.study_rows.study_rows`
reduces the cells of one law x scenario x uncertainty over their seeds to one
:class:`.study_rows.StudyRow`. A cell carries its whole configuration as plain values, so any
process or machine with exo_ilc_ros installed runs it without the files it came from; and every
result is a function of the cell alone, so the table is the same however the cells are scheduled
(a process pool, a Dask cluster, one by one).

A *law* is any config file laid over the shipped ``config/exo_ilc.yaml``; the shipped short names
(:data:`SHIPPED_LAWS`) name the project's own. A *scenario* is an overlay of
``config/scenarios/`` (or any file of that layout) laid over the law's config.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ... import __version__
from ..errors import ConfigError, ExoIlcError
from ..loop.rate import with_control_rate
from ..loop.record import TrialRecord
from ..params.config import Config, config_dir, load_config, scenario_names, scenario_path
from ..person.cuffs import cuff_metrics
from ..session.learning_session import run_trials
from .shipped_laws import SHIPPED_LAWS

SEED_PARAMETER = "patient.seed"
"""The parameter every per-trial random stream of the patient derives from (with the trial)."""


@dataclass(frozen=True)
class LawSpec:
    """A learning law of the study: its label, the config file laid over the shipped one (None:
    the shipped config itself) and the values set on top."""

    label: str
    path: Path | None = None
    values: Mapping[str, Any] = field(default_factory=dict)

    def describe(self) -> str:
        """``robust (config/robust.yaml)``, ``linear (shipped config, law: linear)``."""
        where = str(self.path) if self.path is not None else "shipped config"
        extra = ", ".join(f"{k}: {v}" for k, v in self.values.items())
        return f"{self.label} ({where}{', ' + extra if extra else ''})"


def resolve_law(text: str) -> LawSpec:
    """A law from the command line: a shipped short name (:data:`SHIPPED_LAWS`), a config file
    (labelled by its stem), or ``LABEL=FILE``."""
    label, sep, rest = text.partition("=")
    if sep and label and rest:
        spec = resolve_law(rest)
        return LawSpec(label, spec.path, spec.values)
    if text in SHIPPED_LAWS:
        name, values = SHIPPED_LAWS[text]
        path = None if name is None else config_dir() / name
        if path is not None and not path.is_file():
            raise ConfigError("--laws", f"the shipped law {text!r} needs {path}, which is "
                              "missing")
        return LawSpec(text, path, dict(values))
    path = Path(text)
    if path.suffix in (".yaml", ".yml") or path.exists():
        if not path.is_file():
            raise ConfigError("--laws", f"no such config file {text!r}")
        return LawSpec(path.stem, path)
    raise ConfigError("--laws", f"unknown law {text!r}; use a shipped name ("
                      + ", ".join(SHIPPED_LAWS) + "), a config file or LABEL=FILE")


@dataclass(frozen=True)
class ScenarioSpec:
    """A patient scenario: its label and overlay file."""

    label: str
    path: Path


def resolve_scenario(text: str) -> ScenarioSpec:
    """A scenario from the command line: a shipped name or an overlay file (``LABEL=FILE``
    names it)."""
    label, sep, rest = text.partition("=")
    if sep and label and rest:
        return ScenarioSpec(label, scenario_path(rest))
    path = scenario_path(text)
    return ScenarioSpec(path.stem, path)


SCENARIO_ORDER = ("ideal", "sensor", "friction", "spastic", "voluntary", "realistic")
"""The shipped scenarios from the paper's plant to every effect at once (the table's order)."""


def shipped_scenarios() -> list[str]:
    """Every shipped scenario: those of :data:`SCENARIO_ORDER` in that order, then the rest."""
    names = scenario_names()
    return [n for n in SCENARIO_ORDER if n in names] + \
        [n for n in names if n not in SCENARIO_ORDER]


@dataclass(frozen=True, eq=False)
class StudyCell:
    """One law x scenario x mass uncertainty x seed, with its whole configuration."""

    law: str
    scenario: str
    mass_uncertainty: float
    seed: int
    values: dict[str, Any]
    """Every parameter's value (:attr:`Config.values`): the cell runs without any file."""

    @property
    def label(self) -> str:
        """``robust / sensor / 10 % / seed 0``."""
        return (f"{self.law} / {self.scenario} / {100 * self.mass_uncertainty:g} % / "
                f"seed {self.seed}")


def cell_config(law: LawSpec, scenario: ScenarioSpec, mass_uncertainty: float, seed: int,
                trials: int) -> Config:
    """The configuration of one cell: the shipped config, the law's file, the scenario overlay,
    then the law's values, the uncertainty, the trial count (every trial runs:
    ``stop_when_settled`` 0) and the seed, at the period ``control.period_rule`` gives. A broken
    file is named in the error."""
    overrides: dict[str, Any] = {**law.values, "max_trials": int(trials),
                                 "mass_uncertainty": float(mass_uncertainty),
                                 "stop_when_settled": 0, SEED_PARAMETER: int(seed)}
    try:
        return with_control_rate(load_config(law.path, overrides, overlays=[scenario.path]))
    except ConfigError as exc:
        if exc.source:
            raise
        raise ConfigError(exc.key, f"{exc.rule} (law {law.label}, scenario {scenario.label}, "
                          f"delta {mass_uncertainty:g}, seed {seed})") from None


def study_cells(laws: Sequence[LawSpec], scenarios: Sequence[ScenarioSpec],
                mass_uncertainties: Sequence[float], seeds: Sequence[int],
                trials: int) -> list[StudyCell]:
    """Every law x scenario x uncertainty x seed, in that nesting order (the table's)."""
    for kind, labels in (("law", [law.label for law in laws]),
                         ("scenario", [s.label for s in scenarios])):
        twice = sorted({x for x in labels if labels.count(x) > 1})
        if twice:
            raise ConfigError(f"--{kind}s", f"the {kind} label {twice[0]!r} is given twice "
                              f"(name one LABEL=FILE)")
    cells = []
    for law in laws:
        for scenario in scenarios:
            for delta in mass_uncertainties:
                for seed in seeds:
                    config = cell_config(law, scenario, delta, seed, trials)
                    cells.append(StudyCell(law.label, scenario.label, float(delta), int(seed),
                                           config.values))
    return cells


@dataclass(eq=False)
class CellResult:
    """What one cell ran, per trial (rows) and joint (columns); the trials' records stay where
    the cell ran."""

    law: str
    scenario: str
    mass_uncertainty: float
    seed: int
    error_bound: float
    samples: int
    """Samples per trial (N + 1)."""
    true_max_abs_error: np.ndarray
    """max_t |e_j| of the plant's true state (the measured one where the plant has no sensor
    model)."""
    max_abs_error: np.ndarray
    """max_t |e_j| as the controller measured it."""
    max_abs_feedforward: np.ndarray
    max_abs_effort: np.ndarray
    samples_at_limit: np.ndarray
    """Per trial: samples at which some joint's effort is at its limit."""
    aborted: list[int]
    """Trials the error envelope aborted."""
    failure: str | None = None
    """Why the run stopped before its last trial (a law that learned a non-finite input ...)."""
    nonfinite: str | None = None
    """Where the first non-finite state or effort appeared (the run itself went on)."""
    version: str = __version__
    """The exo_ilc_ros that ran the cell (a cluster must run the client's)."""
    seconds: float = 0.0
    """Wall time of the run where it ran (not part of the outcome: :meth:`same_as` ignores it)."""
    peak_cuff_force: np.ndarray | None = None
    """Per trial and cuff (upper arm, forearm), the peak |force| the cuff pressed into the
    person (N; :func:`..person.cuffs.cuff_metrics`); None: no person strapped in."""
    peak_cuff_torque: np.ndarray | None = None
    """Per trial and cuff, the peak |torque| (N m); None: no person."""

    @property
    def trials(self) -> int:
        """Trials run."""
        return int(self.true_max_abs_error.shape[0])

    def same_as(self, other: CellResult) -> bool:
        """Bit for bit the same outcome (NaN equal to NaN)."""
        arrays = ("true_max_abs_error", "max_abs_error", "max_abs_feedforward",
                  "max_abs_effort", "samples_at_limit")
        return (self.law, self.scenario, self.mass_uncertainty, self.seed, self.aborted,
                self.failure, self.nonfinite, self.samples) == \
            (other.law, other.scenario, other.mass_uncertainty, other.seed, other.aborted,
             other.failure, other.nonfinite, other.samples) and \
            all(np.array_equal(getattr(self, a), getattr(other, a), equal_nan=True)
                for a in arrays) and \
            all((getattr(self, a) is None) == (getattr(other, a) is None) and
                (getattr(self, a) is None or
                 np.array_equal(getattr(self, a), getattr(other, a), equal_nan=True))
                for a in ("peak_cuff_force", "peak_cuff_torque"))


def true_max_abs_error(record: TrialRecord) -> np.ndarray:
    """The record's max |e| of the true state where the plant reports one, else the measured."""
    true = getattr(record, "true_max_abs_error", None)
    return np.asarray(record.max_abs_error if true is None else true)


def run_cell(cell: StudyCell) -> CellResult:
    """Run one cell in-process and reduce it to its per-trial tables. A run the session stops
    (:class:`ExoIlcError`: a learned input that is not finite ...) keeps the trials before and
    says why in ``failure``."""
    config = Config(cell.values, f"study cell {cell.label}")
    limit = np.asarray(config["control.effort_limit"], dtype=float)
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("true", "measured", "ff", "effort",
                                                         "cuff_force", "cuff_torque")}
    at_limit: list[int] = []
    aborted: list[int] = []

    nonfinite: list[str] = []

    def reduce(record: TrialRecord) -> None:
        if not nonfinite:
            bad = ~(np.all(np.isfinite(record.effort), axis=1)
                    & np.all(np.isfinite(record.position), axis=1))
            if np.any(bad):
                after = "" if record.aborted_at is None else \
                    f", in the safe hold after the envelope abort at sample {record.aborted_at}"
                nonfinite.append(f"non-finite state or effort from trial {record.trial}, "
                                 f"sample {int(np.flatnonzero(bad)[0])}{after}")
        rows["true"].append(true_max_abs_error(record))
        rows["measured"].append(np.asarray(record.max_abs_error))
        rows["ff"].append(np.max(np.abs(record.feedforward), axis=0))
        rows["effort"].append(np.max(np.abs(record.effort), axis=0))
        if record.cuff_wrench is not None:
            cuffs = cuff_metrics(np.asarray(record.cuff_wrench))
            rows["cuff_force"].append(cuffs[:, 0])
            rows["cuff_torque"].append(cuffs[:, 2])
        at_limit.append(int(np.count_nonzero(np.any(np.abs(record.effort) >= limit, axis=1))))
        if record.aborted:
            aborted.append(record.trial)

    failure = None
    start = time.perf_counter()
    try:
        run_trials(config, on_trial=reduce)
    except ExoIlcError as exc:
        failure = f"after trial {len(at_limit)}: {exc}"
    seconds = time.perf_counter() - start
    joints = config.joints
    samples = int(round(config["trajectory.duration"] / config["control.period"])) + 1

    def table(key: str) -> np.ndarray:
        return np.array(rows[key], dtype=float).reshape(-1, joints)

    def cuffs(key: str) -> np.ndarray | None:
        return np.array(rows[key], dtype=float) if rows[key] else None

    return CellResult(cell.law, cell.scenario, cell.mass_uncertainty, cell.seed,
                      float(config["error_bound"]), samples, table("true"), table("measured"),
                      table("ff"), table("effort"), np.array(at_limit, dtype=np.int64),
                      aborted, failure, nonfinite[0] if nonfinite else None, seconds=seconds,
                      peak_cuff_force=cuffs("cuff_force"),
                      peak_cuff_torque=cuffs("cuff_torque"))


