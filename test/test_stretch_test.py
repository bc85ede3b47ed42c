"""The stretch test (core/person/stretch_test.py, ``exo-ilc stretch-test``) on MyoSuite's small
elbow: the ramp by hand, the hinge fit on a known hinge, and McPherson et al. 2018's findings on
the presets: reflex stiffness rises with velocity while the threshold angle moves little, MAS 0
has no reflex, and no reflex torque comes before the delay after a threshold is crossed."""

from __future__ import annotations

import contextlib
import io
import json
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core.person.neural_drive import DriveSettings, with_preset
from exo_ilc_ros.core.person.stretch_test import (
    RampAndHold,
    StretchPerson,
    StretchTrace,
    hinge_fit,
    measure_stretch,
    run_stretch,
    spring_damper_fit,
    stretch_person,
    stretch_test,
)

pytest.importorskip("myo_sim")
BASE = DriveSettings(delay=0.1, spastic_muscles=("BIClong", "BICshort", "BRA", "BRD"))
RAMP = RampAndHold(start=math.radians(120.0), end=math.radians(40.0), hold=0.1)


@pytest.fixture(scope="module")
def person() -> StretchPerson:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return stretch_person("myoelbow")


def test_ramp_profile_by_hand() -> None:
    """Rest, a constant-acceleration blend, the constant velocity, the blend down, hold: the
    angle moves by exactly start - end, the velocity is the ramp's within its window."""
    ramp = RampAndHold(start=1.0, end=0.5, velocity=1.0, rest=0.1, hold=0.1, blend=0.02)
    t, q, qd, qdd = ramp.profile(0.001)
    assert q[0] == 1.0 and q[-1] == pytest.approx(0.5, abs=1e-9)
    first, last = ramp.ramp_window()
    assert (first, last) == (pytest.approx(0.12), pytest.approx(0.6))
    window = (t > first + 1e-9) & (t < last - 1e-9)
    np.testing.assert_allclose(qd[window], -1.0)
    assert np.all(qd[t <= 0.1] == 0.0) and np.all(qd[t >= 0.62] == 0.0)
    np.testing.assert_allclose(qdd[(t > 0.1) & (t < 0.12)], -50.0)  # 1 rad/s over 20 ms


def test_hinge_fit_finds_a_known_hinge() -> None:
    x = np.linspace(0.0, 1.5, 301)
    y = 4.0 * np.maximum(x - 0.6, 0.0)
    knee, slope = hinge_fit(x, y)
    assert knee == pytest.approx(0.6, abs=0.01) and slope == pytest.approx(4.0, rel=0.02)


def test_mas_0_shows_no_reflex(person: StretchPerson) -> None:
    for velocity in (30.0, 150.0):
        m = measure_stretch(person, with_preset(BASE, "0"),
                            replace(RAMP, velocity=math.radians(velocity)), "0")
        assert m.reflex_peak == 0.0 and m.stiffness == 0.0 and m.threshold_angle is None
        assert m.resistance > 0.0  # the passive muscles and joint still resist


def test_reflex_torque_is_exactly_the_reflex(person: StretchPerson) -> None:
    """A drive whose reflex never fires (threshold beyond the stretch) gives the reflex-free
    stretch's resistance to the last digit: the subtraction leaves no passive residue."""
    quiet = replace(with_preset(BASE, "3"), length_threshold=5.0)
    a = run_stretch(person, quiet, replace(RAMP, velocity=math.radians(90.0)))
    b = run_stretch(person, replace(quiet, length_gain=0.0, velocity_gain=0.0),
                    replace(RAMP, velocity=math.radians(90.0)))
    np.testing.assert_array_equal(a.resistance, b.resistance)


@pytest.mark.parametrize("grade", ["1+", "3"])
def test_stiffness_rises_with_velocity_threshold_moves_little(person: StretchPerson,
                                                              grade: str) -> None:
    """McPherson et al. 2018: reflex stiffness rises with stretch velocity, the threshold angle
    moves little. Here: K grows at every step 30 -> 90 -> 150 deg/s and at least doubles; the
    threshold angle moves by no more than the delay's share (velocity x delay: the reflex acts
    0.1 s after the threshold is crossed) plus 5 deg."""
    settings = with_preset(BASE, grade)
    measures = [measure_stretch(person, settings, replace(RAMP, velocity=math.radians(v)), grade)
                for v in (30.0, 90.0, 150.0)]
    stiffness = [m.stiffness for m in measures]
    assert stiffness[0] < stiffness[1] < stiffness[2] and stiffness[2] > 2.0 * stiffness[0]
    thresholds = [m.threshold_angle for m in measures]
    assert None not in thresholds
    delay_share = (150.0 - 30.0) * BASE.delay
    assert abs(thresholds[2] - thresholds[0]) <= delay_share + 5.0  # type: ignore[operator]
    for m in measures:  # delay respected: the reflex torque rises >= 0.1 s after a crossing
        assert m.onset_time is not None and m.crossing_time is not None
        assert m.onset_time - m.crossing_time >= BASE.delay - 1e-9


