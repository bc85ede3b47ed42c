"""Patients drawn from published distributions (issue 33): each patient is a set of config
overrides through the one schema (``patient.*``, ``mass_uncertainty``, ``person.*``), so it lies
over any arm file, reproducible from (seed, index).

Every patient is a point of the unit cube (:class:`PopulationSpec.coordinates`): one coordinate
in [0, 1] per drawn quantity, mapped onto the published ranges by :func:`patient_from_unit`. A
population draws the coordinates uniformly from ``default_rng(SeedSequence([seed, index]))``
(:func:`draw_patient`); the falsification (:mod:`exo_ilc_ros.analysis.falsification`) searches
the same cube, so it can only find patients the ranges allow.

Sources of each quantity (:data:`SOURCES`; docs/every-patient.md), per joint of the patient
(``patient.joints`` where the arm file names them, else every arm joint):

- **MAS grade** (Modified Ashworth, 0 / 1 / 1+ / 2 / 3): 27 % of patients spastic (MAS >= 1)
  at the elbow 12 months after stroke (Watkins et al. 2002, Clin Rehabil 16:515, 106 patients;
  19-21 % at 1 week-3 months, Sommerfeld et al. 2004, Stroke 35:134); the spastic share split
  over grades 1 / 1+ / 2 / 3 as 3 / 5 / 3 / 3, McCrea et al. 2003's 17 patients (J Neurosci
  Methods 128:121; grade 0 there: 3). A grade is one patient's, on every joint, through its
  preset (core/loop/patient.py ``MAS_PRESETS``: spastic stiffness, damping and stretch reflex).
- **Passive stiffness** K (N m/rad): healthy elbow 0.40-1.8 (Wiegner and Watts 1986, JNNP
  49:1171); in chronic stroke K rises with the MAS (McCrea et al. 2003, r = 0.82). Drawn
  uniformly in a band that rises with the grade (:data:`STIFFNESS_BANDS`, derived), within the
  issue's 0-4 N m/rad.
- **Rest angle** q_0 (rad from the movement's start): up to 0.6 rad off the start, farther with
  a higher grade (resting elbow angle vs MAS, r = -0.89, McCrea et al. 2003; healthy neutral
  angle 107 +- 10 deg, Wiegner and Watts 1986): |q_0 - q_start| <= :data:`REST_BANDS` of the
  grade, either side (derived).
- **Viscous friction** B: 0-0.4 N m s/rad (MAHI Open Exo's identified 0.0025-0.069; OpenSim arm
  damping ~0.1, Saul et al. 2015; McCrea et al. 2003's fitted B; the issue's range).
- **Coulomb friction** F_c: 0-0.35 N m (MAHI Open Exo's identified 0.10-0.18 N m; the issue's
  range).
- **Sensors**: a 14-bit joint encoder (2 pi / 2^14 = 3.8e-4 rad) with velocity differenced and
  10 ms low-passed in :attr:`PopulationSpec.encoder_share` of the patients (half: the issue),
  ideal sensors in the rest (sensor.yaml, realistic.yaml).
- **Mass error**: the plant's masses 5-15 % off the controller's, heavier or lighter
  (``mass_uncertainty``; the issue's range; the study's 5 / 10 / 15 %).
- **Voluntary effort and fatigue** in :attr:`PopulationSpec.voluntary_share` of the patients
  (0 by default: a patient's non-repeating effort sets a floor no learning removes, the
  voluntary scenario's 1.2-1.6e-2 rad, so the certificate's 0.005 rad is for a passive
  patient): voluntary.yaml's spring-damper toward the reference scaled by 0-1, its trial-to-trial
  amplitude and timing sd (Emken et al. 2007, J NeuroEng Rehabil 4:8) and fatigue (Xu, Chu and
  Rogers 2014) scaled alike.
- **Body size** (only where the arm file carries a person, ``person.enabled``, or scales a
  person with muscles to one, ``musculoskeletal.body_size: person``): sex 50/50,
  height and body mass each at a percentile drawn uniformly in 5-95 % of the adult table
  :data:`ADULT_PERCENTILES` (NHANES 2003-2006, McDowell et al. 2008, Natl Health Stat Report 10,
  adults 20 years and over; rounded), interpolated linearly; de Leva 1996 makes the segments
  (core/arm/body_segments.py). Height and mass are drawn independently (their correlation,
  ~0.4-0.5, is left out: the extremes are both kept).

**A person with muscles** (``musculoskeletal.model`` set: MyoArm or the elbow model strapped in
cuffs, issue 34; core/person/): the patient is the person's parameters, not torques on the
exoskeleton's joints (the virtual patient's ``patient.*`` effects are refused there):

- **MAS grade**: drawn as above; its preset of the neural drive (``person.drive.mas_grade``,
  core/person/neural_drive.py ``MAS_DRIVE_PRESETS``: tone, the delayed stretch reflex per
  spastic muscle on fibre length and velocity; docs/stretch-test.md).
- **Misalignment**: the exoskeleton's offset from the fit to the person's joints uniform in a
  ball of :data:`MISALIGNMENT_OFFSET` mm (issue 34: up to 10 mm; misaligned joint axes are what
  load the cuffs, Schiele and van der Helm 2006, IEEE TNSRE 14:456), and a rotation uniform
  within +- :data:`MISALIGNMENT_ROTATION` deg about each base axis (derived: "a few degrees").
- **Strap stiffness**: one coordinate places the patient's cuffs between the softest and the
  stiffest of Schiebl et al. 2025's linear fits (Sensors 25:4605, Appendix B.1: subject-group
  and mean individual regressions, both load directions) on every axis at once
  (:data:`STRAP_STIFFNESS_RANGE`): the spread of the published fits, not of the 21 subjects.
- **Mass error**: the exoskeleton's masses, as above.
- **Body size**, as above, when the config scales the person (``musculoskeletal.body_size:
  person``, core/person/body_size.py); with ``model`` every person is MyoSuite's one adult.
- Not drawn: the sensors (the strapped plant has no sensor model: its measured state is the
  true one), voluntary effort.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..loop.patient import patient_joint_indices, patient_joint_signs
from ..params import schema
from ..params.config import Config

MAS_ORDER = ("0", "1", "1+", "2", "3")
"""The grades a patient may have (the presets of core/loop/patient.py ``MAS_PRESETS``)."""

SPASTIC_SHARE = 0.27
"""Share of patients with MAS >= 1 (Watkins et al. 2002: 27 % at 12 months)."""

MCCREA_GRADE_COUNTS = {"1": 3, "1+": 5, "2": 3, "3": 3}
"""McCrea et al. 2003: patients per spastic grade (17 in all, 3 of grade 0)."""

STIFFNESS_BANDS: dict[str, tuple[float, float]] = {
    "0": (0.0, 1.8), "1": (0.4, 2.2), "1+": (0.8, 2.8), "2": (1.4, 3.4), "3": (2.0, 4.0)}
"""MAS grade -> passive stiffness band (N m/rad), derived: grade 0 from 0 (the paper's plant) to
Wiegner and Watts' healthy 1.8; each grade shifted up (McCrea et al. 2003, r = 0.82) to 4 at
grade 3 (the issue's range)."""

REST_BANDS: dict[str, float] = {"0": 0.2, "1": 0.3, "1+": 0.4, "2": 0.5, "3": 0.6}
"""MAS grade -> largest |q_0 - q_start| (rad), derived: farther with the grade (McCrea et al.
2003, r = -0.89), 0.6 rad at grade 3 (the issue's range)."""

VISCOUS_MAX = 0.4
"""N m s/rad (the issue's range; MAHI Open Exo, OpenSim arm, McCrea et al. 2003)."""
COULOMB_MAX = 0.35
"""N m (the issue's range; MAHI Open Exo's 0.10-0.18)."""
ENCODER_RESOLUTION = 2.0 * math.pi / 2 ** 14
"""rad: a 14-bit joint encoder."""
ENCODER_VELOCITY_FILTER = 0.01
"""s: the differenced velocity's first-order filter (realistic.yaml)."""
MASS_ERROR = (0.05, 0.15)
"""|mass_uncertainty| range (the issue's 5-15 %)."""

VOLUNTARY_STIFFNESS = 2.5
VOLUNTARY_DAMPING_RATIO = 0.48
"""voluntary.yaml: K_v up to 2.5 N m/rad (half the controller's shoulder stiffness), D_v about
0.48 K_v (its 1.2 / 2.5)."""
VOLUNTARY_AMPLITUDE_SD = 0.2
VOLUNTARY_TIMING_SD = 0.05
VOLUNTARY_FATIGUE_RATE = 0.002
"""voluntary.yaml's largest values (Emken et al. 2007; Xu, Chu and Rogers 2014)."""

ADULT_PERCENTILES: dict[str, dict[str, tuple[float, float, float]]] = {
    "male": {"height": (1.63, 1.76, 1.88), "body_mass": (62.0, 86.0, 125.0)},
    "female": {"height": (1.51, 1.62, 1.73), "body_mass": (50.0, 72.0, 113.0)},
}
"""Adults 20 years and over, 5th / 50th / 95th percentile of height (m) and body mass (kg),
NHANES 2003-2006 (McDowell et al. 2008, Natl Health Stat Report 10, Tables 11-12 and 15-16;
rounded here: check the table before a clinical use)."""

MISALIGNMENT_OFFSET = 10.0
"""mm: the largest offset of the exoskeleton from the fit to the person's joints (issue 34)."""
MISALIGNMENT_ROTATION = 3.0
"""deg: the largest rotation about each of the exoskeleton's base axes (derived)."""
STRAP_STIFFNESS_RANGE: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "stiffness": ((2800.0, 3200.0, 2100.0), (4100.0, 4600.0, 2600.0)),
    "rotational_stiffness": ((0.20 * 180 / math.pi, 0.18 * 180 / math.pi, 0.03 * 180 / math.pi),
                             (0.22 * 180 / math.pi, 0.19 * 180 / math.pi,
                              0.04 * 180 / math.pi)),
}
"""``strapping.*`` key -> (softest, stiffest) per cuff axis [x mediolateral, y anteroposterior,
z along the limb]: the lowest and highest of Schiebl et al. 2025's linear fits over both load
directions (subject-group regressions and the mean of the individual ones, Appendix B.1):
latero-medial 2.8-4.1, caudo-cranial 3.2-4.6, disto-proximal 2.1-2.6 N/mm; rotation 0.20-0.22,
0.18-0.19, 0.03-0.04 N m/deg (here N/m and N m/rad)."""

SOURCES: dict[str, str] = {
    "mas": "Watkins et al. 2002 (Clin Rehabil 16:515): 27 % spastic at 12 months; Sommerfeld "
           "et al. 2004 (Stroke 35:134): 19-21 % early; grades 1/1+/2/3 as McCrea et al. 2003's "
           "17 patients (3/5/3/3); presets core/loop/patient.py MAS_PRESETS",
    "stiffness": "Wiegner and Watts 1986 (JNNP 49:1171): healthy elbow 0.40-1.8 N m/rad; "
                 "McCrea et al. 2003 (J Neurosci Methods 128:121): K rises with MAS (r = 0.82); "
                 "0-4 N m/rad (issue 33)",
    "rest": "McCrea et al. 2003: resting angle vs MAS r = -0.89; Wiegner and Watts 1986: "
            "neutral 107 +- 10 deg; up to 0.6 rad off the start (issue 33)",
    "viscous": "MAHI Open Exo identified B 0.0025-0.069 N m s/rad; OpenSim arm damping ~0.1 "
               "(Saul et al. 2015); McCrea et al. 2003; 0-0.4 N m s/rad (issue 33)",
    "coulomb": "MAHI Open Exo identified F_k 0.10-0.18 N m; 0-0.35 N m (issue 33)",
    "encoder": "14-bit joint encoder, 2 pi / 2^14 rad, velocity differenced (sensor.yaml); "
               "in half of the patients (issue 33)",
    "mass": "5-15 % mass error either way (issue 33; the study's 5/10/15 %)",
    "voluntary": "voluntary.yaml: half the controller's stiffness and damping; amplitude and "
                 "timing variability (Emken et al. 2007, J NeuroEng Rehabil 4:8); fatigue "
                 "(Xu, Chu and Rogers 2014, Control Eng Pract)",
    "body": "NHANES 2003-2006 adult percentiles (McDowell et al. 2008, Natl Health Stat "
            "Report 10); segments de Leva 1996 (J Biomech 29:1223)",
    "drive": "a person with muscles: the MAS grade's neural drive preset (core/person/"
             "neural_drive.py MAS_DRIVE_PRESETS; Feng and Mak 2002, Koo and Mak 2006, "
             "SpasticMyoElbow; calibrated against McPherson et al. 2018)",
    "misalignment": "offset up to 10 mm in a ball (issue 34); rotation +-3 deg per axis "
                    "(derived); misalignment loads the cuffs: Schiele and van der Helm 2006 "
                    "(IEEE TNSRE 14:456)",
    "strap": "Schiebl et al. 2025 (Sensors 25:4605, Appendix B.1): the softest to the "
             "stiffest linear fit per axis, 2.1-4.6 N/mm, 0.03-0.22 N m/deg",
}
"""Each drawn quantity's source (the coordinates' families: :func:`coordinate_family`)."""


@dataclass(frozen=True)
class PopulationSpec:
    """The population's ranges (defaults: the issue's) and which effects it draws."""

    mas_probabilities: Mapping[str, float] = field(default_factory=lambda: {
        "0": 1.0 - SPASTIC_SHARE,
        **{g: SPASTIC_SHARE * n / sum(MCCREA_GRADE_COUNTS.values())
           for g, n in MCCREA_GRADE_COUNTS.items()}})
    """MAS grade -> probability (sums to 1)."""
    encoder_share: float = 0.5
    voluntary_share: float = 0.0
    mass_error: tuple[float, float] = MASS_ERROR

    def __post_init__(self) -> None:
        if set(self.mas_probabilities) - set(MAS_ORDER) or \
                abs(sum(self.mas_probabilities.values()) - 1.0) > 1e-9 or \
                any(p < 0 for p in self.mas_probabilities.values()):
            raise ValueError(f"mas_probabilities must be probabilities of the grades "
                             f"{MAS_ORDER} summing to 1, got {dict(self.mas_probabilities)}")
        for name in ("encoder_share", "voluntary_share"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)}")
        low, high = self.mass_error
        if not 0.0 <= low <= high < 0.9:
            raise ValueError(f"mass_error must be 0 <= low <= high < 0.9, got {self.mass_error}")

    def coordinates(self, joints: Sequence[str], person: bool,
                    muscles: bool = False) -> list[str]:
        """The unit-cube coordinates of one patient of these joints: one per drawn quantity
        (``muscles``: a person with muscles, whose patient is the person's parameters)."""
        if muscles:
            return ["mas", "mass.size", "mass.sign", "misalignment.radius",
                    "misalignment.polar", "misalignment.azimuth", "misalignment.rotation.x",
                    "misalignment.rotation.y", "misalignment.rotation.z", "strap.stiffness",
                    *(BODY_COORDINATES if person else ())]
        names = ["mas", "encoder", "mass.size", "mass.sign"]
        for j in joints:
            names += [f"stiffness.{j}", f"rest.{j}", f"viscous.{j}", f"coulomb.{j}"]
        if self.voluntary_share > 0:
            names += ["voluntary", "voluntary.gain", "voluntary.amplitude",
                      "voluntary.timing", "voluntary.fatigue"]
        if person:
            names += BODY_COORDINATES
        return names


