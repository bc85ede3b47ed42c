"""Trial-to-trial convergence of the learning laws in the sampled closed loop (ROS-free).

Linearisation (what ``exo-ilc analyze-loop`` computes). The plant is a(q) qdd + c(q, qdot) = Q
with every mass scaled by (1 + delta), so a = (1 + delta) a_N and c = (1 + delta) c_N (gravity,
Coriolis and centrifugal terms are all linear in the masses). Computed torque Q = a_N u + c_N
then gives, exactly,

    qdd = u / (1 + delta) - delta / (1 + delta) a_N(q)^-1 c_N(q, qdot),

i.e. per joint a double integrator with gain g = 1 / (1 + delta) plus a term d(q, qdot) that
does not depend on u. Around the reference, d(q_d, qdot_d) repeats identically every trial and
drops out of the trial-to-trial difference; its variation with the error (O(delta) times the
gravity stiffness, a few s^-2 against K_P = 10-16) is neglected, as is the effort limit. The
effort is held over each period T (ZOH), so per joint, with x = (q, qdot):

    x_{i+1} = A x_i + B u_i,  A = [[1, T], [0, 1]],  B = g [T^2 / 2, T],
    u_i = u_ff,i + K_P e_i + K_D e_dot_i,  e = q_d - q.

Transfer functions from u_ff to the sampled signals of one trial (z-domain, N large):
e = -P_q u_ff, e_dot = -P_v u_ff, e_ddot = -D P_v u_ff with P = (zI - A + B K)^-1 B,
K = [K_P, K_D], and D(z) = (z - z^-1) / (2T) the central difference of ``numpy.gradient``.
The whole input is u = S u_ff with S = 1 - K_P P_q - K_D P_v = 1 / (1 + K (zI - A)^-1 B), the
input sensitivity of the sampled loop.

A law u_ff,k+1 = Q(m u_k + G_p e_k + G_d e_dot_k + G_dd e_ddot_k), with memory m = S
(``total_input``: u_{k-1} is the whole input) or m = 1 (``feedforward``), maps the learned input
of one trial to the next by the factor

    F(e^jw) = Q(e^jw) [m(e^jw) - G_p P_q(e^jw) - G_d P_v(e^jw) - G_dd D(e^jw) P_v(e^jw)].   (*)

|F| < 1 at every frequency makes the iteration a contraction (for long trials); where |F| > 1 the
learned input grows by that factor per trial at that frequency, whatever the error looks like.
For the sign law only its linear part is analysed (G = 0, F = Q m): the sign steps are a bounded
input each trial, so they stay bounded exactly when |Q m| < 1 and are amplified without bound in
the band where |Q m| > 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..learning.laws import Memory
from ..learning.qfilter import QFilter, qfilter_of
from ..loop.gains import feedback_gains
from ..params.config import Config
from ..reference.exercise import exercise_duration
from .joint_loop import JointLoop
from .norm_optimal_robustness import frequency_factor, lifted_factor
from .patient_load import PatientLoad


def lifted_map(loop: JointLoop, samples: int, memory: Memory,
               gains: tuple[float, float, float], qfilter: QFilter | None = None,
               forgetting: float | None = None, gate: float = 1.0) -> np.ndarray:
    """The (N+1) x (N+1) matrix F of u_ff,k+1 = F u_ff,k + const over one finite trial: eq (*)
    lifted, with the trial's edges (x(0) = x_d(0), the unapplied last sample, ``numpy.gradient``'s
    one-sided ends and the Q-filter's edge handling) included exactly. With ``forgetting``
    (assist-as-needed) f M + G (F - M) at the deadband's gate G = ``gate`` (:mod:`.assist`).

    P_q[i, m] = [1 0] (A - B K)^(i-m-1) B for i > m (Markov parameters), likewise P_v.
    """
    T, g = loop.period, loop.gain
    a = np.array([[1.0, T], [0.0, 1.0]])
    b = g * np.array([T * T / 2.0, T])
    a_cl = a - np.outer(b, [loop.kp + loop.stiffness, loop.kd + loop.damping])
    markov = np.zeros((samples, 2))
    x = b.copy()
    for m in range(1, samples):
        markov[m] = x
        x = a_cl @ x
    lag = np.subtract.outer(np.arange(samples), np.arange(samples))
    index = np.clip(lag, 0, samples - 1)
    pq = np.where(lag > 0, markov[index, 0], 0.0)
    pv = np.where(lag > 0, markov[index, 1], 0.0)
    gradient = np.gradient(np.eye(samples), T, axis=0)
    eye = np.eye(samples)
    base = eye - loop.kp * pq - loop.kd * pv if memory is Memory.TOTAL_INPUT else eye
    gp, gd, gdd = gains
    f = base - gp * pq - gd * pv - gdd * (gradient @ pv)
    if forgetting is not None:
        f = forgetting * base + gate * (f - base)
    if qfilter is not None:
        f = qfilter.apply(eye) @ f
    return np.asarray(f)


@dataclass(frozen=True)
class LiftedCheck:
    """The finite-trial map of one joint: spectral radius of F and the mean growth per trial
    of ||F^K||_2 over ``trials`` = K trials, log(||F^K||) / K."""

    spectral_radius: float
    growth_per_trial: float
    trials: int


def lifted_check(f: np.ndarray, trials: int = 1000) -> LiftedCheck:
    """Spectral radius and log(||F^K||_2) / K of a lifted map ``f``."""
    radius = float(np.max(np.abs(np.linalg.eigvals(f))))
    norm = float(np.linalg.norm(np.linalg.matrix_power(f, trials), 2))
    growth = float(np.log(norm) / trials) if norm > 0.0 else -np.inf
    return LiftedCheck(radius, growth, trials)


@dataclass(frozen=True)
class Band:
    """A frequency interval (Hz) where a factor exceeds 1, and its largest value there."""

    low_hz: float
    high_hz: float
    peak: float
    peak_hz: float


def bands_above_one(frequency_hz: np.ndarray, factor: np.ndarray,
                    threshold: float = 1.0 + 1e-9) -> list[Band]:
    """The contiguous intervals of ``frequency_hz`` where ``factor`` > 1."""
    above = factor > threshold
    out: list[Band] = []
    i = 0
    n = len(factor)
    while i < n:
        if not above[i]:
            i += 1
            continue
        j = i
        while j + 1 < n and above[j + 1]:
            j += 1
        k = i + int(np.argmax(factor[i:j + 1]))
        out.append(Band(float(frequency_hz[i]), float(frequency_hz[j]), float(factor[k]),
                        float(frequency_hz[k])))
        i = j + 1
    return out


@dataclass(frozen=True)
class JointFactor:
    """One joint's factor |F| over frequency, without and with the Q-filter."""

    joint: str
    unfiltered: np.ndarray
    filtered: np.ndarray | None
    lifted: LiftedCheck | None = None
    lifted_filtered: LiftedCheck | None = None

    def worst(self, filtered: bool) -> tuple[float, int]:
        """(max |F|, its frequency index) without or with the Q-filter."""
        values = self.filtered if filtered and self.filtered is not None else self.unfiltered
        k = int(np.argmax(values))
        return float(values[k]), k


