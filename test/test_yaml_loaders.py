"""The config and a bag's metadata.yaml are parsed by libyaml when PyYAML has it (every command
parses the shipped config; the pure-Python parser took 0.05-0.15 s of it): the values are the
pure-Python loader's, type for type, and a refused document's error is PyYAML's own."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from exo_ilc_ros.bag.storage import safe_load_yaml
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import (
    FastRosYamlLoader,
    RosYamlLoader,
    load_config,
    load_ros_yaml,
    read_yaml,
)

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = sorted((ROOT / "config").rglob("*.yaml"))
SCALARS = ["1e-5", "-1.5E+3", "1_000", "0x1F", "0o17", "017", ".inf", "-.Inf", ".nan", "~",
           "null", "yes", "No", "on", "2001-12-14", "12:30:00", "1.0", "1", "'1'", "+1",
           "1e5x", "[1e-3, 2E1, -1.5e+2, 1_0]", "{a: 1e-2, b: [true, off]}", '"\\t"', "0.",
           "-0", "!!str 5", "a: &x 1\nb: *x", "- 1\n- - 2\n  - 3"]


def typed(value: Any) -> Any:
    """``value`` with every leaf's type beside it (1 and 1.0 and True differ; NaN equals)."""
    if isinstance(value, dict):
        return {typed(k): typed(v) for k, v in value.items()}
    if isinstance(value, list):
        return [typed(v) for v in value]
    return type(value).__name__, repr(value)


def test_libyaml_is_used() -> None:
    """The test below compares two parsers, not one with itself."""
    assert yaml.__with_libyaml__
    assert FastRosYamlLoader.__mro__[1] is yaml.CSafeLoader


@pytest.mark.parametrize("text", [*SCALARS, *(p.read_text() for p in SHIPPED)],
                         ids=[*SCALARS, *(str(p.relative_to(ROOT)) for p in SHIPPED)])
def test_both_parsers_read_the_same_values(text: str) -> None:
    assert typed(load_ros_yaml(text)) == typed(yaml.load(text, Loader=RosYamlLoader))
    assert typed(safe_load_yaml(text)) == typed(yaml.safe_load(text))


def test_the_ros_float_rule_holds_for_both() -> None:
    """``1e-5`` is a float as rcl reads it (YAML 1.2), for either loader; YAML 1.1 (safe_load)
    keeps it a string."""
    for loader in (RosYamlLoader, FastRosYamlLoader):
        assert yaml.load("[1e-5, 2E1, v1e5]", Loader=loader) == [1e-5, 20.0, "v1e5"]
    assert safe_load_yaml("1e-5") == "1e-5"


@pytest.mark.parametrize("text", ["a: [1, 2", "a: b: c", "a:\n\t- 1", "{a: 1", "- a\nb: 1",
                                  "a: 'x", "\x07"])
def test_a_refused_document_gets_pyyamls_error(text: str) -> None:
    with pytest.raises(yaml.YAMLError) as python:
        yaml.load(text, Loader=RosYamlLoader)
    with pytest.raises(yaml.YAMLError) as ours:
        load_ros_yaml(text)
    assert str(ours.value) == str(python.value)
    with pytest.raises(yaml.YAMLError) as safe:
        safe_load_yaml(text)
    assert str(safe.value) == str(python.value)


def test_a_config_file_with_a_yaml_error_names_line_and_column(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text('"/**":\n  ros__parameters:\n    max_trials: [1, 2\n')
    with pytest.raises(ConfigError, match=r"invalid YAML: .* at line 4, column 1"):
        read_yaml(bad)
    with pytest.raises(ConfigError, match="invalid YAML"):
        load_config(bad)
