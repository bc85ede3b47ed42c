"""What a newcomer's mistakes get (issue 36, point 10): a misspelled key or node section gets the
closest known name, a YAML of parameters only (no node sections) is read as the README's "any
subset of the keys" promises, a parameter beside node sections says where it belongs, and an
unknown patient's error says how to start a first session."""

from __future__ import annotations

from pathlib import Path

import pytest

from exo_ilc_ros.cli.main import main as exo_ilc
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.params.config import load_config


def _error(tmp_path: Path, text: str) -> ConfigError:
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        load_config(path)
    assert error.value.source == str(path)
    return error.value


@pytest.mark.parametrize(("text", "key", "suggestion"), [
    ("ilc_supervisor:\n  ros__parameters:\n    max_trails: 20\n", "max_trials", "max_trials"),
    ('"/**":\n  ros__parameters:\n    trajectory:\n      durration: 2.0\n',
     "trajectory.durration", "trajectory.duration"),
    ("max_trails: 20\n", "max_trails", "max_trials"),
])
def test_a_misspelled_key_gets_the_closest_name(tmp_path: Path, text: str, key: str,
                                                suggestion: str) -> None:
    error = _error(tmp_path, text)
    assert error.rule == f"unknown parameter; did you mean {suggestion!r}?"
    assert error.key in (key, "max_trails")
    with pytest.raises(ConfigError, match="did you mean 'error_bound'"):
        load_config().replace({"error_bund": 0.01})


def test_a_misspelled_section_gets_the_closest_name(tmp_path: Path) -> None:
    error = _error(tmp_path, "ilc_supervisr:\n  ros__parameters:\n    law: sign\n")
    assert error.key == "ilc_supervisr" and "unknown node section" in error.rule
    assert "did you mean 'ilc_supervisor'?" in error.rule


def test_a_file_of_parameters_only_is_read(tmp_path: Path) -> None:
    """No node section at all: each parameter goes to its node's (shared, supervisor, plant)."""
    path = tmp_path / "flat.yaml"
    path.write_text("max_trials: 20\nlaw: linear\nmass_uncertainty: 0.15\n"
                    "trajectory:\n  duration: 2.0\ncontrol.kp: 25.0\n")
    config = load_config(path)
    assert (config["max_trials"], config["law"], config["mass_uncertainty"]) == \
        (20, "linear", 0.15)
    assert config["trajectory.duration"] == 2.0 and config["control.kp"] == [25.0] * 3
    assert exo_ilc(["simulate", "--config", str(path), "--trials", "1", "--quiet"]) == 0


def test_a_parameter_beside_node_sections_says_where_it_belongs(tmp_path: Path) -> None:
    error = _error(tmp_path, '"/**":\n  ros__parameters:\n    trajectory:\n      duration: 2.0\n'
                   "max_trials: 3\n")
    assert error.key == "max_trials"
    assert error.rule.startswith("is a parameter, not a node section: put max_trials under "
                                 "ilc_supervisor: ros__parameters:")


def test_an_unknown_patient_is_told_about_new_patient(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = exo_ilc(["simulate", "--patient", "p_first", "--profiles", str(tmp_path / "p"),
                    "--trials", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "unknown patient 'p_first'" in err
    assert "for the patient's first session add --new-patient" in err
