"""Checks of command-line values where they are given (argparse ``type=``), and a config built
from ``--config`` and flags that says which flag broke a rule.

Every check raises :class:`argparse.ArgumentTypeError`, so argparse prints
``exo-ilc CMD: error: argument --FLAG: RULE, got VALUE`` and exits with 2: the message names the
flag, the value and the rule. A flag that sets a config parameter is checked with that
parameter's rule from :mod:`..core.schema` (the rule lives there once; ``simulate``, ``run``,
``tune`` ... give the same message for the same value).
"""

from __future__ import annotations

import argparse
import math
import re
import shutil
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..core.errors import ConfigError, ExoIlcError
from ..core.params import schema
from ..core.params.config import Config, load_config, scenario_names, scenario_path
from ..core.params.redact import hide_password
from ..orchestration.launcher import MAX_DOMAIN_ID

FIGURE_SUFFIXES = (".png", ".pdf", ".svg", ".svgz", ".jpg", ".jpeg", ".tif", ".tiff", ".webp",
                   ".eps", ".ps", ".pgf", ".raw", ".rgba")
"""File types matplotlib writes (the figure's format comes from the suffix)."""


class FlagError(ExoIlcError):
    """A command-line value breaks a rule only visible once the config is known (e.g. a cut-off
    above the Nyquist frequency of the config's control period)."""

    def __init__(self, flag: str, value: Any, rule: str, parameter: str = "") -> None:
        self.flag = flag
        self.value = value
        self.rule = rule
        why = f" (the rule of parameter {parameter})" if parameter else ""
        super().__init__(f"argument {flag}: {rule}, got {value!r}{why}")


def _number(text: str) -> Any:
    """``text`` as an int, else a float, else itself (the schema's coerce then names the type)."""
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def parameter(name: str, extra: Callable[[Any], str | None] | None = None
              ) -> Callable[[str], Any]:
    """argparse type: a value of schema parameter ``name``, checked with the schema's rule
    (and ``extra``, a rule of the command itself: a message, or None when the value is fine)."""
    param = schema.BY_NAME[name]

    def convert(text: str) -> Any:
        value = _number(text) if param.kind in (schema.Kind.DOUBLE, schema.Kind.INTEGER) \
            else text
        try:
            value = schema.coerce(param, value)
            schema.check_value(param, value, 0)
        except ConfigError as exc:  # the schema's rule, with the value as typed
            rule = re.sub(r"[,;] got .*$", "", exc.rule, flags=re.DOTALL)
            raise argparse.ArgumentTypeError(f"{rule}, got {text!r} (the rule of parameter "
                                             f"{name})") from None
        problem = extra(value) if extra is not None else None
        if problem:
            raise argparse.ArgumentTypeError(f"{problem}, got {text!r}")
        return value

    convert.__name__ = name
    return convert


MAX_MASS_UNCERTAINTY = 1.0
"""A --mass-uncertainty above this (+100 %: twice the model's masses) is taken for a percentage
typed as a number and refused."""


def plausible_fraction(value: Any) -> str | None:
    """The rule of ``--mass-uncertainty`` beyond the schema's: a fraction, not a percentage."""
    if value <= MAX_MASS_UNCERTAINTY:
        return None
    return (f"is a fraction of the model's masses (0.10 = 10 %) and at most "
            f"{MAX_MASS_UNCERTAINTY:g} (+100 %); {value:g} would make every mass "
            f"{1 + value:g} times the model's: did you mean {value / 100:g} ({value:g} %)?")


def mass_uncertainty(text: str) -> float:
    """argparse type of every ``--mass-uncertainty``: the schema's rule and
    :func:`plausible_fraction`."""
    return float(parameter("mass_uncertainty", plausible_fraction)(text))


def integer(minimum: int | None = None, maximum: int | None = None,
            why: str = "") -> Callable[[str], int]:
    """argparse type: an integer in [minimum, maximum] (either end open when None)."""
    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            rule = f"from {minimum} to {maximum}" if minimum is not None and maximum is not None \
                else f">= {minimum}" if minimum is not None else f"<= {maximum}"
            raise argparse.ArgumentTypeError(f"must be an integer {rule}{why}, got {text!r}")
        return value

    convert.__name__ = "integer"
    return convert


