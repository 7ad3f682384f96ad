"""Equations of motion as rows (Herzog et al. 2016, eqs. 1 and 13): for every y = (q̈, λ, τ) the
residual of FullDynamics is M q̈ + h − Sᵀ τ − Jᵀ λ evaluated with pinocchio.rnea and
finite-difference contact Jacobians; NewtonEuler is its 6 floating-base rows."""

import numpy as np
import pinocchio as pin
import pytest

from wholebody.tasks import FullDynamics, NewtonEuler
from wholebody.variables import Variables

from . import _fd

ROBOTS = ("talos14", "hyq")


def _case(robot, seed, contacts=None):
    q, v = _fd.state_near_reference(robot, seed)
    robot.update(q, v)
    variables = Variables(robot, contacts)
    J = _fd.contact_jacobians_fd(robot, q, variables.contacts)
    rng = np.random.default_rng(seed)
    y = dict(qdd=rng.normal(size=robot.nv), lam=rng.normal(scale=100.0, size=variables.n_lambda),
             tau=rng.normal(scale=20.0, size=robot.na))
    return q, v, variables, J, y


def _rnea_residual(robot, q, v, J, qdd, lam, tau):
    data = robot.model.createData()
    return (pin.rnea(robot.model, data, q, v, qdd) - np.r_[np.zeros(6), tau] - J.T @ lam)


def _contact_sets(robot):
    return [None, robot.contact_names[:1]]


@pytest.mark.parametrize("seed", (0, 1))
@pytest.mark.parametrize("name", ROBOTS)
def test_full_dynamics_residual_is_the_rnea_residual(robots, name, seed):
    robot = robots[name]
    for contacts in _contact_sets(robot):
        q, v, variables, J, y = _case(robot, seed, contacts)
        rows = FullDynamics().rows(robot, variables)
        assert rows.m == robot.nv and rows.is_equality
        expected = _rnea_residual(robot, q, v, J, **y)
        np.testing.assert_allclose(_fd.row_residual(rows, **y), expected, rtol=1e-7, atol=1e-5)


@pytest.mark.parametrize("seed", (0, 1))
@pytest.mark.parametrize("name", ROBOTS)
def test_newton_euler_rows_are_the_floating_base_rows(robots, name, seed):
    """Eq. 13: the first 6 rows, free of τ."""
    robot = robots[name]
    for contacts in _contact_sets(robot):
        q, v, variables, J, y = _case(robot, seed, contacts)
        rows = NewtonEuler().rows(robot, variables)
        assert rows.m == 6 and rows.tau is None
        expected = _rnea_residual(robot, q, v, J, **y)[:6]
        np.testing.assert_allclose(_fd.row_residual(rows, qdd=y["qdd"], lam=y["lam"]), expected,
                                   rtol=1e-7, atol=1e-5)


@pytest.mark.parametrize("name", ROBOTS)
def test_forward_dynamics_satisfies_the_rows(robots, name):
    """(q̈ from ABA, λ, τ) satisfies FullDynamics and NewtonEuler; moving one torque by 1 Nm
    breaks the full rows (not the floating-base ones, which do not see τ)."""
    robot = robots[name]
    q, v, variables, J, y = _case(robot, 2)
    qdd = _fd.forward_dynamics(robot, q, v, y["tau"], J, y["lam"])
    full, base = FullDynamics().rows(robot, variables), NewtonEuler().rows(robot, variables)
    np.testing.assert_allclose(_fd.row_residual(full, qdd, y["lam"], y["tau"]), 0, atol=1e-6)
    np.testing.assert_allclose(_fd.row_residual(base, qdd, y["lam"]), 0, atol=1e-6)
    tau = y["tau"].copy()
    tau[3] += 1.0
    residual = _fd.row_residual(full, qdd, y["lam"], tau)
    assert abs(residual[6 + 3]) == pytest.approx(1.0, rel=1e-6)


def test_the_check_detects_a_wrong_contact_term(robots):
    """The RNEA check fails for rows whose contact columns miss the foot-sphere offset (the frame
    origin's Jacobian instead of the contact point's) or have the wrong sign."""
    robot = robots["hyq"]
    q, v, variables, J, y = _case(robot, 3)
    rows = FullDynamics().rows(robot, variables)
    expected = _rnea_residual(robot, q, v, J, **y)
    origin = np.vstack([pin.getFrameJacobian(robot.model, robot.data, c.frame_id,
                                             pin.LOCAL_WORLD_ALIGNED)[:3] for c in robot.contacts])
    for lam_block in (-origin.T, -rows.lam):
        wrong = type(rows)(qdd=rows.qdd, lam=lam_block, tau=rows.tau, target=rows.target)
        with pytest.raises(AssertionError):
            np.testing.assert_allclose(_fd.row_residual(wrong, **y), expected, rtol=1e-7, atol=1e-5)
