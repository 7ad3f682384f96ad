"""Centroidal momentum tasks: MomentumPD's q̈ rows are A_G (finite differences of the momentum
h_G = A_G v wrt v, from pinocchio.computeCentroidalMomentum), its drift Ȧ_G v (finite differences
of A_G(q) v along v); MomentumForce's contact map is the Newton-Euler law of the whole robot
(Herzog et al. 2016, eq. 21): ḣ_G = G λ + m g for any motion consistent with the dynamics."""

import numpy as np
import pinocchio as pin
import pytest

from wholebody.tasks import MomentumForce, MomentumPD
from wholebody.variables import Variables

from . import _fd

ROBOTS = ("talos14", "hyq")


def _at(robot, seed):
    q, v = _fd.state_near_reference(robot, seed)
    robot.update(q, v)
    return q, v


def _momentum_terms(robot, q, v):
    """(A_G, Ȧ_G v, h_G) from computeCentroidalMomentum and finite differences."""
    hg = _fd.centroidal_momentum(robot)
    A = np.column_stack([(hg(q, v + _fd.EPS * e) - hg(q, v - _fd.EPS * e)) / (2 * _fd.EPS)
                         for e in np.eye(robot.nv)])
    e = _fd.EPS
    Adv = (hg(_fd.moved(robot, q, v, e), v) - hg(_fd.moved(robot, q, v, -e), v)) / (2 * e)
    return A, Adv, hg(q, v)