BODY_COORDINATES = ("body.sex", "body.height", "body.mass")
"""The unit-cube coordinates of a person's body size (sex, height and body mass)."""


def coordinate_family(name: str) -> str:
    """The :data:`SOURCES` entry a coordinate draws from (``stiffness.elbow`` -> stiffness)."""
    head = name.split(".", 1)[0]
    return {"mass": "mass", "body": "body"}.get(head, head)


def has_muscles(base: Config) -> bool:
    """The config straps a person with muscles into the exoskeleton (its patients are drawn
    as the person's parameters)."""
    return str(base.values["musculoskeletal.model"]) != "none"


def has_body_size(base: Config) -> bool:
    """The config's person takes a body size: the URDF person (``person.enabled``) or a
    person with muscles scaled to it (``musculoskeletal.body_size: person``)."""
    values = base.values
    if has_muscles(base):
        return str(values["musculoskeletal.body_size"]) == "person"
    return bool(values["person.enabled"])


def cube_coordinates(base: Config, spec: PopulationSpec) -> list[str]:
    """The unit-cube coordinates of a patient on the arm of ``base``."""
    return spec.coordinates(schema.patient_joint_names(base.values), has_body_size(base),
                            has_muscles(base))


@dataclass(frozen=True)
class Patient:
    """One patient of a population: where it came from and the config overrides it is."""

    index: int
    """Its index in the population (-1: not drawn from one, e.g. found by a search)."""
    unit: dict[str, float]
    """Its point of the unit cube (:meth:`PopulationSpec.coordinates`)."""
    overrides: dict[str, Any]
    """Config overrides (schema keys) that make the patient on the arm file."""

    @property
    def mas_grade(self) -> str:
        """Its Modified Ashworth grade."""
        o = self.overrides
        return str(o.get("patient.spasticity.mas_grade", o.get("person.drive.mas_grade")))

    def describe(self) -> str:
        """One line: grade, per-joint K / q_0 offset / B / F_c, encoder, mass error (a person
        with muscles: grade, misalignment, strap stiffness, mass error)."""
        o = self.overrides
        if "person.drive.mas_grade" in o:
            def vector(key: str, digits: int) -> str:
                return "/".join(f"{x:.{digits}f}" for x in o[key])
            return (f"MAS {self.mas_grade}, misaligned "
                    f"{vector('strapping.misalignment.offset', 1)} mm "
                    f"{vector('strapping.misalignment.rotation', 1)} deg, straps "
                    f"{'/'.join(f'{x / 1000:.2f}' for x in o['strapping.stiffness'])} N/mm, "
                    f"mass {100 * o['mass_uncertainty']:+.1f} %{self._body()}")

        def joints(key: str) -> str:
            return "/".join(f"{x:.2f}" for x in o[key])
        text = (f"MAS {self.mas_grade}, K {joints('patient.passive.stiffness')} N m/rad "
                f"rest {joints('patient.passive.rest_position')} rad, B "
                f"{joints('patient.friction.viscous')}, F_c {joints('patient.friction.coulomb')}"
                f", {'14-bit encoder' if o['patient.sensor.quantisation'] else 'ideal sensors'}"
                f", mass {100 * o['mass_uncertainty']:+.1f} %")
        return text + self._body()

    def _body(self) -> str:
        o = self.overrides
        if "person.body_mass" not in o:
            return ""
        return f", {o['person.sex']} {o['person.height']:.2f} m {o['person.body_mass']:.0f} kg"


