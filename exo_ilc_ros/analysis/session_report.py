"""The session report a therapist reads: one self-contained HTML page per session (figures as
base64 PNG, no script, no external file), built from the session's bags and the patient's
profiles (``exo-ilc report BAG [BAG ...] --html report.html``).

Per exercise: the tracking error and the robot's assistance over the trials, the patient's share
of the work, the trials the safety envelope stopped or the watchdog made run again and what that
means, and the session beside the patient's earlier sessions of the exercise (the profile
versions' provenance). Every number carries its unit.
"""

from __future__ import annotations

import base64
import html
import io
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from ..bag.provenance import (
    EXERCISE,
    EXERCISE_ORDER,
    PATIENT,
    PROFILE_STARTED_FROM,
    PROFILE_VERSION,
    SESSION,
)
from ..bag.run import BagRun
from ..bag.storage import read_metadata
from ..core.loop.record import TrialRecord
from ..core.params.config import Config
from ..core.persistence.profiles import ProfileBook
from ..core.person.cuffs import cuff_table, first_beyond_cuff_limit
from ..core.programs.identified import SHOWN, UNITS, WORDS, Identified
from ..core.programs.metrics import TrialMetrics, config_metrics
from ..core.programs.therapy import IDENTIFICATION
from ..core.reference.build import build_reference
from ..core.reference.exercise import PAPER_EXERCISE
from .identified import format_value, trend
from .therapy import DEGREES, DISPLAY, display_value, share_note
from .wording import count_phrase


@dataclass
class ExerciseRun:
    """One exercise of a session as its bag holds it."""

    path: Path
    patient: str
    exercise: str
    session: str
    joint_names: list[str]
    metrics: list[TrialMetrics]
    error_bound: float
    envelope: list[float]
    law: str
    assist: bool
    period: float
    watchdog_periods: int
    aborts: list[tuple[int, int]] = field(default_factory=list)
    """(trial, sample) the error envelope stopped."""
    reruns: list[tuple[int, str]] = field(default_factory=list)
    """(trial, reason) of every attempt discarded and run again (watchdog, lost, timeout)."""
    notes: list[str] = field(default_factory=list)
    profile_version: str = ""
    started_from: str = ""
    order: int = 0
    """Place in the session (1, 2, ...); 0: unknown (a bag of an earlier version)."""
    identified: list[Identified] = field(default_factory=list)
    """The identified patient after each trial (its summaries'; empty: none)."""
    cuff_forces: np.ndarray | None = None
    """A person strapped in: per completed trial and cuff the peak and RMS |force| (N) and
    |torque| (N m) on the person (``core.person.cuffs``); None: no person."""
    cuff_limit: list[float] = field(default_factory=list)
    """``safety.cuff_force_limit`` (N per cuff; 0: none) of the run."""
    cuff_aborts: list[int] = field(default_factory=list)
    """Trials stopped because a cuff pressed past its limit (of :attr:`aborts`)."""
    cuff_trials: list[int] = field(default_factory=list)
    """The trial of each row of :attr:`cuff_forces`."""


def _record_of(run: BagRun, k: int, config: Config) -> TrialRecord | None:
    """Trial ``k`` of ``run`` as a record (for metrics of a bag that has none filed)."""
    trial = run.trials.get(k)
    if trial is None or not trial.complete or trial.feedforward is None or \
            np.isnan(trial.command).any():
        return None
    reference = build_reference(config)
    if reference.samples != trial.position.shape[0]:
        return None
    at = trial.aborted_at if trial.aborted_at is None or trial.aborted_at >= 0 else None
    return TrialRecord(k, reference, trial.position, trial.velocity, trial.feedforward,
                       trial.command, trial.command, None, at)


