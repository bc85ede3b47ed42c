"""``exo-ilc report BAG... --html report.html``: the session report a therapist reads."""

from __future__ import annotations

import argparse
import html
import sys
from pathlib import Path
from typing import Any
from urllib.parse import quote

from ..core.persistence.files import write_bytes_atomic
from ..core.persistence.profiles import ProfileBook
from .analyze import bag_paths
from .arguments import directory, output_file


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "report", help="the therapy session report (one HTML page per session)",
        description="Read the bags of a therapy session (exo-ilc simulate/run --patient ... "
        "--bag) and write one self-contained HTML page per session: per exercise the error "
        "and the assistance over the trials, the patient's share of the work, safety events "
        "and the comparison with the patient's earlier sessions (from --profiles).")
    parser.add_argument("bags", nargs="+", metavar="BAG", help="bag directories")
    parser.add_argument("--html", required=True, type=output_file((".html", ".htm")),
                        metavar="OUT.html", help="the page to write; with bags of several "
                        "sessions one page each, OUT_<patient>_<session>.html, and OUT.html "
                        "the index linking them")
    parser.add_argument("--profiles", metavar="DIR", type=directory,
                        help="profiles root, for the comparison with earlier sessions "
                        "(default: $EXO_ILC_PROFILES or .exo-ilc/profiles, if it exists)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Read, group by session, render and write."""
    from ..analysis.session_report import (
        exercise_run,
        group_by_session,
        identification_trends,
        identified_history,
        render_session,
    )
    from ..bag import BagError, read_bag
    from ..core.programs.therapy import profiles_root

    runs = []
    for path in bag_paths(args.bags, "report"):  # bags/* also matches bags/README.md
        try:
            runs.append(exercise_run(read_bag(path)))
        except BagError as exc:
            print(f"exo-ilc report: error: {path}: {exc}", file=sys.stderr)
            return 2
    root = profiles_root(args.profiles)
    book = ProfileBook(root) if root.is_dir() else None
    sessions = group_by_session(runs)
    out = Path(args.html)
    pages: list[tuple[str, str, Path, list[str]]] = []
    for (patient, session), members in sessions.items():
        target = out if len(sessions) == 1 else \
            out.with_name(f"{out.stem}_{patient}_{session}{out.suffix}")
        pages.append((str(patient), str(session), target, [str(r.exercise) for r in members]))
        page = render_session(members, book)
        write_bytes_atomic(target, page.encode("utf-8"))
        target.chmod(0o644)  # a page to share (the atomic temp file is private)
        print(f"wrote {target} (patient {patient}, session {session}, "
              f"{len(members)} exercise(s))")
        for run in members:  # the identified patient's trend across sessions
            for line in identification_trends(identified_history(run, book), run.joint_names):
                print(f"  {run.exercise}: {line}")
    if len(pages) > 1:  # the file asked for: the index of the sessions' pages
        write_bytes_atomic(out, session_index(pages).encode("utf-8"))
        out.chmod(0o644)
        print(f"wrote {out} (the index of {len(pages)} sessions' pages)")
    return 0


def session_index(pages: list[tuple[str, str, Path, list[str]]]) -> str:
    """A self-contained HTML page linking each session's page (patient, session, target,
    exercises), by its name beside the index."""
    rows = "\n".join(
        f'<tr><td>{html.escape(patient)}</td><td>{html.escape(session)}</td><td><a href="'
        f'{html.escape(quote(target.name))}">{html.escape(target.name)}</a></td>'
        f"<td>{html.escape(', '.join(exercises))}</td></tr>"
        for patient, session, target, exercises in pages)
    return ('<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            "<title>Therapy sessions</title></head><body><h1>Therapy sessions</h1>"
            "<p>One report page per session, beside this one.</p><table><thead><tr>"
            "<th>patient</th><th>session</th><th>report</th><th>exercises</th></tr></thead>"
            f"<tbody>\n{rows}\n</tbody></table></body></html>\n")
