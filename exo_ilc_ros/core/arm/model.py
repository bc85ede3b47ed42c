"""The exoskeleton-arm model: a chain of truncated-cone links, eqs (1)-(7)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

from ..errors import ModelError
from ..params.schema import AXIS_VECTORS
from . import dynamics
from .geometry import cone_inertia_tensor, truncated_cone

LINK_DIRECTION = np.array([0.0, 0.0, -1.0])
"""Every link points along -z of its own frame: at q = 0 the arm hangs straight down."""


Gravity = float | Sequence[float] | np.ndarray
"""A gravity acceleration: its magnitude along -z (m/s^2), or its vector."""


def gravity_vector(gravity: Gravity) -> np.ndarray:
    """The gravity acceleration vector (m/s^2): (0, 0, -g) of a magnitude g, else the vector
    given."""
    if isinstance(gravity, (int, float)):
        return np.array([0.0, 0.0, -float(gravity)])
    vector = np.array([float(v) for v in gravity])
    if vector.shape != (3,):
        raise ModelError(f"gravity must be a magnitude or [x, y, z], got {list(gravity)!r}")
    return vector


@dataclass(frozen=True, eq=False)
class ArmModel:
    """A serial arm of revolute joints, each link a solid truncated cone.

    Link i turns about ``axes[i]`` (a unit vector of link i-1's frame) at ``offsets[i]`` (the end
    of link i-1); its centre of mass ``coms[i]`` and central inertia ``inertias[i]`` are in its own
    frame. At q = 0 all frames are parallel to the inertial frame Oxyz (z up).
    """

    masses: np.ndarray
    lengths: np.ndarray
    radius_proximal: np.ndarray
    radius_distal: np.ndarray
    axes: np.ndarray
    offsets: np.ndarray
    coms: np.ndarray
    inertias: np.ndarray
    gravity: np.ndarray
    position_lower: np.ndarray | None = None
    """rad per joint, from a URDF's ``<limit lower>`` (-inf: none); None: a cone arm (no limits)."""
    position_upper: np.ndarray | None = None
    velocity_limit: np.ndarray | None = None
    """rad/s per joint, from a URDF's ``<limit velocity>`` (inf: none)."""
    effort_limit: np.ndarray | None = None
    """N m per joint, from a URDF's ``<limit effort>`` (inf: none)."""

    @classmethod
    def from_links(cls, masses: Sequence[float], lengths: Sequence[float],
                   radius_proximal: Sequence[float], radius_distal: Sequence[float],
                   joint_axes: Sequence[str], gravity: Gravity = 9.81
                   ) -> ArmModel:
        """Build the arm from per-link masses, lengths, cone radii and joint axis names;
        ``gravity`` the acceleration along -z (m/s^2), or its vector in Oxyz."""
        n = len(masses)
        if not (len(lengths) == len(radius_proximal) == len(radius_distal) == len(joint_axes) == n):
            raise ModelError("masses, lengths, radii and joint axes must have one entry per link")
        try:
            axes = np.array([AXIS_VECTORS[name] for name in joint_axes], dtype=float)
        except KeyError as exc:
            raise ModelError(f"unknown joint axis {exc.args[0]!r}; use one of "
                             f"{sorted(AXIS_VECTORS)}") from None
        offsets = np.zeros((n, 3))
        coms = np.zeros((n, 3))
        inertias = np.zeros((n, 3, 3))
        for i in range(n):
            if i > 0:
                offsets[i] = lengths[i - 1] * LINK_DIRECTION
            props = truncated_cone(masses[i], lengths[i], radius_proximal[i], radius_distal[i])
            coms[i] = props.com_distance * LINK_DIRECTION
            inertias[i] = cone_inertia_tensor(props, LINK_DIRECTION)
        return cls(np.asarray(masses, dtype=float), np.asarray(lengths, dtype=float),
                   np.asarray(radius_proximal, dtype=float), np.asarray(radius_distal, dtype=float),
                   axes, offsets, coms, inertias, gravity_vector(gravity))

    @property
    def dof(self) -> int:
        """Number of joints."""
        return int(self.masses.shape[0])

    # --- the model's arrays in the order the kernels take them ---
    @property
    def kernel_args(self) -> tuple[np.ndarray, ...]:
        """(masses, axes, offsets, coms, inertias, gravity) for the compiled kernels."""
        return (self.masses, self.axes, self.offsets, self.coms, self.inertias, self.gravity)

    def metric_tensor(self, q: np.ndarray) -> np.ndarray:
        """a(q), eq (2): the symmetric positive definite inertia matrix."""
        a, _, _ = dynamics.metric_terms(_vec(q), *self.kernel_args, False)
        return a

    def metric_tensors(self, positions: np.ndarray) -> np.ndarray:
        """a(q) of eq (2) at every row of ``positions`` (samples, n): (samples, n, n)."""
        return np.array([self.metric_tensor(q) for q in positions])

    def metric_derivative(self, q: np.ndarray) -> np.ndarray:
        """d a / d q as ``da[k, a, b] = d a_ab / d q_k``."""
        _, da, _ = dynamics.metric_terms(_vec(q), *self.kernel_args, True)
        return da

    def christoffel(self, q: np.ndarray) -> np.ndarray:
        """Christoffel symbols of the first kind, eq (5): ``G[a, b, c] = Gamma_{ab,c}``."""
        return dynamics.christoffel_from_derivative(self.metric_derivative(q))

    def gravity_forces(self, q: np.ndarray) -> np.ndarray:
        """Generalized gravitational forces Q^g of eq (6)."""
        _, _, qg = dynamics.metric_terms(_vec(q), *self.kernel_args, False)
        return qg

    def bias_forces(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """c(q, qdot) of eq (7): Christoffel terms minus gravity, so that a qdd + c = Q^u.

        Evaluated by the O(n) projection the integrator uses; :meth:`christoffel_bias_forces`
        gives the same vector through the Christoffel symbols of eq (5).
        """
        _, c = dynamics.inertia_and_bias(_vec(q), _vec(qd), *self.kernel_args)
        return c

    def christoffel_bias_forces(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """c(q, qdot) = sum_ab Gamma_{ab,c} qdot_a qdot_b - Q^g_c, eqs (1), (5), (6)."""
        _, da, qg = dynamics.metric_terms(_vec(q), *self.kernel_args, True)
        return dynamics.christoffel_bias(da, qg, _vec(qd))

    def forward_dynamics(self, q: np.ndarray, qd: np.ndarray, effort: np.ndarray) -> np.ndarray:
        """qdd from eq (8): a(q) qdd = Q^u - c(q, qdot)."""
        a, c = dynamics.inertia_and_bias(_vec(q), _vec(qd), *self.kernel_args)
        return dynamics.solve_spd(a, _vec(effort) - c)

    def inverse_dynamics(self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
        """Q^u = a(q) qdd + c(q, qdot), eq (8)."""
        a, c = dynamics.inertia_and_bias(_vec(q), _vec(qd), *self.kernel_args)
        return np.asarray(a @ _vec(qdd) + c)

    def kinetic_energy(self, q: np.ndarray, qd: np.ndarray) -> float:
        """(1/2) qdot^T a(q) qdot."""
        v = _vec(qd)
        return 0.5 * float(v @ self.metric_tensor(q) @ v)

    def potential_energy(self, q: np.ndarray) -> float:
        """Gravitational potential energy, zero at the shoulder height."""
        _, _, rc, _ = dynamics.chain_frames(_vec(q), self.axes, self.offsets, self.coms,
                                            self.inertias)
        return float(-np.sum(self.masses * (rc @ self.gravity)))


class MassBearing(Protocol):
    """A dataclass of an arm's links with per-link ``masses`` and ``inertias``."""

    @property
    def masses(self) -> np.ndarray: ...
    @property
    def inertias(self) -> np.ndarray: ...


MassBearingT = TypeVar("MassBearingT", bound=MassBearing)


def with_mass_scale(arm: MassBearingT, mass_uncertainty: float) -> MassBearingT:
    """The same arm (an :class:`ArmModel` or a URDF chain) with every mass (and so every
    inertia) scaled by (1 + delta), eq (15): the one mass scaling of the package."""
    scale = 1.0 + float(mass_uncertainty)
    if scale <= 0.0:
        raise ModelError("mass uncertainty must be greater than -1")
    return dataclasses.replace(arm, masses=arm.masses * scale,  # type: ignore[type-var]
                               inertias=arm.inertias * scale)


def _vec(x: np.ndarray | Sequence[float]) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64)
