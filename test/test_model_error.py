"""Issue 33, honest identification: the friction law's model error. The trial refitted with a
hard Coulomb law (sgn for the model's tanh) moves each estimate by d; the 95 % interval is
value +- 1.96 sqrt(SE^2 + d^2), while the precision rule reads the noise's SE alone."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from exo_ilc_ros.core import Experiment, load_config
from exo_ilc_ros.core.arm.build import build_arm
from exo_ilc_ros.core.learning.identification import JointForceIdentifier
from exo_ilc_ros.core.learning.identification_settings import Z95, IdentificationSettings, judge
from exo_ilc_ros.core.learning.recursive_least_squares import law_difference
from exo_ilc_ros.core.params.config import scenario_path


def test_law_difference_by_hand() -> None:
    """One column: the fit is (c . y) / (c . c); y = 2 s (s the hard law's column): the hard
    refit gives 2, the smooth column t gives (t . y) / (t . t), the shift their difference."""
    hard = np.array([-1.0, -1.0, 1.0, 1.0])
    smooth = np.array([-0.9, -0.5, 0.5, 0.9])
    y = 2.0 * hard
    shift = law_difference(smooth[:, None], y, 0, hard)
    expected = 2.0 - (smooth @ y) / (smooth @ smooth)
    assert shift.shape == (1,)
    assert math.isclose(shift[0], expected, rel_tol=1e-12)
    # a second column the law does not touch moves only by its correlation with the first
    phi = np.column_stack([smooth, np.ones(4)])
    both = law_difference(phi, y + 0.3, 0, hard)
    assert np.allclose(both, [2.0, 0.3] - np.linalg.lstsq(phi, y + 0.3, rcond=None)[0])


def test_intervals_carry_the_model_error_and_trust_reads_the_noise() -> None:
    """Our plant's friction patient on the reversing exercise: every fitted parameter's
    interval is value +- 1.96 hypot(SE, model error); the model error is > 0 for the ones
    fitted beside Coulomb friction, 0 where it is left out (the paper's one-way movement) and
    with ``reversal_speed`` 0 (the tanh law trusted at every speed); the trust reason is the
    noise SE's (a precision between the noise's half-width and the interval's still uses the
    estimate); the JSON carries it."""
    config = load_config(overlays=[scenario_path("friction")],
                         overrides={"exercise.name": "reach_and_return_identify",
                                    "mass_uncertainty": 0.05})
    experiment = Experiment(config)
    record = experiment.run_trial(np.zeros(experiment.reference.position.shape), 1)
    settings = IdentificationSettings.from_config(config, reversal_speed=0.2, reflex=False)
    estimate = JointForceIdentifier(build_arm(config), settings).update_record(record)
    seen = fitted = 0
    for joint in estimate.joints:
        for name in ("viscous", "coulomb", "stiffness", "offset", "rest_position"):
            p = joint[name]
            if not math.isfinite(p.value):
                continue
            half = Z95 * math.hypot(p.standard_error, p.model_error)
            assert math.isclose(p.high - p.value, half, rel_tol=1e-9, abs_tol=1e-15)
            assert math.isclose(p.value - p.low, half, rel_tol=1e-9, abs_tol=1e-15)
            assert p.total_error >= p.standard_error
            if p.identifiable:
                assert p.reason == judge(name, p.value, p.standard_error, settings)
            seen += 1
        if "coulomb" not in joint.absorbed:
            assert joint["viscous"].model_error > 0.0 and joint["coulomb"].model_error > 0.0
            fitted += 1
    assert seen >= 12 and fitted >= 1
    # a precision between the noise's half-width and the interval's: still used
    joint = next(j for j in estimate.joints if "coulomb" not in j.absorbed)
    b = joint["viscous"]
    noise, total = Z95 * b.standard_error, Z95 * b.total_error
    assert noise < total
    between = dataclasses.replace(settings,
                                  relative_precision=(noise + total) / 2.0 / abs(b.value))
    again = JointForceIdentifier(build_arm(config), between).update_record(record)
    assert again.joints[joint.joint]["viscous"].trustworthy
    assert again.joints[joint.joint]["viscous"].high - b.value > between.relative_precision \
        * abs(b.value)
    data = json.loads(json.dumps(estimate.as_dict()))
    assert data["joints"][0]["parameters"]["viscous"]["model_error"] > 0.0
    one_way = load_config(overlays=[scenario_path("friction")],
                          overrides={"mass_uncertainty": 0.05})
    paper = Experiment(one_way)
    plain = JointForceIdentifier(build_arm(one_way), IdentificationSettings.from_config(
        one_way, reversal_speed=0.2, reflex=False)).update_record(
        paper.run_trial(np.zeros(paper.reference.position.shape), 1))
    absorbed = [j for j in plain.joints if "coulomb" in j.absorbed]
    assert absorbed, "the paper's movement leaves a joint's Coulomb friction out"
    for joint in absorbed:
        assert joint["viscous"].model_error == 0.0 and joint["offset"].model_error == 0.0
    trusted = JointForceIdentifier(build_arm(config), IdentificationSettings.from_config(
        config, reversal_speed=0.0, reflex=False)).update_record(record)
    assert all(j[name].model_error == 0.0 for j in trusted.joints
               for name in ("viscous", "coulomb", "stiffness")), "reversal_speed 0: tanh trusted"
