"""Validation of parameter changes, ROS-free (what arrives on the wire is checked beside the
loop: :mod:`exo_ilc_ros.core.loop.wire_input`).

:func:`validate_update` is the set-parameters path: merge the changes into the current
configuration, validate the whole, return the new Config or the ConfigError naming key and rule.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..errors import ConfigError
from . import schema
from .config import Config, unknown_parameter


def validate_update(current: Config, changes: Mapping[str, Any], live_only: bool = True,
                    node: str | None = None) -> Config | ConfigError:
    """The set-parameters path (what a node's on-set-parameters callback runs): ``changes``
    (dotted names) merged into ``current``, the whole validated. Returns the new Config
    (``current`` itself if nothing changes), or the ConfigError naming the key and the rule.
    With ``live_only``, a change to a parameter that is not ``live`` is refused (restart
    needed); with ``node``, a parameter that node does not declare is unknown. ROS's own
    parameters (``use_sim_time``) are ignored."""
    known = schema.BY_NAME if node is None else {p.name: p for p in schema.parameters_of(node)}
    filtered: dict[str, Any] = {}
    for name, value in changes.items():
        if name in schema.ROS_BUILTIN:
            continue
        spec = known.get(name)
        if spec is None:
            return ConfigError(str(name), unknown_parameter(str(name), known))
        if live_only and not spec.live:
            return ConfigError(name, "cannot change while the graph runs (restart the node "
                               "with the new value)")
        filtered[name] = value
    if not filtered:
        return current
    try:
        return current.replace(filtered)
    except ConfigError as exc:
        return exc
    except (TypeError, ValueError, OverflowError) as exc:  # defensive: never raise to ROS
        return ConfigError(next(iter(filtered)), f"invalid value: {exc}")
