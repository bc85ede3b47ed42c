"""The trial-to-trial factor with the patient in the loop, worst case over ranges of patients
(``exo-ilc analyze-loop --patient-ranges``): what a law must survive when identification cannot
help (the patient's forces not yet, or never, identified).

A passive stiffness K on a joint adds K / I to the closed loop's stiffness and a viscous B adds
B / I to its damping (:class:`.joint_loop.JointLoop`, eq (6)'s Q^c and Q^v), I the inertia the
joint's torque meets. On a serial arm that is not the diagonal of a_N: a torque on the elbow
also accelerates the joints beyond it, so the elbow's own acceleration per N m is
(a_N(q)^-1)_jj, and I = 1 / (a_N(q)^-1)_jj, the joint's inertia with the others free (the
paper's arm at its start: 0.041 kg m^2 on the diagonal, 0.011 with the shoulders free). The
worst case along the reference is the smallest I, so per joint

    stiffness_j = (K_j + K_MAS) max_t (a_N(q_d(t))^-1)_jj,
    damping_j   = (B_j + B_MAS) max_t (a_N(q_d(t))^-1)_jj                                (PR)

on the arm joints the patient acts on (``patient.joints``), 0 elsewhere. The ranges' corners
(K and B at 0 and at their largest, every MAS preset, the mass error at both ends) are the
candidates: |F| of eq (*) (:mod:`.factors`) is evaluated at each and the largest kept per
joint. With the law's own update only (identification's inverse left out: the robust case)
and, where the config has them, the progress gain on and off and the averaging gain at
``min_gain`` and 1 (u_ff,k+1 = (1 - K) u_ff,k + K F u_ff,k: the factor (1 - K) + K F).

The stretch reflex is in the loop too (issue 33): each MAS preset's reflex gain G, per unit
of the same inertia (reflex_j = G max_t (a_N(q_d(t))^-1)_jj, s^-1), on the velocity
``reflex_delay`` ago (0.1 s, SpasticMyoElbow's, rounded to control periods), linearised where
it is active (above its threshold, below its ceiling: the worst case, as during the movement).
The reflex is counted on a joint whose reference moves faster than the preset's threshold
somewhere (max_t |qdot_d,j(t)| > v_th; the paper's quintic moves the elbow at up to 0.196
rad/s, above MAS 3's 0.1, below MAS 2's 0.2). The patient's stiffness and damping act within
the period as the plant integrates them (``continuous_patient``), the reflex and the PD held
over it. A delayed damping can make the loop *within a trial* unstable, where eq (*) means
nothing: so every corner's poles are checked first
(:meth:`.joint_loop.JointLoop.spectral_radius`), and a corner whose loop has a pole on or
outside the unit circle is the worst there is (factor inf, reported with the pole's radius and
frequency). Against a delayed velocity feedback G an undelayed damping D > G keeps the loop
stable for any delay; the paper arm's elbow (I >= 0.011 kg m^2) would need K_D > (G - B) / I
~ 110 s^-1 against MAS 3's 2 N m s/rad, and a PD sampled at 100 Hz does not get there: over
K_P 225-6400 s^-2 and K_D 30-150 s^-1 its loop keeps a pole at radius 1.04-1.16 (4.8 Hz, the
chatter the population's MAS 3 patients show, at the lower K_D). Nor does any other velocity
feedback at 100 Hz: with G T / I >= 1 (``JointWorst.sampled_reflex``: 1.83 there) even the
deadbeat one leaves a pole outside the unit circle, and the report says so.

Left out, as in :mod:`.patient_load`: the Coulomb friction (it saturates: a bounded torque
each trial, learned like any repeating disturbance), the reflex's threshold and ceiling (they
bound an unstable loop's oscillation, a limit cycle, not remove it), the sensors (a
differentiated, low-passed encoder velocity lags the controller's damping further); the
coupling between joints (what a_N^-1 carries from the elbow's torque to the wrist's
acceleration, a repeating disturbance of the wrist learned like the others); and the
identified forces' inverse (it makes the factor the arm's alone once the patient is
identified: ``--scenarios``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from ..learning.laws import Memory
from ..learning.qfilter import qfilter_of
from ..loop.gains import feedback_gains, lightest_inverse_inertia
from ..loop.patient import MAS_PRESETS, patient_joint_indices
from ..params.config import Config
from ..reference.build import build_reference
from .factors import learning_gains
from .joint_loop import JointLoop


@dataclass(frozen=True)
class PatientRanges:
    """The ranges the worst case is taken over (the issue's stroke population, by default):
    passive stiffness and viscous friction from 0 to their largest (per patient joint, N m/rad
    and N m s/rad), the MAS presets (their spastic stiffness and damping added), the mass
    error's ends."""

    stiffness: float = 4.0
    viscous: float = 0.4
    mas_grades: tuple[str, ...] = ("0", "1", "1+", "2", "3")
    mass_uncertainty: tuple[float, float] = (0.05, 0.15)
    reflex_delay: float = 0.1
    """s: the stretch reflex's delay (SpasticMyoElbow's 0.1 s, the presets'); each MAS
    preset's reflex gain acts on the velocity this long ago."""
    reflex: bool = True
    """The presets' stretch reflex in the loop (False: left out, as before issue 33's
    MAS 3 patients)."""

    def corners(self) -> list[tuple[float, float, str, float]]:
        """(K, B, MAS grade, delta) of every corner."""
        return list(itertools.product((0.0, self.stiffness), (0.0, self.viscous),
                                      self.mas_grades, self.mass_uncertainty))


@dataclass(frozen=True)
class JointWorst:
    """One joint's worst factor over the ranges (with the Q-filter when the config has one)
    and the corner that gives it; ``nominal`` the same law's worst without a patient."""

    joint: str
    worst: float
    frequency_hz: float
    stiffness: float
    """N m/rad: the corner's passive plus spastic stiffness (0 where no patient joint acts)."""
    damping: float
    mas_grade: str
    mass_uncertainty: float
    nominal: float
    inverse_inertia: float
    """max_t (a_N^-1)_jj of (PR)."""
    patient: bool = True
    """A patient's joint acts on this arm joint (``patient.joints``)."""
    radius: float = 0.0
    """The largest pole radius of the loop within a trial at the worst corner (>= 1: unstable
    there, :attr:`worst` is inf)."""
    radius_hz: float = 0.0
    """That pole's frequency (Hz)."""
    reflex_gain: float = 0.0
    """N m s/rad: the corner's stretch reflex gain (its MAS preset's; 0 where none)."""
    sampled_reflex: float = 0.0
    """G T / I at the worst corner: its reflex gain over the joint's lightest inertia times the
    control period. At 1 or above no velocity feedback at this period holds the loop while the
    reflex is active, whatever the gains: against v_{i+1} = -(G T / I) v_{i-d} the best one
    (deadbeat, K_D T = 1) leaves poles of radius (G T / I)^(1 / (d + 1)); only a shorter period
    (below I / G) or damping inside the period (the patient's own, a damper) can."""

    @property
    def reflex_outruns_period(self) -> bool:
        """G T / I >= 1 (:attr:`sampled_reflex`): the period, not the gains, leaves the loop
        unstable."""
        return self.sampled_reflex >= 1.0

    @property
    def unstable(self) -> bool:
        """The loop within a trial is unstable at the worst corner (the reflex's delay)."""
        return self.radius >= 1.0


@dataclass(frozen=True)
class RangeAnalysis:
    """Per joint the worst factor with the patient in the loop (:class:`JointWorst`)."""

    ranges: PatientRanges
    joints: list[JointWorst]

    def worst(self) -> float:
        """max over joints of the worst factor."""
        return max(j.worst for j in self.joints)


def analyze_patient_ranges(config: Config, ranges: PatientRanges | None = None,
                           points: int = 1001) -> RangeAnalysis:
    """(PR) at every corner of ``ranges``: the worst |F| per joint of the config's linear or
    sign law (its linear part) with the patient in the loop, the Q-filter, progress gain and
    averaging as the config has them, identification's inverse left out."""
    ranges = ranges or PatientRanges()
    period = float(config["control.period"])
    frequency = np.linspace(0.0, 0.5 / period, points)
    q_filter = qfilter_of(config)
    q = q_filter.response(frequency) if q_filter is not None else np.ones_like(frequency)
    memory = Memory(config["memory"])
    law = config["law"] if config["law"] in ("linear", "sign") else "linear"
    gains_of = learning_gains(config, law)
    progress = np.asarray(config["progress_gain.position"], dtype=float)
    averaging = (float(config["averaging.min_gain"]), 1.0) \
        if float(config["averaging.memory"]) > 0.0 else (1.0,)
    on_patient = np.zeros(config.joints, dtype=bool)
    on_patient[patient_joint_indices(config)] = True
    inverse_inertia = lightest_inverse_inertia(config)
    delay = int(round(ranges.reflex_delay / period))
    peak_speed = np.max(np.abs(build_reference(config).velocity), axis=0)
    out = []
    kp_all, kd_all = feedback_gains(config)
    for j, (name, kp, kd) in enumerate(zip(config["joint_names"], kp_all.tolist(),
                                           kd_all.tolist(), strict=True)):
        best: tuple[float, int, tuple[float, float, str, float], float, float] | None = None
        nominal = 0.0
        corners = ranges.corners() if on_patient[j] else \
            [(0.0, 0.0, "0", d) for d in ranges.mass_uncertainty]
        for corner in corners:
            k, b, grade, delta = corner
            spastic_k, spastic_b, reflex_gain = MAS_PRESETS[grade][:3]
            stiffness = (k + spastic_k) * inverse_inertia[j] if on_patient[j] else 0.0
            damping = (b + spastic_b) * inverse_inertia[j] if on_patient[j] else 0.0
            active = on_patient[j] and ranges.reflex and \
                peak_speed[j] > MAS_PRESETS[grade][3]
            reflex = reflex_gain * inverse_inertia[j] if active else 0.0
            loop = JointLoop(1.0 / (1.0 + delta), float(kp), float(kd), period, stiffness,
                             damping, reflex, delay, continuous_patient=True)
            radius, radius_hz = loop.spectral_radius()
            if radius >= 1.0:
                value, index = math.inf, int(np.argmin(np.abs(frequency - radius_hz)))
            else:
                factor = factor_with_patient(loop, frequency, memory, gains_of[j],
                                             progress[j], averaging, q)
                value, index = float(np.max(factor)), int(np.argmax(factor))
            if stiffness == 0.0 and damping == 0.0 and reflex == 0.0:
                nominal = max(nominal, value)
            if best is None or value > best[0] or (value == best[0] == math.inf
                                                   and radius > best[3]):
                best = (value, index, corner, radius, radius_hz)
        assert best is not None
        value, index, (k, b, grade, delta), radius, radius_hz = best
        spastic_k, spastic_b, reflex_gain = MAS_PRESETS[grade][:3]
        total_k = k + spastic_k if on_patient[j] else 0.0
        total_b = b + spastic_b if on_patient[j] else 0.0
        total_g = reflex_gain if on_patient[j] and ranges.reflex and \
            peak_speed[j] > MAS_PRESETS[grade][3] else 0.0
        out.append(JointWorst(name, value, float(frequency[index]), total_k, total_b, grade,
                              delta, nominal, float(inverse_inertia[j]), bool(on_patient[j]),
                              radius, radius_hz, total_g,
                              total_g * float(inverse_inertia[j]) * period))
    return RangeAnalysis(ranges, out)


def factor_with_patient(loop: JointLoop, frequency: np.ndarray, memory: Memory,
                  gains: tuple[float, float, float], progress: float,
                  averaging: tuple[float, ...], q: np.ndarray) -> np.ndarray:
    """|F| of eq (*) on ``loop`` (the patient in it: its ``stiffness`` and ``damping``), at
    ``frequency`` (Hz), Q-filter response ``q``: the largest of |(1 - K) + K Q F| over the
    progress gain off and on (``progress`` added to G_p) and the averaging gains K in
    ``averaging``."""
    w = 2.0 * np.pi * frequency * loop.period
    z = np.exp(1j * w)
    pq, pv = loop.closed_loop(z)
    d = (z - 1.0 / z) / (2.0 * loop.period)
    m = 1.0 - loop.kp * pq - loop.kd * pv if memory is Memory.TOTAL_INPUT else 1.0
    gp, gd, gdd = gains
    worst = np.zeros(frequency.shape)
    for extra in sorted({0.0, float(progress)}):
        f = q * (m - (gp + extra) * pq - gd * pv - gdd * d * pv)
        for gain in averaging:
            worst = np.maximum(worst, np.abs((1.0 - gain) + gain * f))
    return worst
