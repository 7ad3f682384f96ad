"""The weak-joint scenario's measures without simulation: the post-solve clip count (a PassiveWBC
cycle whose eq. 19 torque left the limits and was clipped by the output guard), the stance posture
builder and the static LP of the knee torque (scipy linprog, independent of the controller)."""

import numpy as np
import pinocchio as pin
import pytest

from wholebody.control.passive import PassiveWBC
from wholebody.guard import LIMIT_TOLERANCE, Outcome
from wholebody.robots.roles import contact_roles, leg_joints
from wholebody.scenarios.weak_joint import (crawl_supports, post_solve_clipped, shank_angle_deg,
                                            stance_posture, static_knee_torque)
from wholebody.tasks import TorqueLimits


@pytest.fixture(scope="module")
def hyq(robots):
    return robots["hyq"]


def weak_knee(robot):
    return leg_joints(robot, contact_roles(robot)["left-front"])[-1]


def eq19_excess(robot, sol, lo, hi):
    """How far the torque of eq. 19, recomputed from the solution's q̈ and forces, leaves [lo, hi]."""
    J = robot.stacked_contact_jacobian()
    tau = robot.M[6:] @ sol.qdd + robot.h[6:] - J[:, 6:].T @ sol.lam
    return float(np.max(np.maximum(tau - hi, lo - tau)))


def standing_cycles(robot, wbc, n=4, seed=3):
    """One cycle per perturbed standing state; yields each solution while the robot is at its
    state (the robot's cached terms are those of the cycle)."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        q = robot.q_ref.copy()
        q[7:] += rng.normal(scale=0.02, size=robot.na)
        yield wbc.compute(q, np.zeros(robot.nv), 0.0)


@pytest.mark.parametrize("qp_knows_the_limit", [True, False])
def test_post_solve_clip_count_matches_the_recomputed_torque(hyq, qp_knows_the_limit):
    """A knee limit of 10 Nm (standing needs far more). When the QP's torque rows carry it, no
    cycle is clipped; when the QP is given the real limits instead (its rows widened, the guard
    still at 10 Nm) the eq. 19 torque leaves the guard's limits and every such cycle is counted,
    exactly those whose recomputed torque exceeds the limits."""
    knee = weak_knee(hyq)
    k = hyq.joint_names.index(knee)
    wbc = PassiveWBC(hyq, torque_limit_override={knee: 10.0}, engine="python")
    if not qp_knows_the_limit:  # the QP's torque-limit task without the override
        hard = wbc._stack.hard
        hard[hard.index(wbc.torque_limits)] = TorqueLimits()
    counted, expected = 0, 0
    for sol in standing_cycles(hyq, wbc):
        lo, hi = wbc._tau_bounds
        assert hi[k] == 10.0
        excess = eq19_excess(hyq, sol, lo, hi)
        expected += excess > LIMIT_TOLERANCE
        counted += post_solve_clipped(sol)
        assert sol.outcome in (Outcome.SOLVED, Outcome.CLIPPED)
        assert abs(sol.tau[k]) <= 10.0 + 1e-9  # what leaves the controller is within the limit
    assert counted == expected
    if qp_knows_the_limit:
        assert counted == 0
    else:
        assert counted == 4


def test_held_cycles_are_not_post_solve_clips():
    class Sol:
        outcome = Outcome.HELD
    assert not post_solve_clipped(Sol)


def test_stance_posture_straightens_the_knees_keeping_the_feet_under_the_base(hyq):
    q = stance_posture(hyq, 0.8)
    np.testing.assert_array_equal(stance_posture(hyq, 1.0), hyq.q_ref)
    data = hyq.model.createData()
    for posture in (hyq.q_ref, q):
        pin.framesForwardKinematics(hyq.model, data, posture)
    for c in hyq.contacts:
        knee = 7 + hyq.joint_names.index(leg_joints(hyq, c.name)[-1])
        assert q[knee] == pytest.approx(0.8 * hyq.q_ref[knee])
        assert shank_angle_deg(hyq, q, c.name) < shank_angle_deg(hyq, hyq.q_ref, c.name) - 5.0

    def feet_x(posture):
        pin.framesForwardKinematics(hyq.model, data, posture)
        return [data.oMi[1].actInv(data.oMf[c.frame_id]).translation[0] for c in hyq.contacts]
    np.testing.assert_allclose(feet_x(q), feet_x(hyq.q_ref), atol=1e-6)
    assert q[2] > hyq.q_ref[2] + 0.03  # taller
    pin.framesForwardKinematics(hyq.model, data, q)
    lowest = min(hyq.contact_lowest_point(c, data.oMf[c.frame_id])[2] for c in hyq.contacts)
    assert lowest == pytest.approx(0.0, abs=1e-9)


def test_static_lp_knee_torque_srdf_posture_vs_taller_stance(hyq):
    """On four feet the knee can be unloaded (0 Nm); on the crawl's three-foot supports the
    standing posture needs more than the paper's 26 Nm on the LF knee, the 0.8 stance less."""
    knee, foot = weak_knee(hyq), contact_roles(hyq)["left-front"]
    four = static_knee_torque(hyq, hyq.q_ref, knee, [(hyq.contact_names, np.zeros(2))])
    assert four[0]["min_abs_tau_Nm"] == pytest.approx(0.0, abs=1e-6)
    need = {}
    for k in (1.0, 0.8):
        q = stance_posture(hyq, k)
        lp = static_knee_torque(hyq, q, knee, crawl_supports(hyq, q, foot, 0.11))
        assert all(r["min_abs_tau_Nm"] is not None for r in lp)
        need[k] = max(r["min_abs_tau_Nm"] for r in lp)
    assert need[1.0] > 26.0 > need[0.8]
