"""Norm-optimal ILC (Amann, Owens and Rogers) over the lifted model of the sampled closed loop.

Each trial's update minimises, over the next trial's feed-forward u (all joints, all N+1
samples, stacked sample by sample),

    J(u) = ||e_k+1||^2_We + ||u - u_ff,k||^2_Wd + ||u||^2_Wu,                           (NO1)

with the next error predicted by the lifted model e_k+1 = e_k - G (u - u_ff,k): G maps a change
of the feed-forward to the change of the position over one trial from x(0) = x_d(0) (the trial's
edges included exactly, the last sample's feed-forward is never applied), and We, Wd, Wu are
the per-joint weights ``norm_optimal.weight_error``, ``weight_input_change`` and
``weight_input_size``. Its minimiser is

    u_ff,k+1 = u_ff,k + H^-1 (G^T We e_k - Wu u_ff,k),   H = G^T We G + Wd + Wu,
             = Phi u_ff,k + L e_k,   L = H^-1 G^T We,   Phi = I - H^-1 Wu,              (NO2)

The constrained update (``norm_optimal.constrained``) minimises the same J subject to

    |tau_k+1| <= (1 - margin) control.effort_limit,   |u| <= feedforward_limit (where > 0),  (NO3)

tau_k+1 = tau_k + a_N(q_k) (u_k+1 - u_k) + J_k (x_k+1 - x_k) the computed torque of the next trial
predicted from this one's (u the whole input, feed-forward plus PD feedback, J_k = d tau / d x at
fixed u, x_k+1 - x_k from the model; margin = ``norm_optimal.effort_margin``), as a sparse QP in
the states of the model (:func:`solve_constrained`, Clarabel), instead of clipping the result
after the fact.

The model (``norm_optimal.model_kind``) is the closed loop the computed torque leaves when the
plant's masses are (1 + delta_m) times the nominal ones, delta_m =
``norm_optimal.model_mass_uncertainty``:

    qdd = g u - (1 - g) a_N(q)^-1 c_N(q, qdot),   g = 1 / (1 + delta_m),                (NO4)

the effort held over each period T, u = u_ff + K_P e + K_D e_dot.

* ``per_joint``: the second term's variation is neglected: per joint a ZOH double integrator of
  gain g under PD, the construction of :mod:`.convergence` (``analyze-loop``); G is block diagonal.
* ``linearised``: (NO4) linearised along the reference, the second term's Jacobians included
  (the gravity stiffness and velocity terms the mass error leaves): coupled and time-varying.

G, L and Phi depend only on the configuration (model, gains, period, reference, weights): they
are computed once and cached (:func:`learning_matrices`), so an update is one matrix-vector
product (milliseconds). The law itself (:class:`NormOptimalLaw`) uses the same minimiser without
them: the Riccati gains of :mod:`exo_ilc_ros.core.learning.norm_optimal_recursive`, cached the
same way (:func:`recursive_matrices`), memory linear in the samples; G, L and Phi remain for the
robustness check (``analyze-loop``) and as the tests' oracle.
"""

from __future__ import annotations

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
from ..errors import SafetyError
from ..loop.record import TrialRecord
from ..params.config import Config
from ..reference.build import build_reference
from ..reference.trajectory import SampledReference
from .laws import FeedforwardUpdate, InitialFeedforward, _initial
from .norm_optimal_recursive import RiccatiGains, riccati_gains, solve_constrained_banded


class ModelKind(Enum):
    """Which lifted model the learning matrix is built from (module docstring)."""

    PER_JOINT = "per_joint"
    LINEARISED = "linearised"


MODEL_KEYS = ("norm_optimal.model_kind", "norm_optimal.model_mass_uncertainty", "control.period",
              "control.kp", "control.kd", "trajectory.start", "trajectory.goal",
              "trajectory.duration", "model.link_masses", "model.link_lengths",
              "model.radius_proximal", "model.radius_distal", "model.joint_axes",
              "model.gravity", "exercise.name", "exercise.file")
"""Every config value the lifted model depends on (its cache key)."""
WEIGHT_KEYS = ("norm_optimal.weight_error", "norm_optimal.weight_input_change",
               "norm_optimal.weight_input_size")


def _key(config: Config, names: tuple[str, ...]) -> str:
    return json.dumps({k: config[k] for k in names}, sort_keys=True)


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
                           *build_arm(config).kernel_args, hq, hv)
    return hq, hv


