"""``exo-ilc clean``: list the bags and stores that runs left behind, with their sizes, and delete
old ones (``--keep N`` newest, ``--older-than AGE``); a dry run unless ``--yes``."""

from __future__ import annotations

import argparse
import os
import re
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError

DEFAULT_RUNS_DIR = ".exo-ilc/runs"
"""Where ``exo-ilc run`` puts its per-invocation stores (``<date-time>-<pid>/store``)."""
IN_USE_SECONDS = 120.0
"""An entry written to this recently may belong to a run still going (:func:`in_use`): never
deleted."""
_UNITS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0, "w": 7 * 86400.0}


@dataclass
class Entry:
    """One bag or one run's store directory."""

    kind: str  # "bag" or "store"
    path: Path
    size: int
    modified: float  # newest mtime of anything inside
    delete: bool = False
    in_use: bool = False


def parse_age(text: str) -> float:
    """``7d``, ``12h``, ``30m``, ``90s``, ``2w`` or a number of days, in seconds."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d*)?)\s*([smhdw]?)\s*", text)
    if match is None:
        raise ConfigError("--older-than", f"{text!r} is not an age such as 7d, 12h, 30m or 2w")
    return float(match.group(1)) * _UNITS[match.group(2) or "d"]


def register(sub: Any) -> None:
    """Add the sub-command."""
    parser = sub.add_parser(
        "clean", help="list the bags and stores of past runs with their sizes; delete old ones",
        description="Every `exo-ilc run` keeps a bag (bags/<run-name>/) and a store "
        f"({DEFAULT_RUNS_DIR}/<date-time>-<pid>/). This lists them, newest first, with sizes "
        "and dates, and with --keep and/or --older-than marks the older ones for deletion: a "
        "dry run unless --yes. A run still going (its bag still recording, its process "
        "alive, written in the last two minutes) is never deleted; stores named with --store "
        "elsewhere are not touched.")
    parser.add_argument("--bag-dir", default="bags", metavar="DIR",
                        help="where the bags are (default: bags)")
    parser.add_argument("--runs-dir", default=DEFAULT_RUNS_DIR, metavar="DIR",
                        help=f"where the runs' stores are (default: {DEFAULT_RUNS_DIR})")
    parser.add_argument("--keep", type=int, metavar="N",
                        help="keep the N newest bags and the N newest stores, delete the rest")
    parser.add_argument("--older-than", metavar="AGE",
                        help="delete entries last written more than AGE ago (7d, 12h, 30m, "
                        "2w; a bare number is days); with --keep, the N newest stay anyway")
    parser.add_argument("--only", choices=("bags", "stores"),
                        help="look at bags or stores only (default: both)")
    parser.add_argument("--yes", action="store_true",
                        help="really delete (default: only show what would be deleted)")
    parser.set_defaults(func=clean)


def _measure(path: Path) -> tuple[int, float]:
    """Total size in bytes and newest mtime of a directory tree."""
    size, newest = 0, path.stat().st_mtime
    for item in path.rglob("*"):
        try:
            stat = item.lstat()
        except OSError:  # removed meanwhile
            continue
        newest = max(newest, stat.st_mtime)
        if item.is_file() and not item.is_symlink():
            size += stat.st_size
    return size, newest


def _is_bag(path: Path) -> bool:
    """A rosbag2 bag directory, or a recording killed before its first trial was filed."""
    return (path / "metadata.yaml").is_file() or (path / ".splits").is_dir() or \
        any(path.glob("*.mcap")) or any(path.glob("*.db3"))


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def in_use(entry: Entry, now: float) -> bool:
    """``entry`` may belong to a run still going: written in the last :data:`IN_USE_SECONDS`
    and not finished. A bag is finished once it has no ``.splits/`` (its writer moves each
    finished file out of it and removes it on close); a run's store
    (``<date-time>-<pid>``) once its process is gone."""
    from ..bag.writer import SPLITS_DIR

    if now - entry.modified >= IN_USE_SECONDS:
        return False
    if entry.kind == "bag":
        return (entry.path / SPLITS_DIR).is_dir()
    match = re.fullmatch(r"\d{8}-\d{6}-(\d+)", entry.path.name)
    return match is None or _process_alive(int(match.group(1)))


def find_entries(bag_dir: Path, runs_dir: Path, only: str | None = None) -> list[Entry]:
    """Bags under ``bag_dir`` and run directories under ``runs_dir``, newest first per kind."""
    entries: list[Entry] = []
    kinds = [("bag", bag_dir, _is_bag), ("store", runs_dir, lambda p: p.is_dir())]
    for kind, root, accept in kinds:
        if (only is not None and only != kind + "s") or not root.is_dir():
            continue
        found = [Entry(kind, path, *_measure(path)) for path in sorted(root.iterdir())
                 if path.is_dir() and not path.is_symlink() and accept(path)]
        entries += sorted(found, key=lambda e: e.modified, reverse=True)
    return entries


def mark(entries: list[Entry], keep: int | None, older_than: float | None,
         now: float | None = None) -> None:
    """Set ``delete`` on the entries beyond the ``keep`` newest of their kind and/or last
    written more than ``older_than`` seconds ago; never on one in use (:func:`in_use`)."""
    now = time.time() if now is None else now
    rank: dict[str, int] = {}
    for entry in entries:  # newest first per kind
        rank[entry.kind] = rank.get(entry.kind, 0) + 1
        beyond_keep = keep is None or rank[entry.kind] > keep
        old = older_than is None or now - entry.modified > older_than
        entry.in_use = in_use(entry, now)
        entry.delete = beyond_keep and old and not entry.in_use and \
            (keep is not None or older_than is not None)


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"  # pragma: no cover


def clean(args: argparse.Namespace) -> int:
    """List, mark, and (with --yes) delete."""
    if args.keep is not None and args.keep < 0:
        raise ConfigError("--keep", f"{args.keep} must be >= 0")
    older = parse_age(args.older_than) if args.older_than is not None else None
    entries = find_entries(Path(args.bag_dir), Path(args.runs_dir), args.only)
    mark(entries, args.keep, older)
    selecting = args.keep is not None or older is not None
    for kind, root in (("bag", args.bag_dir), ("store", args.runs_dir)):
        group = [e for e in entries if e.kind == kind]
        if args.only is not None and args.only != kind + "s":
            continue
        print(f"{kind}s in {root}: {len(group)}, {_size(sum(e.size for e in group))}")
        for e in group:
            when = time.strftime("%Y-%m-%d %H:%M", time.localtime(e.modified))
            state = ("delete" if e.delete else "in use" if e.in_use else "keep") \
                if selecting else ""
            print(f"  {when}  {_size(e.size):>10}  {state:<7} {e.path}")
    doomed = [e for e in entries if e.delete]
    freed = _size(sum(e.size for e in doomed))
    if not selecting:
        print("nothing selected: add --keep N and/or --older-than AGE to choose what to delete")
        return 0
    if not doomed:
        print("nothing to delete")
        return 0
    if not args.yes:
        print(f"would delete {len(doomed)} entries, {freed}; run again with --yes to delete")
        return 0
    for e in doomed:
        shutil.rmtree(e.path)
    print(f"deleted {len(doomed)} entries, {freed}")
    return 0
