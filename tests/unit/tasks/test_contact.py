"""Contact constraint and contact-force conditions: J q̈ + J̇ v = 0 with J and J̇ v from finite
differences of the contact point (the sole origin, or the bottom of a foot sphere, as a body-fixed
point); friction pyramid, normal-force bounds and centre of pressure accept a force explicitly
constructed inside and reject one just outside; the force regulariser's minimiser is its target."""

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import linprog

from wholebody.tasks import (CenterOfPressure, ContactConstraint, ForceRegularizer, FrictionCone,
                             NormalForceBounds, tangent_basis)
from wholebody.variables import Variables

from . import _fd

ROBOTS = ("talos14", "hyq")
TILTED = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])


def _at(robot, seed, scale=0.05):
    q, v = _fd.state_near_reference(robot, seed, scale=scale)
    robot.update(q, v)
    return q, v


def _fd_contact_terms(robot, q, v, names):
    J, drift = [], []
    for n in names:
        pose = _fd.BodyPoint.contact(robot, n, q).pose
        dim = robot.contact(n).dim
        J.append(_fd.jacobian_fd(robot, pose, q)[:dim])
        drift.append(_fd.drift_fd(robot, pose, q, v)[:dim])
    return np.vstack(J), np.concatenate(drift)


@pytest.mark.parametrize("seed", (0, 1))
@pytest.mark.parametrize("name", ROBOTS)
def test_contact_constraint_is_the_contact_point_acceleration(robots, name, seed):
    robot = robots[name]
    q, v = _at(robot, seed)
    for names in (robot.contact_names, robot.contact_names[1:]):
        J, drift = _fd_contact_terms(robot, q, v, names)
        rows = ContactConstraint().rows(robot, Variables(robot, names))
        assert rows.lam is None and rows.tau is None
        np.testing.assert_allclose(rows.qdd, J, atol=1e-8)
        np.testing.assert_allclose(rows.target, -drift, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ROBOTS)
