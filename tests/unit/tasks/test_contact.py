"""Contact constraint and contact-force conditions: J q̈ + J̇ v = 0 with J and J̇ v from finite
differences of the contact point (the sole origin, or the bottom of a foot sphere, as a body-fixed
point); friction pyramid, normal-force bounds and centre of pressure accept a force explicitly
constructed inside and reject one just outside; the force regulariser's minimiser is its target."""

import numpy as np
import pytest

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


def test_friction_torsion_bounds_the_yaw_moment_of_a_sole(robots):
    """torsion=True adds |tau.n| <= (2/3) min(half sizes) mu f_n for soles."""
    robot = robots["talos14"]
    _at(robot, 5)
    mu, variables = robot.friction, Variables(robot)
    rows = FrictionCone(mu, torsion=True).rows(robot, variables)
    assert rows.m == 6 * 2
    sole = robot.contact_names[0]
    bound = 2.0 / 3.0 * min(robot.contact(sole).spec.half_size) * mu * 300.0
    for sign in (1, -1):
        for ratio, ok in ((0.99, True), (1.01, False)):
            wrench = np.r_[0.0, 0.0, 300.0, 0.0, 0.0, sign * ratio * bound]
            assert _fd.satisfies(rows, lam=_stacked(robot, variables, {sole: wrench})) is ok
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
