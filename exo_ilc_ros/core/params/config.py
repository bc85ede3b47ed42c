"""Loading, validating and writing the ROS-parameter YAML that configures everything.

The shipped ``config/exo_ilc.yaml`` holds every parameter's value; a user file (same layout,
any subset of keys) and command-line overrides are laid over it, then the whole is checked
against :mod:`schema`. Nodes read the same files as ROS parameters.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import os
import re
import sys
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

from ..errors import ConfigError
from . import schema
from .urdf_xml import (
    UrdfError,
    UrdfJoint,
    UrdfKeyError,
    chain_joints,
    read_urdf_text,
    resolve_package_uri,
    resolved_chain,
)

PACKAGE = "exo_ilc_ros"
DEFAULT_CONFIG_NAME = "exo_ilc.yaml"


def config_dir() -> Path:
    """Where the shipped configs are: the ament share directory of an installed package, the
    ``config/`` of a source checkout or editable install, or ``<prefix>/share`` of a pip install.
    ``EXO_ILC_CONFIG_DIR`` overrides all three."""
    looked = []
    for candidate in _config_dir_candidates():
        if (candidate / DEFAULT_CONFIG_NAME).is_file():
            return candidate
        looked.append(candidate)
    raise ConfigError("config", "cannot find the shipped config/exo_ilc.yaml; looked in "
                      + ", ".join(str(c) for c in looked))


def _config_dir_candidates() -> Iterator[Path]:
    """:func:`config_dir`'s places in order, the ament index asked only when the checkout has
    no config (importing it costs every command's start)."""
    override = os.environ.get("EXO_ILC_CONFIG_DIR")
    if override:
        yield Path(override)
    yield Path(__file__).resolve().parents[3] / "config"  # source / editable
    try:
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory(PACKAGE)) / "config"
    except Exception:  # not installed through ament, or AMENT_PREFIX_PATH unset
        pass
    else:
        yield share
    yield Path(sys.prefix) / "share" / PACKAGE / "config"


def default_config_path() -> Path:
    """The shipped ``exo_ilc.yaml`` (the paper's experiment under the canonical reading)."""
    return config_dir() / DEFAULT_CONFIG_NAME


class RosYamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader that also reads ``1e-5`` as a float, as rcl's parameter parser
    (YAML 1.2) does; PyYAML alone (YAML 1.1) would make it the string '1e-5'."""


class FastRosYamlLoader(getattr(yaml, "CSafeLoader", yaml.SafeLoader)):  # type: ignore[misc]
    """:class:`RosYamlLoader` over libyaml's parser when PyYAML has it (10x faster: the shipped
    config took 0.05-0.15 s of every command's start with the pure-Python one); the same
    resolvers and constructor, so the same values."""


ROS_FLOAT = re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")
"""A float in exponent notation without a dot (``1e-5``): YAML 1.2's, not YAML 1.1's."""
for _loader in (RosYamlLoader, FastRosYamlLoader):
    _loader.add_implicit_resolver("tag:yaml.org,2002:float", ROS_FLOAT, list("-+0123456789"))


def load_ros_yaml(text: str) -> Any:
    """A ROS parameter YAML document (or ``-p`` value) read as rcl types it. A document libyaml
    refuses is read again by PyYAML's own parser, so an error says what PyYAML says."""
    try:
        return yaml.load(text, Loader=FastRosYamlLoader)
    except yaml.YAMLError:
        return yaml.load(text, Loader=RosYamlLoader)


def unknown_parameter(key: str, known: Iterable[str] | None = None) -> str:
    """The rule an unknown parameter breaks, with the closest known name (``known``; default:
    every parameter) when one is close: ``unknown parameter; did you mean 'law'?``."""
    close = difflib.get_close_matches(key, list(schema.BY_NAME if known is None else known),
                                      n=1, cutoff=0.75)
    return "unknown parameter" + (f"; did you mean {close[0]!r}?" if close else "")


def _is_section(key: Any, body: Any) -> bool:
    """A top-level key of a ROS parameter YAML that names a node section."""
    name = str(key).lstrip("/") if key != schema.SHARED else key
    return name in schema.SECTIONS or (isinstance(body, dict) and "ros__parameters" in body)