@njit(cache=True, error_model="numpy")
def _bias_jacobians_kernel(position: np.ndarray, velocity: np.ndarray, step: float,
                           masses: np.ndarray, axes: np.ndarray, offsets: np.ndarray,
                           coms: np.ndarray, inertias: np.ndarray, gravity: np.ndarray,
                           hq: np.ndarray, hv: np.ndarray) -> None:
    """:func:`_bias_jacobians` compiled: the same central differences as its former Python loop
    (the same doubles on the paper's arm; for more joints numba's LAPACK solve may differ from
    numpy's in the last bit), 55x faster, which matters at 1 kHz."""
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
                a, c = inertia_and_bias(q_plus, v_plus, masses, axes, offsets, coms, inertias,
                                        gravity)
                h_plus = np.linalg.solve(a, c)
                a, c = inertia_and_bias(q_minus, v_minus, masses, axes, offsets, coms,
                                        inertias, gravity)
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


def build_lifted_model(config: Config) -> LiftedModel:
    """The lifted model of the config's ``norm_optimal.model_kind`` (module docstring, (NO4))."""

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
    disc = _expm_batch(cont * period)
    a, b = disc[:, :2 * n, :2 * n], disc[:, :2 * n, 2 * n:]
    k = np.hstack([np.diag(config["control.kp"]), np.diag(config["control.kd"])])
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


def lifted_model(config: Config) -> LiftedModel:
    """:func:`build_lifted_model`, cached by the values it depends on (:data:`MODEL_KEYS`)."""
    key = _key(config, MODEL_KEYS)
    model = _MODELS.get(key)
    if model is None:
        model = build_lifted_model(config)
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


def learning_matrices(config: Config) -> LearningMatrices:
    """L and Phi of (NO2) for the config, computed once per configuration (cached by the model's
    values and the weights; a change of any other parameter reuses them)."""
    key = (_key(config, MODEL_KEYS), _key(config, WEIGHT_KEYS))
    matrices = _MATRICES.get(key)
    if matrices is None:
        start = time.perf_counter()
        built = _build_matrices(lifted_model(config), Weights.of(config))
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


def recursive_matrices(config: Config) -> RecursiveMatrices:
    """:class:`RecursiveMatrices` for the config, cached as :func:`learning_matrices`."""
    key = (_key(config, MODEL_KEYS), _key(config, WEIGHT_KEYS))
    matrices = _RECURSIVE.get(key)
    if matrices is None:
        start = time.perf_counter()
        model, weights = lifted_model(config), Weights.of(config)
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


@dataclass(frozen=True, eq=False)
class Constraints:
    """What (NO3) bounds: the effort limit (N m) and the feed-forward bound (inf: none), with
    the nominal arm that predicts the effort."""

    effort_limit: np.ndarray
    feedforward_limit: np.ndarray
    nominal: tuple[np.ndarray, ...]
    effort_margin: float = 0.0
    """Share of the effort limit kept free for the prediction's error."""


