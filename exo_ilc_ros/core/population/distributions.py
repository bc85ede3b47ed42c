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
- **Body size** (only where the arm file carries a person, ``person.enabled``): sex 50/50,
  height and body mass each at a percentile drawn uniformly in 5-95 % of the adult table
  :data:`ADULT_PERCENTILES` (NHANES 2003-2006, McDowell et al. 2008, Natl Health Stat Report 10,
  adults 20 years and over; rounded), interpolated linearly; de Leva 1996 makes the segments
  (core/arm/body_segments.py). Height and mass are drawn independently (their correlation,
  ~0.4-0.5, is left out: the extremes are both kept).
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

    def coordinates(self, joints: Sequence[str], person: bool) -> list[str]:
        """The unit-cube coordinates of one patient of these joints: one per drawn quantity."""
        names = ["mas", "encoder", "mass.size", "mass.sign"]
        for j in joints:
            names += [f"stiffness.{j}", f"rest.{j}", f"viscous.{j}", f"coulomb.{j}"]
        if self.voluntary_share > 0:
            names += ["voluntary", "voluntary.gain", "voluntary.amplitude",
                      "voluntary.timing", "voluntary.fatigue"]
        if person:
            names += ["body.sex", "body.height", "body.mass"]
        return names


def coordinate_family(name: str) -> str:
    """The :data:`SOURCES` entry a coordinate draws from (``stiffness.elbow`` -> stiffness)."""
    head = name.split(".", 1)[0]
    return {"mass": "mass", "body": "body"}.get(head, head)


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
        return str(self.overrides["patient.spasticity.mas_grade"])

    def describe(self) -> str:
        """One line: grade, per-joint K / q_0 offset / B / F_c, encoder, mass error."""
        o = self.overrides

        def joints(key: str) -> str:
            return "/".join(f"{x:.2f}" for x in o[key])
        text = (f"MAS {self.mas_grade}, K {joints('patient.passive.stiffness')} N m/rad "
                f"rest {joints('patient.passive.rest_position')} rad, B "
                f"{joints('patient.friction.viscous')}, F_c {joints('patient.friction.coulomb')}"
                f", {'14-bit encoder' if o['patient.sensor.quantisation'] else 'ideal sensors'}"
                f", mass {100 * o['mass_uncertainty']:+.1f} %")
        if "person.body_mass" in o:
            text += (f", {o['person.sex']} {o['person.height']:.2f} m "
                     f"{o['person.body_mass']:.0f} kg")
        return text


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
    person = bool(values["person.enabled"])
    missing = [c for c in spec.coordinates(joints, person) if c not in unit]
    if missing:
        raise ValueError(f"the patient's point lacks the coordinates {missing}")
    u = {k: min(max(float(v), 0.0), 1.0) for k, v in unit.items()}
    probabilities = spec.mas_probabilities
    if uniform_grades:
        grades = [g for g in MAS_ORDER if probabilities.get(g, 0.0) > 0]
        probabilities = {g: 1.0 / len(grades) for g in grades}
    grade = _grade(u["mas"], probabilities)
    low, high = STIFFNESS_BANDS[grade]
    reach = REST_BANDS[grade]
    # q_0 counts from patient.joint_zero, signed as patient.joints (core/loop/patient.py
    # rest_positions): the rest angle 'off the start' in the patient's angle
    start = np.asarray(values["trajectory.start"], dtype=float)[patient_joint_indices(base)]
    zero = np.asarray(values["patient.joint_zero"], dtype=float)
    signs = patient_joint_signs(base)
    offsets = [reach * (2.0 * u[f"rest.{j}"] - 1.0) for j in joints]
    rest = signs * (start - zero) + np.asarray(offsets)
    size = spec.mass_error[0] + (spec.mass_error[1] - spec.mass_error[0]) * u["mass.size"]
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
        "mass_uncertainty": size if u["mass.sign"] >= 0.5 else -size,
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
        sex = "male" if u["body.sex"] < 0.5 else "female"
        table = ADULT_PERCENTILES[sex]
        overrides.update({
            "person.sex": sex,
            "person.height": _percentile(table["height"], 0.05 + 0.9 * u["body.height"]),
            "person.body_mass": _percentile(table["body_mass"], 0.05 + 0.9 * u["body.mass"]),
        })
    return Patient(index, u, overrides)


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
    joints = schema.patient_joint_names(base.values)
    names = spec.coordinates(joints, bool(base.values["person.enabled"]))
    rng = np.random.default_rng(np.random.SeedSequence([seed, index]))
    point = rng.random(len(names))
    patient = patient_from_unit(base, spec, dict(zip(names, point.tolist(), strict=True)),
                                index)
    patient.overrides["patient.seed"] = patient_seed(seed, index)
    return patient


def draw_population(base: Config, spec: PopulationSpec, size: int, seed: int) -> list[Patient]:
    """Patients 0 .. size-1 of the population ``seed`` (:func:`draw_patient`)."""
    return [draw_patient(base, spec, seed, i) for i in range(size)]