def flatten_ros_yaml(document: Any, source: str) -> dict[str, Any]:
    """Flat ``{dotted name: value}`` from a ROS parameter YAML (``node: ros__parameters: ...``),
    or from a file of parameters only (no node section at all: ``max_trials: 20``,
    ``model: {gravity: 9.81}``; each goes to its node's section).

    Unknown sections and unknown keys are errors naming the file and key (with the closest
    known name); a key in the wrong section is an error too (it would silently not reach its
    node under ROS), and so is a parameter beside node sections.
    """
    if document is None:
        return {}
    if not isinstance(document, dict):
        raise ConfigError("<file>", "must be a mapping of node names to ros__parameters",
                          source)
    if not any(_is_section(key, body) for key, body in document.items()):
        return _flat_parameters(document, source)
    flat: dict[str, Any] = {}
    for section, body in document.items():
        name = str(section).lstrip("/") if section != schema.SHARED else section
        if name not in schema.SECTIONS:
            params = dict(flatten_tree({str(section): body}))
            known = [k for k in params if k in schema.BY_NAME]
            if known:
                raise ConfigError(str(section), f"is a parameter, not a node section: put "
                                  f"{known[0]} under {schema.BY_NAME[known[0]].section}: "
                                  "ros__parameters:, or give no node section at all (a file "
                                  "of parameters only)", source)
            close = difflib.get_close_matches(name, list(schema.SECTIONS), n=1, cutoff=0.75)
            raise ConfigError(str(section), "unknown node section; expected one of "
                              + ", ".join(schema.SECTIONS)
                              + (f" (did you mean {close[0]!r}?)" if close else ""), source)
        if not isinstance(body, dict) or set(body) != {"ros__parameters"}:
            raise ConfigError(str(section), "must contain exactly one key, ros__parameters",
                              source)
        params = body["ros__parameters"] or {}
        if not isinstance(params, dict):
            raise ConfigError(f"{section}.ros__parameters", "must be a mapping", source)
        for key, value in flatten_tree(params, ""):
            if key in schema.ROS_BUILTIN:
                continue
            param = schema.BY_NAME.get(key)
            if param is None:
                raise ConfigError(key, unknown_parameter(key), source)
            if param.section != name:
                raise ConfigError(key, f"belongs in section {param.section!r}, not {section!r}",
                                  source)
            if key in flat:
                raise ConfigError(key, "given twice", source)
            flat[key] = value
    return flat