def number(minimum: float | None = None, strictly_positive: bool = False,
           why: str = "") -> Callable[[str], float]:
    """argparse type: a finite number, >= minimum or > 0."""
    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be finite (no NaN or inf), got {text!r}")
        if strictly_positive and value <= 0.0:
            raise argparse.ArgumentTypeError(f"must be > 0{why}, got {text!r}")
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum:g}{why}, got {text!r}")
        return value

    convert.__name__ = "number"
    return convert


def domain_id(text: str) -> int:
    """argparse type: a ROS domain id."""
    return integer(0, MAX_DOMAIN_ID, " (a ROS domain id; 0-101 is safe on Linux)")(text)


def nonempty(text: str) -> str:
    """argparse type: a string that is not empty (or only blanks)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"must not be empty, got {text!r}")
    return text


def input_file(text: str) -> str:
    """argparse type: an existing file to read."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"must be a file, got the directory {text!r}")
    if not path.is_file():
        raise argparse.ArgumentTypeError(f"no such file: {text!r}")
    return text


def output_file(suffixes: tuple[str, ...] = (), make_parents: bool = False,
                what: str = "") -> Callable[[str], str]:
    """argparse type: a file to write: not a directory, its directory there (or made by the
    writer when ``make_parents``), and one of ``suffixes`` (any when empty)."""
    def convert(text: str) -> str:
        path = Path(text)
        if not text or path.is_dir():
            raise argparse.ArgumentTypeError(f"must be a file name, got the directory {text!r}"
                                             if text else "must be a file name, got ''")
        if suffixes and path.suffix.lower() not in suffixes:
            raise argparse.ArgumentTypeError(
                f"must end in {', '.join(suffixes)}{what}, got {text!r}")
        parent = next((p for p in path.absolute().parents if p.exists()), None)
        if parent is not None and not parent.is_dir():
            raise argparse.ArgumentTypeError(f"{parent} is not a directory, got {text!r}")
        if not make_parents and not path.absolute().parent.is_dir():
            raise argparse.ArgumentTypeError(f"directory {str(path.parent)!r} does not exist, "
                                             f"got {text!r}")
        return text

    convert.__name__ = "file"
    return convert


def figure_file(text: str) -> str:
    """argparse type: a figure to write (format from the suffix) in an existing directory."""
    return output_file(FIGURE_SUFFIXES, what=" (a figure format)")(text)


def figure_path(text: str) -> str:
    """argparse type: a figure written by :func:`..figures.save` (which makes the directory)."""
    return output_file(FIGURE_SUFFIXES, make_parents=True, what=" (a figure format)")(text)


def json_file(text: str) -> str:
    """argparse type: a JSON (or CSV, YAML ...) file to write."""
    return output_file()(text)


def directory(text: str) -> str:
    """argparse type: a directory to write into (made if missing), not an existing file."""
    if not text:
        raise argparse.ArgumentTypeError("must be a directory name, got ''")
    path = Path(text)
    existing = next((p for p in (path, *path.parents) if p.exists()), None)
    if existing is not None and not existing.is_dir():
        raise argparse.ArgumentTypeError(f"must be a directory, but {str(existing)!r} is a "
                                         f"file, got {text!r}")
    return text


def scenario(text: str) -> str:
    """argparse type: a virtual-patient scenario, a shipped name (config/scenarios/) or a YAML
    file; returns the file's path (its keys are checked when the config is loaded)."""

    try:
        return str(scenario_path(text))
    except ConfigError:
        if text.endswith((".yaml", ".yml")) or "/" in text:
            raise argparse.ArgumentTypeError(f"no such scenario file, got {text!r}") from None
        raise argparse.ArgumentTypeError(
            f"unknown scenario; shipped: {', '.join(scenario_names())} (or a YAML file), "
            f"got {text!r}") from None


CONFIG_HELP = "ROS parameter YAML laid over the shipped config/exo_ilc.yaml (any subset of keys)"
"""The help of ``--config`` where a command says nothing more of it."""


def add_config_argument(parser: argparse.ArgumentParser, help: str = CONFIG_HELP) -> None:
    """``--config FILE``: a ROS parameter YAML laid over the shipped config (every command that
    reads a config declares it here; ``help`` says what the command does with it)."""
    parser.add_argument("--config", type=input_file, help=help)


def add_mass_uncertainty_argument(parser: argparse.ArgumentParser, help: str,
                                  default: list[float] | None = None) -> None:
    """``--mass-uncertainty D [D ...]``: plant mass uncertainties, each checked by
    :func:`mass_uncertainty` (every command that takes them declares them here)."""
    parser.add_argument("--mass-uncertainty", type=mass_uncertainty, nargs="+", metavar="D",
                        default=default, help=help)