@dataclass(frozen=True)
class LoopAnalysis:
    """The factor (*) of one law per joint on a frequency grid from 0 to Nyquist."""

    law: str
    memory: Memory
    mass_uncertainty: float
    period: float
    frequency_hz: np.ndarray
    joints: list[JointFactor]
    qfilter: QFilter | None
    forgetting: float | None = None
    """Assist-as-needed's forgetting factor when it is on (factors: worst over its gate)."""
    patient: PatientLoad | None = None
    """The patient whose linear joint forces the plant carries (None: the arm alone)."""

    @property
    def nyquist_hz(self) -> float:
        """1 / (2 T)."""
        return 0.5 / self.period

    def worst(self, filtered: bool = False) -> float:
        """max over joints and frequencies of |F|."""
        return max(j.worst(filtered)[0] for j in self.joints)

    def growth_per_trial(self, filtered: bool = False) -> float:
        """Predicted asymptotic growth of max |u_ff|: log(max |F|) per trial (<= 0: none)."""
        return float(np.log(self.worst(filtered)))


def learning_gains(config: Config, law: str) -> list[tuple[float, float, float]]:
    """(G_p, G_d, G_dd) per joint: the linear law's gains, zero for the sign law's linear part."""
    if law == "linear":
        return list(zip(config["linear.gain_position"], config["linear.gain_velocity"],
                        config["linear.gain_acceleration"], strict=True))
    return [(0.0, 0.0, 0.0)] * config.joints


