"""The model norm-optimal ILC learns over (:mod:`.norm_optimal` holds the law and its equations
(NO1)-(NO4)): the lifted model G of the sampled closed loop, eq (NO4) per joint or linearised
along the reference, the dense learning matrices L and Phi of (NO2) (the robustness check's and
the tests' oracle) and the Riccati gains the law uses (:func:`recursive_matrices`), each built
once per configuration and cached."""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from enum import Enum
from functools import cached_property
from typing import Any

import numpy as np
from numba import njit
from scipy.linalg import cho_factor, cho_solve

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..arm.build import build_arm
from ..arm.dynamics import inertia_and_bias
from ..loop.gains import feedback_gains
from ..params import schema
from ..params.config import Config
from ..reference.build import build_reference
from ..reference.trajectory import SampledReference
from .norm_optimal_recursive import RiccatiGains, riccati_gains


class ModelKind(Enum):
    """Which lifted model the learning matrix is built from (module docstring)."""

    PER_JOINT = "per_joint"
    LINEARISED = "linearised"


MODEL_KEYS = ("norm_optimal.model_kind", "norm_optimal.model_mass_uncertainty", "control.period",
              "control.kp", "control.kd", "control.min_stiffness", "control.min_damping",
              "trajectory.start", "trajectory.goal",
              "trajectory.duration", "model.link_masses", "model.link_lengths",
              "model.radius_proximal", "model.radius_distal", "model.joint_axes",
              "model.gravity", "model.gravity_direction", "exercise.name", "exercise.file",
              *schema.URDF_KEYS, *schema.PERSON_KEYS)
"""Every config value the lifted model depends on (its cache key; a URDF by its contents, a
person's segments only with ``person.enabled``)."""
WEIGHT_KEYS = ("norm_optimal.weight_error", "norm_optimal.weight_input_change",
               "norm_optimal.weight_input_size")


def _key(config: Config, names: tuple[str, ...]) -> str:
    return json.dumps(config.identity_values(names), sort_keys=True)


@dataclass(frozen=True, eq=False)
class PatientLinearisation:
    """The identified patient's joint forces linearised along the reference, per sample and
    joint: tau_p(q_d + dq, qdot_d + dqdot) ~ tau_p(q_d, qdot_d) + S dq + D dqdot with diagonal S
    (N m/rad) and D (N m s/rad) (:meth:`..learning.patient_model.JointForceModel.
    linearisation`): the plant norm-optimal's lifted model is rebuilt about."""

    stiffness: np.ndarray
    """(N+1, n) N m/rad."""
    damping: np.ndarray
    """(N+1, n) N m s/rad."""

    @cached_property
    def key(self) -> str:
        """The cache key: a digest of both arrays rounded to 1e-9."""
        digest = hashlib.sha256()
        for array in (self.stiffness, self.damping):
            digest.update(np.round(np.asarray(array, dtype=float), 9).tobytes())
        return digest.hexdigest()


@dataclass(frozen=True, eq=False)
class LiftedModel:
    """x_i+1 = (A_i - B_i K) x_i + B_i du_ff,i, x = (dq, dqdot) of every joint, x_0 = 0; the
    position change dq = G du_ff over the trial (index i * joints + j: sample i, joint j)."""

    a: np.ndarray
    """(N+1, 2n, 2n): A_i, the plant over period i (ZOH)."""
    b: np.ndarray
    """(N+1, 2n, n): B_i."""
    k: np.ndarray
    """(n, 2n): [K_P, K_D]."""

    @cached_property
    def g(self) -> np.ndarray:
        """(n (N+1), n (N+1)): the lifted map from the feed-forward change to the position
        change (built on first use: the law itself needs only A, B and K)."""
        count, n = self.samples, self.joints
        closed = self.a - self.b @ self.k
        g = np.zeros((count * n, count * n))
        states = np.zeros((2 * n, count * n))  # response of x_i to every input sample
        for i in range(count):
            g[i * n:(i + 1) * n] = states[:n]
            if i + 1 < count:
                states[:, :(i + 1) * n] = closed[i] @ states[:, :(i + 1) * n]
                states[:, i * n:(i + 1) * n] += self.b[i]
        return g

    @property
    def joints(self) -> int:
        """n."""
        return int(self.k.shape[0])

    @property
    def samples(self) -> int:
        """N + 1."""
        return int(self.a.shape[0])


