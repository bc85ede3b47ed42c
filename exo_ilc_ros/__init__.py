"""exo_ilc_ros: iterative learning control (sgnPDD^2 / PD) for a rehabilitation exoskeleton arm,
as a ROS-free core (:mod:`exo_ilc_ros.core`) under thin ROS 2 nodes (:mod:`exo_ilc_ros.nodes`)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from typing import Any

__version__ = "0.1.0"


def load_public(package: str, where: Mapping[str, str], name: str,
                namespace: dict[str, Any]) -> Any:
    """A package face's public ``name``, its module (``where[name]``, relative to ``package``)
    imported on first use and the value kept in the face's ``namespace`` (PEP 562: the faces'
    ``__getattr__``, so importing a face loads nothing heavy)."""
    module = where.get(name)
    if module is None:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(module, package), name)
    namespace[name] = value
    return value