@pytest.mark.parametrize("seed", (0, 1))
@pytest.mark.parametrize("name", ROBOTS)
def test_momentum_pd_rows_are_the_centroidal_momentum_matrix_and_drift(robots, name, seed):
    robot = robots[name]
    q, v = _at(robot, seed)
    A, Adv, _ = _momentum_terms(robot, q, v)
    task = MomentumPD(P=np.zeros((6, 6)), D=np.zeros((6, 6)))
    rows = task.rows(robot, Variables(robot))
    assert rows.lam is None and rows.tau is None
    np.testing.assert_allclose(rows.qdd, A, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(rows.target, -Adv, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("name", ROBOTS)
def test_momentum_matrix_linear_part_is_mass_times_com_jacobian(robots, name):
    """Linear momentum = m ċ: the first 3 rows of A_G are m times the finite-difference CoM
    Jacobian."""
    robot = robots[name]
    q, _ = _at(robot, 2)
    com = _fd.com_fd(robot)
    e = _fd.EPS
    Jc = np.column_stack([(com(_fd.moved(robot, q, d, e)) - com(_fd.moved(robot, q, d, -e))) / (2 * e)
                          for d in np.eye(robot.nv)])
    rows = MomentumPD().rows(robot, Variables(robot))
    np.testing.assert_allclose(rows.qdd[:3], robot.mass * Jc, atol=1e-6)


@pytest.mark.parametrize("name", ROBOTS)
def test_momentum_pd_target_is_eq_22(robots, name):
    """A_G q̈ + Ȧ_G v = P [m (x_ref - x); 0] + D (h_ref - h) + ḣ_ref."""
    robot = robots[name]
    q, v = _at(robot, 3)
    _, Adv, h = _momentum_terms(robot, q, v)
    rng = np.random.default_rng(7)
    P, D = np.diag(rng.uniform(1, 50, 6)), np.diag(rng.uniform(1, 20, 6))
    task = MomentumPD(P=P, D=D)
    offset = np.array([0.01, -0.02, 0.005])
    task.com_ref = _fd.com_fd(robot)(q) + offset
    task.h_ref, task.hdot_ref = rng.normal(size=6), rng.normal(size=6)
    rows = task.rows(robot, Variables(robot))
    expected = (P @ np.r_[robot.mass * offset, np.zeros(3)] + D @ (task.h_ref - h) + task.hdot_ref
                - Adv)
    np.testing.assert_allclose(rows.target, expected, rtol=1e-6, atol=1e-5)


def _dynamics_consistent_motion(robot, q, v, seed):
    """(λ, q̈): random contact forces and torques, q̈ from ABA with finite-difference contact
    Jacobians."""
    rng = np.random.default_rng(seed)
    J = _fd.contact_jacobians_fd(robot, q, robot.contact_names)
    lam = rng.normal(scale=50.0, size=J.shape[0])
    tau = rng.normal(scale=10.0, size=robot.na)
    return lam, _fd.forward_dynamics(robot, q, v, tau, J, lam)


@pytest.mark.parametrize("name", ROBOTS)
def test_momentum_force_map_is_the_newton_euler_law(robots, name):
    """With K = 0, k = 0 the rows are G λ: for a motion consistent with the dynamics,
    G λ + m g = ḣ_G (pinocchio.computeCentroidalMomentumTimeVariation with that q̈), and MomentumPD's
    own rows agree: A_G q̈ + Ȧ_G v = ḣ_G."""
    robot = robots[name]
    q, v = _at(robot, 4)
    lam, qdd = _dynamics_consistent_motion(robot, q, v, 4)
    data = robot.model.createData()
    hdot = pin.computeCentroidalMomentumTimeVariation(robot.model, data, q, v, qdd).vector
    variables = Variables(robot)
    n_lam = variables.n_lambda
    force = MomentumForce(K=np.zeros((n_lam, 9)), k=np.zeros(n_lam)).rows(robot, variables)
    assert force.qdd is None and force.tau is None
    gravity = robot.mass * np.r_[robot.model.gravity.linear, np.zeros(3)]
    np.testing.assert_allclose(force.lam @ lam + gravity, hdot, rtol=1e-6, atol=1e-5)
    pd = MomentumPD(P=np.zeros((6, 6)), D=np.zeros((6, 6))).rows(robot, variables)
    np.testing.assert_allclose(pd.qdd @ qdd - pd.target, hdot, rtol=1e-6, atol=1e-5)


@pytest.mark.parametrize("name", ROBOTS)
def test_momentum_force_target_is_eq_24(robots, name):
    """G (λ + K [x; h] - k) = 0: the residual of the rows at any λ is G (λ + K s - k), with the
    state s = [CoM; h_G] evaluated independently."""
    robot = robots[name]
    q, v = _at(robot, 5)
    variables = Variables(robot)
    n_lam = variables.n_lambda
    rng = np.random.default_rng(5)
    K, k, lam = rng.normal(size=(n_lam, 9)), rng.normal(size=n_lam), rng.normal(size=n_lam)
    rows = MomentumForce(K=K, k=k).rows(robot, variables)
    G = MomentumForce(K=np.zeros((n_lam, 9)), k=np.zeros(n_lam)).rows(robot, variables).lam
    state = np.r_[_fd.com_fd(robot)(q), _fd.centroidal_momentum(robot)(q, v)]
    np.testing.assert_allclose(_fd.row_residual(rows, lam=lam), G @ (lam + K @ state - k),
                               rtol=1e-9, atol=1e-7)


def test_momentum_force_on_a_contact_subset_fills_its_columns_only(robots):
    robot = robots["hyq"]
    q, v = _at(robot, 6)
    variables = Variables(robot)
    subset = robot.contact_names[1:3]
    n = 3 * len(subset)
    rows = MomentumForce(K=np.zeros((n, 9)), k=np.zeros(n), contacts=subset).rows(robot, variables)
    full = MomentumForce(K=np.zeros((12, 9)), k=np.zeros(12)).rows(robot, variables)
    for name in robot.contact_names:
        sl = variables.lambda_slices[name]
        expected = full.lam[:, sl] if name in subset else np.zeros((6, 3))
        np.testing.assert_array_equal(rows.lam[:, sl], expected)
    with pytest.raises(ValueError, match="K must be"):
        MomentumForce(K=np.zeros((12, 9)), k=np.zeros(12), contacts=subset).rows(robot, variables)
    with pytest.raises(ValueError, match="not set"):
        MomentumForce().rows(robot, variables)


def test_the_checks_detect_a_wrong_momentum_map(robots):
    """The Newton-Euler check fails when the forces act at the frame origins instead of the
    contact points (the sphere bottoms of HyQ's feet, 2 cm lower), and the A_G check fails for
    the matrix of the momentum about the base origin instead of the CoM."""
    robot = robots["hyq"]
    q, v = _at(robot, 4)
    lam, qdd = _dynamics_consistent_motion(robot, q, v, 4)
    data = robot.model.createData()
    hdot = pin.computeCentroidalMomentumTimeVariation(robot.model, data, q, v, qdd).vector
    G = MomentumForce(K=np.zeros((12, 9)), k=np.zeros(12)).rows(robot, Variables(robot)).lam.copy()
    for i, c in enumerate(robot.contacts):  # shift each point 2 cm up: +[r ẑ]x on the moments
        r = np.array([0.0, 0.0, c.spec.radius])
        G[3:, 3 * i:3 * i + 3] += pin.skew(r)
    gravity = robot.mass * np.r_[robot.model.gravity.linear, np.zeros(3)]
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(G @ lam + gravity, hdot, rtol=1e-6, atol=1e-5)
    A, _, _ = _momentum_terms(robot, q, v)
    about_base = robot.A_G.copy()
    offset = robot.com - q[:3]
    about_base[3:] += pin.skew(offset) @ robot.A_G[:3]
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(about_base, A, rtol=1e-6, atol=1e-6)
