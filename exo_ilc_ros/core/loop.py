"""Transitional: ``nodes/ilc_supervisor.py`` still imports ``record_from_samples`` from here;
it lives in :mod:`.trial` (with ``period_ns`` and ``sample_index``). Delete this module once the
supervisor imports it from ``core.trial``."""

from __future__ import annotations

from .trial import period_ns, record_from_samples, sample_index

__all__ = ["period_ns", "record_from_samples", "sample_index"]