def _effort_along(record: TrialRecord, nominal: tuple[np.ndarray, ...], step: float = 1e-6
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Along trial k: tau_k = a_N(q) u + c_N(q, qdot) (before the limit clamps it), a_N(q) and
    d tau / d (q, qdot) at fixed u (central differences: gravity and Coriolis change with the
    state the next trial reaches)."""
    count, n = record.position.shape
    tau = np.empty((count, n))
    inertia = np.empty((count, n, n))
    jacobian = np.empty((count, n, 2 * n))
    _effort_along_kernel(np.ascontiguousarray(record.position),
                         np.ascontiguousarray(record.velocity),
                         np.ascontiguousarray(record.control_input), step, *nominal, tau,
                         inertia, jacobian)
    return tau, inertia, jacobian


@njit(cache=True, error_model="numpy")
def _effort_along_kernel(position: np.ndarray, velocity: np.ndarray, control: np.ndarray,
                         step: float, masses: np.ndarray, axes: np.ndarray,
                         offsets: np.ndarray, coms: np.ndarray, inertias: np.ndarray,
                         gravity: np.ndarray, tau: np.ndarray, inertia: np.ndarray,
                         jacobian: np.ndarray) -> None:
    """:func:`_effort_along` compiled (the same doubles as its former Python loop)."""
    count, n = position.shape
    for i in range(count):
        u = control[i].copy()
        a, c = inertia_and_bias(position[i].copy(), velocity[i].copy(), masses, axes, offsets,
                                coms, inertias, gravity)
        inertia[i] = a
        tau[i] = a @ u + c
        x = np.concatenate((position[i], velocity[i]))
        for m in range(2 * n):
            x_plus, x_minus = x.copy(), x.copy()
            x_plus[m] += step
            x_minus[m] -= step
            a, c = inertia_and_bias(x_plus[:n].copy(), x_plus[n:].copy(), masses, axes,
                                    offsets, coms, inertias, gravity)
            e_plus = a @ u + c
            a, c = inertia_and_bias(x_minus[:n].copy(), x_minus[n:].copy(), masses, axes,
                                    offsets, coms, inertias, gravity)
            e_minus = a @ u + c
            for k in range(n):
                jacobian[i, k, m] = (e_plus[k] - e_minus[k]) / (2.0 * step)


@dataclass(frozen=True)
class ConstrainedStep:
    """The solution of (NO3) and which constraints hold with equality."""

    change: np.ndarray
    """u_ff,k+1 - u_ff,k, shape (N+1, joints)."""
    predicted_effort: np.ndarray
    effort_active: np.ndarray
    """Per joint: samples at the effort limit in the prediction."""
    feedforward_active: np.ndarray
    """Per joint: samples at the feed-forward bound."""
    status: str


QP_TOLERANCE = 1e-12
"""Clarabel's gap and feasibility tolerances: the QP's u_ff within ~1e-8 of (NO2)'s when no
constraint is active (tested)."""


def solve_constrained(matrices: LearningMatrices | RecursiveMatrices, constraints: Constraints,
                      record: TrialRecord) -> ConstrainedStep:
    """(NO3) as a sparse QP over z = (du_ff, x_0..x_N) with the model's dynamics as equalities,
    solved by Clarabel (interior point). Active: within 1e-6 (relative) of a bound."""
    import clarabel
    from scipy import sparse

    model, w = matrices.model, matrices.weights
    count, n = record.error.shape
    nv, nx = count * n, count * 2 * n
    we, wd, wu = w.stacked(count)
    u_ff = record.feedforward.ravel()
    # cost 1/2 z' P z + q' z: sum we (e - dq)^2 + wd du^2 + wu (u_ff + du)^2 (constants dropped)
    px = np.zeros((count, 2 * n))
    px[:, :n] = 2.0 * we.reshape(count, n)
    qx = np.zeros((count, 2 * n))
    qx[:, :n] = -2.0 * we.reshape(count, n) * record.error
    p = sparse.diags(np.concatenate([2.0 * (wd + wu), px.ravel()])).tocsc()
    q = np.concatenate([2.0 * wu * u_ff, qx.ravel()])

    def x_col(i: int) -> int:
        return nv + i * 2 * n

    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    row = 0

    def block(r0: int, c0: int, m: np.ndarray) -> None:
        rr, cc = np.nonzero(np.ones_like(m, dtype=bool))
        rows.append(rr + r0)
        cols.append(cc + c0)
        vals.append(m.ravel())

    # equalities: x_0 = 0; x_i+1 - (A_i - B_i K) x_i - B_i du_i = 0
    block(row, x_col(0), np.eye(2 * n))
    row += 2 * n
    closed = model.a - model.b @ model.k
    for i in range(count - 1):
        block(row, x_col(i + 1), np.eye(2 * n))
        block(row, x_col(i), -closed[i])
        block(row, i * n, -model.b[i])
        row += 2 * n
    equalities = row
    tau, inertia, jacobian = _effort_along(record, constraints.nominal)
    lim = constraints.effort_limit * (1.0 - constraints.effort_margin)
    bounds: list[np.ndarray] = []
    # effort: +-(a_N,i (du_i - K x_i) + J_i x_i) <= lim -+ tau_i
    for sign in (1.0, -1.0):
        for i in range(count):
            block(row, i * n, sign * inertia[i])
            block(row, x_col(i), sign * (jacobian[i] - inertia[i] @ model.k))
            row += n
        bounds.append((lim - sign * tau).ravel())
    bounded = np.flatnonzero(np.isfinite(np.tile(constraints.feedforward_limit, count)))
    if bounded.size:
        ff_lim = np.tile(constraints.feedforward_limit, count)[bounded]
        for sign in (1.0, -1.0):
            rows.append(row + np.arange(bounded.size))
            cols.append(bounded)
            vals.append(np.full(bounded.size, sign))
            row += bounded.size
            bounds.append(ff_lim - sign * u_ff[bounded])
    a = sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(row, nv + nx))
    b = np.concatenate([np.zeros(equalities), *bounds])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    # Tight: the input-change weight is tiny, so the cost is flat along the directions the
    # model barely sees; the default 1e-8 gap leaves ~1e-4 rad/s^2 of slack in u_ff there.
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = QP_TOLERANCE
    settings.tol_ktratio = 1e-10
    solver = clarabel.DefaultSolver(p, q, a, b, [clarabel.ZeroConeT(equalities),
                                                 clarabel.NonnegativeConeT(row - equalities)],
                                    settings)
    solution = solver.solve()
    status = str(solution.status)
    if "Solved" not in status:
        raise SafetyError(f"trial {record.trial}: the constrained norm-optimal update was not "
                          f"solved ({status}); the limits may be infeasible together")
    z = np.asarray(solution.x)
    du = z[:nv].reshape(count, n)
    x = z[nv:].reshape(count, 2 * n)
    predicted = (tau + np.einsum("ijk,ik->ij", inertia, du - x @ model.k.T)
                 + np.einsum("ijk,ik->ij", jacobian, x))
    tol = 1e-6
    effort_active = np.sum(np.abs(predicted) >= lim * (1.0 - tol), axis=0)
    new = record.feedforward + du
    ff_active = np.sum(np.abs(new) >= constraints.feedforward_limit * (1.0 - tol), axis=0)
    return ConstrainedStep(du, predicted, effort_active, ff_active, status)


@dataclass(frozen=True, eq=False)
class NormOptimalLaw:
    """Norm-optimal ILC, (NO2) (or (NO3) with ``constraints``): the feed-forward of the next
    trial minimises the weighted next error, input change and input size over the lifted model.
    Learns from the previous feed-forward (not the whole input: the model already holds the PD
    part), whatever ``memory`` says."""

    matrices: RecursiveMatrices
    constraints: Constraints | None = None
    initial: InitialFeedforward = InitialFeedforward.ZERO

    @classmethod
    def from_config(cls, config: Config) -> NormOptimalLaw:
        """The config's weights and model (matrices from the cache), its limits when
        ``norm_optimal.constrained``."""
        constraints = None
        if config["norm_optimal.constrained"]:
            ff = np.asarray(config["feedforward_limit"], dtype=float)
            constraints = Constraints(np.asarray(config["control.effort_limit"], dtype=float),
                                      np.where(ff > 0.0, ff, np.inf),
                                      build_arm(config).kernel_args,
                                      float(config["norm_optimal.effort_margin"]))
        return cls(recursive_matrices(config), constraints,
                   InitialFeedforward(config["initial_feedforward"]))

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """Zero, or q_ddot_d, per the ``initial`` option."""
        return _initial(reference, self.initial)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """(NO2): u_ff,k+1 = Phi u_ff,k + L e_k; with constraints the QP (NO3), and a note
        naming the constraints that were active."""
        shape = record.feedforward.shape
        model = self.matrices.model
        if shape[0] != model.samples or shape[1] != model.joints:
            raise SafetyError(f"trial {record.trial}: {shape[0]} samples, but the learning "
                              f"matrix was built for {self.matrices.model.samples}")
        if self.constraints is not None:
            step = solve_constrained_recursive(self.matrices, self.constraints, record)
            notes = constraint_notes(step)
            return FeedforwardUpdate(record.feedforward + step.change, None, notes)
        new = self.matrices.next_feedforward(record.feedforward.ravel(), record.error.ravel())
        return FeedforwardUpdate(new.reshape(shape), None)


def solve_constrained_recursive(matrices: RecursiveMatrices, constraints: Constraints,
                                record: TrialRecord) -> ConstrainedStep:
    """(NO3) as :func:`solve_constrained`, the QP assembled banded
    (:func:`exo_ilc_ros.core.learning.norm_optimal_recursive.solve_constrained_banded`)."""
    model, w = matrices.model, matrices.weights
    tau, inertia, jacobian = _effort_along(record, constraints.nominal)
    banded = solve_constrained_banded(
        model.a, model.b, model.k, w.error, w.input_change, w.input_size, record.feedforward,
        record.error, tau, inertia, jacobian,
        constraints.effort_limit * (1.0 - constraints.effort_margin),
        constraints.feedforward_limit)
    if not banded.solved:
        raise SafetyError(f"trial {record.trial}: the constrained norm-optimal update was not "
                          f"solved ({banded.status}); the limits may be infeasible together")
    return ConstrainedStep(banded.change, banded.predicted_effort, banded.effort_active,
                           banded.feedforward_active, banded.status)


def constraint_notes(step: ConstrainedStep) -> tuple[str, ...]:
    """One line per kind of active constraint of (NO3) (empty: none active)."""
    notes = []
    if np.any(step.effort_active):
        notes.append("effort limit active at " + "/".join(str(int(c)) for c in step.effort_active)
                     + " samples (per joint) of the next trial's predicted effort")
    if np.any(step.feedforward_active):
        notes.append("feed-forward bound active at "
                     + "/".join(str(int(c)) for c in step.feedforward_active)
                     + " samples (per joint)")
    return tuple(notes)


# --- robustness (analyze-loop) ------------------------------------------------------------------


