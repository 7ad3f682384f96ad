"""Both engines on every preset robot, not only the papers' talos14 and HyQ: the compiled
HierarchyCycle (Table 2, PD and LQR-shaped momentum rows) and the compiled PassiveWBC cycle give
the Python reference's torques on each preset's own model (unaligned joint axes, contact offsets,
locked joints, soles off their frames), and those torques satisfy the equations of motion
computed here with Pinocchio directly."""

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.control.passive import PassiveWBC
from wholebody.control.balance import MomentumBalance
from wholebody.robots import preset_names
from wholebody.solvers import SolverSettings

from conftest import native_cycle_or_skip

native_cycle_or_skip("_hierarchy_cycle")
native_cycle_or_skip("_passive_references")

PRESETS = preset_names()


def point_footed(robot) -> bool:
    return all(c.dim == 3 for c in robot.contacts)


def contact_jacobian(robot, q) -> np.ndarray:
    """The contacts' point (sphere bottom) or sole Jacobians, LOCAL_WORLD_ALIGNED, from Pinocchio."""
    model, data = robot.model, robot.model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    blocks = []
    for c in robot.contacts:
        J = pin.getFrameJacobian(model, data, c.frame_id, pin.LOCAL_WORLD_ALIGNED)
        if c.dim == 3:  # the sphere bottom d = (0, 0, -r): J_lin - [d]x J_ang
            d = np.array([0.0, 0.0, -c.spec.radius])
            J = J[:3] - np.cross(d, J[3:].T).T
        blocks.append(J)
    return np.vstack(blocks)


def assert_equations_of_motion(robot, q, v, qdd, tau, lam, where):
    """M qdd + h = S^T tau + J_c^T lambda, with M and h from Pinocchio's CRBA and RNEA."""
    data = robot.model.createData()
    M = pin.crba(robot.model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    h = pin.rnea(robot.model, robot.model.createData(), q, v, np.zeros(robot.nv))
    S_T = np.vstack([np.zeros((6, robot.na)), np.eye(robot.na)])
    terms = [M @ qdd, h, S_T @ tau, contact_jacobian(robot, q).T @ lam]
    residual = terms[0] + terms[1] - terms[2] - terms[3]
    scale = sum(np.linalg.norm(t) for t in terms)
    assert np.linalg.norm(residual) <= 1e-8 * scale, (where, np.linalg.norm(residual), scale)


@pytest.fixture(scope="module")
def presets():
    return {name: wb.load_robot(name) for name in PRESETS}


@pytest.mark.parametrize("gains", ["pd", "lqr"])
@pytest.mark.parametrize("name", PRESETS)
def test_momentum_balance_engines_agree(presets, name, gains):
    """Momentum balance (Herzog et al. 2016, Table 2 with PD or LQR momentum gains) on a smooth
    motion near the preset's posture: the compiled cycle's tau, qdd and lambda equal the Python
    engine's to 1e-6, satisfy the dynamics and stay within the torque limits. Quadprog on both (see
    test_cycle.test_torques_equal_python_and_satisfy_dynamics for why not DAQP)."""
    robot = presets[name]
    settings = SolverSettings(backend="quadprog")
    native = MomentumBalance(robot, gains=gains, settings=settings, engine="native")
    python = MomentumBalance(robot, gains=gains, settings=settings, engine="python")
    for i, (q, v) in enumerate(robot.smooth_motion(8, 0.05)):
        a, b = native.compute(q, v, 0.0), python.compute(q, v, 0.0)
        where = f"{name} state {i}"
        assert a.ok and b.ok and a.status == b.status, (where, a.status, b.status)
        scale = max(1.0, np.abs(b.tau).max())
        np.testing.assert_allclose(a.tau, b.tau, rtol=0, atol=1e-6 * scale, err_msg=where)
        np.testing.assert_allclose(a.lam, b.lam, rtol=0, atol=1e-6 * scale, err_msg=where)
        assert_equations_of_motion(robot, q, v, a.qdd, a.tau, a.lam, where)
        robot.update(q, v)
        lo, hi = robot.torque_bounds()
        assert np.all(a.tau >= lo - 1e-6) and np.all(a.tau <= hi + 1e-6), where


STANCES = [(True, True, True, True), (False, True, True, True), (True, False, False, True)]


@pytest.mark.parametrize("name", [n for n in PRESETS if n not in ("talos14", "talos", "romeo")])
def test_passive_engines_agree(presets, name, plan_for):
    """The passive WBC (Fahmi et al. 2019) on every quadruped preset, four, three and two feet in
    stance: the compiled cycle gives the Python engine's torques, forces and accelerations, which
    satisfy the dynamics with the stance feet's forces."""
    robot = presets[name]
    assert point_footed(robot)
    rng = np.random.default_rng(11)
    for i, (q, v) in enumerate(robot.smooth_motion(6, 0.05)):
        robot.update(q, v)
        plan = plan_for(robot, rng, STANCES[i % len(STANCES)])
        legs = type("Planner", (), {"legs": robot.contact_names})()
        python = PassiveWBC(robot, planner=legs, engine="python")
        native = PassiveWBC(robot, planner=legs, engine="native")
        a, b = python.cycle(q, v, plan), native.cycle(q, v, plan)
        where = f"{name} state {i}"
        assert a.ok and b.ok, (where, a.status, b.status)
        scale = max(1.0, np.abs(a.tau).max())
        np.testing.assert_allclose(b.tau, a.tau, rtol=0, atol=1e-6 * scale, err_msg=where)
        np.testing.assert_allclose(b.lam, a.lam, rtol=0, atol=1e-5 * scale, err_msg=where)
        np.testing.assert_allclose(b.qdd, a.qdd, rtol=0, atol=1e-5 * scale, err_msg=where)
        assert a.contacts == b.contacts, where
        assert_equations_of_motion_on(robot, q, v, a, where)


def assert_equations_of_motion_on(robot, q, v, solution, where):
    """The dynamics with the solution's contacts only (the swing feet carry no force)."""
    lam = np.zeros(3 * len(robot.contacts))
    for name, force in solution.forces.items():
        k = robot.contact_names.index(name)
        lam[3 * k:3 * k + 3] = force
    assert_equations_of_motion(robot, q, v, solution.qdd, solution.tau, lam, where)