def _percentile(table: tuple[float, float, float], p: float) -> float:
    """Linear through (5 %, 50 %, 95 %) of a percentile table, at p in [0.05, 0.95]."""
    return float(np.interp(p, (0.05, 0.5, 0.95), table))


def _grade(u: float, probabilities: Mapping[str, float]) -> str:
    """The grade at u of the inverse cumulative distribution (grades in :data:`MAS_ORDER`)."""
    total = 0.0
    grades = [g for g in MAS_ORDER if probabilities.get(g, 0.0) > 0]
    for g in grades:
        total += probabilities[g]
        if u < total:
            return g
    return grades[-1]


def patient_from_unit(base: Config, spec: PopulationSpec, unit: Mapping[str, float],
                      index: int = -1, uniform_grades: bool = False) -> Patient:
    """The patient at a point of the unit cube on the arm of ``base`` (:data:`SOURCES`: how
    each coordinate maps onto its range). ``uniform_grades``: every grade of ``spec`` a share
    of the MAS coordinate alike (a search covers the rare grades as well as the common)."""
    values = base.values
    joints = schema.patient_joint_names(values)
    person = has_body_size(base)
    missing = [c for c in cube_coordinates(base, spec) if c not in unit]
    if missing:
        raise ValueError(f"the patient's point lacks the coordinates {missing}")
    u = {k: min(max(float(v), 0.0), 1.0) for k, v in unit.items()}
    probabilities = spec.mas_probabilities
    if uniform_grades:
        grades = [g for g in MAS_ORDER if probabilities.get(g, 0.0) > 0]
        probabilities = {g: 1.0 / len(grades) for g in grades}
    grade = _grade(u["mas"], probabilities)
    if has_muscles(base):
        return Patient(index, u, {**person_overrides(spec, u, grade),
                                  **(body_overrides(u) if person else {})})
    low, high = STIFFNESS_BANDS[grade]
    reach = REST_BANDS[grade]
    # q_0 counts from patient.joint_zero, signed as patient.joints (core/loop/patient.py
    # rest_positions): the rest angle 'off the start' in the patient's angle
    start = np.asarray(values["trajectory.start"], dtype=float)[patient_joint_indices(base)]
    zero = np.asarray(values["patient.joint_zero"], dtype=float)
    signs = patient_joint_signs(base)
    offsets = [reach * (2.0 * u[f"rest.{j}"] - 1.0) for j in joints]
    rest = signs * (start - zero) + np.asarray(offsets)
    encoder = u["encoder"] < spec.encoder_share
    overrides: dict[str, Any] = {
        "patient.spasticity.mas_grade": grade,
        "patient.passive.stiffness": [low + (high - low) * u[f"stiffness.{j}"] for j in joints],
        "patient.passive.rest_position": [float(x) for x in rest],
        "patient.friction.viscous": [VISCOUS_MAX * u[f"viscous.{j}"] for j in joints],
        "patient.friction.coulomb": [COULOMB_MAX * u[f"coulomb.{j}"] for j in joints],
        "patient.sensor.quantisation": ENCODER_RESOLUTION if encoder else 0.0,
        "patient.sensor.differentiate_velocity": encoder,
        "patient.sensor.velocity_filter": ENCODER_VELOCITY_FILTER if encoder else 0.0,
        "mass_uncertainty": mass_error(spec, u),
    }
    for key in ("stiffness", "damping", "reflex_gain", "reflex_threshold", "reflex_max"):
        overrides[f"patient.spasticity.{key}"] = [0.0] * len(joints)  # the grade's preset
    if spec.voluntary_share > 0:
        share = u["voluntary.gain"] if u["voluntary"] < spec.voluntary_share else 0.0
        overrides.update({
            "patient.voluntary.stiffness": [VOLUNTARY_STIFFNESS * share] * len(joints),
            "patient.voluntary.damping":
                [VOLUNTARY_STIFFNESS * VOLUNTARY_DAMPING_RATIO * share] * len(joints),
            "patient.voluntary.amplitude_sd": VOLUNTARY_AMPLITUDE_SD * u["voluntary.amplitude"],
            "patient.voluntary.timing_sd": VOLUNTARY_TIMING_SD * u["voluntary.timing"],
            "patient.voluntary.fatigue_rate": VOLUNTARY_FATIGUE_RATE * u["voluntary.fatigue"],
        })
    if person:
        overrides.update(body_overrides(u))
    return Patient(index, u, overrides)


