"""Bags of runs (ROS-free): writing them (:class:`BagWriter`, :func:`write_run`; MCAP with
``mcap``'s writer, every chunk, data section and summary under a CRC), checking them
(:func:`check_mcap`) and reading them back into per-trial data and the report's tables
(:func:`read_bag`).

Everything follows the wire contract of :mod:`exo_ilc_ros.wire.topics`; a bag's ``metadata.yaml``
``custom_data`` carries the run's provenance (:mod:`.provenance`).
"""

from __future__ import annotations

from typing import Any

from .. import load_public

_WHERE = {
    "BagError": ".errors",
    "BagReadError": ".errors",
    "BagWriteError": ".errors",
    "McapCheck": ".integrity",
    "check_mcap": ".integrity",
    "ParameterChange": ".provenance",
    "Provenance": ".provenance",
    "provenance_data": ".provenance",
    "read_provenance": ".provenance",
    "BagRun": ".run",
    "TrialData": ".run",
    "read_bag": ".reader",
    "trials_filed": ".storage",
    "run_name": ".run_writer",
    "unique_path": ".run_writer",
    "write_run": ".run_writer",
    "BagWriter": ".writer",
}
"""Public name -> the module that defines it (loaded on first use, PEP 562: importing the face
loads neither numba nor rclpy)."""

__all__ = sorted(_WHERE)


def __getattr__(name: str) -> Any:
    """Load a public name's module on first use (PEP 562)."""
    return load_public(__name__, _WHERE, name, globals())


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
