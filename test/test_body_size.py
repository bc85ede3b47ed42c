"""A person with muscles scaled to a body size (core/person/body_size.py): the arm takes de
Leva's segments of the person, the muscles keep their state at rest, the exoskeleton sits
where the person's joints now are, and a population draws the size when the config asks."""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np
import pytest

from exo_ilc_ros.core.params.config import config_dir, load_config
from exo_ilc_ros.core.person.body_size import measure_arm, scaled_person_spec
from exo_ilc_ros.core.person.model import ANATOMY, compile_quietly, rest_pose
from exo_ilc_ros.core.person.strapped import StrappedArm
from exo_ilc_ros.core.population.distributions import (
    ADULT_PERCENTILES,
    PopulationSpec,
    cube_coordinates,
    draw_patient,
)

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

ELBOW = config_dir() / "myoelbow.yaml"
SMALL = {"musculoskeletal.body_size": "person", "person.body_mass": 50.0,
         "person.height": 1.51, "person.sex": "female"}
"""A 5th-percentile woman (NHANES): the elbow model's adult is much bigger."""


def _config(**overrides: Any) -> Any:
    return load_config(ELBOW, overrides={"trajectory.duration": 1.0,
                                         "musculoskeletal.settle_time": 0.0, **overrides})


def _model(config: Any) -> Any:
    return compile_quietly(scaled_person_spec(config))


def test_the_arm_takes_de_levas_segments_of_the_person() -> None:
    """de Leva 1996 Table 4, female, by hand: upper arm 275.1 mm x 1.51 / 1.735 = 0.23943 m
    and 2.55 % of 50 kg = 1.275 kg; forearm 264.3 mm -> 0.23003 m, 1.38 % -> 0.69 kg, its
    centre of mass 0.4559 L = 0.10487 m from the elbow; hand 78.0 mm -> 0.067885 m, 0.56 % ->
    0.28 kg, its centre 0.7474 L = 0.050737 m past the wrist. Forearm with hand: 0.97 kg,
    centre (0.69 x 0.10487 + 0.28 x (0.23003 + 0.050737)) / 0.97 = 0.15564 m."""
    anatomy = ANATOMY["myoelbow"]
    own = measure_arm(_model(_config()), anatomy)
    assert own.upper_arm_length == pytest.approx(0.2907, abs=1e-3)  # the model's adult
    small = measure_arm(_model(_config(**SMALL)), anatomy)
    assert small.upper_arm_length == pytest.approx(0.23943, abs=1e-5)
    assert small.upper_arm_mass == pytest.approx(1.275, rel=1e-12)
    assert small.forearm_mass == pytest.approx(0.97, rel=1e-12)
    assert small.forearm_com == pytest.approx(0.15564, abs=1e-5)


def test_model_size_is_the_model_and_the_scaled_inertia_follows_mass_times_length_squared(
) -> None:
    own, small = _model(_config()), _model(_config(**SMALL))
    same = _model(_config(**{**SMALL, "musculoskeletal.body_size": "model"}))
    np.testing.assert_array_equal(same.body_inertia, own.body_inertia)  # the keys unused
    np.testing.assert_array_equal(same.actuator_gainprm, own.actuator_gainprm)
    a = measure_arm(own, ANATOMY["myoelbow"])
    b = measure_arm(small, ANATOMY["myoelbow"])
    humerus = own.body("r_humerus").id
    factor = (b.upper_arm_mass / a.upper_arm_mass) * \
        (b.upper_arm_length / a.upper_arm_length) ** 2
    np.testing.assert_allclose(small.body_inertia[humerus], own.body_inertia[humerus] * factor,
                               rtol=1e-9)
    np.testing.assert_array_equal(small.body_mass[0], own.body_mass[0])  # the world as it was