def body_overrides(u: Mapping[str, float]) -> dict[str, Any]:
    """The person's sex, height and body mass at a point of the unit cube (module docstring,
    *Body size*)."""
    sex = "male" if u["body.sex"] < 0.5 else "female"
    table = ADULT_PERCENTILES[sex]
    return {
        "person.sex": sex,
        "person.height": _percentile(table["height"], 0.05 + 0.9 * u["body.height"]),
        "person.body_mass": _percentile(table["body_mass"], 0.05 + 0.9 * u["body.mass"]),
    }


def mass_error(spec: PopulationSpec, u: Mapping[str, float]) -> float:
    """The signed mass error of the coordinates ``mass.size`` and ``mass.sign``."""
    size = spec.mass_error[0] + (spec.mass_error[1] - spec.mass_error[0]) * u["mass.size"]
    return size if u["mass.sign"] >= 0.5 else -size


def person_overrides(spec: PopulationSpec, u: Mapping[str, float],
                     grade: str) -> dict[str, Any]:
    """A person with muscles at a point of the unit cube (module docstring): the grade's neural
    drive preset, the misalignment (an offset uniform in a ball, a rotation per axis), the
    cuffs' stiffness between the published fits, the exoskeleton's mass error."""
    radius = MISALIGNMENT_OFFSET * u["misalignment.radius"] ** (1.0 / 3.0)  # uniform in a ball
    cos_polar = 2.0 * u["misalignment.polar"] - 1.0
    sin_polar = math.sqrt(max(0.0, 1.0 - cos_polar ** 2))
    azimuth = 2.0 * math.pi * u["misalignment.azimuth"]
    offset = [radius * sin_polar * math.cos(azimuth), radius * sin_polar * math.sin(azimuth),
              radius * cos_polar]
    rotation = [MISALIGNMENT_ROTATION * (2.0 * u[f"misalignment.rotation.{a}"] - 1.0)
                for a in "xyz"]
    strap = u["strap.stiffness"]
    overrides: dict[str, Any] = {
        "person.drive.mas_grade": grade,
        "strapping.misalignment.offset": [float(x) for x in offset],
        "strapping.misalignment.rotation": [float(x) for x in rotation],
        "mass_uncertainty": mass_error(spec, u),
    }
    for key, (soft, stiff) in STRAP_STIFFNESS_RANGE.items():
        overrides[f"strapping.{key}"] = [float(a + (b - a) * strap)
                                         for a, b in zip(soft, stiff, strict=True)]
    return overrides


