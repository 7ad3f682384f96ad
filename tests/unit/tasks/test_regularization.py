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
