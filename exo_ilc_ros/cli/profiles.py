"""``exo-ilc profiles``: list, show, export and roll back patients' learned profiles."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ..analysis.wording import count_phrase
from ..core.persistence.profiles import ProfileBook, export_profile
from .arguments import directory, integer, output_file


def register(sub: Any) -> None:
    """Add the sub-command and its actions."""
    parser = sub.add_parser(
        "profiles", help="list, show, export or roll back patients' learned profiles",
        description="A profile is the feed-forward a patient's sessions learned for one "
        "exercise, versioned (one version per session) with its provenance. See "
        "docs/therapy.md.")
    parser.add_argument("--profiles", metavar="DIR", type=directory,
                        help="profiles root (default: $EXO_ILC_PROFILES or .exo-ilc/profiles)")
    actions = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    listing = actions.add_parser("list", help="patients, or one patient's exercises")
    listing.add_argument("patient", nargs="?", help="list this patient's exercises and versions")
    show = actions.add_parser("show", help="every version of a patient's exercise profile")
    show.add_argument("patient")
    show.add_argument("exercise")
    export = actions.add_parser("export", help="a version to .json or .npz")
    export.add_argument("patient")
    export.add_argument("exercise")
    export.add_argument("out", type=output_file((".json", ".npz")), help="file to write "
                        "(.json: provenance and the feed-forward as lists; .npz: arrays)")
    export.add_argument("--version", type=integer(1), help="default: the current version")
    rollback = actions.add_parser("rollback", help="make an earlier version the current one "
                                  "(the next session starts from it; nothing is deleted)")
    rollback.add_argument("patient")
    rollback.add_argument("exercise")
    rollback.add_argument("version", type=integer(1))
    parser.set_defaults(func=run)


def _version_line(entry: dict[str, Any], current: int | None) -> str:
    from ..analysis.therapy import DEGREES
    mark = "*" if entry["version"] == current else " "
    error = " ".join(f"{x * DEGREES:.3g}" for x in entry.get("final_max_abs_error", []))
    share = (entry.get("metrics") or {}).get("patient_share_total")
    share_text = "" if share is None else f", patient share {100.0 * share:.3g} %"
    return (f" {mark} v{entry['version']:<3} {entry.get('updated', entry.get('created', '?'))}  "
            f"{entry.get('status', '?'):<11} {count_phrase(entry.get('trials', 0), 'trial'):>10} "
            f"({entry.get('trials_total', 0)} in all), law {entry.get('law', '?')}"
            f"{', assist-as-needed' if entry.get('assist_as_needed') else ''}, "
            f"final max |e| {error} deg{share_text}, from "
            f"{'v' + str(entry['started_from']) if entry.get('started_from') else 'zero'}"
            f"{_not_included(entry)}, config {entry.get('config_digest', '?')}"
            f"{_resumed(entry)}")


def _resumed(entry: dict[str, Any]) -> str:
    """', session S, resumed after 2 trials' for a session stopped and resumed (and, while
    unfinished, the session id ``exo-ilc run --resume`` takes)."""
    resumed = entry.get("resumed") or []
    if not resumed and entry.get("status") == "complete":
        return ""
    after = ", ".join(str(r.get("after_trials")) for r in resumed)
    return f", session {entry.get('session') or '?'}" + \
        (f", resumed after {after} trials" if resumed else "")


def _not_included(entry: dict[str, Any]) -> str:
    """' (without v3, v4: begun before it by other sessions)' when the session did not start
    from every version before its own (concurrent sessions, or versions rolled back over)."""
    others = entry.get("not_included") or []
    if not others:
        return ""
    return f" (without {', '.join(f'v{v}' for v in others)}: begun before it, not learned from)"


def run(args: argparse.Namespace) -> int:
    """Do the action."""
    from ..analysis.therapy import DEGREES
    from ..core.programs.therapy import profiles_root
    book = ProfileBook(profiles_root(args.profiles))
    if args.action == "list":
        if args.patient is None:
            patients = book.patients()
            if not patients:
                print(f"no profiles under {book.root}")
            for patient in patients:
                print(f"{patient}: {', '.join(book.exercises(patient))}")
            return 0
        for exercise in book.exercises(args.patient):
            index = book.require_index(args.patient, exercise)
            entry = index["versions"][index["current"] - 1] if index["current"] else None
            versions = count_phrase(len(index["versions"]), "version")
            print(f"{exercise}: {versions}, current v{index['current']}"
                  + ("" if entry is None else f" ({entry.get('trials_total', 0)} trials "
                     f"learned, {entry.get('status')})"))
        return 0
    if args.action == "show":
        index = book.require_index(args.patient, args.exercise)
        print(f"patient {args.patient}, exercise {args.exercise} "
              f"({book.directory(args.patient, args.exercise)}); * current")
        for entry in index["versions"]:
            print(_version_line(entry, index["current"]))
        profile = book.load(args.patient, args.exercise)
        peak = " ".join(f"{x * DEGREES:.3g}"
                        for x in np.max(np.abs(profile.feedforward), axis=0))
        print(f"current v{profile.version}: {profile.feedforward.shape[0]} samples, "
              f"max |u_ff| per joint {peak} deg/s^2 (sha256 checked)")
        return 0
    if args.action == "export":
        profile = book.load(args.patient, args.exercise, args.version)
        print(f"wrote {export_profile(profile, args.out)} (v{profile.version})")
        return 0
    index = book.rollback(args.patient, args.exercise, args.version)
    print(f"patient {args.patient}, exercise {args.exercise}: current version is now "
          f"v{index['current']} (of {len(index['versions'])}); the next session starts from it")
    return 0
