"""Running a population's certificate (issue 33) and reporting it: the patients' cells on the
study's process pool or Dask cluster (:func:`.study.run_cells`), every patient's outcome written
as a line of a JSON Lines file as it finishes (a run interrupted and started again with the same
file runs only the patients not yet in it), the certificate as text, JSON and a figure, and the
worst patients as scenario overlays."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from matplotlib.figure import Figure

from ..core.errors import ConfigError
from ..core.params import schema
from ..core.person.cuffs import CUFFS
from ..core.population.certificate import (
    CRITERIA,
    Certificate,
    PatientOutcome,
    feedforward_limit,
    patient_outcome,
)
from ..core.population.distributions import SOURCES, Patient
from ..core.programs.study import CellResult, StudyCell
from .study import run_cells

OnOutcome = Callable[[PatientOutcome], None]


SIZE_KEY = "population"
"""The setup's population size: not part of what a rows file is of (patient i of a seed is the
same whatever the size), so a file of 1000 patients gives a certificate of its first 200, and a
run of 200 grows to 1000 with the same file."""


def _identity(setup: Mapping[str, Any]) -> Any:
    return json.loads(json.dumps({k: v for k, v in setup.items() if k != SIZE_KEY}))


def read_rows(path: Path, setup: Mapping[str, Any]) -> dict[int, PatientOutcome]:
    """The outcomes a rows file already holds, by patient index ({} if there is no file). Its
    first line is the run's setup; a file of another setup (the population's size aside:
    :data:`SIZE_KEY`) is an error (never overwritten)."""
    if not path.is_file() or path.stat().st_size == 0:
        return {}
    lines = path.read_text().splitlines()
    head = json.loads(lines[0])
    if not isinstance(head.get("setup"), dict) or _identity(head["setup"]) != _identity(setup):
        raise ConfigError("--rows", f"{path} holds another population or law "
                          f"({head.get('setup')}); give a new file")
    out: dict[int, PatientOutcome] = {}
    for line in lines[1:]:
        try:
            data = json.loads(line)
        except json.JSONDecodeError:  # a line cut short by an interruption: run it again
            continue
        outcome = PatientOutcome.from_json(data["outcome"])
        out[outcome.index] = outcome
    return out


def run_population(cells: Sequence[StudyCell], trials: int, workers: int,
                   dask: str | Any | None, rows: Path | None, setup: Mapping[str, Any],
                   on_outcome: OnOutcome | None = None) -> list[PatientOutcome]:
    """Every patient's outcome (the cells' ``seed`` is the patient's index): those already in
    ``rows`` read back, the others run and appended to it one line each as they finish. The
    file keeps every patient it held, of the cells or not (a smaller population's run reads
    its first patients and loses none of the others)."""
    done = read_rows(rows, setup) if rows is not None else {}
    todo = [c for c in cells if c.seed not in done]
    if rows is not None:  # the header and the whole lines read (a line cut short is dropped)
        rows.parent.mkdir(parents=True, exist_ok=True)
        rows.write_text("".join(json.dumps(x) + "\n" for x in [
            {"setup": setup}, *({"outcome": o.to_json()} for o in done.values())]))
    handle = rows.open("a") if rows is not None else None

    def finished(cell: StudyCell, result: CellResult) -> None:
        outcome = patient_outcome(cell.seed, result, trials, feedforward_limit(cell.values))
        done[cell.seed] = outcome
        if handle is not None:
            handle.write(json.dumps({"outcome": outcome.to_json()}) + "\n")
            handle.flush()
        if on_outcome is not None:
            on_outcome(outcome)

    for cell in cells:
        if on_outcome is not None and cell.seed in done:
            on_outcome(done[cell.seed])
    try:
        run_cells(todo, workers, dask, on_result=finished)
    finally:
        if handle is not None:
            handle.close()
    return [done[c.seed] for c in cells if c.seed in done]


def format_certificate(cert: Certificate, patients: Mapping[int, Patient], worst: int) -> str:
    """The certificate as text: the shares, trials to the bound, the worst patients, the
    verdict against the issue's criteria."""
    s = cert.summary()
    n = s["patients"]

    def share(key: str) -> str:
        value = s[f"share_{key}"]
        return f"{round(value * n)}/{n} ({100 * value:.1f} %)"

    def trial(x: float | None) -> str:
        return "never" if x is None else f"{x:g}"

    lines = [f"Certificate of {cert.label}: {n} patients x {cert.trials} trials, bound "
             f"{cert.error_bound:g} rad (true max |e|, worst joint)",
             f"  finite                         {share('finite')}",
             f"  bounded (finite, not growing)  {share('bounded')}",
             f"  within the bound by trial 10   {share('within_by_10')}   (>= "
             f"{100 * CRITERIA['within_by_10_share']:g} % to pass)",
             f"  within the bound by trial 25   {share('within_by_25')}   (all to pass)",
             f"  any aborted trial              {share('any_abort')}",
             f"  3 aborted trials in a row      {share('abort_run_3')}   (none to pass)",
             f"  more than 2 aborted trials     {share('aborts_over_2')}   (none to pass)",
             f"  trials to the bound (settled): median {trial(s['settled_median'])}, p95 "
             f"{trial(s['settled_p95'])}; first within: median {trial(s['first_median'])}, p95 "
             f"{trial(s['first_p95'])}"]
    if "cuff_force_max_N" in s:
        per_cuff = s["cuff_peaks_per_cuff"]
        lines.append(f"  peak cuff force (N, worst cuff per patient): max "
                     f"{s['cuff_force_max_N']:.1f}, p95 {s['cuff_force_p95_N']:.1f}; highest "
                     "per cuff " + ", ".join(
                         f"{name} {f:.1f} N / {t:.2f} N m" for name, f, t in zip(
                             CUFFS, per_cuff["force_N"], per_cuff["torque_Nm"], strict=False)))
    lines.append(f"Worst {min(worst, n)} patients:")
    for o in cert.worst(worst):
        where = "never within" if o.settled is None else f"settled at {o.settled}"
        final = "not finite" if not math.isfinite(o.final_error) else \
            f"final {o.final_error:.2e} rad"
        lines.append(f"  #{o.index}: {final}, {where}, {o.aborts} aborts (run {o.abort_run})"
                     f"{', GROWING' if o.growing else ''}"
                     f"{', AT ITS LIMIT' if o.at_limit else ''}"
                     f"{_cuff_text(o)}"
                     f"{': ' + o.failure if o.failure else ''}")
        if o.index in patients:
            lines.append(f"      {patients[o.index].describe()}")
    verdict = "PASS" if cert.passes else "FAIL: " + "; ".join(cert.reasons())
    lines.append(f"Verdict (the criteria above): {verdict}")
    return "\n".join(lines)


