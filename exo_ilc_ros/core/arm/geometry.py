"""Mass properties of the arm's links: solid truncated cones of uniform density."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import Polynomial

from ..errors import ModelError


@dataclass(frozen=True)
class ConeProperties:
    """Centre of mass and central inertia of a solid truncated cone along its own axis."""

    com_distance: float
    """Distance of the centre of mass from the proximal face, along the axis (m)."""
    axial_inertia: float
    """Moment of inertia about the cone axis through the centre of mass (kg m^2)."""
    transverse_inertia: float
    """Moment of inertia about any axis through the centre of mass normal to the cone axis."""


def truncated_cone(mass: float, length: float, radius_proximal: float,
                   radius_distal: float) -> ConeProperties:
    """Mass properties of a uniform solid truncated cone (frustum).

    The cone is cut into discs of radius r(s) = R1 + (R2 - R1) s / l at distance s from the
    proximal face; each disc contributes dm = rho pi r^2 ds, (1/2) r^2 dm about the axis and
    (1/4) r^2 dm + (s - s_c)^2 dm about a transverse axis. The integrals are polynomials in s,
    integrated exactly. A massless or zero-length link (the paper's fictive link) has no inertia.
    """
    if mass < 0.0 or length < 0.0 or radius_proximal < 0.0 or radius_distal < 0.0:
        raise ModelError("link mass, length and radii must be non-negative")
    if mass == 0.0 or length == 0.0:
        return ConeProperties(0.0, 0.0, 0.0)
    if radius_proximal == 0.0 and radius_distal == 0.0:
        raise ModelError("a link with mass needs a positive radius at one end at least")
    radius = Polynomial([radius_proximal, (radius_distal - radius_proximal) / length])
    s = Polynomial([0.0, 1.0])
    area = radius**2  # times pi, which cancels against the density

    def integral(p: Polynomial) -> float:
        antiderivative = p.integ()
        return float(antiderivative(length) - antiderivative(0.0))

    volume = integral(area)
    density = mass / volume  # per pi
    com = integral(area * s) / volume
    axial = density * integral(0.5 * area * radius**2)
    transverse = density * integral(0.25 * area * radius**2 + area * (s - com) ** 2)
    return ConeProperties(com, axial, transverse)


def cone_inertia_tensor(props: ConeProperties, axis: np.ndarray) -> np.ndarray:
    """Central inertia tensor of a cone whose axis is the unit vector ``axis`` (3x3, kg m^2)."""
    u = np.asarray(axis, dtype=float)
    u = u / np.linalg.norm(u)
    parallel = np.outer(u, u)
    return props.axial_inertia * parallel + props.transverse_inertia * (np.eye(3) - parallel)
