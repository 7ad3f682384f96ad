"""Regularisers (Fahmi et al. 2019, eq. 7a and Sect. V-D): each set of rows is minimised exactly
by its target — q̈ = 0, purely normal forces, contact forces that load no joint (checked with
finite-difference contact Jacobians)."""

import numpy as np
import pytest

from wholebody.tasks.contact import tangent_basis
from wholebody.tasks.regularization import (AccelerationRegularizer, ContactTorqueRegularizer,
                                            TangentialForceRegularizer)
from wholebody.variables import Variables

from . import _fd

ROBOTS = ("talos14", "hyq")


def _at(robot, seed):
    q, v = _fd.state_near_reference(robot, seed)
    robot.update(q, v)
    return q, v


@pytest.mark.parametrize("name", ROBOTS)
def test_acceleration_regularizer_minimiser_is_zero(robots, name):
    robot = robots[name]
    _at(robot, 0)
    rows = AccelerationRegularizer().rows(robot, Variables(robot))
    qdd = np.random.default_rng(0).normal(size=robot.nv)
    np.testing.assert_allclose(_fd.row_residual(rows, qdd=qdd), qdd, atol=0)


def test_tangential_force_regularizer_costs_the_tangential_force(robots):
    """Residual norm = |tangential part| about each contact's normal: zero for forces along the
    normals, whatever the normal forces."""
    robot = robots["hyq"]
    _at(robot, 1)
    variables = Variables(robot)
    tilted = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
    normals = {robot.contact_names[0]: tilted}
    rows = TangentialForceRegularizer(normals=normals).rows(robot, variables)
    assert rows.m == 2 * 4
    rng = np.random.default_rng(1)
    n_of = {c: normals.get(c, np.array([0.0, 0.0, 1.0])) for c in robot.contact_names}
    normal_forces = np.concatenate([rng.uniform(50, 300) * n_of[c] for c in robot.contact_names])
    np.testing.assert_allclose(_fd.row_residual(rows, lam=normal_forces), 0, atol=1e-10)
    tangential = np.concatenate([np.cross(n_of[c], rng.normal(size=3)) for c in robot.contact_names])
    residual = _fd.row_residual(rows, lam=normal_forces + tangential)
    for i, c in enumerate(robot.contact_names):
        assert np.linalg.norm(residual[2 * i:2 * i + 2]) == pytest.approx(
            np.linalg.norm(tangential[3 * i:3 * i + 3]), rel=1e-10)


def _parallel_gap(force, normal, lean):
    """|f − (f·n / lean·n) lean|: how far a force is from the lean's direction at the same normal
    component (the lean scaled to the force's normal part, then subtracted)."""
    return np.linalg.norm(force - (force @ normal) / (lean @ normal) * lean)


def test_leaning_tangential_regularizer_costs_the_departure_from_the_lean(robots):
    """With a lean (e.g. the desired net force), the residual vanishes on forces parallel to the
    lean, whatever their size, and otherwise measures the distance from the lean's ray at the
    same normal component; a lean that does not press into the surface leaves the plain
    tangential rows."""
    robot = robots["hyq"]
    _at(robot, 1)
    variables = Variables(robot)
    rng = np.random.default_rng(3)
    tilted = np.array([0.1, -0.2, 1.0]) / np.linalg.norm([0.1, -0.2, 1.0])
    normals = {robot.contact_names[1]: tilted}
    n_of = {c: normals.get(c, np.array([0.0, 0.0, 1.0])) for c in robot.contact_names}
    lean = np.array([60.0, -110.0, 800.0])  # tangential-to-normal ratio < 0.2 about every normal
    rows = TangentialForceRegularizer(normals=normals, lean=lean, mu=0.6).rows(robot, variables)
    parallel = np.concatenate([rng.uniform(0.05, 0.5) * lean for _ in robot.contact_names])
    np.testing.assert_allclose(_fd.row_residual(rows, lam=parallel), 0, atol=1e-10)
    forces = parallel + rng.normal(scale=20.0, size=parallel.shape)
    residual = _fd.row_residual(rows, lam=forces)
    for i, c in enumerate(robot.contact_names):
        assert np.linalg.norm(residual[2 * i:2 * i + 2]) == pytest.approx(
            _parallel_gap(forces[3 * i:3 * i + 3], n_of[c], lean), rel=1e-10)
    plain = TangentialForceRegularizer(normals=normals).rows(robot, variables).lam
    pulling = TangentialForceRegularizer(normals=normals, lean=-lean).rows(robot, variables).lam
    np.testing.assert_allclose(pulling, plain, atol=0)


def test_leaning_regularizer_caps_the_lean_at_the_cone(robots):
    """A lean steeper than the friction cone is met at the cone's edge in its direction: a force
    of tangential-to-normal ratio mu along the lean's tangential direction has zero residual."""
    robot = robots["hyq"]
    _at(robot, 1)
    lean = np.array([300.0, 400.0, 500.0])  # ratio 1.0 about the vertical
    rows = TangentialForceRegularizer(lean=lean, mu=0.5).rows(robot, Variables(robot))
    edge = np.array([0.3, 0.4, 1.0]) * 100.0  # ratio 0.5 along (0.6, 0.8)
    np.testing.assert_allclose(rows.lam[:2, :3] @ edge, 0, atol=1e-10)
    assert np.linalg.norm(rows.lam[:2, :3] @ lean) > 1.0


@pytest.mark.parametrize("name", ROBOTS)
def test_contact_torque_regularizer_rows_are_the_joint_torques_of_the_forces(robots, name):
    """Rows -J_jᵀ λ: the joint part of the generalized force of λ, negated (J by finite
    differences)."""
    robot = robots[name]
    q, _ = _at(robot, 2)
    variables = Variables(robot)
    J = _fd.contact_jacobians_fd(robot, q, robot.contact_names)
    lam = np.random.default_rng(2).normal(scale=100.0, size=variables.n_lambda)
    rows = ContactTorqueRegularizer().rows(robot, variables)
    np.testing.assert_allclose(_fd.row_residual(rows, lam=lam), -(J.T @ lam)[6:], rtol=1e-7, atol=1e-5)


def test_the_check_detects_a_wrong_tangent(robots):
    """The tangential check fails for rows that use the normal instead of a tangent."""
    robot = robots["hyq"]
    _at(robot, 1)
    rows = TangentialForceRegularizer().rows(robot, Variables(robot))
    wrong = rows.lam.copy()
    wrong[0, :3] = tangent_basis(np.array([0.0, 0.0, 1.0]))[2]
    forces = np.tile([0.0, 0.0, 200.0], 4)
    np.testing.assert_allclose(rows.lam @ forces, 0, atol=1e-10)
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(wrong @ forces, 0, atol=1e-10)