def _cuff_text(outcome: PatientOutcome) -> str:
    """``, cuffs 41.2 / 56.0 N`` (upper arm / forearm peak force), or nothing."""
    if not outcome.peak_cuff_force:
        return ""
    return ", cuffs " + " / ".join(f"{f:.1f}" for f in outcome.peak_cuff_force) + " N"


def certificate_json(cert: Certificate, setup: Mapping[str, Any],
                     patients: Mapping[int, Patient], worst: int,
                     falsification: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The certificate for machines: setup, summary, the worst patients with their parameters,
    every patient's outcome and parameters, the sources, the falsification."""
    def entry(o: PatientOutcome) -> dict[str, Any]:
        p = patients.get(o.index)
        return {**o.to_json(), "overrides": None if p is None else p.overrides}
    return {"setup": dict(setup), "criteria": CRITERIA, "summary": cert.summary(),
            "worst": [entry(o) for o in cert.worst(worst)],
            "patients": [entry(o) for o in cert.outcomes], "sources": SOURCES,
            "falsification": None if falsification is None else dict(falsification)}


def certificate_figure(cert: Certificate) -> Figure:
    """Left: how many patients reach the bound (settled) by each trial, with those never there;
    right: every patient's worst-joint true max |e| per trial (grey), the worst five coloured,
    the bound dashed."""
    cuffs = [o for o in cert.outcomes if o.peak_cuff_force]
    fig = Figure(figsize=(16.5 if cuffs else 11, 4.2))
    axes = fig.subplots(1, 3 if cuffs else 2)
    left, right = axes[0], axes[1]
    if cuffs:
        _cuff_panel(axes[2], cert.label, cuffs)
    k = cert.trials
    settled = [o.settled for o in cert.outcomes]
    counts = np.bincount([s for s in settled if s is not None], minlength=k + 1)[1:k + 1]
    never = sum(1 for s in settled if s is None)
    left.bar(np.arange(1, k + 1), counts, color="tab:green", label="settled at trial")
    left.bar([k + 2], [never], color="tab:red", label="never within")
    left.axvline(10.5, color="k", ls=":", lw=1)
    if k >= 25:
        left.axvline(25.5, color="k", ls=":", lw=1)
    ticks = [t for t in (1, 5, 10, 15, 20, 25) if t <= k]
    left.set_xticks([*ticks, k + 2], [*map(str, ticks), "never"])
    left.set_xlabel("trial from which the patient stays within the bound")
    left.set_ylabel("patients")
    left.set_title(f"{cert.label}: trials to the bound ({len(cert.outcomes)} patients)")
    left.legend(fontsize=8)
    worst = {o.index for o in cert.worst(5)}
    for o in cert.outcomes:
        y = np.array(o.worst_error_per_trial, dtype=float)
        if not y.size:
            continue
        trials = np.arange(1, y.size + 1)
        if o.index in worst:
            right.semilogy(trials, y, lw=1.6, label=f"#{o.index}")
        else:
            right.semilogy(trials, y, color="0.7", lw=0.6)
    right.axhline(cert.error_bound, color="k", ls="--", lw=1, label="bound")
    right.set_xlabel("trial")
    right.set_ylabel("true max |e|, worst joint (rad)")
    verdict = "PASS" if cert.passes else "FAIL"
    right.set_title(f"every patient (worst five coloured): {verdict}")
    right.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def _cuff_panel(ax: Any, label: str, outcomes: Sequence[PatientOutcome]) -> None:
    """Each patient's peak force per cuff over its trials (a person with muscles)."""
    index = np.array([o.index for o in outcomes])
    forces = np.array([o.peak_cuff_force for o in outcomes], dtype=float)
    for c, name in enumerate(CUFFS):
        ax.scatter(index, forces[:, c], s=14, label=name.replace("_", " "))
    worst = np.max(forces, axis=1)
    ax.axhline(float(np.percentile(worst, 95)), color="k", ls=":", lw=1,
               label="p95 (worst cuff)")
    ax.set_xlabel("patient")
    ax.set_ylabel("peak cuff force over the trials (N)")
    ax.set_title(f"{label}: cuff forces (max {worst.max():.0f} N)")
    ax.set_ylim(bottom=0.0)
    ax.legend(fontsize=8)


def scenario_yaml(overrides: Mapping[str, Any], header: str) -> str:
    """A scenario overlay (``config/scenarios/`` layout) that sets ``overrides``: each key in
    its node's section, nested by its dots."""
    document: dict[str, Any] = {}
    for key, value in overrides.items():
        section = schema.BY_NAME[key].section
        node = document.setdefault(section, {"ros__parameters": {}})["ros__parameters"]
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = value.item() if isinstance(value, np.generic) else value
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    return comment + yaml.safe_dump(document, sort_keys=False, default_flow_style=None)


def write_scenario(path: Path | str, patient: Patient, header: str) -> Path:
    """Write the patient as a scenario overlay (:func:`scenario_yaml`) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(scenario_yaml(patient.overrides, header))
    return path


def finite_or_none(x: float) -> float | None:
    """JSON has no inf or NaN."""
    return float(x) if math.isfinite(x) else None
