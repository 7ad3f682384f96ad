"""What the legs can reach: how high a foot rises within its joint limits, how a slope stance moves
the legs from their posture, the swing apex the planner caps with it, the trunk's terrain alignment.

Evidence: a different solver for each quantity (scipy's SLSQP for the highest foot, its bounded
nonlinear least squares for the slope stance, both on Pinocchio's kinematics), the standing foot
height from the posture for the capped apex, and Pinocchio's Euler angles for the trunk's pitch.
"""

import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import least_squares, minimize

import wholebody as wb
from wholebody.planning import GaitPlanner, Terrain, TrunkReference, VelocityCommand, crawl
from wholebody.planning.footholds import Footprint
from wholebody.planning.reach import (REACH_MARGIN, foot_lift, slope_stance_change,
                                      terrain_alignment_for)
from wholebody.robots.roles import leg_joints


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def _leg(robot, contact):
    model = robot.model
    joints = [model.joints[model.getJointId(j)] for j in leg_joints(robot, contact)]
    return np.array([j.idx_q for j in joints])


def _foot(robot, q, contact):
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.contact(contact).frame_id].translation.copy()


@pytest.mark.parametrize("margin", [0.0, REACH_MARGIN])
def test_foot_lift_is_the_highest_foot_within_the_shrunk_limits(hyq, margin):
    """SLSQP maximises the foot's height over the leg's joints, its x and y held as equality
    constraints, inside the limits shrunk by ``margin`` of the range: the same height."""
    contact = hyq.contact_names[0]
    iq = _leg(hyq, contact)
    lo, hi = hyq.model.lowerPositionLimit[iq], hyq.model.upperPositionLimit[iq]
    q0 = hyq.q_ref.copy()
    bounds = list(zip(np.minimum(lo + margin * (hi - lo), q0[iq]),
                      np.maximum(hi - margin * (hi - lo), q0[iq])))
    start = _foot(hyq, q0, contact)  # the base is level in the posture: base z is world z

    def foot(x):
        q = q0.copy()
        q[iq] = x
        return _foot(hyq, q, contact)

    best = minimize(lambda x: -foot(x)[2], q0[iq], method="SLSQP", bounds=bounds,
                    constraints={"type": "eq", "fun": lambda x: foot(x)[:2] - start[:2]},
                    options={"ftol": 1e-12, "maxiter": 500})
    assert best.success, best.message
    assert foot_lift(hyq, contact, margin=margin) == pytest.approx(foot(best.x)[2] - start[2],
                                                                   abs=1e-4)


def test_foot_lift_stops_at_up_to(hyq):
    contact = hyq.contact_names[0]
    assert foot_lift(hyq, contact) > 0.05
    assert foot_lift(hyq, contact, up_to=0.05) == pytest.approx(0.05, abs=1e-12)


@pytest.mark.parametrize("angle, alignment", [(15.0, 1.0), (15.0, 0.0), (-15.0, 1.0),
                                              (-12.0, 0.5)])
def test_slope_stance_change_against_nonlinear_least_squares(hyq, angle, alignment):
    """The stance rebuilt here from its definition (the CoM at its standing height above the slope
    point under it, the trunk inclined by atan(alignment tan angle), each foot at its horizontal
    offset from the CoM on the slope, one radius along the normal), each three-joint leg solved
    by scipy's bounded nonlinear least squares: the same largest joint move."""
    a = math.radians(angle)
    fp = Footprint.from_robot(hyq).centered_on_com()
    R = pin.rpy.rpyToMatrix(0.0, -math.atan(alignment * math.tan(a)), 0.0)
    q = hyq.q_ref.copy()
    q[:3] = np.array([0.0, 0.0, fp.com[2] + fp.base_height]) - R @ fp.com
    q[3:7] = pin.Quaternion(R).coeffs()
    normal = np.array([-math.sin(a), 0.0, math.cos(a)])
    moves = []
    for k, contact in enumerate(fp.legs):
        iq = _leg(hyq, contact)
        lo, hi = hyq.model.lowerPositionLimit[iq], hyq.model.upperPositionLimit[iq]
        x, y = fp.feet_from_com()[k]
        target = np.array([x, y, math.tan(a) * x]) + fp.foot_radius[k] * normal

        def miss(x_leg):
            qq = q.copy()
            qq[iq] = x_leg
            return _foot(hyq, qq, contact) - target

        sol = least_squares(miss, hyq.q_ref[iq], bounds=(lo, hi), xtol=1e-14, ftol=1e-14)
        assert np.linalg.norm(sol.fun) < 1e-6
        moves.append(np.max(np.abs(sol.x - hyq.q_ref[iq]) / (hi - lo)))
    assert slope_stance_change(hyq, a, alignment) == pytest.approx(max(moves), abs=1e-5)


