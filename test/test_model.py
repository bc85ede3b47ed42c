"""The arm model against an independent oracle (Pinocchio on the URDF) and against physics."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exo_ilc_ros.core import ArmModel, build_arm, load_config
from exo_ilc_ros.core.arm import dynamics
from exo_ilc_ros.core.arm.geometry import truncated_cone
from exo_ilc_ros.core.arm.model import with_mass_scale
from exo_ilc_ros.core.arm.urdf import arm_urdf
from exo_ilc_ros.core.loop.controller import computed_torque_kernel
from exo_ilc_ros.core.loop.plant import PlantDynamics, integrate_period
from exo_ilc_ros.core.reference.trajectory import QuinticTrajectory

pin = pytest.importorskip("pinocchio")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def arm() -> ArmModel:
    return build_arm(load_config())


@pytest.fixture(scope="module")
def oracle() -> tuple:
    model = pin.buildModelFromXML((ROOT / "urdf" / "exo_arm.urdf").read_text())
    return model, model.createData()


def random_states(count: int, seed: int = 7) -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-np.pi, np.pi, 3), rng.uniform(-4.0, 4.0, 3)) for _ in range(count)]


def test_shipped_urdf_is_generated_from_the_shipped_config(arm: ArmModel) -> None:
    config = load_config()
    expected = arm_urdf(arm, config["joint_names"], config["control.effort_limit"])
    assert (ROOT / "urdf" / "exo_arm.urdf").read_text() == expected, \
        "urdf/exo_arm.urdf is stale: regenerate with `exo-ilc urdf --out urdf/exo_arm.urdf`"


def test_oracle_loads_the_arm_as_three_revolute_joints(oracle: tuple) -> None:
    model, _ = oracle
    assert (model.nq, model.nv) == (3, 3)
    assert np.allclose(model.gravity.linear, [0.0, 0.0, -9.81])
    assert pytest.approx(sum(i.mass for i in model.inertias)) == 2.5


def test_metric_tensor_matches_pinocchio(arm: ArmModel, oracle: tuple) -> None:
    model, data = oracle
    for q, _ in random_states(150):
        expected = pin.crba(model, data, q)
        expected = np.triu(expected) + np.triu(expected, 1).T  # pinocchio < 3 fills one triangle
        np.testing.assert_allclose(arm.metric_tensor(q), expected, rtol=0, atol=1e-9)


def test_bias_and_gravity_match_pinocchio(arm: ArmModel, oracle: tuple) -> None:
    model, data = oracle
    for q, qd in random_states(150, seed=11):
        nle = pin.nonLinearEffects(model, data, q, qd)  # C(q, qd) qd + g(q)
        gravity = pin.computeGeneralizedGravity(model, data, q)
        np.testing.assert_allclose(arm.bias_forces(q, qd), nle, rtol=0, atol=1e-9)
        np.testing.assert_allclose(arm.christoffel_bias_forces(q, qd), nle, rtol=0, atol=1e-9)
        np.testing.assert_allclose(arm.gravity_forces(q), -gravity, rtol=0, atol=1e-9)


def test_forward_and_inverse_dynamics_match_pinocchio(arm: ArmModel, oracle: tuple) -> None:
    model, data = oracle
    rng = np.random.default_rng(3)
    for q, qd in random_states(100, seed=5):
        qdd = rng.uniform(-10, 10, 3)
        tau = pin.rnea(model, data, q, qd, qdd)
        np.testing.assert_allclose(arm.inverse_dynamics(q, qd, qdd), tau, rtol=0, atol=1e-9)
        np.testing.assert_allclose(arm.forward_dynamics(q, qd, tau), qdd, rtol=0,
                                   atol=1e-8)


def test_metric_tensor_is_symmetric_positive_definite(arm: ArmModel) -> None:
    for q, _ in random_states(200, seed=13):
        a = arm.metric_tensor(q)
        np.testing.assert_array_equal(a, a.T)
        assert np.linalg.eigvalsh(a).min() > 0.0


def test_christoffel_symbols_follow_eq5(arm: ArmModel) -> None:
    """Gamma_{ab,c} = (d_a a_bc + d_b a_ca - d_c a_ab) / 2, symmetric in a, b; the metric
    derivative checked against central differences."""
    for q, _ in random_states(20, seed=17):
        gamma = arm.christoffel(q)
        np.testing.assert_allclose(gamma, np.swapaxes(gamma, 0, 1), atol=1e-14)
        h = 1e-6
        numeric = np.array([(arm.metric_tensor(q + h * np.eye(3)[k])
                             - arm.metric_tensor(q - h * np.eye(3)[k])) / (2 * h)
                            for k in range(3)])
        np.testing.assert_allclose(arm.metric_derivative(q), numeric, atol=1e-8)


def test_mass_uncertainty_scales_the_whole_model(arm: ArmModel) -> None:
    plant = with_mass_scale(arm, 0.15)
    for q, qd in random_states(10):
        np.testing.assert_allclose(plant.metric_tensor(q), 1.15 * arm.metric_tensor(q),
                                   atol=1e-15)
        np.testing.assert_allclose(plant.bias_forces(q, qd), 1.15 * arm.bias_forces(q, qd),
                                   atol=1e-13)


def test_truncated_cone_matches_closed_forms() -> None:
    m, length, r1, r2 = 1.4, 0.369, 0.05, 0.04
    props = truncated_cone(m, length, r1, r2)
    com = length * (r1**2 + 2 * r1 * r2 + 3 * r2**2) / (4 * (r1**2 + r1 * r2 + r2**2))
    axial = 0.3 * m * (r1**5 - r2**5) / (r1**3 - r2**3)
    assert props.com_distance == pytest.approx(com, rel=1e-12)
    assert props.axial_inertia == pytest.approx(axial, rel=1e-12)
    cylinder = truncated_cone(2.0, 0.5, 0.1, 0.1)
    assert cylinder.com_distance == pytest.approx(0.25)
    assert cylinder.transverse_inertia == pytest.approx(2.0 * (3 * 0.01 + 0.25) / 12)
    cone = truncated_cone(3.0, 0.4, 0.1, 0.0)  # solid cone, apex at the distal end
    assert cone.com_distance == pytest.approx(0.1)
    assert cone.transverse_inertia == pytest.approx(3.0 * (3 / 20 * 0.01 + 3 / 80 * 0.16))
    assert truncated_cone(0.0, 0.0, 0.0, 0.0).transverse_inertia == 0.0


def test_free_plant_conserves_energy(arm: ArmModel) -> None:
    q = np.array([0.3, -0.5, 1.0])
    qd = np.array([1.0, -0.8, 1.5])
    energy0 = arm.kinetic_energy(q, qd) + arm.potential_energy(q)
    args = arm.kernel_args
    drift = 0.0
    for _ in range(1000):  # 10 s of 10 ms periods, 1 ms RK4 sub-steps, no effort, no damping
        q, qd = integrate_period(q, qd, np.zeros(3), 0.01, 10, args, args,
                                 int(PlantDynamics.FULL))
        drift = max(drift, abs(arm.kinetic_energy(q, qd) + arm.potential_energy(q) - energy0))
    assert drift < 1e-8
    assert np.abs(qd).max() > 0.1  # it really moved


def test_computed_torque_linearises_the_arm_exactly(arm: ArmModel) -> None:
    """Eqs (9)-(10): with delta = 0, Q = a(q) u + c(q, qdot) gives qdd = u, so u = qdd_d(t)
    applied continuously (evaluated at every RK4 stage) reproduces the reference."""
    config = load_config()
    traj = QuinticTrajectory.rest_to_rest(config["trajectory.start"], config["trajectory.goal"],
                                          config["trajectory.duration"])
    limit = np.full(3, 1e9)

    def rate(t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        _, _, qdd_d = traj.evaluate(t)
        effort = computed_torque_kernel(q, qd, qdd_d, arm.kernel_args, limit)
        return arm.forward_dynamics(q, qd, effort)

    h = 1e-3
    q, qd, _ = (x.copy() for x in traj.evaluate(0.0))
    worst = 0.0
    for i in range(int(round(traj.duration / h))):
        t = i * h
        k1q, k1v = qd, rate(t, q, qd)
        k2q, k2v = qd + h / 2 * k1v, rate(t + h / 2, q + h / 2 * k1q, qd + h / 2 * k1v)
        k3q, k3v = qd + h / 2 * k2v, rate(t + h / 2, q + h / 2 * k2q, qd + h / 2 * k2v)
        k4q, k4v = qd + h * k3v, rate(t + h, q + h * k3q, qd + h * k3v)
        q = q + h / 6 * (k1q + 2 * k2q + 2 * k3q + k4q)
        qd = qd + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        worst = max(worst, np.abs(traj.evaluate(t + h)[0] - q).max())
    assert worst < 1e-6


def test_paper_approximation_equals_full_plant_without_uncertainty(arm: ArmModel) -> None:
    q0, qd0 = np.array([0.2, 0.4, -0.3]), np.array([0.5, -0.2, 0.1])
    effort = np.array([1.0, -2.0, 0.5])
    args = arm.kernel_args
    full = integrate_period(q0, qd0, effort, 0.01, 10, args, args, int(PlantDynamics.FULL))
    approx = integrate_period(q0, qd0, effort, 0.01, 10, args, args,
                              int(PlantDynamics.PAPER_APPROXIMATION))
    np.testing.assert_allclose(full[0], approx[0], atol=1e-14)
    plant = with_mass_scale(arm, 0.1)
    full = integrate_period(q0, qd0, effort, 0.01, 10, plant.kernel_args, args, 0)
    approx = integrate_period(q0, qd0, effort, 0.01, 10, plant.kernel_args, args, 1)
    assert not np.allclose(full[1], approx[1], atol=1e-9)  # the approximation differs with delta


def random_chain(n: int, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """kernel_args of a generic chain: tilted axes, offsets and centres of mass off the axes,
    full (non-diagonal) inertia tensors, gravity not along z."""
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    root = rng.normal(size=(n, 3, 3))
    inertias = 0.02 * (root @ np.swapaxes(root, 1, 2) + 0.1 * np.eye(3))
    return (rng.uniform(0.2, 2.0, n), axes, 0.3 * rng.normal(size=(n, 3)),
            0.2 * rng.normal(size=(n, 3)), inertias, np.array([0.4, -0.3, -9.81]))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 6])
def test_fast_kernels_match_the_reference_path_on_other_chains(n: int) -> None:
    """The fused outward pass (a and c of eq (7)) and the solves against the slow reference
    path (eq (2) loops, c by the Christoffel contraction of eq (5)) and numpy, for any n."""
    rng = np.random.default_rng(100 + n)
    args = random_chain(n, rng)
    ws = dynamics.workspace(n)  # reused across states, as the integrator does
    out = np.empty(n)
    for _ in range(30):
        q, qd, effort = (rng.uniform(-np.pi, np.pi, n), rng.uniform(-4.0, 4.0, n),
                         rng.uniform(-5.0, 5.0, n))
        a_ref, da, qg = dynamics.metric_terms(q, *args, True)
        c_ref = dynamics.christoffel_bias(da, qg, qd)
        a, c = dynamics.inertia_and_bias(q, qd, *args)
        np.testing.assert_allclose(a, a_ref, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(a, a.T)
        np.testing.assert_allclose(c, c_ref, rtol=0, atol=1e-11)
        bias = np.empty(n)
        a_ws = dynamics.inertia_and_bias_into(q, qd, *args, ws, bias)
        np.testing.assert_array_equal(a_ws, a)
        np.testing.assert_array_equal(bias, c)
        dynamics.forward_dynamics_into(q, qd, effort, args, ws, out)
        expected = np.linalg.solve(a_ref, effort - c_ref)
        np.testing.assert_allclose(out, expected, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(dynamics.solve_spd(a, effort - c), expected, rtol=1e-9,
                                   atol=1e-9)
        aliased = effort.copy()  # out may be the effort array itself
        dynamics.forward_dynamics_into(q, qd, aliased, args, ws, aliased)
        np.testing.assert_array_equal(aliased, out)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_solves_reject_a_matrix_that_is_not_positive_definite(n: int) -> None:
    """The 3x3 unrolled solve and the general Cholesky fail alike, also inside the forward
    dynamics (a massless chain has a = 0)."""
    indefinite = np.eye(n)
    indefinite[-1, -1] = -1.0
    with pytest.raises(ValueError, match="not positive definite"):
        dynamics.solve_spd(indefinite, np.ones(n))
    masses, axes, offsets, coms, inertias, gravity = random_chain(n, np.random.default_rng(n))
    args = (0.0 * masses, axes, offsets, coms, 0.0 * inertias, gravity)
    with pytest.raises(ValueError, match="not positive definite"):
        dynamics.forward_dynamics_into(np.zeros(n), np.zeros(n), np.ones(n), args,
                                       dynamics.workspace(n), np.empty(n))


def test_chain_frames_are_the_kinematics_of_the_arm(arm: ArmModel) -> None:
    """e_i, p_i, r_Ci and R_i J_i R_i^T: unit axes, rotated inertia with the same spectrum."""
    for q, _ in random_states(10, seed=23):
        e, p, rc, jw = dynamics.chain_frames(q, arm.axes, arm.offsets, arm.coms, arm.inertias)
        assert e.shape == p.shape == rc.shape == (3, 3) and jw.shape == (3, 3, 3)
        np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-15)
        np.testing.assert_allclose(p[0], arm.offsets[0], atol=1e-15)
        for i in range(3):
            np.testing.assert_allclose(np.linalg.norm(rc[i] - p[i]),
                                       np.linalg.norm(arm.coms[i]), atol=1e-15)
            np.testing.assert_allclose(np.linalg.eigvalsh(jw[i]),
                                       np.linalg.eigvalsh(arm.inertias[i]), atol=1e-15)