def test_contact_constraint_pulls_feet_back_to_their_anchors(robots, name):
    """Stance task (Fahmi et al. 2019, eq. 32): target = -J̇ v + kp (anchor - x) - kd ẋ, the
    anchor being the contact frame's position at first use."""
    robot = robots[name]
    q0, _ = _at(robot, 2)
    task = ContactConstraint(kp=300.0, kd=30.0)
    task.rows(robot, Variables(robot))
    anchors = {n: _fd.BodyPoint(robot, robot.contact(n).frame_id).pose(q0)[0]
               for n in robot.contact_names}
    q, v = _at(robot, 3)
    J, drift = _fd_contact_terms(robot, q, v, robot.contact_names)
    rows = task.rows(robot, Variables(robot))
    expected, r = -drift.copy(), 0
    for n in robot.contact_names:
        dim = robot.contact(n).dim
        pos = _fd.BodyPoint(robot, robot.contact(n).frame_id).pose(q)[0]
        velocity = J[r:r + dim] @ v
        expected[r:r + 3] += 300.0 * (anchors[n] - pos) - 30.0 * velocity[:3]
        expected[r + 3:r + dim] -= 30.0 * velocity[3:]
        r += dim
    np.testing.assert_allclose(rows.target, expected, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("rank", (3, 6))
def test_independent_rows_keep_the_least_squares_solutions(rank):
    """independent_rows on J (6 x 9, of rank ``rank``) and a target no x meets exactly (rank 3):
    the returned rows are ``rank`` independent rows and zeros, and their solutions are exactly
    the least-squares solutions of J x ≈ target — the same null space as J (scipy), and
    numpy's lstsq solution meets them; at full rank they are J's own solutions."""
    from scipy.linalg import null_space

    from wholebody.tasks.contact import independent_rows
    rng = np.random.default_rng(rank)
    J = rng.normal(size=(6, rank)) @ rng.normal(size=(rank, 9))
    target = rng.normal(size=6)
    rows, targets, found = independent_rows(J, target, 1e-9)
    assert found == rank
    assert not rows[rank:].any() and not targets[rank:].any()
    assert np.linalg.matrix_rank(rows[:rank]) == rank
    N, M = null_space(J), null_space(rows)
    np.testing.assert_allclose(M @ M.T, N @ N.T, atol=1e-10)
    x = np.linalg.lstsq(J, target, rcond=None)[0]
    np.testing.assert_allclose(rows @ x, targets, atol=1e-10)
    if rank < 6:
        assert np.linalg.norm(J @ x - target) > 0.1  # no exact solution
    else:
        y = np.linalg.lstsq(rows, targets, rcond=None)[0]
        np.testing.assert_allclose(J @ y, target, atol=1e-10)
    # the rows do not depend on the row order of J (each singular vector's sign is fixed)
    order = rng.permutation(6)
    again, again_targets, _ = independent_rows(J[order], target[order], 1e-9)
    np.testing.assert_allclose(again, rows, atol=1e-10)
    np.testing.assert_allclose(again_targets, targets, atol=1e-10)
    # rows with a NaN are returned as they are (for the cycle's checks), no rows give no rows
    J[1, 2] = np.nan
    same, same_targets, kept = independent_rows(J, target, 1e-9)
    assert kept == 6 and np.isnan(same[1, 2]) and np.array_equal(same_targets, target)
    empty = independent_rows(np.zeros((0, 9)), np.zeros(0), 1e-9)
    assert empty[0].shape == (0, 9) and empty[2] == 0


def test_tangent_basis_is_right_handed_and_orthonormal():
    for normal in (np.array([0, 0, 2.0]), TILTED, np.array([1.0, 0, 0]), np.array([0, -1.0, 0.1])):
        t1, t2, n = tangent_basis(normal)
        B = np.column_stack([t1, t2, n])
        np.testing.assert_allclose(B.T @ B, np.eye(3), atol=1e-12)
        assert np.linalg.det(B) == pytest.approx(1.0)
        np.testing.assert_allclose(n, normal / np.linalg.norm(normal), atol=1e-12)


def _force(normal, tangential_ratio, mu, azimuth, fn=300.0):
    """A force of normal component ``fn`` along ``normal`` and a tangential part of magnitude
    ``tangential_ratio * mu * fn`` in direction ``azimuth`` (an orthonormal tangent frame built
    here, not with tangent_basis)."""
    n = normal / np.linalg.norm(normal)
    a = np.cross(n, [0.3, 0.9, 0.1])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    return fn * n + tangential_ratio * mu * fn * (np.cos(azimuth) * a + np.sin(azimuth) * b)


def _stacked(robot, variables, per_contact):
    lam = np.zeros(variables.n_lambda)
    for n, value in per_contact.items():
        sl = variables.lambda_slices[n]
        lam[sl.start:sl.start + len(value)] = value
    return lam


@pytest.mark.parametrize("name", ROBOTS)
def test_friction_pyramid_accepts_forces_inside_and_rejects_forces_outside(robots, name):
    """The pyramid |f.t1| <= mu f_n, |f.t2| <= mu f_n (a square in the tangent plane) contains
    the circle of radius mu f_n and lies inside the circle of radius sqrt(2) mu f_n: a force with
    |f_t| = 0.99 mu f_n is inside in every tangential direction, one with 1.01 sqrt(2) mu f_n
    outside in every direction; along the square's axes the bound is exactly mu f_n; a pulling
    force (f_n < 0) is outside."""
    robot = robots[name]
    _at(robot, 4)
    mu = robot.friction
    variables = Variables(robot)
    for normal in (np.array([0.0, 0.0, 1.0]), TILTED):
        task = FrictionCone(mu, normals={n: normal for n in robot.contact_names})
        rows = task.rows(robot, variables)
        assert not rows.is_equality and rows.qdd is None and rows.tau is None
        assert rows.m == 4 * len(robot.contact_names)
        for azimuth in np.linspace(0, 2 * np.pi, 13):
            for contact in robot.contact_names:
                inside = _stacked(robot, variables, {
                    c: _force(normal, 0.99, mu, azimuth) for c in robot.contact_names})
                assert _fd.satisfies(rows, lam=inside)
                outside = inside.copy()
                outside[variables.lambda_slices[contact].start:][:3] = _force(
                    normal, 1.01 * np.sqrt(2), mu, azimuth)
                assert not _fd.satisfies(rows, lam=outside)
        t1, t2, n = tangent_basis(normal)
        for t in (t1, -t1, t2, -t2):  # along the pyramid's axes the bound is exactly mu f_n
            for ratio, ok in ((0.99, True), (1.01, False)):
                f = 300.0 * (n + ratio * mu * t)
                lam = _stacked(robot, variables, {robot.contact_names[0]: f})
                assert _fd.satisfies(rows, lam=lam) is ok
        pull = _stacked(robot, variables, {robot.contact_names[-1]: -50.0 * n})
        assert not _fd.satisfies(rows, lam=pull)


def _corner_pyramids_carry(R, origin_to_corners, mu, wrench) -> bool:
    """Whether square friction pyramids (axes R) at the corners can produce ``wrench`` = [f; tau]
    (world axes, about the sole origin): a feasibility LP over the corners' edge forces."""
    edges = [R @ np.array([sx * mu, sy * mu, 1.0]) for sx in (1, -1) for sy in (1, -1)]
    generators = np.array([np.r_[e, np.cross(p, e)] for p in origin_to_corners for e in edges]).T
    lp = linprog(np.zeros(generators.shape[1]), A_eq=generators, b_eq=wrench,
                 bounds=[(0.0, None)] * generators.shape[1], method="highs")
    return lp.status == 0


def _sample_sole_wrenches(R, hx, hy, mu, count, seed):
    """Wrenches [f; tau] (world axes) around a 300 N load, spread across the cone's boundary."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        local = np.array([0.0, 0.0, 300.0]) + rng.normal(size=3) * [100.0, 100.0, 40.0]
        moment = rng.normal(size=3) * [0.6 * hy, 0.6 * hx, 0.5 * mu * (hx + hy)] * 300.0
        yield np.r_[R @ local, R @ moment]


def test_wrench_cone_block_is_the_contact_wrench_cone():
    """The pyramid about the sole's axes, the CoP rows and the yaw-moment rows hold exactly for
    the wrenches that friction pyramids at the sole's four corners can produce (an LP over the
    corner forces decides), for a tilted and yawed sole."""
    R = pin.rpy.rpyToMatrix(0.3, -0.2, 0.9)
    hx, hy, mu = 0.1, 0.05, 0.6
    corners = [R @ np.array([sx * hx, sy * hy, 0.0]) for sx in (1, -1) for sy in (1, -1)]
    pyramid = np.zeros((4, 6))
    pyramid[:, :3] = [R[:, 0] - mu * R[:, 2], -R[:, 0] - mu * R[:, 2], R[:, 1] - mu * R[:, 2],
                      -R[:, 1] - mu * R[:, 2]]
    rows = np.vstack([pyramid, CenterOfPressure.block(R, hx, hy),
                      FrictionCone.wrench_cone_block(R, hx, hy, mu)])
    verdicts = []
    for wrench in _sample_sole_wrenches(R, hx, hy, mu, 400, seed=3):
        truth = _corner_pyramids_carry(R, corners, mu, wrench)
        assert bool(np.all(rows @ wrench <= 1e-9)) == truth, wrench
        verdicts.append(truth)
    assert 50 < sum(verdicts) < 350  # both sides of the boundary were sampled
    # the yaw moment alone: up to mu (X + Y) f_n with the CoP at the centre, nothing beyond
    for ratio, ok in ((0.99, True), (1.01, False)):
        wrench = np.r_[300.0 * R[:, 2], ratio * mu * (hx + hy) * 300.0 * R[:, 2]]
        assert bool(np.all(rows @ wrench <= 0.0)) is ok


def test_friction_torsion_rows_are_the_measured_soles_wrench_cones(robots):
    """torsion=True on talos14 turned by 90 deg (the soles' x along world y, so the pyramid about
    world z is the soles' own): FrictionCone + CenterOfPressure hold exactly for the wrenches the
    corner pyramids of the measured sole can produce; 4 + 8 rows per sole, 4 without torsion."""
    robot = robots["talos14"]
    q = robot.q_ref.copy()
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, np.pi / 2)).coeffs()
    robot.update(q, np.zeros(robot.nv))
    mu, variables = 0.5, Variables(robot)
    rows = FrictionCone(mu, torsion=True).rows(robot, variables)
    cop = CenterOfPressure().rows(robot, variables)
    assert rows.m == 12 * len(robot.contact_names)
    for k, sole in enumerate(robot.contact_names):
        placement = robot.data.oMf[robot.contact(sole).frame_id]
        R, (hx, hy) = placement.rotation, robot.contact(sole).spec.half_size
        assert abs(R[1, 0]) > 0.999  # the sole's x is along world y
        corners = [R @ np.array([sx * hx, sy * hy, 0.0]) for sx in (1, -1) for sy in (1, -1)]
        for wrench in _sample_sole_wrenches(R, hx, hy, mu, 150, seed=k):
            lam = _stacked(robot, variables, {sole: wrench})
            ours = _fd.satisfies(rows, lam=lam) and _fd.satisfies(cop, lam=lam)
            assert ours == _corner_pyramids_carry(R, corners, mu, wrench), wrench
    assert FrictionCone(mu).rows(robot, variables).m == 4 * 2
    with pytest.raises(ValueError, match="mu"):
        FrictionCone(0.0)


@pytest.mark.parametrize("name", ROBOTS)
def test_normal_force_bounds(robots, name):
    robot = robots[name]
    _at(robot, 6)
    variables = Variables(robot)
    for normal in (np.array([0.0, 0.0, 1.0]), TILTED):
        rows = NormalForceBounds(f_min=10.0, f_max=500.0,
                                 normals={n: normal for n in robot.contact_names}
                                 ).rows(robot, variables)
        t = np.cross(normal, [1.0, 0, 0])  # tangential parts do not count
        for fn, ok in ((10.1, True), (499.0, True), (9.9, False), (500.1, False)):
            lam = _stacked(robot, variables, {c: fn * normal + 50 * t for c in robot.contact_names})
            assert _fd.satisfies(rows, lam=lam) is ok
    with pytest.raises(ValueError):
        NormalForceBounds(f_min=2.0, f_max=1.0)


def _sole_wrench(R, cop_local, fn):
    """Wrench [f; tau] about the sole origin (world axes) of a force fn along the sole normal
    applied at ``cop_local`` (sole coordinates): tau = (R p) x f."""
    f = R @ np.array([0.0, 0.0, fn])
    return np.r_[f, np.cross(R @ np.r_[cop_local, 0.0], f)]


@pytest.mark.parametrize("margin", (0.0, 0.2))
def test_centre_of_pressure_stays_in_the_sole(robots, margin):
    """A normal force at a point inside the (margin-shrunk) sole is accepted, one 1 % beyond
    any edge is rejected, on soles tilted by a random posture (rows in sole axes)."""
    robot = robots["talos14"]
    q, _ = _at(robot, 7, scale=0.2)
    variables = Variables(robot)
    rows = CenterOfPressure(margin=margin).rows(robot, variables)
    assert rows.m == 8 and not rows.is_equality
    for sole in robot.contact_names:
        _, R = _fd.BodyPoint(robot, robot.contact(sole).frame_id).pose(q)
        assert np.degrees(np.arccos(R[2, 2])) > 1.0  # really tilted
        hx, hy = (1 - margin) * np.asarray(robot.contact(sole).spec.half_size)
        for corner in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
            cop = np.array([corner[0] * hx, corner[1] * hy])
            lam = _stacked(robot, variables, {sole: _sole_wrench(R, 0.99 * cop, 400.0)})
            assert _fd.satisfies(rows, lam=lam, tol=1e-7)
            for axis in (0, 1):
                beyond = 0.99 * cop
                beyond[axis] = 1.01 * cop[axis]
                lam = _stacked(robot, variables, {sole: _sole_wrench(R, beyond, 400.0)})
                assert not _fd.satisfies(rows, lam=lam, tol=1e-7)


def test_centre_of_pressure_ignores_point_contacts(robots):
    robot = robots["hyq"]
    _at(robot, 0)
    assert CenterOfPressure().rows(robot, Variables(robot)).m == 0


@pytest.mark.parametrize("name", ROBOTS)
def test_force_regularizer_minimiser_is_its_target(robots, name):
    robot = robots[name]
    _at(robot, 8)
    variables = Variables(robot)
    rng = np.random.default_rng(8)
    targets = {n: rng.normal(size=robot.contact(n).dim) for n in robot.contact_names[:1]}
    rows = ForceRegularizer(targets=targets).rows(robot, variables)
    lam, *_ = np.linalg.lstsq(rows.lam, rows.target, rcond=None)
    np.testing.assert_allclose(lam, _stacked(robot, variables, targets), atol=1e-10)
    np.testing.assert_allclose(_fd.row_residual(rows, lam=lam), 0, atol=1e-10)


def test_the_checks_detect_wrong_contact_rows(robots):
    """The finite-difference check rejects the sphere centre's Jacobian and drift (HyQ's foot
    frame, 2 cm above the contact point), and the CoP check rejects rows with the sole's half
    sizes swapped."""
    robot = robots["hyq"]
    q, v = _at(robot, 0)
    J, drift = _fd_contact_terms(robot, q, v, robot.contact_names)
    centre = np.vstack([robot.contact_frame_jacobians[i, :3] for i in range(4)])
    centre_drift = np.concatenate([robot.contact_frame_drifts[i, :3] for i in range(4)])
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(centre, J, atol=1e-8)
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(-centre_drift, -drift, rtol=1e-5, atol=1e-6)
    talos = robots["talos14"]
    q, _ = _at(talos, 7, scale=0.2)
    sole = talos.contact_names[0]
    _, R = _fd.BodyPoint(talos, talos.contact(sole).frame_id).pose(q)
    hx, hy = talos.contact(sole).spec.half_size
    swapped = CenterOfPressure.block(R, hy, hx)
    wrench = _sole_wrench(R, np.array([0.99 * hx, 0.0]), 400.0)
    assert np.any(swapped @ wrench > 1e-7)  # the swapped sole rejects a CoP inside the real one