def exercise_run(run: BagRun) -> ExerciseRun:
    """The report's view of a bag: its metrics (filed in the summaries, else computed from the
    samples), aborts and reruns, and the patient / exercise / session it belongs to."""
    custom = dict(read_metadata(run.path).get("custom_data") or {})
    sidecar = run.path / "therapy.json"  # a graph run's (cli/therapy.py writes it)
    if PATIENT not in custom and sidecar.is_file():
        try:
            side = json.loads(sidecar.read_text())
            custom.update({PATIENT: str(side["patient"]), EXERCISE: str(side["exercise"]),
                           SESSION: str(side["session"]),
                           PROFILE_VERSION: str(side.get("profile_version") or ""),
                           PROFILE_STARTED_FROM: str(side.get("profile_started_from") or ""),
                           EXERCISE_ORDER: str(side.get("exercise_order") or "")})
        except (OSError, ValueError, KeyError) as exc:
            run.notes.append(f"{sidecar}: unreadable ({exc}); patient unknown")
    config = run.provenance.config
    values = config.values if config is not None else {}
    names = run.joint_names
    metrics: list[TrialMetrics] = []
    for k in run.completed:
        summary = run.summaries.get(k, {})
        aborted = run.trials[k].aborted_at is not None if k in run.trials else False
        found = TrialMetrics.from_summary(k, summary, names, aborted)
        if found is None and config is not None:  # a bag of a version without metrics
            record = _record_of(run, k, config)
            found = None if record is None else config_metrics(
                record, config.with_mass_uncertainty(run.mass_uncertainty))
        if found is not None:
            metrics.append(found)
    identified = [found for found in (Identified.from_summary(k, run.summaries.get(k, {}),
                                                             names) for k in run.completed)
                  if found is not None]
    aborts = [(k, t.aborted_at if t.aborted_at is not None else -1)
              for k, t in sorted(run.trials.items()) if t.aborted_at is not None]
    reruns = [(k, reason) for k, t in sorted(run.trials.items()) for reason in t.reruns]
    limit = [float(x) for x in values.get("safety.cuff_force_limit", [])]
    pressed = [k for k, sample in aborts if sample >= 0 and _pressed_at(run, k) == sample]
    return ExerciseRun(
        run.path, custom.get(PATIENT, "") or "(no patient)",
        custom.get(EXERCISE, "") or str(values.get("exercise.name", PAPER_EXERCISE)),
        custom.get(SESSION, "") or run.path.name, names, metrics, run.error_bound,
        list(values.get("safety.error_envelope", [])), run.law,
        bool(values.get("assist_as_needed.enabled", False)), run.period,
        int(values.get("safety.watchdog_periods", 0)), aborts, reruns, list(run.notes),
        custom.get(PROFILE_VERSION, ""), custom.get(PROFILE_STARTED_FROM, ""),
        int(custom.get(EXERCISE_ORDER) or 0) if str(custom.get(EXERCISE_ORDER) or "").isdigit()
        else 0, identified, cuff_table([run.summaries.get(k, {}) for k in run.completed]),
        limit, pressed, list(run.completed))


def _pressed_at(run: BagRun, trial: int) -> int:
    """The first sample of ``trial`` a cuff pressed past the run's limit (-1: none, or no
    cuff wrenches recorded)."""
    wrench = run.trials[trial].cuff_wrench
    config = run.provenance.config
    if wrench is None or config is None:
        return -1
    return first_beyond_cuff_limit(wrench, [float(x) for x in
                                            config["safety.cuff_force_limit"]])


def group_by_session(runs: Sequence[ExerciseRun]) -> dict[tuple[str, str], list[ExerciseRun]]:
    """(patient, session) -> its exercises in session order (``order``; bags without it after
    those with it, in the order given)."""
    out: dict[tuple[str, str], list[ExerciseRun]] = {}
    for run in runs:
        out.setdefault((run.patient, run.session), []).append(run)
    return {key: sorted(members, key=lambda r: r.order or 1 << 30)
            for key, members in out.items()}


def _png(fig: Figure) -> str:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def exercise_figure(run: ExerciseRun) -> Figure:
    """Per trial: peak true |e| (deg, log), assistance RMS (N m), learned feed-forward RMS
    (deg/s^2), the patient's share (%, as in the table); one line per joint, whole trials on
    the trial axis."""
    fig = Figure(figsize=(10.0, 6.4), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True)
    trials = np.array([m.trial for m in run.metrics])
    panels = ((axes[0, 0], "max_error", "peak true |e| (°)", DEGREES),
              (axes[0, 1], "assistance_rms", "assistance: RMS torque beyond gravity (N m)", 1.0),
              (axes[1, 0], "feedforward_rms", "learned feed-forward RMS (°/s²)", DEGREES),
              (axes[1, 1], "patient_share", "patient's share of the work (%)", 100.0))
    for ax, name, label, scale in panels:
        table = np.array([getattr(m, name) for m in run.metrics]) * scale
        for j, joint in enumerate(run.joint_names):
            ax.plot(trials, table[:, j], marker=".", markersize=3, linewidth=1.0, label=joint)
        ax.set_ylabel(label, fontsize=8)
        ax.grid(True, linewidth=0.3)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    axes[0, 0].set_yscale("log")
    axes[0, 0].axhline(run.error_bound * DEGREES, color="k", linestyle="--", linewidth=0.8,
                       label=f"bound {run.error_bound * DEGREES:.2g}°")
    share = 100.0 * np.array([m.patient_share_total for m in run.metrics])
    axes[1, 1].plot(trials, share, color="k", linewidth=1.6, label="whole arm")
    for ax in axes[1]:
        ax.set_xlabel("trial")
    for ax in axes.ravel():
        ax.legend(fontsize=7)
    fig.suptitle(f"{run.exercise}: {len(run.metrics)} trial{'s' if len(run.metrics) != 1 else ''}",
                 fontsize=10)
    return fig


STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 62em; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.25em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5em 0 1em; }
td, th { border: 1px solid #bbb; padding: 0.2em 0.6em; text-align: right; }
th { background: #eef; } td.l, th.l { text-align: left; }
.note { color: #444; font-size: 0.92em; } .warn { color: #8a3b00; }
img { max-width: 100%; }
"""


def _e(text: Any) -> str:
    return html.escape(str(text))


def _number(x: float, unit: str) -> str:
    """``x`` with its unit: a share (unit 1) in per cent, SPARC as a dimensionless index."""
    if unit == "1":
        return f"{100.0 * x:.3g} %"
    if unit == "SPARC":
        return f"{x:.3f} (SPARC, dimensionless)"
    return f"{x:.3g} {_e(unit)}"


def _joint_rows(run: ExerciseRun) -> str:
    first, last = run.metrics[0], run.metrics[-1]
    rows = []
    for name, (label, unit, _) in DISPLAY.items():
        for which, m in ((f"trial {first.trial}", first), (f"trial {last.trial}", last)):
            why = m.spasticity_reasons() if name == "spasticity" else [""] * len(run.joint_names)
            cells = "".join(
                f"<td>{display_value(name, x)}{'' if not np.isfinite(x) else ' ' + _e(unit)}"
                + (f"<br><span class=note>{_e(w)}</span>" if w else "") + "</td>"
                for x, w in zip(getattr(m, name), why, strict=True))
            rows.append(f"<tr><td class=l>{_e(label)}</td><td class=l>{which}</td>{cells}</tr>")
    for name, label, unit in (("patient_share_total", "patient's share, whole arm", "1"),
                              ("smoothness", "smoothness, SPARC of the speed", "SPARC")):
        a, b = getattr(first, name), getattr(last, name)
        rows.append(f"<tr><td class=l>{label}</td><td class=l>trial {first.trial} → "
                    f"{last.trial}</td><td colspan={len(run.joint_names)}>{_number(a, unit)} → "
                    f"{_number(b, unit)}</td></tr>")
    head = "".join(f"<th>{_e(n)}</th>" for n in run.joint_names)
    note = share_note([first, last])
    return (f"<table><tr><th class=l>metric</th><th class=l>trial</th>{head}</tr>"
            + "".join(rows) + "</table>" + (f"<p class=note>{_e(note)}.</p>" if note else ""))


def _cuffs(run: ExerciseRun) -> str:
    """The forces the cuffs pressed into the person (only with a person strapped in)."""
    forces = run.cuff_forces
    if forces is None or not len(forces) or len(run.cuff_trials) != len(forces):
        return ""
    rows = []
    for c, cuff in enumerate(("upper-arm cuff", "forearm cuff")):
        peaks = forces[:, c, 0]
        worst = int(np.nanargmax(peaks)) if np.isfinite(peaks).any() else 0
        limit = run.cuff_limit[c] if c < len(run.cuff_limit) else 0.0
        rows.append(
            f"<tr><td class=l>{cuff}</td><td>{forces[0, c, 0]:.3g} N</td>"
            f"<td>{forces[-1, c, 0]:.3g} N</td><td>{forces[-1, c, 1]:.3g} N</td>"
            f"<td>{peaks[worst]:.3g} N (trial {run.cuff_trials[worst]})</td>"
            f"<td>{np.nanmax(forces[:, c, 2]):.3g} N m</td>"
            f"<td>{f'{limit:g} N' if limit > 0 else 'none'}</td></tr>")
    first, last = run.cuff_trials[0], run.cuff_trials[-1]
    return ("<h3>Forces on the person (cuffs)</h3><table><tr><th class=l>cuff</th>"
            f"<th>peak force, trial {first}</th><th>peak force, trial {last}</th>"
            f"<th>RMS force, trial {last}</th><th>highest peak force</th>"
            "<th>highest peak torque</th><th>limit</th></tr>" + "".join(rows) + "</table>"
            "<p class=note>What it means: the force and torque each cuff pressed into the "
            "arm (the exoskeleton never sits exactly on the arm's joints, and the arm's muscles "
            "pull). A trial in which a cuff pressed past its limit was stopped there and the "
            "arm held where it was (Safety events).</p>")


def _events(run: ExerciseRun) -> str:
    parts = []
    pressed = [(k, s) for k, s in run.aborts if k in run.cuff_aborts]
    if pressed:
        limits = ", ".join(f"{x:g} N" for x in run.cuff_limit) or "?"
        parts.append(
            f"<p class=warn><b>{len(pressed)} trial(s) stopped by the cuff-force limit</b> "
            f"({limits}, upper-arm and forearm cuff): " + ", ".join(
                f"trial {k} at t = {s * run.period:.2f} s" for k, s in pressed)
            + ".</p><p class=note>What it means: a cuff pressed harder into the arm than the "
            "limit allows. The robot stopped following the movement and held the arm where it "
            "was; the trial is kept and was learned from up to where it stopped.</p>")
    envelope_aborts = [(k, s) for k, s in run.aborts if k not in run.cuff_aborts]
    if envelope_aborts:
        items = []
        for trial, sample in envelope_aborts:
            when = f"at t = {sample * run.period:.2f} s" if sample >= 0 else "(sample unknown)"
            envelope = ", ".join(f"{x:g} rad" for x in run.envelope) or "?"
            items.append(f"<li>trial {trial} stopped {when}</li>")
        parts.append(
            f"<p class=warn><b>{len(envelope_aborts)} trial(s) stopped by the safety envelope</b> "
            f"(|error| above {envelope} per joint).</p><ul>{''.join(items)}</ul>"
            "<p class=note>What it means: the arm moved further from the planned movement than "
            "the safety envelope allows (a strong push or pull, a spasm, or assistance that did "
            "not fit). The robot stopped following the movement and held the arm where it was. "
            "The trial is kept in the record and was learned from up to where it stopped (with "
            "a smaller step for the joint that left the envelope), so the next trial used "
            "changed assistance; a few such trials in a row end the session.</p>")
    else:
        parts.append("<p>No trial was stopped by the safety envelope.</p>")
    trips = [(k, r) for k, r in run.reruns if r == "watchdog"]
    others = [(k, r) for k, r in run.reruns if r != "watchdog"]
    if trips:
        timeout = run.watchdog_periods * run.period
        parts.append(
            f"<p class=warn><b>{len(trips)} watchdog trip(s)</b>: trial(s) "
            f"{', '.join(str(k) for k, _ in trips)}.</p><p class=note>What it means: the "
            f"controller received no joint measurement for {run.watchdog_periods} control "
            f"periods ({timeout:.2f} s) and held the arm still. This is a communication or "
            "computer stall, not something the patient did. The interrupted attempt was "
            "discarded and the trial run again from the same assistance; nothing was lost.</p>")
    else:
        parts.append("<p>No watchdog trip.</p>")
    if others:
        parts.append("<p class=note>Trials run again for other reasons: " + ", ".join(
            f"trial {k} ({_e(r)})" for k, r in others) + " (the attempt was discarded, the "
            "trial repeated with the same assistance; results unaffected).</p>")
    return "".join(parts)


def _history(run: ExerciseRun, book: ProfileBook | None) -> str:
    if book is None or run.patient == "(no patient)":
        return "<p class=note>No profiles given (--profiles): no comparison with earlier " \
               "sessions.</p>"
    index = book.index(run.patient, run.exercise) if run.patient in book.patients() else None
    if index is None:
        return f"<p class=note>No earlier sessions of {_e(run.exercise)} in {_e(book.root)}.</p>"
    rows = []
    for entry in _earlier_versions(index["versions"], run.profile_version):
        metrics = entry.get("metrics") or {}
        peak = max(entry.get("final_max_abs_error") or [float("nan")])
        assist = metrics.get("assistance_rms")
        share = metrics.get("patient_share_total")
        mark = " (this session)" if str(entry["version"]) == run.profile_version else ""
        rows.append(
            f"<tr><td class=l>v{entry['version']}{mark}</td><td class=l>"
            f"{_e(entry.get('updated', entry.get('created', '?')))}</td>"
            f"<td>{entry.get('trials', 0)}</td><td>{entry.get('trials_total', 0)}</td>"
            f"<td>{peak * DEGREES:.3g}°</td>"
            f"<td>{'-' if assist is None else f'{max(assist):.3g} N m'}</td>"
            f"<td>{'-' if share is None else _number(share, '1')}</td>"
            f"<td class=l>{_e(entry.get('status', '?'))}</td></tr>")
    return ("<table><tr><th class=l>session (profile)</th><th class=l>last saved (UTC)</th>"
            "<th>trials</th><th>trials in all</th><th>final peak |e|, worst joint</th>"
            "<th>final assistance RMS, worst joint</th><th>final patient share</th>"
            "<th class=l>status</th></tr>" + "".join(rows) + "</table>")


def identified_history(run: ExerciseRun,
                       book: ProfileBook | None) -> list[tuple[str, Identified]]:
    """(``v<version>``, the identified patient after its last trial) of every session of the
    exercise up to this one that kept one (the profile versions' ``metrics.identification``),
    in order; empty without profiles."""
    if book is None or run.patient == "(no patient)" or run.patient not in book.patients():
        return []
    index = book.index(run.patient, run.exercise)
    if index is None:
        return []
    out = []
    for entry in _earlier_versions(index["versions"], run.profile_version):
        data = (entry.get("metrics") or {}).get(IDENTIFICATION)
        if not data:
            continue
        try:
            out.append((f"v{entry['version']}", Identified.from_json(data)))
        except (KeyError, TypeError, ValueError):
            continue
    return out


def _series(history: Sequence[tuple[str, Identified]], p: str,
            j: int) -> list[tuple[str, float]]:
    return [(session, item.joints[j][p].value if item.joints[j][p].identifiable
             else float("nan")) for session, item in history if j < len(item.joints)]


def identification_trends(history: Sequence[tuple[str, Identified]],
                          joint_names: Sequence[str]) -> list[str]:
    """One line per joint and parameter with an estimate in two sessions or more:
    ``elbow_flexion damping 0.82 -> 0.61 N m s/rad over 6 sessions``."""
    lines = []
    for j, name in enumerate(joint_names):
        for p in SHOWN:
            line = trend(_series(history, p, j), p, name)
            if line:
                lines.append(line)
    return lines


def identification_figure(history: Sequence[tuple[str, Identified]],
                          joint_names: Sequence[str]) -> Figure:
    """Per parameter the estimate of each session (the last trial's) with its 95 % interval,
    one line per joint (not identifiable: left out)."""
    fig = Figure(figsize=(10.0, 2.2 * ((len(SHOWN) + 1) // 2)), layout="constrained")
    axes = fig.subplots((len(SHOWN) + 1) // 2, 2, squeeze=False).ravel()
    x = np.arange(1, len(history) + 1)
    for ax, p in zip(axes, SHOWN, strict=False):
        for j, name in enumerate(joint_names):
            values = np.array([v for _, v in _series(history, p, j)])
            low = np.array([item.joints[j][p].low for _, item in history])
            high = np.array([item.joints[j][p].high for _, item in history])
            spread = np.nan_to_num(np.vstack([values - low, high - values]), nan=0.0)
            ax.errorbar(x, values, yerr=np.clip(spread, 0.0, None), marker="o", markersize=3,
                        linewidth=1.0, capsize=2, label=name)
        ax.set_ylabel(f"{WORDS[p]} ({UNITS[p]})", fontsize=8)
        ax.set_xticks(x, [s for s, _ in history], fontsize=7)
        ax.grid(True, linewidth=0.3)
        ax.legend(fontsize=7)
    for ax in axes[len(SHOWN):]:
        ax.set_visible(False)
    fig.suptitle("the identified patient per session (after each session's last trial)",
                 fontsize=10)
    return fig


def _identification(run: ExerciseRun, book: ProfileBook | None) -> str:
    """The identified patient after the session's last trial and its trend across sessions
    ("" when the run identified nothing)."""
    if not run.identified:
        return ""
    last = run.identified[-1]
    head = "".join(f"<th>{_e(WORDS[p])}</th>" for p in SHOWN)
    rows = "".join(
        f"<tr><td class=l>{_e(j.name)}</td>"
        + "".join(f"<td>{_e(format_value(p, j[p]))} {_e(UNITS[p])}</td>" for p in SHOWN)
        + f"<td>{'yes' if j.trustworthy else 'no'}</td><td>{'yes' if j.used else 'no'}</td>"
        + f"<td class=l><span class=note>{_e(j.reason)}</span></td></tr>"
        for j in last.joints)
    out = (f"<h3>The identified patient</h3><p>After trial {last.trial} (95 % intervals; "
           "n.i.: the movement did not determine it):</p><table><tr><th class=l>joint</th>"
           f"{head}<th>trusted</th><th>used by the robot</th><th class=l>why not</th></tr>"
           f"{rows}</table>")
    history = identified_history(run, book)
    lines = identification_trends(history, run.joint_names)
    if lines:
        out += ("<p>Across sessions:</p><ul>" + "".join(f"<li>{_e(line)}</li>" for line in lines)
                + "</ul><img alt='the identified patient per session' src='data:image/png;"
                f"base64,{_png(identification_figure(history, run.joint_names))}'>")
    return out


def _earlier_versions(versions: Sequence[dict[str, Any]],
                      this: str) -> list[dict[str, Any]]:
    """The profile versions up to this session's (a later session is not an earlier one);
    all of them when this session's version is unknown."""
    try:
        limit = int(this)
    except ValueError:
        return list(versions)
    return [v for v in versions if int(v["version"]) <= limit]


def render_session(runs: Sequence[ExerciseRun], book: ProfileBook | None = None) -> str:
    """The HTML page of one session (all ``runs`` share the patient and session)."""
    first = runs[0]
    sections = []
    for run in runs:
        if not run.metrics:
            sections.append(f"<h2>{_e(run.exercise)}</h2><p class=warn>No completed trial with "
                            f"metrics in {_e(run.path)}.</p>")
            continue
        start = f"from profile v{run.started_from}" if run.started_from else \
            "from no stored profile"
        aan = ", assist-as-needed" if run.assist else ""
        sections.append(
            f"<h2>{_e(run.exercise)}</h2><p>{count_phrase(len(run.metrics), 'trial')}, "
            "learning law "
            f"{_e(run.law)}{aan}, started {start}"
            + (f", saved as profile v{_e(run.profile_version)}" if run.profile_version else "")
            + f". Error bound {run.error_bound * DEGREES:.2g}°. "
            f"Bag: <code>{_e(run.path)}</code></p>"
            f"<img alt='error, assistance, feed-forward and patient share over the trials of "
            f"{_e(run.exercise)}' src='data:image/png;base64,{_png(exercise_figure(run))}'>"
            + _joint_rows(run) + _cuffs(run) + "<h3>Safety events</h3>" + _events(run)
            + _identification(run, book)
            + "<h3>Compared with earlier sessions</h3>" + _history(run, book))
    glossary = (
        "<h2>How to read this page</h2><ul class=note>"
        "<li><b>peak / RMS true |e|</b> (degrees): how far the arm was from the planned movement "
        "(largest and typical), from the arm's true position.</li>"
        "<li><b>assistance</b> (N m): the robot's torque beyond what merely holds the arm up "
        "against gravity (RMS over the movement); falling assistance with a small error means "
        "the patient does more.</li>"
        "<li><b>learned feed-forward</b> (°/s²): the part of the assistance the robot learned "
        "from earlier trials.</li>"
        "<li><b>patient's share of the work</b> (%): 1 - robot torque / torque the movement "
        "needs (Guidali et al. 2013); 0 %: the robot did it all, 100 %: the patient did, "
        "below 0 %: the patient worked against the robot; 0 % also when the difference is "
        "within what the measurement resolves (a passive patient).</li>"
        "<li><b>smoothness</b> (SPARC, dimensionless): spectral arc length of the speed "
        "(Balasubramanian et al. 2015); closer to 0 is smoother.</li>"
        "<li><b>velocity-dependent resistance B</b> (N m per °/s): extra torque per unit speed "
        "the robot needed; rises with spasticity. Not measurable on a joint the exercise "
        "barely moves (under 5°).</li></ul>")
    title = f"Therapy session: patient {first.patient}, session {first.session}"
    return ("<!DOCTYPE html><html lang=en><head><meta charset='utf-8'>"
            f"<title>{_e(title)}</title><style>{STYLE}</style></head><body>"
            f"<h1>{_e(title)}</h1><p>{len(runs)} exercise(s): "
            + ", ".join(_e(r.exercise) for r in runs) + ".</p>"
            + "".join(sections) + glossary + "</body></html>\n")