def test_on_level_ground_both_alignments_are_the_same_stance(hyq):
    assert slope_stance_change(hyq, 0.0, 1.0) == pytest.approx(slope_stance_change(hyq, 0.0, 0.0),
                                                               abs=1e-12)


def test_a_foot_out_of_reach_is_an_infinite_change(hyq):
    assert slope_stance_change(hyq, math.radians(60.0), 0.0) == math.inf


def test_terrain_alignment_for_takes_the_smaller_change(hyq):
    """HyQ on the paper's 15°: the trunk parallel to the slope (Fig. 8); IIT Centauro, whose legs
    stand splayed under hip-yaw axes, moves them less with a level trunk."""
    from conftest import centauro_description

    share, changes = terrain_alignment_for(hyq, math.radians(15.0))
    assert share == 1.0 and changes[1.0] < changes[0.0]
    centauro = wb.load_robot(centauro_description())
    share, changes = terrain_alignment_for(centauro, math.radians(15.0))
    assert share == 0.0 and changes[0.0] < changes[1.0]


@pytest.mark.parametrize("reach", [0.03, math.inf])
def test_the_swing_apex_is_capped_by_the_leg_reach(hyq, reach):
    """On level ground under a trunk at its standing height, the standing foot is one radius above
    the ground: a swing rises min(clearance, reach) above that."""
    planner = GaitPlanner.for_robot(hyq, crawl(start=0.5), VelocityCommand.constant(0.1),
                                    clearance=0.1, limit_swing=False)
    planner.reach[:] = reach
    radius = Footprint.from_robot(hyq).foot_radius
    top = np.full(4, -np.inf)
    for t in np.arange(0.0, 0.5 + planner.schedule.period, 0.002):
        plan = planner.update(t)
        for i in np.flatnonzero(~plan.contact):
            top[i] = max(top[i], plan.foot_position[i, 2])
    assert top == pytest.approx(radius + min(0.1, reach), abs=1e-6)


def test_planners_measure_the_reach_of_each_leg(hyq):
    planner = GaitPlanner.for_robot(hyq, crawl(start=0.5), VelocityCommand.constant(0.1))
    legs = planner.legs
    assert planner.reach == pytest.approx([foot_lift(hyq, leg) for leg in legs])
    off = GaitPlanner.for_robot(hyq, crawl(start=0.5), limit_swing=False)
    assert np.all(np.isinf(off.reach))


@pytest.mark.parametrize("alignment", [1.0, 0.5, 0.0])
def test_the_trunk_inclination_is_the_share_of_the_slope(alignment):
    """On a 15° ramp rising along x, the trunk's pitch (ZYX Euler) is atan(share tan 15°), nose up;
    its yaw the heading."""
    a = math.radians(15.0)
    ramp = Terrain.plane((-math.sin(a), 0.0, math.cos(a)))
    trunk = TrunkReference(VelocityCommand.constant(0.1), (0.0, 0.0, 0.6), yaw0=0.0,
                           terrain=ramp, terrain_alignment=alignment)
    roll, pitch, yaw = pin.rpy.matrixToRpy(trunk.rotation(1.0))
    assert pitch == pytest.approx(-math.atan(alignment * math.tan(a)), abs=1e-12)
    assert roll == pytest.approx(0.0, abs=1e-12) and yaw == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("share", [-0.1, 1.5, math.nan])
def test_a_terrain_alignment_outside_zero_one_is_refused(share):
    with pytest.raises(ValueError, match="terrain_alignment"):
        TrunkReference(None, (0.0, 0.0, 0.6), terrain_alignment=share)


def test_the_ramp_resolves_its_alignment_from_the_robot(hyq):
    """-1 (the default): HyQ's is the paper's parallel trunk; a share given is kept."""
    from wholebody.scenarios import ramp

    defaults = {p.name: p.default for p in ramp.PARAMETERS}
    defaults["speed"] = 0.0
    assert ramp.resolve(defaults, hyq)["terrain_alignment"] == 1.0
    assert ramp.resolve({**defaults, "terrain_alignment": 0.25}, hyq)["terrain_alignment"] == 0.25


def test_a_leg_joint_without_limits_keeps_none(hyq):
    """A knee whose URDF gives no limits (Pinocchio's +-max float) is not frozen by the margin:
    the foot rises at least as far as with the knee's real limits."""
    import copy

    contact = hyq.contact_names[0]
    limited = foot_lift(hyq, contact)
    free = copy.deepcopy(hyq)
    knee = _leg(free, contact)[-1]
    free.model.lowerPositionLimit[knee] = -np.finfo(float).max
    free.model.upperPositionLimit[knee] = np.finfo(float).max
    assert foot_lift(free, contact) >= limited - 1e-9 > 0.0
