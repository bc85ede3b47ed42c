"""Counts as a reader says them: "1 version", "2 versions", "1 uncertainty"."""

from __future__ import annotations

IRREGULAR = {"uncertainty": "uncertainties", "process": "processes", "patient's": "patients'"}


def count_phrase(count: int, noun: str, plural: str = "") -> str:
    """``count`` and ``noun``, plural unless ``count`` is 1 (``plural`` for an irregular one)."""
    many = plural or IRREGULAR.get(noun) or noun + "s"
    return f"{count} {noun if count == 1 else many}"
