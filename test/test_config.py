"""The parameter schema and the shipped YAML: loading, overlaying, rejecting bad values."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
import yaml

from exo_ilc_ros.core import ConfigError, config_dir, default_config_path, load_config
from exo_ilc_ros.core.params import schema
from exo_ilc_ros.core.params.config import read_yaml

ROOT = Path(__file__).resolve().parents[1]


def test_shipped_config_is_found_from_the_checkout_and_is_complete() -> None:
    assert default_config_path() == ROOT / "config" / "exo_ilc.yaml"
    flat = read_yaml(default_config_path())
    assert set(flat) == set(schema.BY_NAME), "the shipped YAML must set every parameter"
    config = load_config()
    assert config["model.link_masses"] == [0.0, 1.4, 1.1]
    assert config["control.kp"] == [16.0, 10.0, 10.0]
    assert config["schedule.position.level_high"] == [0.9, 0.5, 0.1]


def test_config_dir_env_override(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "exo_ilc.yaml").write_text((ROOT / "config" / "exo_ilc.yaml").read_text())
    monkeypatch.setenv("EXO_ILC_CONFIG_DIR", str(tmp_path))
    assert config_dir() == tmp_path


def test_every_choice_in_the_shipped_yaml_is_commented() -> None:
    text = (ROOT / "config" / "exo_ilc.yaml").read_text()
    for param in schema.PARAMETERS:
        if param.choices or param.section == schema.SHARED:
            leaf = param.name.split(".")[-1]
            lines = [ln for ln in text.splitlines() if re.match(rf"\s+{re.escape(leaf)}:", ln)]
            assert lines and all("#" in ln for ln in lines), f"{param.name} needs a comment"


def test_user_file_overlays_the_defaults(tmp_path: Path) -> None:
    user = tmp_path / "user.yaml"
    user.write_text("plant_simulator:\n  ros__parameters:\n    mass_uncertainty: 0.15\n"
                    "ilc_supervisor:\n  ros__parameters:\n    schedule:\n      position:\n"
                    "        level_high: [1.0, 0.5, 0.1]\n")
    config = load_config(user)
    assert config["mass_uncertainty"] == 0.15
    assert config["schedule.position.level_high"] == [1.0, 0.5, 0.1]
    assert config["schedule.position.level_mid"] == [0.03, 0.05, 0.05]
    assert config.source == str(user)


def test_ros_yaml_round_trip(tmp_path: Path) -> None:
    config = load_config(overrides={"mass_uncertainty": 0.1, "law": "linear"})
    out = tmp_path / "out.yaml"
    out.write_text(config.to_ros_yaml("written by a test"))
    document = yaml.safe_load(out.read_text())
    assert set(document) == {p.section for p in schema.PARAMETERS}
    again = load_config(out)
    assert again.values == config.values
    assert again.digest() == config.digest()
    assert load_config().digest() != config.digest()


class _UniqueKeyLoader(yaml.SafeLoader):
    """A YAML loader that refuses a mapping holding one key twice (PyYAML keeps the last)."""


def _unique_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode) -> dict[Any, Any]:
    keys = [loader.construct_object(k) for k, _ in node.value]
    assert len(keys) == len(set(keys)), f"a key twice in one mapping: {sorted(keys)}"
    return loader.construct_mapping(node)


_UniqueKeyLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _unique_mapping)


def test_ros_yaml_of_another_arm_reads_back_every_value(tmp_path: Path) -> None:
    """A 7-joint arm under patient_aware.yaml, written and read back: every value as it was
    (a group such as ``safety.*`` whose keys the schema lists apart, the person's cuff limit
    after the others, is written once: opened twice, YAML kept only the last and the Panda's
    7-joint hold gains came back as the 3-joint default)."""
    config = load_config(config_dir() / "arms" / "panda.yaml",
                         overlays=[config_dir() / "patient_aware.yaml"])
    out = tmp_path / "out.yaml"
    out.write_text(config.to_ros_yaml("written by a test"))
    yaml.load(out.read_text(), Loader=_UniqueKeyLoader)
    again = load_config(out)
    assert again.values == config.values
    assert again.digest() == config.digest()


BAD_VALUES: list[tuple[dict[str, Any], str, str]] = [
    ({"schedule.position.threshold_low": [25.0, 2.0, 1.0]}, "schedule.position.threshold_low",
     "thresholds must increase"),
    ({"schedule.velocity.level_mid": [0.005, -0.1, 0.005]}, "schedule.velocity.level_mid",
     ">= 0"),
    ({"control.kp": [16.0, -1.0, 10.0]}, "control.kp", ">= 0"),
    ({"model.link_masses": [0.0, -1.4, 1.1]}, "model.link_masses", ">= 0"),
    ({"control.kd": [8.0, 5.0]}, "control.kd", "one entry per joint (3: shoulder_flexion"),
    ({"model.joint_axes": ["x", "w", "x"]}, "model.joint_axes", "unknown joint axis 'w'"),
    ({"law": "magic"}, "law", "must be one of sign, linear"),
    ({"error_bound": 0.0}, "error_bound", "> 0"),
    ({"error_bound": float("nan")}, "error_bound", "finite"),
    ({"max_trials": 2.5}, "max_trials", "integer"),
    ({"integration_step": 0.003}, "integration_step", "divide control.period"),
    ({"trajectory.duration": 5.005}, "trajectory.duration", "whole number of control periods"),
    ({"control.kp": "16"}, "control.kp", "must be a list"),
    ({"joint_names": ["a", "a", "b"]}, "joint_names", "unique"),
]


@pytest.mark.parametrize(("overrides", "key", "rule"), BAD_VALUES)
def test_invalid_values_name_the_key_and_the_rule(overrides: dict[str, Any], key: str,
                                                  rule: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(overrides=overrides)
    assert info.value.key == key
    assert rule in info.value.rule
    assert key in str(info.value)


@pytest.mark.parametrize(("text", "key", "rule"), [
    ("ilc_supervisor:\n  ros__parameters:\n    learning_rate: 0.1\n", "learning_rate",
     "unknown parameter"),
    ("ilc_supervisor:\n  ros__parameters:\n    mass_uncertainty: 0.1\n", "mass_uncertainty",
     "belongs in section 'plant_simulator'"),
    ("planner:\n  ros__parameters:\n    x: 1\n", "planner", "unknown node section"),
    ("ilc_supervisor:\n  parameters:\n    law: sign\n", "ilc_supervisor", "ros__parameters"),
    ("ilc_supervisor: [1, 2\n", "<file>", "invalid YAML"),
])
def test_invalid_files_name_the_file_key_and_rule(tmp_path: Path, text: str, key: str,
                                                  rule: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert (info.value.key, info.value.source) == (key, str(path))
    assert rule in info.value.rule


def test_missing_file_is_a_config_error(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "nope.yaml")


def test_scenario_overlays_are_laid_over_the_config_in_order(tmp_path):
    from exo_ilc_ros.core.params.config import scenario_names, scenario_path

    assert "ideal" in scenario_names()
    ideal = load_config(overlays=[scenario_path("ideal")])
    assert ideal.values == load_config().values
    law = tmp_path / "law.yaml"
    law.write_text("ilc_supervisor:\n  ros__parameters:\n    law: linear\n    max_trials: 7\n")
    scenario = tmp_path / "s.yaml"
    scenario.write_text("ilc_supervisor:\n  ros__parameters:\n    max_trials: 9\n")
    config = load_config(law, overlays=[scenario])
    assert (config["law"], config["max_trials"]) == ("linear", 9)
    with pytest.raises(ConfigError, match="unknown scenario 'nope'"):
        scenario_path("nope")
    bad = tmp_path / "bad.yaml"
    bad.write_text("plant_simulator:\n  ros__parameters:\n    no_such_key: 1\n")
    with pytest.raises(ConfigError) as info:
        load_config(law, overlays=[bad])
    assert info.value.source == str(bad) and info.value.key == "no_such_key"
