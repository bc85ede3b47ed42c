"""Bags of runs (ROS-free): writing them (:class:`BagWriter`, :func:`write_run`; MCAP with
``mcap``'s writer, every chunk, data section and summary under a CRC), checking them
(:func:`check_mcap`) and reading them back into per-trial data and the report's tables
(:func:`read_bag`).

Everything follows the wire contract of :mod:`exo_ilc_ros.wire.topics`; a bag's ``metadata.yaml``
``custom_data`` carries the run's provenance (:mod:`.provenance`).
"""

from __future__ import annotations

from .errors import BagError, BagReadError, BagWriteError
from .integrity import McapCheck, check_mcap
from .provenance import ParameterChange, Provenance, provenance_data, read_provenance
from .reader import BagRun, TrialData, read_bag, trials_filed
from .run_writer import run_name, unique_path, write_run
from .writer import BagWriter

__all__ = [
    "BagError",
    "BagReadError",
    "BagRun",
    "BagWriteError",
    "BagWriter",
    "McapCheck",
    "ParameterChange",
    "Provenance",
    "TrialData",
    "check_mcap",
    "provenance_data",
    "read_bag",
    "read_provenance",
    "run_name",
    "trials_filed",
    "unique_path",
    "write_run",
]