def search_point(patient: Patient, spec: PopulationSpec) -> dict[str, float]:
    """The patient's point of the unit cube as :func:`patient_from_unit` reads it with
    ``uniform_grades`` (the MAS coordinate moved to the middle of its grade's equal share)."""
    grades = [g for g in MAS_ORDER if spec.mas_probabilities.get(g, 0.0) > 0]
    point = dict(patient.unit)
    point["mas"] = (grades.index(patient.mas_grade) + 0.5) / len(grades)
    return point


def patient_seed(seed: int, index: int) -> int:
    """The patient's own ``patient.seed`` (its per-trial noise), from (seed, index)."""
    return int(np.random.SeedSequence([seed, index, 1]).generate_state(1)[0])


def draw_patient(base: Config, spec: PopulationSpec, seed: int, index: int) -> Patient:
    """Patient ``index`` of the population ``seed``: its point of the unit cube drawn uniformly
    from ``default_rng(SeedSequence([seed, index]))``; the same (seed, index) is the same
    patient on every machine, whatever the population's size."""
    names = cube_coordinates(base, spec)
    rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
    point = rng.random(len(names))
    patient = patient_from_unit(base, spec, dict(zip(names, point.tolist(), strict=True)),
                                index)
    patient.overrides["patient.seed"] = patient_seed(seed, index)
    return patient


def draw_population(base: Config, spec: PopulationSpec, size: int, seed: int) -> list[Patient]:
    """Patients 0 .. size-1 of the population ``seed`` (:func:`draw_patient`)."""
    return [draw_patient(base, spec, seed, i) for i in range(size)]