def _bias_jacobians(config: Config, reference: SampledReference,
                    step: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """d h / d q and d h / d qdot along the reference, h = a_N^-1 c_N (central differences)."""

    count, n = reference.position.shape
    hq = np.empty((count, n, n))
    hv = np.empty((count, n, n))
    _bias_jacobians_kernel(np.ascontiguousarray(reference.position),
                           np.ascontiguousarray(reference.velocity), step,
                           build_arm(config).kernel_args, hq, hv)
    return hq, hv


@njit(cache=True, error_model="numpy")
def _bias_jacobians_kernel(position: np.ndarray, velocity: np.ndarray, step: float,
                           nominal: tuple, hq: np.ndarray, hv: np.ndarray) -> None:
    """:func:`_bias_jacobians` compiled: the same central differences as its former Python loop
    (the same doubles on the paper's arm; for more joints numba's LAPACK solve may differ from
    numpy's in the last bit), 55x faster, which matters at 1 kHz. ``nominal``: the arm's
    ``kernel_args``."""
    count, n = position.shape
    for i in range(count):
        for j in range(n):
            for of_velocity in (False, True):
                q_plus, q_minus = position[i].copy(), position[i].copy()
                v_plus, v_minus = velocity[i].copy(), velocity[i].copy()
                if of_velocity:
                    v_plus[j] += step
                    v_minus[j] -= step
                else:
                    q_plus[j] += step
                    q_minus[j] -= step
                a, c = inertia_and_bias(q_plus, v_plus, *nominal)
                h_plus = np.linalg.solve(a, c)
                a, c = inertia_and_bias(q_minus, v_minus, *nominal)
                h_minus = np.linalg.solve(a, c)
                out = hv if of_velocity else hq
                for k in range(n):
                    out[i, k, j] = (h_plus[k] - h_minus[k]) / (2.0 * step)


def _expm_batch(m: np.ndarray, order: int = 8) -> np.ndarray:
    """exp(m) for a stack of small matrices of small norm (here ||A T|| < 0.1): Taylor series,
    exact to rounding at that norm."""
    out = np.broadcast_to(np.eye(m.shape[-1]), m.shape).copy()
    term = out.copy()
    for p in range(1, order + 1):
        term = term @ m / p
        out += term
    return out


def build_lifted_model(config: Config, patient: PatientLinearisation | None = None
                       ) -> LiftedModel:
    """The lifted model of the config's ``norm_optimal.model_kind`` (module docstring, (NO4));
    with ``patient`` about the identified plant: its joint forces' stiffness S and damping D
    along the reference enter the continuous model as -g a_N(q_d)^-1 S dq and
    -g a_N(q_d)^-1 D dqdot (eq (8) with eq (6)'s terms, g = 1 / (1 + the model's mass
    uncertainty))."""

    kind = ModelKind(config["norm_optimal.model_kind"])
    reference = build_reference(config)
    count, n = reference.position.shape
    period = float(config["control.period"])
    gain = 1.0 / (1.0 + float(config["norm_optimal.model_mass_uncertainty"]))
    # Continuous (dq, dqdot, du) per period, du held: [[0, I, 0], [-(1-g) Hq, -(1-g) Hv, g I]].
    cont = np.zeros((count, 3 * n, 3 * n))
    cont[:, :n, n:2 * n] = np.eye(n)
    cont[:, n:2 * n, 2 * n:] = gain * np.eye(n)
    if kind is ModelKind.LINEARISED and gain != 1.0:
        hq, hv = _bias_jacobians(config, reference)
        cont[:, n:2 * n, :n] = -(1.0 - gain) * hq
        cont[:, n:2 * n, n:2 * n] = -(1.0 - gain) * hv
    if patient is not None:
        arm = build_arm(config)
        minv = np.linalg.inv(arm.metric_tensors(reference.position))
        cont[:, n:2 * n, :n] -= gain * minv * patient.stiffness[:, None, :]
        cont[:, n:2 * n, n:2 * n] -= gain * minv * patient.damping[:, None, :]
    disc = _expm_batch(cont * period)
    a, b = disc[:, :2 * n, :2 * n], disc[:, :2 * n, 2 * n:]
    kp, kd = feedback_gains(config)
    k = np.hstack([np.diag(kp), np.diag(kd)])
    return LiftedModel(np.ascontiguousarray(a), np.ascontiguousarray(b), k)


_MODELS: dict[str, LiftedModel] = {}
_MATRICES: dict[tuple[str, str], LearningMatrices] = {}
_RECURSIVE: dict[tuple[str, str], RecursiveMatrices] = {}
CACHE_SIZE = 4
"""Configurations kept (a live change back and forth between two settings costs nothing)."""


def _remember(cache: dict[Any, Any], key: Any, value: Any) -> None:
    cache[key] = value
    while len(cache) > CACHE_SIZE:
        del cache[next(iter(cache))]


def lifted_model(config: Config, patient: PatientLinearisation | None = None) -> LiftedModel:
    """:func:`build_lifted_model`, cached by the values it depends on (:data:`MODEL_KEYS`, the
    patient's linearisation)."""
    key = _key(config, MODEL_KEYS) + ("" if patient is None else patient.key)
    model = _MODELS.get(key)
    if model is None:
        model = build_lifted_model(config, patient)
        _remember(_MODELS, key, model)
    return model


@dataclass(frozen=True, eq=False)
class Weights:
    """We, Wd, Wu of (NO1), per joint."""

    error: np.ndarray
    input_change: np.ndarray
    input_size: np.ndarray

    @classmethod
    def of(cls, config: Config) -> Weights:
        """The config's ``norm_optimal.weight_*``."""
        return cls(*(np.asarray(config[k], dtype=float) for k in WEIGHT_KEYS))

    def stacked(self, samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The diagonals of We, Wd, Wu over ``samples`` samples (sample-major)."""
        return (np.tile(self.error, samples), np.tile(self.input_change, samples),
                np.tile(self.input_size, samples))


@dataclass(frozen=True, eq=False)
class LearningMatrices:
    """L and Phi of (NO2) for one model and one set of weights: an update is one
    matrix-vector product (two with an input-size weight)."""

    model: LiftedModel
    weights: Weights
    learning: np.ndarray
    """L = H^-1 G^T We."""
    memory: np.ndarray | None
    """Phi = I - H^-1 Wu; None when it is the identity (no input-size weight)."""
    seconds: float = field(default=0.0, compare=False)
    """Seconds it took to build L and Phi (and the model, if it was not cached yet)."""

    def next_feedforward(self, feedforward: np.ndarray, error: np.ndarray) -> np.ndarray:
        """u_ff,k+1 = Phi u_ff,k + L e_k of (NO2), stacked (sample-major)."""
        memory = feedforward if self.memory is None else self.memory @ feedforward
        return np.asarray(memory + self.learning @ error)

    @property
    def phi(self) -> np.ndarray:
        """Phi as a matrix (the identity when there is no input-size weight)."""
        return np.eye(self.learning.shape[0]) if self.memory is None else self.memory


def _build_matrices(model: LiftedModel, weights: Weights) -> LearningMatrices:
    """L and Phi of (NO2) from one Cholesky factorisation of H."""
    we, wd, wu = weights.stacked(model.samples)
    gtw = model.g.T * we
    h = gtw @ model.g
    h[np.diag_indices_from(h)] += wd + wu
    factor = cho_factor(h, overwrite_a=True)
    learning = np.ascontiguousarray(cho_solve(factor, gtw))
    memory = None
    if np.any(wu > 0.0):
        memory = np.eye(wu.size) - np.asarray(cho_solve(factor, np.diag(wu)))
    return LearningMatrices(model, weights, learning, memory)


def learning_matrices(config: Config, patient: PatientLinearisation | None = None
                      ) -> LearningMatrices:
    """L and Phi of (NO2) for the config (about the identified ``patient``), computed once per
    configuration (cached by the model's values and the weights; a change of any other
    parameter reuses them)."""
    key = (_key(config, MODEL_KEYS) + ("" if patient is None else patient.key),
           _key(config, WEIGHT_KEYS))
    matrices = _MATRICES.get(key)
    if matrices is None:
        start = time.perf_counter()
        built = _build_matrices(lifted_model(config, patient), Weights.of(config))
        matrices = LearningMatrices(built.model, built.weights, built.learning, built.memory,
                                    time.perf_counter() - start)
        _remember(_MATRICES, key, matrices)
    return matrices


@dataclass(frozen=True, eq=False)
class RecursiveMatrices:
    """(NO2) without lifted matrices: the Riccati gains of
    :mod:`exo_ilc_ros.core.learning.norm_optimal_recursive` (memory linear in the samples),
    the law's drop-in for :class:`LearningMatrices` (same minimiser to rounding, tested)."""

    model: LiftedModel
    weights: Weights
    gains: RiccatiGains
    seconds: float = field(default=0.0, compare=False)
    """Seconds it took to build the gains (and the model, if it was not cached yet)."""

    def next_feedforward(self, feedforward: np.ndarray, error: np.ndarray) -> np.ndarray:
        """u_ff,k+1 of (NO2), stacked (sample-major), as
        :meth:`LearningMatrices.next_feedforward`."""
        return self.gains.next_feedforward(feedforward, error)


def recursive_matrices(config: Config, patient: PatientLinearisation | None = None
                       ) -> RecursiveMatrices:
    """:class:`RecursiveMatrices` for the config (about the identified ``patient``), cached as
    :func:`learning_matrices`."""
    key = (_key(config, MODEL_KEYS) + ("" if patient is None else patient.key),
           _key(config, WEIGHT_KEYS))
    matrices = _RECURSIVE.get(key)
    if matrices is None:
        start = time.perf_counter()
        model, weights = lifted_model(config, patient), Weights.of(config)
        gains = riccati_gains(model.a, model.b, model.k, weights.error, weights.input_change,
                              weights.input_size)
        matrices = RecursiveMatrices(model, weights, gains, time.perf_counter() - start)
        _remember(_RECURSIVE, key, matrices)
    return matrices


def clear_cache() -> None:
    """Forget every cached model and learning matrix (benchmarks)."""
    _MODELS.clear()
    _MATRICES.clear()
    _RECURSIVE.clear()




