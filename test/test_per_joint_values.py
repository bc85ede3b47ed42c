"""One rule for every per-joint key (core/params/schema.py ``per_joint_values``): a list, one
value for every joint, or a map by joint name ('*' for the rest), with errors naming the key;
and config/patient_aware.yaml laid over every shipped arm file."""

from __future__ import annotations

from pathlib import Path

import pytest

from exo_ilc_ros.core import ConfigError, load_config
from exo_ilc_ros.core.params import schema

ROOT = Path(__file__).resolve().parents[1]
ARMS = sorted((ROOT / "config" / "arms").glob("*.yaml"))
PER_JOINT = [p for p in schema.PARAMETERS if p.per_joint and p.kind is schema.Kind.DOUBLE_ARRAY
             and p.name not in schema.CONE_KEYS]


def _joints(config, param: schema.Parameter) -> list[str]:
    return schema.patient_joint_names(config.values) if param.patient_joint \
        else config["joint_names"]


@pytest.mark.parametrize("param", PER_JOINT, ids=lambda p: p.name)
def test_every_per_joint_key_takes_a_scalar_and_a_name_map(param: schema.Parameter) -> None:
    config = load_config()
    names = _joints(config, param)
    current = [float(x) for x in config[param.name]]
    # the rule itself: a scalar is repeated, a map is put in the joints' order
    assert schema.per_joint_values(param, 0.5, names) == [0.5] * len(names)
    assert schema.per_joint_values(param, {names[-1]: 2.0, "*": 0.5}, names) == \
        [0.5] * (len(names) - 1) + [2.0]
    # through the whole config (its rules between keys too): the shipped values by name, as a
    # YAML map with '*' for the first joint and as ROS's 'name: value' string
    by_name = {"*": current[0], **{n: x for n, x in zip(names[1:], current[1:], strict=True)}}
    assert config.replace({param.name: by_name})[param.name] == current
    text = ", ".join(f"{n}: {x!r}" for n, x in zip(names, current, strict=True))
    assert config.replace({param.name: text})[param.name] == current
    if len(set(current)) == 1:
        assert config.replace({param.name: current[0]})[param.name] == current


@pytest.mark.parametrize(("value", "rule"), [
    ({"elbow": 3.0, "*": 1.0}, "control.kp: joint 'elbow' is not one of the arm's joints "
     "(shoulder_flexion, shoulder_abduction, elbow_flexion)"),
    ({"elbow_flexion": 3.0}, "control.kp: the map by joint name leaves out shoulder_flexion, "
     "shoulder_abduction"),
    ({"elbow_flexion": "3", "*": 1.0}, "control.kp: joint 'elbow_flexion': must be a number, "
     "got '3'"),
    ({"elbow_flexion": -3.0, "*": 1.0}, "control.kp: joint 'elbow_flexion': must be >= 0, "
     "got -3.0"),
    ("elbow_flexion: fast", "control.kp: entry 'elbow_flexion: fast' is not 'joint_name: "
     "value' (a number)"),
    ("elbow_flexion: 1, elbow_flexion: 2", "control.kp: joint 'elbow_flexion' is given twice"),
    ("16", "control.kp: must be a list, one value for every joint or a map by joint name"),
    ([1.0, 2.0], "control.kp: must have one entry per joint (3: shoulder_flexion, "
     "shoulder_abduction, elbow_flexion), one value for every joint or a map by joint name, "
     "got 2 entries"),
])
def test_a_bad_per_joint_value_names_the_key_and_the_joint(value, rule: str) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(overrides={"control.kp": value})
    assert rule in str(info.value)


def test_a_patient_key_maps_by_the_patients_joint_names() -> None:
    panda = load_config(ROOT / "config" / "arms" / "panda.yaml")
    changed = panda.replace({"patient.passive.stiffness": {"elbow_flexion": 2.0, "*": 0.5}})
    assert changed["patient.passive.stiffness"] == [0.5, 0.5, 2.0]
    with pytest.raises(ConfigError) as info:
        panda.replace({"patient.passive.stiffness": {"panda_joint4": 2.0, "*": 0.0}})
    assert "joint 'panda_joint4' is not one of the patient's joints" in str(info.value)
    assert panda.replace({"control.kp": {"panda_joint7": 40.0, "*": 16.0}})["control.kp"] == \
        [16.0] * 6 + [40.0]


def test_a_yaml_map_by_joint_name_in_a_file(tmp_path: Path) -> None:
    file = tmp_path / "gains.yaml"
    file.write_text('"/**":\n  ros__parameters:\n    control:\n'
                    "      kp: {elbow_flexion: 20.0, '*': 12.0}\n"
                    "      kd: {shoulder_flexion: 9.0, shoulder_abduction: 6.0, "
                    "elbow_flexion: 8.0}\n")
    config = load_config(file)
    assert config["control.kp"] == [12.0, 12.0, 20.0]
    assert config["control.kd"] == [9.0, 6.0, 8.0]
    again = tmp_path / "again.yaml"  # what the nodes get: lists, read back the same
    again.write_text(config.to_ros_yaml())
    assert load_config(again)["control.kp"] == [12.0, 12.0, 20.0]


@pytest.mark.parametrize("arm", [None, *ARMS], ids=lambda a: "paper" if a is None else a.stem)
def test_patient_aware_lays_over_every_shipped_arm(arm: Path | None) -> None:
    config = load_config(arm, overlays=[ROOT / "config" / "patient_aware.yaml"])
    assert config["identification.in_loop"] and config["q_filter.enabled"]
    for param in PER_JOINT:
        assert len(config[param.name]) == len(_joints(config, param)), param.name
