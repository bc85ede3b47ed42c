"""Error types of the core, each raised with a message naming what was wrong and where."""

from __future__ import annotations


class ExoIlcError(Exception):
    """Base class of every error raised by exo_ilc_ros."""


class ConfigError(ExoIlcError):
    """A configuration value breaks a rule of the parameter schema.

    ``key`` is the dotted parameter name (``schedule.position.threshold_low``), ``rule`` the rule it
    breaks, ``source`` the file (or other origin) the value came from, when known.
    """

    def __init__(self, key: str, rule: str, source: str | None = None) -> None:
        self.key = key
        self.rule = rule
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{key}: {rule}")


class ModelError(ExoIlcError):
    """The arm model cannot be built or evaluated (e.g. a singular metric tensor)."""


class SafetyError(ExoIlcError):
    """A safety rule would be broken (e.g. a learning law produced a non-finite feed-forward)."""


class StoreError(ExoIlcError):
    """The store of learned data cannot be read, written or resumed (says which file and why)."""


class ProfileError(ExoIlcError):
    """A patient's learned profile cannot be found, read, trusted or used with this config
    (says which patient, exercise, version or file, and why)."""
