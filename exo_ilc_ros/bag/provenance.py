"""What a bag's ``metadata.yaml`` ``custom_data`` holds about its run, written and read back.

``custom_data`` is a flat ``{str: str}`` map (rosbag2's rule); structured values are JSON. With
the full effective config, a bag alone is enough to rerun its experiment
(``exo-ilc analyze BAG --config-out FILE`` then ``exo-ilc simulate --config FILE``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .. import __version__
from ..core.errors import ConfigError
from ..core.params import schema
from ..core.params.config import Config, load_config
from ..core.params.redact import redact

PREFIX = "exo_ilc_ros."
VERSION = PREFIX + "version"
RECORDED_BY = PREFIX + "recorded_by"
RUN_NAME = PREFIX + "run_name"
CONFIG_JSON = PREFIX + "config"
CONFIG_YAML = PREFIX + "config_yaml"
CONFIG_DIGEST = PREFIX + "config_digest"
MASS_UNCERTAINTY = PREFIX + "mass_uncertainty"
LAW = PREFIX + "law"
OPTIONS = PREFIX + "options"
PARAMETER_CHANGES = PREFIX + "parameter_changes"
TRIALS_COMPLETED = PREFIX + "trials_completed"
PATIENT = PREFIX + "patient"
EXERCISE = PREFIX + "exercise"
SESSION = PREFIX + "session"
PROFILE_VERSION = PREFIX + "profile_version"
PROFILE_STARTED_FROM = PREFIX + "profile_started_from"
EXERCISE_ORDER = PREFIX + "exercise_order"
"""The exercise's place in its session (1, 2, ...): the report lists them in that order."""

NOT_OPTIONS = frozenset({"wait_for_recorder"})
"""On/off parameters that do not change the results."""
RATE_PARAMETERS = ("control.period", "integration_step")
"""Numbers that decide how the paper is read (the sums (13) depend on the rate)."""


def interpretation_options(values: Mapping[str, Any]) -> dict[str, Any]:
    """Every option that picks a reading of the paper: each enumerated or on/off parameter of
    the schema (law, memory, error_sum, dynamics, q_filter.enabled, ...) and the rates."""
    names = [p.name for p in schema.PARAMETERS if (p.choices or p.kind is schema.Kind.BOOL)
             and p.name not in NOT_OPTIONS] + list(RATE_PARAMETERS)
    return {name: values[name] for name in names if name in values}


def provenance_data(config: Config, *, recorded_by: str,
                    run_name: str = "") -> dict[str, str]:
    """The ``custom_data`` entries of a run with ``config`` (its delta and law: the config's)."""
    values = config.values
    delta = float(values["mass_uncertainty"])
    values["mass_uncertainty"] = delta
    effective = config
    entries = {
        VERSION: __version__,
        RECORDED_BY: recorded_by,
        RUN_NAME: run_name,
        CONFIG_JSON: json.dumps(values, sort_keys=True),
        CONFIG_YAML: effective.to_ros_yaml(f"Effective config of run {run_name or '?'}, "
                                           f"recorded by {recorded_by}"),
        CONFIG_DIGEST: effective.digest(),
        MASS_UNCERTAINTY: repr(delta),
        LAW: str(values["law"]),
        OPTIONS: json.dumps(interpretation_options(values), sort_keys=True),
    }
    return {key: redact(value) for key, value in entries.items()}  # no credential recorded


@dataclass
class ParameterChange:
    """A parameter set while the graph ran, and the trial it took effect at."""

    node: str
    name: str
    value: Any
    stamp_ns: int
    during_trial: int | None
    """The trial running when the change arrived (None: between trials)."""
    effective_trial: int
    """The first trial run with the new value (changes apply at the next trial boundary)."""

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return {"node": self.node, "name": self.name, "value": self.value,
                "stamp_ns": self.stamp_ns, "during_trial": self.during_trial,
                "effective_trial": self.effective_trial}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> ParameterChange:
        """Inverse of :meth:`to_json`."""
        return cls(str(data["node"]), str(data["name"]), data["value"], int(data["stamp_ns"]),
                   None if data.get("during_trial") is None else int(data["during_trial"]),
                   int(data["effective_trial"]))


def parameter_changes_data(changes: Sequence[ParameterChange]) -> dict[str, str]:
    """The ``custom_data`` entry listing ``changes``."""
    return {PARAMETER_CHANGES: json.dumps([c.to_json() for c in changes])}


@dataclass
class Provenance:
    """The provenance a bag carries (every field None/empty when the bag has none, e.g. one
    recorded by ``ros2 bag record``)."""

    version: str | None = None
    recorded_by: str | None = None
    run_name: str | None = None
    config_values: dict[str, Any] | None = None
    config_yaml: str | None = None
    mass_uncertainty: float | None = None
    law: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    parameter_changes: list[ParameterChange] = field(default_factory=list)
    trials_completed: int | None = None
    problems: list[str] = field(default_factory=list)
    """What could not be parsed (the analysis goes on without it)."""

    @property
    def config(self) -> Config | None:
        """The effective config, validated against this version's schema (None if absent or
        no longer valid: see ``problems``). A bag recorded before parameters were added gets
        today's defaults for them, one that names parameters since removed loses those; both
        are said in ``problems``."""
        if self.config_values is None:
            return None
        values = dict(self.config_values)
        missing = [p.name for p in schema.PARAMETERS if p.name not in values]
        removed = sorted(k for k in values if k not in schema.BY_NAME)
        if missing:
            defaults = load_config()  # the shipped defaults
            values.update({name: defaults[name] for name in missing})
            self._note(f"config recorded without {', '.join(missing)} (added since "
                       f"{self.version or 'its version'}): today's defaults used for them")
        for key in removed:
            del values[key]
        if removed:
            self._note(f"config names {', '.join(removed)}, unknown to this version: left out")
        try:
            return Config(values, "bag custom_data")
        except ConfigError as exc:
            self._note(f"config does not validate: {exc}")
            return None

    def _note(self, problem: str) -> None:
        if problem not in self.problems:
            self.problems.append(problem)


def read_provenance(custom: Mapping[str, str] | None) -> Provenance:
    """Parse ``custom_data`` written by :func:`provenance_data` (tolerant: bad entries are
    listed in ``problems``)."""
    out = Provenance()
    if not custom:
        return out
    out.version = custom.get(VERSION)
    out.recorded_by = custom.get(RECORDED_BY)
    out.run_name = custom.get(RUN_NAME) or None
    out.config_yaml = custom.get(CONFIG_YAML)
    out.law = custom.get(LAW)

    def parse(key: str) -> Any:
        text = custom.get(key)
        if text is None:
            return None
        try:
            return json.loads(text)
        except ValueError as exc:
            out.problems.append(f"custom_data {key}: not JSON ({exc})")
            return None

    values = parse(CONFIG_JSON)
    out.config_values = values if isinstance(values, dict) else None
    delta = parse(MASS_UNCERTAINTY)
    out.mass_uncertainty = float(delta) if isinstance(delta, (int, float)) else None
    options = parse(OPTIONS)
    out.options = options if isinstance(options, dict) else {}
    trials = parse(TRIALS_COMPLETED)
    out.trials_completed = int(trials) if isinstance(trials, int) else None
    for item in parse(PARAMETER_CHANGES) or []:
        try:
            out.parameter_changes.append(ParameterChange.from_json(item))
        except (KeyError, TypeError, ValueError) as exc:
            out.problems.append(f"custom_data {PARAMETER_CHANGES}: bad entry {item!r} ({exc})")
    return out
