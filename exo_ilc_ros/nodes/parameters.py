"""The schema's parameters on a node (:class:`SchemaParameters`): declared from the one schema
(config/exo_ilc.yaml through :mod:`exo_ilc_ros.core.params.schema`), changes validated and staged,
and the values a node was given on its command line."""

from __future__ import annotations

import array
import difflib
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import yaml
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..core.errors import ConfigError
from ..core.loop.rate import with_control_rate
from ..core.params import schema
from ..core.params.config import Config, flatten_tree, load_config, load_ros_yaml
from ..core.params.validation import validate_update


class SchemaParameters:
    """Declares the schema's parameters of one node and guards changes to them.

    Every parameter of ``schema.parameters_of(section)`` is declared with the shipped YAML's
    value as default, so ``--params-file`` and ``-p`` override it, the later of them on the
    command line winning (:func:`command_line_parameters`; rclpy alone would let a params
    file's ``<node>:`` section beat a later ``-p``). Types are dynamic and every value goes
    through the schema's ``coerce`` (a user writing ``0`` for a double is fine).
    Changes at runtime, the way rclpy's demos do it: the on-set callback validates (``live``
    parameters only, the schema and the rules between parameters:
    :func:`~exo_ilc_ros.core.params.validation.validate_update`, the one validation path) and
    changes nothing; a refused change returns the key and the rule. The post-set callback, called
    once rclpy has stored the values, applies them to :attr:`pending` and tells the
    :attr:`listeners`. The node decides when :attr:`pending` takes effect.
    """

    def __init__(self, node: Node, section: str) -> None:
        self._node = node
        self._section = section
        self._params = {p.name: p for p in schema.parameters_of(section)}
        defaults = load_config()
        given = command_line_parameters(_command_line(), node.get_fully_qualified_name())
        for name, item in given.items():
            if name not in self._params and name not in schema.ROS_BUILTIN and \
                    not item.wildcard:  # a /** key may be meant for another node
                close = difflib.get_close_matches(name, list(self._params), n=1)
                node.get_logger().warning(f"{item.origin}: {name}: {node.get_name()} has no "
                                          "such parameter; ignored" +
                                          (f" (did you mean {close[0]}?)" if close else ""))
        for p in self._params.values():
            descriptor = ParameterDescriptor(description=p.description, dynamic_typing=True)
            if p.name in given:  # the last value the command line gives, as ROS intends
                try:
                    value = schema.coerce(p, given[p.name].value)
                except ConfigError as exc:
                    raise ConfigError(exc.key, exc.rule, given[p.name].origin) from None
                node.declare_parameter(p.name, value, descriptor, ignore_override=True)
            else:
                node.declare_parameter(p.name, defaults[p.name], descriptor)
        values = defaults.values
        values.update(other_sections(_command_line(), self._params))  # e.g. a 7-joint arm's
        values.update({name: node.get_parameter(name).value for name in self._params})
        given_config = Config(values, f"parameters of node {node.get_name()}")
        self.config: Config = with_control_rate(given_config)
        """The configuration the node started with (validated; ``control.period`` as
        ``control.period_rule`` gives it, :mod:`exo_ilc_ros.core.loop.rate`)."""
        if self.config is not given_config:  # the parameter says the period the node runs
            period = self.config["control.period"]
            node.set_parameters([Parameter("control.period", value=period)])
            node.get_logger().info(
                f"control.period {given_config['control.period']:g} s -> {period:g} s "
                "(control.period_rule reflex: MAS 3's stretch reflex held on every patient "
                "joint)")
        self.pending: Config = self.config
        """The configuration including accepted live changes."""
        self.listeners: list[Callable[[Config], None]] = []
        """Called with the new :attr:`pending` after every accepted change."""
        node.add_on_set_parameters_callback(self.on_set_parameters)
        node.add_post_set_parameters_callback(self.on_parameters_set)

    def _update(self, parameters: list[Parameter]) -> Config | ConfigError:
        return validate_update(self.pending, {p.name: _plain(p.value) for p in parameters},
                               node=self._section)

    def on_set_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a change (nothing changes here: another callback may still refuse it)."""
        checked = self._update(parameters)
        if isinstance(checked, ConfigError):
            return SetParametersResult(successful=False, reason=f"{checked.key}: {checked.rule}")
        return SetParametersResult(successful=True)

    def on_parameters_set(self, parameters: list[Parameter]) -> None:
        """Apply a change rclpy has stored: into :attr:`pending`, then the listeners."""
        updated = self._update(parameters)
        if isinstance(updated, ConfigError):  # validated by on_set_parameters on this state
            self._node.get_logger().error(f"parameter change not applied: {updated}")
            return
        if updated is self.pending:
            return
        self.pending = updated
        for listener in self.listeners:
            listener(updated)


def _plain(value: Any) -> Any:
    """A parameter value as the schema reads it: arrays come as array.array, lists read better
    in a refusal ("got [1, 2]")."""
    return value.tolist() if isinstance(value, array.array) else value


_ROS_FLAGS_WITH_VALUE = frozenset({"-r", "--remap", "-e", "--enclave", "--log-level",
                                   "--log-config-file", "--log-file-name"})
"""ROS arguments (besides ``-p`` and ``--params-file``) that take the next argument."""


_ARGV: list[str] | None = None
"""The command line :func:`exo_ilc_ros.nodes.common.run_nodes` initialised ROS with (None: not
started by it)."""


def given_command_line(argv: list[str] | None) -> None:
    """Remember the command line ROS was initialised with (None: forget it)."""
    global _ARGV
    _ARGV = argv


def _command_line() -> list[str]:
    return list(_ARGV) if _ARGV is not None else []


def _node_pattern(pattern: str) -> re.Pattern[str]:
    """A params-file node key or ``-p`` node prefix (``/**``, ``ns/*``, ``name``) as a regex
    over fully qualified node names."""
    parts = [p for p in pattern.strip("/").split("/") if p]
    regex = "".join("(/[^/]+)*" if p == "**" else "/[^/]*" if p == "*" else "/" + re.escape(p)
                    for p in parts)
    return re.compile(regex or "/")


def _params_file_sections(document: Any, path: tuple[str, ...] = ()
                          ) -> Iterator[tuple[str, Mapping[str, Any]]]:
    """(node key, ros__parameters) of a params file, in file order (namespaces nested)."""
    if not isinstance(document, Mapping):
        return
    for key, body in document.items():
        if key == "ros__parameters" and isinstance(body, Mapping):
            yield "/".join(path), body
        elif isinstance(body, Mapping):
            yield from _params_file_sections(body, (*path, str(key)))


class GivenValue(NamedTuple):
    """A parameter value from the command line, where it came from, and whether it came from a
    wildcard section (``/**``) rather than one naming the node."""

    value: Any
    origin: str
    wildcard: bool = False


def other_sections(argv: Sequence[str], own: Mapping[str, Any]) -> dict[str, Any]:
    """The per-joint parameters that the ``--params-file`` files in ``argv`` give in any
    section, except the node's ``own``: what the node validates its configuration with besides
    its own values (a URDF arm's joint count holds for every section; the shipped defaults are
    the paper's three joints). Other sections' other values stay the shipped ones (a supervisor
    without a plant_simulator to ask keeps the shipped plant values)."""
    out: dict[str, Any] = {}
    args = list(argv)
    for i, arg in enumerate(args[:-1]):
        if arg != "--params-file":
            continue
        try:
            document = load_ros_yaml(Path(args[i + 1]).read_text())
        except (OSError, yaml.YAMLError):
            continue  # command_line_parameters names the file
        for _, body in _params_file_sections(document):
            out.update((name, value) for name, value in flatten_tree(body)
                       if name in schema.BY_NAME and schema.BY_NAME[name].per_joint
                       and name not in own)
    return out


def command_line_parameters(argv: Sequence[str], node_fqn: str) -> dict[str, GivenValue]:
    """The parameter values the ROS arguments in ``argv`` give node ``node_fqn``, each with
    where it came from, the later overriding the earlier: ``--params-file`` sections that match
    the node (its name, ``/**``, wildcards) in file order, ``-p [node:]name:=value`` rules, all
    in command-line order (ROS's rule: later overrides win)."""
    out: dict[str, GivenValue] = {}
    in_ros, i = False, 0
    args = list(argv)
    while i < len(args):
        arg = args[i]
        i += 1
        if arg == "--ros-args":
            in_ros = True
            continue
        if not in_ros:
            continue
        if arg == "--":
            in_ros = False
        elif arg in _ROS_FLAGS_WITH_VALUE:
            i += 1
        elif arg == "--params-file" and i < len(args):
            path, i = args[i], i + 1
            try:
                document = load_ros_yaml(Path(path).read_text())
            except (OSError, yaml.YAMLError) as exc:
                raise ConfigError("--params-file", f"cannot read: {exc}", path) from None
            for key, body in _params_file_sections(document):
                if _node_pattern(key).fullmatch(node_fqn):
                    wildcard = "*" in key
                    out.update((name, GivenValue(value, path, wildcard))
                               for name, value in flatten_tree(body))
        elif arg in ("-p", "--param") and i < len(args):
            rule, i = args[i], i + 1
            target, sep, text = rule.partition(":=")
            node_key, _, name = target.rpartition(":")
            if not sep or (node_key and not _node_pattern(node_key).fullmatch(node_fqn)):
                continue
            try:
                value = load_ros_yaml(text)
            except yaml.YAMLError:
                value = text
            out[name] = GivenValue(value, f"-p {rule}", "*" in node_key)
    return out