def test_every_muscle_keeps_its_fibre_length_at_rest_and_its_force_follows_its_section(
) -> None:
    """At the rest pose every muscle's normalised fibre length (what the stretch reflex reads)
    is the model's: the optimal length and the slack scale with the musculotendon length. The
    peak force scales by the arm's mass ratio over that length ratio."""
    own, small = _model(_config()), _model(_config(**SMALL))
    anatomy = ANATOMY["myoelbow"]

    def at_rest(model: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        data = mujoco.MjData(model)
        data.qpos[:] = rest_pose(model, anatomy)
        mujoco.mj_fwdPosition(model, data)
        lr = model.actuator_lengthrange
        span = model.actuator_gainprm[:, 1] - model.actuator_gainprm[:, 0]
        optimal = (lr[:, 1] - lr[:, 0]) / span
        fibre = model.actuator_gainprm[:, 0] + (data.actuator_length - lr[:, 0]) / optimal
        return np.array(data.actuator_length), fibre, model.actuator_gainprm[:, 2].copy()

    length_a, fibre_a, force_a = at_rest(own)
    length_b, fibre_b, force_b = at_rest(small)
    np.testing.assert_allclose(fibre_b, fibre_a, rtol=1e-9, atol=1e-12)
    ratio = length_b / length_a
    assert np.all((ratio > 0.7) & (ratio < 0.95))  # every muscle shorter in the small arm
    mass = (0.97 + 1.275) / (own.body_mass[own.body("r_humerus").id]
                            + own.body_subtreemass[own.body("r_ulna_radius_hand").id])
    np.testing.assert_allclose(force_b, force_a * mass / ratio, rtol=1e-9)
    np.testing.assert_array_equal(small.actuator_biasprm[:, 2], small.actuator_gainprm[:, 2])


def test_the_exoskeleton_sits_on_the_smaller_persons_joints() -> None:
    """The exoskeleton's shoulder is put on the person's shoulder and its upper arm along the
    humerus: with the person's humerus 0.239 m and the exoskeleton's link unchanged, its elbow
    is off the person's by the difference of the two lengths."""
    big = StrappedArm(_config(), np.zeros(3))
    small = StrappedArm(_config(**SMALL), np.zeros(3))
    humerus = {arm: np.linalg.norm(
        arm.data.xanchor[arm.model.joint("r_elbow_flex").id]
        - arm.data.xpos[arm.model.body("r_humerus").id]) for arm in (big, small)}
    mujoco.mj_kinematics(big.model, big.data)
    mujoco.mj_kinematics(small.model, small.data)
    exo = big.elbow_offset + humerus[big]  # the exoskeleton's upper arm: myoelbow.yaml cuts
    # it to the model's humerus, to within a millimetre, the link the longer
    assert small.elbow_offset == pytest.approx(exo - humerus[small], abs=1e-6)
    assert small.elbow_offset > big.elbow_offset + 0.04


def test_a_population_draws_the_body_size_only_when_the_config_scales_the_person() -> None:
    base = load_config(ELBOW)
    scaled = base.replace({"musculoskeletal.body_size": "person"})
    spec = PopulationSpec(encoder_share=0.0)
    plain = cube_coordinates(base, spec)
    assert not any(c.startswith("body.") for c in plain)
    assert cube_coordinates(scaled, spec) == [*plain, "body.sex", "body.height", "body.mass"]
    for index in range(20):
        a, b = draw_patient(base, spec, 0, index), draw_patient(scaled, spec, 0, index)
        assert {k: v for k, v in b.overrides.items() if not k.startswith("person.")
                or k.startswith("person.drive")} == a.overrides  # the rest as drawn before
        table = ADULT_PERCENTILES[b.overrides["person.sex"]]
        assert table["height"][0] <= b.overrides["person.height"] <= table["height"][2]
        assert f"{b.overrides['person.height']:.2f} m" in b.describe()
        scaled.replace(b.overrides)  # through the schema


def test_the_digest_counts_the_body_size_only_when_it_scales() -> None:
    base = load_config(ELBOW)
    assert "musculoskeletal.body_size" not in base.identity_values()
    assert "person.height" not in base.identity_values()
    assert base.digest() == base.replace({"person.height": 1.6}).digest()
    scaled = base.replace({"musculoskeletal.body_size": "person"})
    assert scaled.digest() != base.digest()
    assert scaled.digest() != scaled.replace({"person.height": 1.6}).digest()