def test_a_shorter_delay_starts_the_reflex_sooner(person: StretchPerson) -> None:
    """The delay is the drive's: 0.02 s instead of 0.1 s moves the onset 0.08 s earlier
    (within the activation's rise, a few steps)."""
    ramp = replace(RAMP, velocity=math.radians(90.0))
    slow = measure_stretch(person, with_preset(BASE, "2"), ramp, "2")
    fast = measure_stretch(person, with_preset(replace(BASE, delay=0.02), "2"), ramp, "2")
    assert slow.crossing_time == fast.crossing_time
    assert slow.onset_time - fast.onset_time == pytest.approx(0.08, abs=0.006)  # type: ignore[operator]


def test_cli_prints_and_writes_the_same_measures(tmp_path: Path) -> None:
    from exo_ilc_ros.cli.main import main
    out = tmp_path / "stretch.json"
    figure = tmp_path / "stretch.png"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        code = main(["stretch-test", "--grades", "0", "2", "--velocities", "60", "150",
                     "--json", str(out), "--plot", str(figure)])
    assert code == 0 and figure.stat().st_size > 0
    document = json.loads(out.read_text())
    table = printed.getvalue().split("spring-damper")[0]
    rows = [line.split() for line in table.splitlines()
            if line.split() and line.split()[0] in ("0", "2")]
    assert len(rows) == len(document["measures"]) == 4
    for row, m in zip(rows, document["measures"], strict=True):
        assert (row[0], float(row[1])) == (m["grade"], m["velocity"])
        assert float(row[4]) == pytest.approx(m["stiffness"], abs=0.005)
        assert float(row[2]) == pytest.approx(m["resistance"], abs=0.005)
    assert document["measures"][0]["threshold_angle"] is None
    assert set(document["spring_dampers"]) == {"0", "2"}
    assert document["measures"][3]["stiffness"] > document["measures"][2]["stiffness"] > 0.0


def test_spring_damper_fit_recovers_a_known_spring_damper() -> None:
    """Stretches whose torque is exactly 3 (theta_0 - theta) + 0.4 thetadot_ext give back
    K 3, B 0.4 and theta_0 (here 80 deg flexion), r2 1."""
    stretches = []
    for velocity in (0.5, 1.0, 2.0):
        ramp = RampAndHold(start=2.0, end=0.5, velocity=velocity, rest=0.1, hold=0.1)
        t, q, qd, _ = ramp.profile(0.002)
        torque = 3.0 * (math.radians(80.0) - q) + 0.4 * (-qd)
        trace = StretchTrace(t, q, torque, np.zeros((t.size, 1)), np.zeros(t.size))
        stretches.append((trace, ramp))
    fit = spring_damper_fit(stretches)
    assert fit.stiffness == pytest.approx(3.0) and fit.damping == pytest.approx(0.4)
    assert fit.offset_angle == pytest.approx(80.0) and fit.r2 == pytest.approx(1.0)


def test_spring_damper_rises_with_the_grade(person: StretchPerson) -> None:
    """McCrea et al. 2003: the hypertonic elbow's K and B rise with the MAS. MAS 0's damping
    is the model's joint damping (0.5 N m s/rad): its muscles resist without reflex and their
    passive force does not depend on velocity."""
    result = stretch_test(person, BASE, ["0", "2"], (60.0, 150.0), RAMP)
    none, spastic = result.spring_dampers["0"], result.spring_dampers["2"]
    assert none.damping == pytest.approx(0.5, abs=0.02)
    assert spastic.stiffness > none.stiffness and spastic.damping > 1.5 * none.damping
    assert len(result.measures) == 4


@pytest.mark.parametrize("argv", [["--velocities", "0"], ["--velocities", "fast"],
                                  ["--grades", "4"], ["--model", "myohand"]])
def test_cli_refuses_bad_input_naming_the_flag(argv: list[str]) -> None:
    from exo_ilc_ros.cli.main import main
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["stretch-test", *argv])
    assert code == 2 and argv[0] in err.getvalue()