def analyze_loop(config: Config, law: str | None = None, points: int = 2001,
                 qfilter: QFilter | None = None,
                 lifted_trials: int = 0, patient: PatientLoad | None = None) -> LoopAnalysis:
    """The factor (*) per joint of ``law`` (default: the config's) on ``points`` frequencies
    from 0 to Nyquist, without and with the Q-filter (``qfilter``, default: the config's).
    ``lifted_trials`` > 0 adds the finite-trial check (:func:`lifted_check`) over that many
    trials. ``patient``: the plant carries that patient's linear joint forces; a config whose
    identification is in the loop inverts them in its update (``identification.inverse_gain``,
    taken as identified exactly), or rebuilds norm-optimal's model about them."""
    name = law or config["law"]
    delta = float(config["mass_uncertainty"])
    period = float(config["control.period"])
    memory = Memory(config["memory"])
    q_filter = qfilter if qfilter is not None else qfilter_of(config)
    frequency = np.linspace(0.0, 0.5 / period, points)
    q = q_filter.response(frequency) if q_filter is not None else None
    if name == "norm_optimal":
        return _analyze_norm_optimal(config, delta, frequency, q_filter, q, lifted_trials,
                                     patient)
    inverse = float(config["identification.inverse_gain"]) if patient is not None and \
        config["identification.enabled"] and config["identification.in_loop"] else 0.0
    forgetting = config["assist_as_needed.forgetting"] \
        if config["assist_as_needed.enabled"] else None
    joints = []
    kp_all, kd_all = feedback_gains(config)
    for j, (name_j, kp, kd, gains) in enumerate(zip(
            config["joint_names"], kp_all.tolist(), kd_all.tolist(),
            learning_gains(config, name), strict=True)):
        stiffness, damping = (0.0, 0.0) if patient is None else \
            (float(patient.stiffness[j]), float(patient.damping[j]))
        loop = JointLoop(1.0 / (1.0 + delta), kp, kd, period, stiffness, damping)
        gains = (gains[0] + inverse * stiffness, gains[1] + inverse * damping, gains[2])
        raw = loop.factor(frequency, memory, gains, forgetting=forgetting)
        plain = with_q = None
        if lifted_trials > 0:
            samples = round(exercise_duration(config) / period) + 1
            gates = (1.0,) if forgetting is None else (0.0, 1.0)  # both ends of the deadband
            plain = max((lifted_check(lifted_map(loop, samples, memory, gains, None, forgetting,
                                                 g), lifted_trials) for g in gates),
                        key=lambda c: c.spectral_radius)
            if q_filter is not None:
                with_q = max((lifted_check(lifted_map(loop, samples, memory, gains, q_filter,
                                                      forgetting, g), lifted_trials)
                              for g in gates), key=lambda c: c.spectral_radius)
        joints.append(JointFactor(name_j, raw, None if q is None else q * raw, plain, with_q))
    return LoopAnalysis(name, memory, delta, period, frequency, joints, q_filter, forgetting,
                        patient)


def _analyze_norm_optimal(config: Config, delta: float, frequency: np.ndarray,
                          q_filter: QFilter | None, q: np.ndarray | None,
                          lifted_trials: int, patient: PatientLoad | None = None
                          ) -> LoopAnalysis:
    """The factor of (NO2) (:func:`.norm_optimal_robustness.frequency_factor`) per joint; its
    memory is the feed-forward. ``lifted_trials`` > 0 adds the whole-arm lifted map's check
    (joints are coupled in the ``linearised`` model: the same check on every joint), against
    the ``patient``'s arm when given (the model about it too when identification is in the
    loop)."""

    plain = None
    if lifted_trials > 0:
        about = patient is not None and config["identification.enabled"] and \
            config["identification.in_loop"]
        check = lifted_factor(config, delta, radius=True,
                              patient=None if patient is None else patient.along(config),
                              model_about_patient=about)
        plain = LiftedCheck(float(check.radius or 0.0), float(np.log(check.norm)), 1)
    joints = [JointFactor(name_j, raw, None if q is None else q * raw, plain, None)
              for name_j, raw in zip(config["joint_names"],
                                     frequency_factor(config, delta, frequency, patient),
                                     strict=True)]
    return LoopAnalysis("norm_optimal", Memory.FEEDFORWARD, delta, float(config["control.period"]),
                        frequency, joints, q_filter, None, patient)


def packet_growth_rate(worst_factor: float, trial: float) -> float:
    """Predicted slope of log max_t |u_ff,k+1 - u_ff,k| around trial k for a factor that peaks
    at rho = ``worst_factor`` at one frequency: log(rho) - 1/(2k).

    Near its peak |F| ~ rho (1 - c (w - w0)^2), so the part of the learned input in that band
    grows as sum over w of |F|^k ~ rho^k / sqrt(k): the measured rate approaches log(rho) from
    below as 1/(2k) (a Gaussian packet narrowing trial by trial).
    """
    return float(np.log(worst_factor) - 0.5 / trial)
