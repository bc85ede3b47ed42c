"""``control.period_rule: reflex`` (core/loop/rate.py, (R)): the period patient_aware.yaml runs
on each arm, by hand from MAS 3's reflex gain and each joint's lightest inertia, and the one
period every program and node runs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rclpy.context import Context

from exo_ilc_ros.cli.main import main
from exo_ilc_ros.core.errors import ConfigError
from exo_ilc_ros.core.loop.gains import lightest_inverse_inertia
from exo_ilc_ros.core.loop.rate import reflex_period, sampled_reflex, with_control_rate
from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.programs.study import LawSpec, ScenarioSpec, cell_config

ROOT = Path(__file__).resolve().parents[1]
AWARE = config_dir() / "patient_aware.yaml"
ARMS = {"ur5": ROOT / "config" / "arms" / "ur5.yaml",
        "panda": ROOT / "config" / "arms" / "panda.yaml"}


def test_the_paper_arm_runs_5_ms_because_its_elbow_is_light() -> None:
    """By hand: MAS 3's G = 2 N m s/rad over the elbow's lightest inertia I (1 / max_t
    (a_N^-1)_33 = 0.01091 kg m^2) at T = 10 ms is G T / I = 1.83 >= 1; at T / 2 = 5 ms 0.917 < 1,
    so the rule halves the period (5 ms = 5 RK4 steps of 1 ms; 5 s = 1000 periods)."""
    config = load_config(AWARE)
    assert config["control.period"] == 0.01 and config["control.period_rule"] == "reflex"
    inverse = lightest_inverse_inertia(config)
    assert 1.0 / inverse[2] == pytest.approx(0.01091, rel=2e-3)
    ratio = sampled_reflex(config)
    np.testing.assert_allclose(ratio, 2.0 * 0.01 * inverse, rtol=1e-12)
    assert ratio[2] == pytest.approx(1.833, abs=2e-3)
    assert reflex_period(config) == 0.005
    rated = with_control_rate(config)
    assert rated["control.period"] == 0.005
    assert float(np.max(sampled_reflex(rated))) < 1.0
    assert with_control_rate(rated) is rated  # idempotent: 5 ms meets (R) itself


@pytest.mark.parametrize("arm", list(ARMS))
def test_the_ur5_and_the_panda_keep_10_ms(arm: str) -> None:
    """Their patient joints are ten times heavier (I >= 0.1 kg m^2 on the Panda's first joint,
    the lightest): G T / I <= 0.2 at 10 ms, and the config is returned as it was, so their
    certificates at 10 ms stand."""
    config = load_config(ARMS[arm], overlays=[AWARE])
    assert float(np.max(sampled_reflex(config))) < 0.2
    assert with_control_rate(config) is config


def test_fixed_runs_the_period_as_given() -> None:
    config = load_config(AWARE, {"control.period_rule": "fixed"})
    assert with_control_rate(config) is config and config["control.period"] == 0.01


def test_the_period_is_a_whole_number_of_rk4_steps() -> None:
    """With 2 ms RK4 steps 5 ms is not whole (2.5 steps) and 10 / 3 ms neither: 10 / 4 ms = 2.5
    ms neither; 10 / 5 = 2 ms is (G T / I 0.37); with a 10 ms step no shorter period exists and
    the rule says so, naming its key."""
    config = load_config(AWARE, {"integration_step": 0.002})
    assert reflex_period(config) == 0.002
    with pytest.raises(ConfigError) as caught:
        reflex_period(load_config(AWARE, {"integration_step": 0.01}))
    assert caught.value.key == "control.period_rule"
    assert "G T / I is 1.83 at 0.01 s" in str(caught.value)


def test_a_joint_the_movement_keeps_still_meets_no_reflex() -> None:
    """The elbow held at 0 (goal 0): its reference never outruns MAS 3's 0.1 rad/s threshold,
    so no reflex there and 10 ms holds (shoulder flexion's 0.39 the largest: its lightest
    inertia along this movement is 0.0515 kg m^2, 0.066 along the paper's)."""
    config = load_config(AWARE, {"trajectory.goal": [np.pi / 2, np.pi / 4, 0.0]})
    ratio = sampled_reflex(config)
    assert ratio[2] == 0.0 and ratio[0] == pytest.approx(0.388, abs=2e-3)
    assert reflex_period(config) == 0.01


def test_programs_run_the_rules_period(capsys: pytest.CaptureFixture[str],
                                       tmp_path: Path) -> None:
    """The study's cells, the ros2_control file (update_rate 200 Hz) and the certificate (which
    says the period it runs) take the rule's period."""
    cell = cell_config(LawSpec("patient_aware", AWARE), ScenarioSpec("ideal", config_dir() /
                       "scenarios" / "ideal.yaml"), 0.1, 0, 2)
    assert cell["control.period"] == 0.005
    out = tmp_path / "controllers.yaml"
    assert main(["ros2-control", "--config", str(AWARE), "--out", str(out)]) == 0
    assert "update_rate: 200" in out.read_text()
    capsys.readouterr()
    main(["certify", "--config", str(AWARE), "--population", "1", "--trials", "1",
          "--workers", "1", "--rows", str(tmp_path / "rows.jsonl")])
    assert "at 5 ms (control.period_rule reflex)" in capsys.readouterr().err


def test_a_node_runs_and_says_the_rules_period() -> None:
    """A node started with patient_aware.yaml as its params file (``ros2 run ... --params-file``)
    runs 5 ms, and its control.period parameter says so."""
    import rclpy
    from rclpy.node import Node

    from exo_ilc_ros.core.params import schema
    from exo_ilc_ros.nodes.parameters import SchemaParameters, given_command_line

    context = Context()
    rclpy.init(context=context)
    given_command_line(["exo_ilc_ros", "--ros-args", "--params-file", str(AWARE)])
    try:
        node = Node("computed_torque_controller", context=context)
        params = SchemaParameters(node, schema.CONTROLLER)
        assert params.config["control.period"] == 0.005
        assert node.get_parameter("control.period").value == 0.005
        node.destroy_node()
    finally:
        given_command_line(None)
        rclpy.try_shutdown(context=context)