def add_scenario_argument(parser: argparse.ArgumentParser) -> None:
    """``--scenario NAME|FILE [NAME|FILE ...]``: virtual patients (or any overlays) laid over
    ``--config``, in order."""
    parser.add_argument("--scenario", type=scenario, metavar="NAME|FILE", nargs="+",
                        help="virtual patient laid over --config: a shipped scenario "
                        "(ideal, sensor, friction, spastic, voluntary, realistic, learning; "
                        "config/scenarios/) or a ROS parameter YAML of the same layout; "
                        "several are laid over in order (e.g. config/robust.yaml friction)")


def write_output(text: str, out: str | None) -> None:
    """``text`` into the file ``out`` (``--out``; says so), or to standard output."""
    if out:
        Path(out).write_text(text)
        print(f"wrote {out}")
    else:
        print(text, end="")


def config_with_flags(path: str | None, flags: Mapping[str, tuple[str, Any]],
                      overlays: Sequence[str] = ()) -> Config:
    """The shipped config, ``path`` (``--config``) and ``overlays`` (``--scenario``) each
    validated whole, then the flags' values ``{parameter: (flag, value)}``, then the period
    ``control.period_rule`` gives (:func:`~exo_ilc_ros.core.loop.rate.with_control_rate`); a
    rule the flags break (e.g. one between parameters) names the flag and its value, not the
    file."""
    from ..core.loop.rate import with_control_rate  # numba's arm model: not at CLI start

    config = load_config(path, overlays=overlays)
    values = {name: value for name, (_, value) in flags.items()}
    if not values:
        return with_control_rate(config)
    try:
        return with_control_rate(config.replace(values))
    except ConfigError as exc:
        if exc.key in flags:
            flag, value = flags[exc.key]
            raise FlagError(flag, value, exc.rule, exc.key) from None
        given = ", ".join(f"{flag} {value}" for flag, value in flags.values())
        raise ConfigError(exc.key, f"{exc.rule} (with {given})", exc.source) from None


def storage(text: str) -> str:
    """argparse type: an Optuna storage, a journal file path or an RDB URL whose SQLAlchemy
    dialect and database driver are installed (``tuning.check_database_driver``, checked
    without connecting)."""
    if "://" not in text:
        return output_file(make_parents=True)(text)
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    from ..analysis.tuning import TuningError, check_database_driver

    try:
        check_database_driver(text)
    except TuningError as exc:
        rule = str(exc).removeprefix(f"--storage {text}: ")
        raise argparse.ArgumentTypeError(f"{rule}, got {hide_password(text)!r}") from None
    try:
        url = make_url(text)
    except ArgumentError:  # pragma: no cover - check_database_driver parsed it already
        return text
    if url.get_backend_name() == "sqlite" and url.database not in (None, "", ":memory:"):
        output_file(make_parents=False)(url.database)  # sqlite makes the file, not its directory
    return text


def shown_command() -> str:
    """How to type ``exo-ilc`` here, for the commands we print: ``exo-ilc`` when that name on
    PATH is this program, else the path of the running script (``.venv/bin/exo-ilc`` in a
    checkout whose venv is not activated)."""
    script = Path(sys.argv[0]) if sys.argv and sys.argv[0] else None
    on_path = shutil.which("exo-ilc")
    if script is None or script.name != "exo-ilc":
        return "exo-ilc" if on_path else f"{Path(sys.executable).name} -m exo_ilc_ros.cli.main"
    if on_path and Path(on_path).resolve() == script.resolve():
        return "exo-ilc"
    try:
        return str(script.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(script.resolve())


def seed(text: str) -> int:
    """argparse type: a random seed numpy accepts, also after adding a worker's number."""
    return integer(0, 2**31 - 1, " (a random seed)")(text)


def at_least_two_trials(value: Any) -> str | None:
    """``exo-ilc tune``'s own rule on --trials (a score needs a trial after the first)."""
    return "must be >= 2 (tuning scores the trials after trial 1)" if value < 2 else None


def yaml_out(text: str) -> str:
    """argparse type: a ROS parameter YAML to write (its directory made if missing)."""
    return output_file((".yaml", ".yml"), make_parents=True, what=" (a ROS parameter YAML)")(text)