def _flat_parameters(document: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The parameters of a file without node sections (:func:`flatten_ros_yaml`)."""
    flat: dict[str, Any] = {}
    for key, value in flatten_tree(document, ""):
        if key in schema.ROS_BUILTIN:
            continue
        if key not in schema.BY_NAME:
            raise ConfigError(key, unknown_parameter(key), source)
        if key in flat:
            raise ConfigError(key, "given twice", source)
        flat[key] = value
    return flat


def flatten_tree(tree: Mapping[str, Any], prefix: str = "") -> Iterable[tuple[str, Any]]:
    """(dotted name, value) of every leaf of a nested ``ros__parameters`` mapping; a per-joint
    key's mapping is its value (a map by joint name, :func:`.schema.per_joint_values`)."""
    for key, value in tree.items():
        name = f"{prefix}{key}"
        param = schema.BY_NAME.get(name)
        if isinstance(value, Mapping) and not (param is not None and param.per_joint):
            yield from flatten_tree(value, name + ".")
        else:
            yield name, value


def validate(values: Mapping[str, Any], source: str | None = None) -> dict[str, Any]:
    """Every parameter present, typed and within its rule; returns the coerced values."""
    missing = [p.name for p in schema.PARAMETERS if p.name not in values]
    if missing:
        raise ConfigError(missing[0], "missing (every parameter needs a value)", source)
    unknown = [k for k in values if k not in schema.BY_NAME]
    if unknown:
        raise ConfigError(unknown[0], unknown_parameter(unknown[0]), source)
    out: dict[str, Any] = {}
    try:
        for param in schema.PARAMETERS:
            out[param.name] = schema.coerce(param, values[param.name])
        names = out["joint_names"]
        joints = len(names)
        if joints < 1:
            raise ConfigError("joint_names", "at least one joint is needed")
        urdf = out["model.source"] == "urdf"
        patient_names = schema.patient_joint_names(out)
        for param in schema.PARAMETERS:
            if urdf and param.name in schema.CONE_KEYS:
                continue  # a cone arm's keys: unused
            count, labels = (len(patient_names), patient_names) if param.patient_joint \
                else (joints, names)
            out[param.name] = schema.per_joint_values(param, out[param.name], labels)
            schema.check_value(param, out[param.name], count, labels)
        schema.check_consistency(out)
        if urdf:
            _check_urdf_joints(out)
        schema.check_patient_joints(out)
    except ConfigError as exc:
        if source and not exc.source:
            raise ConfigError(exc.key, exc.rule, source) from None
        raise
    return out


_URDF_TEXTS: dict[tuple[str, int, int], tuple[str, str, str]] = {}


def urdf_source(values: Mapping[str, Any]) -> tuple[str, str, str]:
    """(text, file, sha256 of the text) of the URDF ``model.urdf`` names (a path or
    ``package://``), read once per file version; :class:`~.urdf_xml.UrdfError` naming the file
    when it cannot be read."""
    path = urdf_path(str(values["model.urdf"]))
    try:
        stat = path.stat()
    except OSError:
        stat = None
    key = (str(path), stat.st_mtime_ns, stat.st_size) if stat is not None else None
    if key is not None and key in _URDF_TEXTS:
        return _URDF_TEXTS[key]
    text, file = read_urdf_text(path)
    entry = (text, file, hashlib.sha256(text.encode("utf-8")).hexdigest())
    if key is not None:
        _URDF_TEXTS[key] = entry
    return entry


def urdf_path(where: str) -> Path:
    """The file ``model.urdf`` names: a path, or ``package://`` the ROS way (``ament_index``);
    ``package://exo_ilc_ros/...`` (the shipped URDFs) also where the shipped configs are
    (:func:`config_dir`: a source checkout or a pip install)."""
    if not where.startswith("package://"):
        return Path(where)
    try:
        return resolve_package_uri(where)
    except UrdfError:
        package, _, relative = where[len("package://"):].partition("/")
        if package != PACKAGE:
            raise
        candidate = config_dir().parent / relative
        if not candidate.is_file():
            raise
        return candidate


def urdf_joints(values: Mapping[str, Any]) -> list[UrdfJoint]:
    """The moving joints of the URDF arm ``values`` describe, in chain order."""
    text, file, _ = urdf_source(values)
    return chain_joints(text, file, values["model.base_link"], values["model.tip_link"],
                        schema.parse_locked_joints(values["model.locked_joints"]))


def _check_urdf_joints(values: Mapping[str, Any]) -> None:
    """``joint_names`` must be the URDF's moving joints (ConfigError naming the URDF's error)."""
    try:
        names = [j.name for j in urdf_joints(values)]
    except UrdfError as exc:
        raise ConfigError(urdf_error_key(exc), str(exc)) from None
    if names != list(values["joint_names"]):
        raise ConfigError("joint_names", f"must be the moving joints of the URDF's chain "
                          f"{values['model.base_link']!r} -> {values['model.tip_link']!r}, "
                          f"[{', '.join(names)}]; got [{', '.join(values['joint_names'])}]")


def urdf_error_key(exc: UrdfError) -> str:
    """The config key a URDF error is about: the one that fixes it (:class:`UrdfKeyError`),
    else ``model.urdf``."""
    return exc.key if isinstance(exc, UrdfKeyError) else "model.urdf"


def _arm_file(file_values: dict[str, Any], values: dict[str, Any], file: Path) -> None:
    """A file that describes a URDF arm: its relative ``model.urdf`` made absolute (relative to
    the file), an empty ``model.base_link`` or ``model.tip_link`` found in the URDF
    (:func:`.urdf_xml.chain_ends`: the root, the single tip), and the ``joint_names`` and
    ``control.effort_limit`` it does not give taken from the URDF (its moving joints and their
    ``<limit effort>``). A URDF error names the file and the key that fixes it."""
    urdf = file_values.get("model.urdf")
    if isinstance(urdf, str) and urdf and not urdf.startswith("package://") \
            and not Path(urdf).is_absolute():
        file_values["model.urdf"] = str((file.parent / urdf).resolve())
    values.update(file_values)
    if values.get("model.source") != "urdf" or not any(k in file_values
                                                       for k in schema.URDF_KEYS):
        return
    try:
        locked = schema.parse_locked_joints(str(values.get("model.locked_joints", "")))
        text, where, _ = urdf_source(values)
        base, tip, joints = resolved_chain(text, where, str(values.get("model.base_link", "")),
                                           str(values.get("model.tip_link", "")), locked)
    except ConfigError as exc:
        raise ConfigError(exc.key, exc.rule, str(file)) from None
    except UrdfError as exc:
        raise ConfigError(urdf_error_key(exc), str(exc), str(file)) from None
    values["model.base_link"], values["model.tip_link"] = base, tip
    if "joint_names" not in file_values:
        values["joint_names"] = [j.name for j in joints]
    if "control.effort_limit" not in file_values:
        missing = [j.name for j in joints if not math.isfinite(j.effort) or j.effort <= 0.0]
        if missing:
            raise ConfigError("control.effort_limit", f"joint {missing[0]!r} has no <limit "
                              "effort> in the URDF: give control.effort_limit", str(file))
        values["control.effort_limit"] = [j.effort for j in joints]


def read_yaml(path: Path | str) -> dict[str, Any]:
    """The flat parameters of one ROS parameter YAML file (not yet validated)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ConfigError("<file>", f"cannot read: {exc.strerror}", str(path)) from None
    except UnicodeDecodeError as exc:
        raise ConfigError("<file>", f"not a text (UTF-8) file: byte {exc.start} is "
                          f"{exc.object[exc.start:exc.start + 1]!r}", str(path)) from None
    try:
        document = load_ros_yaml(text)
    except yaml.YAMLError as exc:
        raise ConfigError("<file>", f"invalid YAML: {yaml_problem(exc)}", str(path)) from None
    return flatten_ros_yaml(document, str(path))


def yaml_problem(exc: yaml.YAMLError) -> str:
    """A PyYAML error in one line: what is wrong and where (line and column, from 1)."""
    problem = getattr(exc, "problem", None)
    mark = getattr(exc, "problem_mark", None)
    if not problem:
        return str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    context = getattr(exc, "context", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{where}" + (f" ({context})" if context else "")


def _same_value(held: Any, given: Any) -> bool:
    """``given`` is ``held`` as validation left it: equal, of the same type, printed the same
    (``1`` is not ``1.0``; a list's items compared too)."""
    return type(held) is type(given) and repr(held) == repr(given)


class Config:
    """A complete, validated set of parameter values (immutable)."""

    def __init__(self, values: Mapping[str, Any], source: str | None = None) -> None:
        self._values = validate(values, source)
        self.source = source

    def __getitem__(self, name: str) -> Any:
        value = self._values[name]
        return list(value) if isinstance(value, list) else value

    @property
    def values(self) -> dict[str, Any]:
        """A copy of every value, by dotted name."""
        return json.loads(json.dumps(self._values))

    @property
    def joints(self) -> int:
        """Number of joints."""
        return len(self._values["joint_names"])

    def replace(self, overrides: Mapping[str, Any]) -> Config:
        """A new Config with ``overrides`` (dotted names) applied and validated; this one when
        every override is the value it has already (same type and spelling: validated as it
        was), so a run that sets what its config holds does not validate it again."""
        unknown = [k for k in overrides if k not in schema.BY_NAME]
        if unknown:
            raise ConfigError(unknown[0], unknown_parameter(unknown[0]))
        if all(_same_value(self._values[k], v) for k, v in overrides.items()):
            return self
        merged = dict(self._values)
        merged.update(overrides)
        return Config(merged, self.source)

    def with_mass_uncertainty(self, delta: float) -> Config:
        """This config with the plant's ``mass_uncertainty`` (eq (15)) set to ``delta``: the one
        way a run at another delta is made (everything reads the key from the config)."""
        return self.replace({"mass_uncertainty": float(delta)})

    def digest(self) -> str:
        """A stable hash of every value (keys stores of learned data; a URDF by its contents,
        :meth:`identity_values`)."""
        blob = json.dumps(self.identity_values(), sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]

    def identity_values(self, names: Iterable[str] | None = None) -> dict[str, Any]:
        """The values of ``names`` (default: all) as digests and keys take them: a cone arm
        without the URDF keys (its digests stay as they were before they existed), a URDF arm
        without the cone keys and with ``model.urdf`` as the sha256 of the file's contents (not
        its path); ``model.urdf_joint_dynamics`` only when it applies them; the person's keys
        only with ``person.enabled``, the neural drive's and the strapping's only with a
        ``musculoskeletal.model`` (and the person's body size with ``musculoskeletal.body_size:
        person``, not its default ``model``), ``patient.joints`` only when given,
        ``model.gravity_direction`` only when it is not -z, ``control.min_stiffness`` and
        ``control.min_damping`` only when some joint's is not 0, ``control.velocity_observer``
        only when it is on (below 1), ``control.period_rule`` only when it is not ``fixed``
        (so, too, for the keys that came before them)."""
        urdf = self._values["model.source"] == "urdf"
        left_out = set(schema.CONE_KEYS if urdf else schema.URDF_KEYS + schema.URDF_PLANT_KEYS)
        if self._values["model.urdf_joint_dynamics"] == "ignore":  # keys as before it existed
            left_out.update(schema.URDF_PLANT_KEYS)
        if not self._values["person.enabled"]:
            left_out.update(schema.PERSON_KEYS)
        if self._values["musculoskeletal.model"] == "none":  # no muscles, no cuffs
            left_out.update(schema.DRIVE_KEYS)
            left_out.update(schema.STRAPPED_KEYS)
        elif self._values["musculoskeletal.body_size"] == "person":  # the person's size counts
            left_out.difference_update(schema.BODY_SIZE_KEYS)
        if self._values["musculoskeletal.body_size"] == "model":  # as before the key
            left_out.add("musculoskeletal.body_size")
        if not self._values[schema.PATIENT_JOINTS]:
            left_out.add(schema.PATIENT_JOINTS)
        for floor in ("control.min_stiffness", "control.min_damping"):
            if not any(self._values[floor]):  # 0: the gains as given, as before the keys
                left_out.add(floor)
        if self._values["control.velocity_observer"] >= 1.0:  # off: as before the key
            left_out.add("control.velocity_observer")
        if self._values["control.period_rule"] == "fixed":  # as before the key
            left_out.add("control.period_rule")
        down = self._values["model.gravity_direction"]
        if down[0] == 0.0 and down[1] == 0.0 and down[2] < 0.0:  # -z: as before the key
            left_out.add("model.gravity_direction")
        out = {k: self[k] for k in (self._values if names is None else names)
               if k not in left_out}
        if urdf and "model.urdf" in out:
            out["model.urdf"] = "sha256:" + self.urdf_digest
        return out

    @property
    def urdf_digest(self) -> str:
        """sha256 of the URDF's text ("" for a cone arm)."""
        if self._values["model.source"] != "urdf":
            return ""
        return urdf_source(self._values)[2]

    def section(self, node: str) -> dict[str, Any]:
        """The values one node declares: the shared parameters and its own."""
        return {p.name: self[p.name] for p in schema.parameters_of(node)}

    def to_ros_yaml(self, header: str = "") -> str:
        """This config as a ROS parameter YAML that ``--params-file`` and :func:`load_config`
        both accept (sections nested, one key per parameter, the schema's text as comments)."""
        lines = [f"# {line}" for line in header.splitlines()]
        for section in schema.SECTIONS:
            params = _grouped([p for p in schema.PARAMETERS if p.section == section])
            if not params:
                continue
            key = f'"{section}"' if section == schema.SHARED else section
            lines += [f"{key}:", "  ros__parameters:"]
            if section == schema.SHARED:
                lines.append("    use_sim_time: true")
            opened: list[str] = []
            for p in params:
                parts = p.name.split(".")
                common = 0
                while (common < len(opened) and common < len(parts) - 1
                       and opened[common] == parts[common]):
                    common += 1
                opened = opened[:common]
                for depth in range(common, len(parts) - 1):
                    lines.append("    " + "  " * depth + f"{parts[depth]}:")
                    opened.append(parts[depth])
                indent = "    " + "  " * (len(parts) - 1)
                value = _yaml_value(self._values[p.name])
                lines.append(f"{indent}{parts[-1]}: {value}  # {p.description}")
        return "\n".join(lines) + "\n"


def _grouped(params: list[schema.Parameter]) -> list[schema.Parameter]:
    """``params`` in schema order, but every dotted group together (``safety.*`` at the place of
    its first key): a group opened twice would be two equal keys of one YAML mapping, and a
    loader keeps only the last."""
    first: dict[tuple[str, ...], int] = {}
    for p in params:
        parts = tuple(p.name.split("."))
        for depth in range(1, len(parts) + 1):
            first.setdefault(parts[:depth], len(first))

    def place(p: schema.Parameter) -> tuple[int, ...]:
        parts = tuple(p.name.split("."))
        return tuple(first[parts[:depth]] for depth in range(1, len(parts) + 1))

    return sorted(params, key=place)


def _yaml_float(x: float) -> str:
    """A float that YAML 1.1 (PyYAML) and rcl both read as a float: ``1e-05`` -> ``1.0e-05``."""
    text = json.dumps(x)
    mantissa, e, exponent = text.partition("e")
    if e and "." not in mantissa:
        return f"{mantissa}.0e{exponent}"
    return text


def _yaml_value(value: Any) -> str:
    """A parameter value as a flow-style YAML scalar or list (JSON, floats made YAML-safe)."""
    if isinstance(value, float):
        return _yaml_float(value)
    if isinstance(value, list):
        return "[" + ", ".join(_yaml_value(v) for v in value) + "]"
    return json.dumps(value)


SCENARIO_DIR_NAME = "scenarios"


def scenario_dir() -> Path:
    """Where the shipped scenario overlays are: ``config/scenarios/``."""
    return config_dir() / SCENARIO_DIR_NAME


def scenario_names() -> list[str]:
    """The shipped scenarios, by name (file stem), sorted."""
    return sorted(p.stem for p in scenario_dir().glob("*.yaml"))


def scenario_path(name_or_path: str | Path) -> Path:
    """A scenario overlay: a shipped name (``realistic`` is ``config/scenarios/realistic.yaml``)
    or a path to a YAML file of the same layout."""
    text = str(name_or_path)
    candidate = Path(text)
    if candidate.suffix in (".yaml", ".yml") or candidate.is_file():
        if not candidate.is_file():
            raise ConfigError("<file>", "no such scenario file", text)
        return candidate
    shipped = scenario_dir() / f"{text}.yaml"
    if not shipped.is_file():
        raise ConfigError("scenario", f"unknown scenario {text!r}; shipped: "
                          + ", ".join(scenario_names()))
    return shipped


def load_config(path: Path | str | None = None,
                overrides: Mapping[str, Any] | None = None,
                overlays: Iterable[Path | str] = ()) -> Config:
    """The shipped defaults, then ``path`` (any subset of keys), then each of ``overlays`` in
    order (e.g. a scenario), then ``overrides``. Each file is validated with what lies under it
    before ``overrides`` replace any of their values; an error names the file that broke it."""
    default = default_config_path()
    values = read_yaml(default)
    source = str(default)
    files = [] if path is None else [Path(path)]
    files += [Path(p) for p in overlays]
    config = Config(values, source)
    for file in files:
        if file.resolve() == default.resolve():
            continue
        _arm_file(read_yaml(file), values, file)
        source = str(file)
        config = Config(values, source)  # the files are checked whole, whatever overrides them
    return config.replace(overrides) if overrides else config
