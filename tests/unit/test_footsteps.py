"""Footstep planning: the step limits measured from the legs' kinematics, the clamping of a step
against the stance sole, and the footsteps of a velocity command or of a list.

Evidence: scipy's SLSQP over a leg's joints on Pinocchio's forward kinematics for the soles'
reach and turn (a different solver from the module's linear programs), from a lowered stance and
within joint bounds both written out here; scipy's bounded least squares for whether a leg holds
its sole at a given step (the stride model against the legs themselves); the soles' standing
positions and headings, sizes and the legs' lengths and joint axes read from the model; a copy of
iCub turned about the vertical; for the planner, the unicycle's own arithmetic (strides of v T,
turns of yaw_rate T) and the bounds re-checked in each stance sole's heading frame computed here.
Robots: the talos14, talos and romeo presets, and G1, iCub and Alexander as tests/conftest.py
describes them.
"""

import copy
import functools
import math

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import least_squares, minimize

import wholebody as wb
from wholebody.control import WalkingConfig
from wholebody.planning.footsteps import (Footstep, FootstepPlanner, StepLimits, clamp_step,
                                          sole_reach)
from wholebody.planning.reach import REACH_MARGIN
from wholebody.robots.roles import biped_soles, leg_joints

SHARE = 0.8  # the default share of the reach a step uses


@pytest.fixture(scope="module")
def talos14():
    return wb.load_robot("talos14")


@pytest.fixture(scope="module")
def limits14(talos14):
    return StepLimits.from_robot(talos14)


@pytest.fixture(scope="module")
def planner(talos14, limits14):
    return FootstepPlanner(talos14, limits14)


def _standing_feet(robot):
    """{sole: (position, yaw)} in the posture, from Pinocchio's kinematics."""
    return {sole: (M.translation, _yaw(M.rotation)) for sole, M in _posture_soles(robot).items()}


def _relative(stance, step_xy, step_yaw, stance_side):
    """(forward, outward lateral distance, outward yaw) of a step in the stance sole's heading
    frame; outward yaw turns the swing sole away from the stance side."""
    (p, yaw) = stance
    c, s = math.cos(yaw), math.sin(yaw)
    d = np.asarray(step_xy)[:2] - np.asarray(p)[:2]
    dx, dy = c * d[0] + s * d[1], -s * d[0] + c * d[1]
    rel = (step_yaw - yaw + math.pi) % (2 * math.pi) - math.pi
    return dx, -stance_side * dy, -stance_side * rel


# ------------------------------------------------------------------ limits from the kinematics
@functools.cache
def _humanoid(name):
    """A humanoid by name: a preset, or G1, iCub, Alexander as tests/conftest.py describes them."""
    from conftest import (ICUB_RIGHT_LEG_INERTIAS, alexander_description, g1_description,
                          icub_description)
    described = {"g1": lambda: g1_description(armature=0.02),
                 "icub": lambda: icub_description(inertia_overrides=ICUB_RIGHT_LEG_INERTIAS),
                 "alexander": alexander_description}
    return wb.load_robot(described[name]() if name in described else name)


def _walking_drop(robot):
    return WalkingConfig.for_robot(robot).com_drop


def _leg_iq(robot, sole):
    model = robot.model
    return np.array([model.joints[model.getJointId(j)].idx_q for j in leg_joints(robot, sole)])


def _bounds(robot, iq, q, margin=REACH_MARGIN):
    """The reach's joint bounds written out: ``margin`` of each range inside the limits, or halfway
    from where ``q`` has the joint to the limit where that leaves it more room."""
    lo, hi = robot.model.lowerPositionLimit[iq], robot.model.upperPositionLimit[iq]
    return (np.minimum(lo + margin * (hi - lo), 0.5 * (q[iq] + lo)),
            np.maximum(hi - margin * (hi - lo), 0.5 * (q[iq] + hi)))


def _yaw(R):
    return math.atan2(R[1, 0], R[0, 0])


def _posture_soles(robot):
    """{sole: SE3} where each sole stands in the posture, made flat (its yaw kept)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    out = {}
    for sole in biped_soles(robot):
        M = data.oMf[robot.contact(sole).frame_id]
        out[sole] = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, _yaw(M.rotation)), M.translation.copy())
    return out


def _heading(robot):
    """(x, y): the soles' mean heading in the posture and its left, world (2,) each."""
    yaws = [_yaw(M.rotation) for M in _posture_soles(robot).values()]
    yaw = yaws[0] + 0.5 * ((yaws[1] - yaws[0] + math.pi) % (2 * math.pi) - math.pi)
    return np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])


def _solve_leg(robot, q, sole, target, bounds=None):
    """``q`` with ``sole``'s leg solved by scipy's bounded least squares (trust region, within
    ``bounds``, default the joint limits) toward the placement ``target`` → (q, the remaining
    log6 error's max)."""
    model = robot.model
    data = model.createData()
    iq = _leg_iq(robot, sole)
    frame = robot.contact(sole).frame_id
    lo, hi = (model.lowerPositionLimit[iq], model.upperPositionLimit[iq]) if bounds is None \
        else bounds

    def error(x):
        q1 = q.copy()
        q1[iq] = x
        pin.framesForwardKinematics(model, data, q1)
        return pin.log6(target.actInv(data.oMf[frame])).vector

    x0 = np.clip(q[iq], lo + 1e-9, hi - 1e-9)
    best = least_squares(error, x0, bounds=(lo, hi), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    out = q.copy()
    out[iq] = best.x
    return out, float(np.abs(error(best.x)).max())


@functools.cache
def _lowered_stance(name, drop):
    """The base level (its yaw kept) ``drop`` below the posture's height, each leg solved so that
    its sole is flat where it stands in the posture."""
    robot = _humanoid(name)
    q = robot.q_ref.copy()
    q[2] -= drop
    yaw = _yaw(pin.Quaternion(robot.q_ref[3:7]).normalized().toRotationMatrix())
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw)).coeffs()
    for sole, target in _posture_soles(robot).items():
        q, error = _solve_leg(robot, q, sole, target)
        assert error < 1e-9
    return q


def _slsqp_reach(robot, sole, direction, q0, bounds=None):
    """Largest displacement of ``sole``'s frame along the horizontal unit ``direction`` (world)
    from where it stands in ``q0`` (flat), its displacement across ``direction``, its height and
    its orientation held, its leg's joints within ``bounds`` (default :func:`_bounds`)."""
    model = robot.model
    data = model.createData()
    iq = _leg_iq(robot, sole)
    lo, hi = _bounds(robot, iq, q0) if bounds is None else bounds
    frame = robot.contact(sole).frame_id
    pin.framesForwardKinematics(model, data, q0)
    start = data.oMf[frame].copy()
    d = np.array([direction[0], direction[1], 0.0])
    across = np.array([[-direction[1], direction[0], 0.0], [0.0, 0.0, 1.0]])

    def placement(x):
        q = q0.copy()
        q[iq] = x
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[frame]

    def held(x):
        M = placement(x)
        return np.concatenate([across @ (M.translation - start.translation),
                               pin.log3(start.rotation.T @ M.rotation)])

    best = minimize(lambda x: -d @ placement(x).translation, q0[iq], method="SLSQP",
                    bounds=list(zip(lo, hi)), constraints={"type": "eq", "fun": held},
                    options={"ftol": 1e-12, "maxiter": 500})
    assert best.success, best.message
    assert np.abs(held(best.x)).max() < 1e-7
    return float(d @ (placement(best.x).translation - start.translation))


def _oracle(name, drop):
    """{sole: (forward, backward, outward, inward)} by SLSQP along and across the soles' heading
    from the lowered stance."""
    robot = _humanoid(name)
    q = _lowered_stance(name, drop)
    x, y = _heading(robot)
    out = {}
    for k, sole in enumerate(biped_soles(robot)):
        side = 1.0 if k == 0 else -1.0
        out[sole] = tuple(_slsqp_reach(robot, sole, d, q)
                          for d in (x, -x, side * y, -side * y))
    return out


@pytest.fixture(scope="module")
def oracle_reach():
    """talos14's {sole: (forward, backward, outward, inward)} in the posture, by SLSQP."""
    return _oracle("talos14", 0.0)


def test_sole_reach_is_the_farthest_flat_sole_within_the_shrunk_limits(talos14, oracle_reach):
    for sole in biped_soles(talos14):
        assert tuple(sole_reach(talos14, sole)) == pytest.approx(oracle_reach[sole], abs=1e-3)


def test_the_stride_is_bounded_by_the_trailing_legs_back_and_the_leading_legs_front_reach(
        limits14, oracle_reach):
    """A step of L: the trailing leg reaches about L behind the pelvis, the leading one L/2 ahead
    (module docstring): L <= b and L <= 2 f, times the share; backward steps mirrored."""
    front = min(r[0] for r in oracle_reach.values())
    back = min(r[1] for r in oracle_reach.values())
    assert limits14.forward == pytest.approx(SHARE * min(back, 2 * front), abs=2e-3)
    assert limits14.backward == pytest.approx(SHARE * min(front, 2 * back), abs=2e-3)


WALKERS = ["talos14", "g1", "icub", "alexander"]


@pytest.mark.parametrize("name", WALKERS)
def test_a_step_of_the_stride_is_held_by_both_legs_and_a_longer_one_is_not(name):
    """The stride model against the legs themselves at the walking CoM drop: with the pelvis
    where the lowered stance has it, the trailing leg holds its sole flat ``forward`` behind its
    standing place and the leading leg ``forward / 2`` ahead of its own, both within the joint
    bounds (bounded least squares); 5 % beyond the unscaled stride (``forward / share``) the leg
    that bounds it cannot. Mirrored for ``backward``."""
    robot = _humanoid(name)
    drop = _walking_drop(robot)
    limits = StepLimits.from_robot(robot, com_height_drop=drop)
    q = _lowered_stance(name, drop)
    x, _ = _heading(robot)
    standing = _posture_soles(robot)

    def error(sole, along):
        target = standing[sole].copy()
        target.translation = target.translation + along * np.r_[x, 0.0]
        return _solve_leg(robot, q, sole, target, _bounds(robot, _leg_iq(robot, sole), q))[1]

    reach = _oracle(name, drop)
    front = min(r[0] for r in reach.values())
    back = min(r[1] for r in reach.values())
    for sole in biped_soles(robot):
        assert error(sole, -limits.forward) < 1e-8  # trailing
        assert error(sole, 0.5 * limits.forward) < 1e-8  # leading
        assert error(sole, limits.backward) < 1e-8  # trailing, stepping backward
        assert error(sole, -0.5 * limits.backward) < 1e-8  # leading, stepping backward
        longer = 1.05 * limits.forward / SHARE
        if back < 2 * front:  # the trailing leg bounds the step
            assert error(sole, -longer) > 1e-4
        else:
            assert error(sole, 0.5 * longer) > 1e-4
        longer = 1.05 * limits.backward / SHARE
        if front < 2 * back:
            assert error(sole, longer) > 1e-4
        else:
            assert error(sole, -0.5 * longer) > 1e-4


def test_alexanders_stride_is_one_it_walks():
    """Closed loop (Walking, 10 steps forward at its scaled 0.4 m/s, the step limit forced):
    Alexander walks with steps up to 0.22 m and falls with 0.24 m (after 4 steps with 0.27 m,
    its trailing knee straightened onto its limit); the pelvis-midway model gave it 0.385 m. Its
    backward reach (0.25 m at the walking drop) bounds it."""
    robot = _humanoid("alexander")
    limits = StepLimits.from_robot(robot, com_height_drop=_walking_drop(robot))
    assert 0.1 < limits.forward < 0.22


def test_icub_reaches_along_its_soles_heading_not_its_backward_facing_base():
    """iCub's base frame faces backwards (yaw pi) while its soles face +x: its reaches are along
    and across the soles' heading (SLSQP along world +x, -x, and the sole's outward side), the
    forward one much shorter than the backward one, so a swap would show."""
    robot = _humanoid("icub")
    base_yaw = _yaw(pin.Quaternion(robot.q_ref[3:7]).normalized().toRotationMatrix())
    assert abs(abs(base_yaw) - math.pi) < 1e-6
    x, _ = _heading(robot)
    assert x[0] > 0.99
    drop = _walking_drop(robot)
    oracle = _oracle("icub", drop)
    for sole in biped_soles(robot):
        reach = sole_reach(robot, sole, drop)
        assert tuple(reach) == pytest.approx(oracle[sole], abs=1e-3)
    assert reach.backward > reach.forward + 0.05


def test_icubs_widths_straddle_its_standing_width():
    """Outward and inward now come from the soles' own sides (they were swapped: width_min was
    the standing width), and the hip roll that iCub's posture holds within its margin is not
    pinned there, so the sole reaches outward: width_min < nominal < width_max, each off the
    standing width by the share of the SLSQP reach."""
    robot = _humanoid("icub")
    drop = _walking_drop(robot)
    limits = StepLimits.from_robot(robot, com_height_drop=drop)
    left, right = biped_soles(robot)
    standing = _posture_soles(robot)
    _, y = _heading(robot)
    nominal = abs(y @ (standing[left].translation - standing[right].translation)[:2])
    assert limits.nominal_width == pytest.approx(nominal, abs=1e-9)
    assert limits.width_min < limits.nominal_width < limits.width_max
    oracle = _oracle("icub", drop)
    outward = min(r[2] for r in oracle.values())
    inward = min(r[3] for r in oracle.values())
    assert limits.width_max == pytest.approx(nominal + SHARE * outward, abs=1e-3)
    half = [robot.contact(s).spec.half_size[1] for s in (left, right)]
    apart = sum(half) + 0.1 * 2 * max(half)  # the soles' edges a tenth of a sole's width apart
    assert limits.width_min == pytest.approx(max(nominal - SHARE * inward, apart), abs=1e-3)
    # the hip roll stands within its margin in the posture: bounded there (the margin, or where
    # the stance has the joint if nearer) the sole would not go outward at all
    model = robot.model
    i = model.joints[model.getJointId("l_hip_roll")].idx_q
    lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
    assert hi - robot.q_ref[i] < REACH_MARGIN * (hi - lo)
    q = _lowered_stance("icub", drop)
    iq = _leg_iq(robot, left)
    lo, hi = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
    pinned = (np.minimum(lo + REACH_MARGIN * (hi - lo), q[iq]),
              np.maximum(hi - REACH_MARGIN * (hi - lo), q[iq]))
    assert _slsqp_reach(robot, left, y, q, bounds=pinned) < 1e-6
    assert outward > 0.02


def test_the_limits_do_not_depend_on_where_the_robot_faces():
    """iCub turned by 90 deg about the vertical (a copy whose posture's base is turned): the same
    limits, the soles' heading turned with it."""
    robot = _humanoid("icub")
    turned = copy.copy(robot)
    R = pin.rpy.rpyToMatrix(0.0, 0.0, 0.5 * math.pi)
    q = robot.q_ref.copy()
    q[:3] = R @ q[:3]
    q[3:7] = pin.Quaternion(R @ pin.Quaternion(q[3:7]).normalized().toRotationMatrix()).coeffs()
    turned.q_ref = q
    drop = _walking_drop(robot)
    a = StepLimits.from_robot(robot, com_height_drop=drop)
    b = StepLimits.from_robot(turned, com_height_drop=drop)
    for name in a.__dataclass_fields__:
        assert getattr(b, name) == pytest.approx(getattr(a, name), abs=1e-6), name


def test_the_widths_come_from_the_standing_soles(talos14, limits14):
    feet = _standing_feet(talos14)
    left, right = biped_soles(talos14)
    nominal = abs(feet[left][0][1] - feet[right][0][1])  # the posture's base is level, yaw 0
    half = sum(talos14.contact(s).spec.half_size[1] for s in (left, right))
    assert limits14.nominal_width == pytest.approx(nominal, abs=1e-9)
    assert half < limits14.width_min <= nominal < limits14.width_max


@pytest.mark.parametrize("name", ["talos14", "talos", "romeo"])
def test_limits_are_plausible_for_each_humanoid(name):
    robot = wb.load_robot(name)
    limits = StepLimits.from_robot(robot)
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, robot.q_ref)
    for sole in biped_soles(robot):
        hip = data.oMi[model.getJointId(leg_joints(robot, sole)[0])].translation
        leg = np.linalg.norm(hip - data.oMf[robot.contact(sole).frame_id].translation)
        if name != "romeo":  # romeo's stride is its ankle's: the next test
            assert limits.forward > 0.1 * leg and limits.backward > 0.1 * leg
        assert limits.width_min > 2.0 * robot.contact(sole).spec.half_size[1]  # no overlap
    assert limits.width_min <= limits.nominal_width < limits.width_max
    assert 0.0 < limits.yaw_in <= limits.yaw_out <= 0.4 + 1e-12


def test_romeos_stride_is_short_as_its_ankle_has_little_room_left():
    """romeo's posture bends its ankles to 0.35 rad of dorsiflexion, its limit 0.52: a flat sole
    hardly goes behind the pelvis (the shank would lean further forward), so at the standing
    height its stride, the share of its backward reach (SLSQP), is short, and lower it is
    shorter still. Freeing the ankle to its stop lengthens the reach: the ankle bounds it. Its
    walking height is above standing (knees and ankles straighter), where the stride is more
    than twice the standing one."""
    robot = _humanoid("romeo")
    model = robot.model
    sole = biped_soles(robot)[0]
    iq = _leg_iq(robot, sole)
    ankle = list(iq).index(model.joints[model.getJointId("LAnklePitch")].idx_q)
    stop = model.lowerPositionLimit[iq][ankle]
    x, _ = _heading(robot)
    strides = {}
    for drop in (0.0, 0.03):
        limits = StepLimits.from_robot(robot, com_height_drop=drop)
        back = min(r[1] for r in _oracle("romeo", drop).values())
        assert limits.forward == pytest.approx(SHARE * back, abs=2e-3)
        strides[drop] = limits.forward
        q = _lowered_stance("romeo", drop)
        lo, hi = _bounds(robot, iq, q)
        lo[ankle] = stop
        assert _slsqp_reach(robot, sole, -x, q, bounds=(lo, hi)) > back + 0.005
    assert 0.0 < strides[0.03] < strides[0.0] < 0.05
    drop = _walking_drop(robot)
    assert drop < 0.0
    walking = StepLimits.from_robot(robot, com_height_drop=drop).forward
    assert walking > 2.0 * strides[0.0]
    back = min(r[1] for r in _oracle("romeo", drop).values())
    assert walking == pytest.approx(SHARE * min(back, 2 * min(r[0] for r in _oracle(
        "romeo", drop).values())), abs=2e-3)


@pytest.mark.parametrize("name", ["talos14", "romeo"])
def test_the_walking_height_has_the_longest_stride_the_torques_allow(name):
    """:func:`walking_com_drop` against a scan twice as fine over the same range: no height
    where a sole holds the robot within its torque limits has a stride more than 3 % longer
    than the chosen one's; the torques at the chosen one are within the limits (the static
    equilibrium on one sole, :func:`conftest.one_sole_holding_torques`)."""
    from conftest import one_sole_holding_torques
    from wholebody.control.walking import (WALKING_DROP_RANGE, single_support_load,
                                           walking_com_drop)
    from wholebody.planning.support_shift import shift_key_pose
    from wholebody.robots.reference import humanoid_length_ratio

    robot = _humanoid(name)
    chosen = walking_com_drop(robot)
    scale = humanoid_length_ratio(robot)
    best = 0.0
    for drop in scale * np.linspace(*WALKING_DROP_RANGE, 21):
        try:
            stride = StepLimits.from_robot(robot, com_height_drop=float(drop)).forward
        except ValueError:
            continue
        load = single_support_load(robot, float(drop))
        if load is not None and load.share <= 1.0:
            best = max(best, stride)
    assert StepLimits.from_robot(robot, com_height_drop=chosen).forward >= 0.97 * best
    for stance, swing in (robot.contact_names, robot.contact_names[::-1]):
        _, q, _ = shift_key_pose(robot, stance, swing, chosen)
        tau = one_sole_holding_torques(robot, q, stance)
        lo, hi = robot.torque_bounds(q)
        assert np.all(tau <= hi * (1 + 1e-3)) and np.all(tau >= lo * (1 + 1e-3))
    robot.update(robot.q_ref, np.zeros(robot.nv))


def test_g1_turns_its_soles_at_the_walking_drop():
    """G1's hip-yaw axes run along its thighs, 27 deg off the vertical in the posture and past 30
    deg at the walking drop (where the yaw limits were 0: no leg joint passed a 30 deg test
    there). Found in the posture, they turn the soles: yaw_out and yaw_in at their caps. SLSQP:
    each leg holds its sole flat where it stands in the lowered stance, turned half of yaw_out
    outward and half of yaw_in inward (a relative yaw turns both hips by half), within the joint
    bounds, and further: outward 2.1 rad (its hip-yaw joint spans +-2.76 rad), inward 0.49."""
    robot = _humanoid("g1")
    model = robot.model
    drop = _walking_drop(robot)
    limits = StepLimits.from_robot(robot, com_height_drop=drop)
    assert limits.yaw_out == pytest.approx(0.4) and limits.yaw_in == pytest.approx(0.2)
    assert StepLimits.from_robot(robot).yaw_out == pytest.approx(0.4)
    q = _lowered_stance("g1", drop)
    data = model.createData()
    for posture, tilt in ((robot.q_ref, (25.0, 30.0)), (q, (30.0, 40.0))):
        pin.forwardKinematics(model, data, posture)
        jid = model.getJointId("left_hip_yaw_joint")
        assert model.joints[jid].shortname() == "JointModelRZ"
        angle = math.degrees(math.acos(abs(data.oMi[jid].rotation[2, 2])))
        assert tilt[0] < angle < tilt[1]
    for k, sole in enumerate(biped_soles(robot)):
        outward = 1.0 if k == 0 else -1.0  # the left sole turns outward to the left
        assert _slsqp_turn(robot, sole, q, outward) > max(0.5 * limits.yaw_out, 1.0)  # 2.1
        assert _slsqp_turn(robot, sole, q, -outward) > 2.0 * 0.5 * limits.yaw_in  # 0.49


def _slsqp_turn(robot, sole, q0, direction):
    """Largest turn (rad) of ``sole``'s frame about the vertical, ``direction`` +1 to the left,
    from where it stands flat in ``q0``, its position held and its sole flat, its leg's joints
    within :func:`_bounds`."""
    model = robot.model
    data = model.createData()
    iq = _leg_iq(robot, sole)
    lo, hi = _bounds(robot, iq, q0)
    frame = robot.contact(sole).frame_id
    pin.framesForwardKinematics(model, data, q0)
    start = data.oMf[frame].copy()

    def placement(x):
        q = q0.copy()
        q[iq] = x
        pin.framesForwardKinematics(model, data, q)
        return data.oMf[frame]

    def turn(x):
        R = start.rotation.T @ placement(x).rotation
        return direction * math.atan2(R[1, 0], R[0, 0])

    def held(x):
        M = placement(x)
        return np.concatenate([M.translation - start.translation, M.rotation[:2, 2]])

    best = minimize(lambda x: -turn(x), q0[iq], method="SLSQP", bounds=list(zip(lo, hi)),
                    constraints={"type": "eq", "fun": held},
                    options={"ftol": 1e-12, "maxiter": 500})
    assert best.success, best.message
    assert np.abs(held(best.x)).max() < 1e-7
    return turn(best.x)


def test_a_narrower_hip_yaw_range_turns_less(talos14, limits14):
    """Romeo's hip-yaw joints (revolute about their frame's z, vertical in the posture) span
    less than talos14's: its soles turn less per step."""
    romeo = wb.load_robot("romeo")

    def yaw_span(robot):
        model, data = robot.model, robot.model.createData()
        pin.forwardKinematics(model, data, robot.q_ref)
        spans = []
        for sole in biped_soles(robot):
            for joint in leg_joints(robot, sole):
                jid = model.getJointId(joint)
                vertical = abs(data.oMi[jid].rotation[2, 2]) > 0.99  # the joint frame's z
                if vertical and "RZ" in model.joints[jid].shortname():
                    i = model.joints[jid].idx_q
                    spans.append(model.upperPositionLimit[i] - model.lowerPositionLimit[i])
        return min(spans)

    assert yaw_span(romeo) < yaw_span(talos14)
    assert StepLimits.from_robot(romeo).yaw_out < limits14.yaw_out


def test_a_lower_com_reaches_further_forward(talos14, limits14):
    """Bent knees leave the leg more to stretch: the stride grows, still within the limits."""
    assert StepLimits.from_robot(talos14, com_height_drop=0.04).forward > limits14.forward


# ------------------------------------------------------------------ clamp_step
LIMITS = StepLimits(forward=0.3, backward=0.2, width_min=0.15, width_max=0.35,
                    nominal_width=0.2, yaw_out=0.4, yaw_in=0.2)


@pytest.mark.parametrize("side", [1, -1])
def test_every_clamped_step_is_within_the_limits(side):
    rng = np.random.default_rng(7)
    for _ in range(400):
        stance = (rng.uniform(-2, 2, 3), rng.uniform(-math.pi, math.pi))
        target, target_yaw = rng.uniform(-3, 3, 2), rng.uniform(-4, 4)
        xy, yaw = clamp_step(stance, side, target, target_yaw, LIMITS)
        dx, width, turn = _relative(stance, xy, yaw, side)
        assert -LIMITS.backward - 1e-12 <= dx <= LIMITS.forward + 1e-12
        assert LIMITS.width_min - 1e-12 <= width <= LIMITS.width_max + 1e-12
        assert -LIMITS.yaw_in - 1e-12 <= turn <= LIMITS.yaw_out + 1e-12
        again = clamp_step(stance, side, xy, yaw, LIMITS)  # a clamped step is kept
        assert again[0] == pytest.approx(xy, abs=1e-12) and again[1] == pytest.approx(yaw)


@pytest.mark.parametrize("side", [1, -1])
def test_a_step_within_the_limits_is_unchanged(side):
    rng = np.random.default_rng(11)
    for _ in range(200):
        p, yaw0 = rng.uniform(-2, 2, 3), rng.uniform(-math.pi, math.pi)
        dx = rng.uniform(-LIMITS.backward, LIMITS.forward)
        width = rng.uniform(LIMITS.width_min, LIMITS.width_max)
        turn = rng.uniform(-LIMITS.yaw_in, LIMITS.yaw_out)
        c, s = math.cos(yaw0), math.sin(yaw0)
        target = p[:2] + dx * np.array([c, s]) - side * width * np.array([-s, c])
        target_yaw = yaw0 - side * turn
        xy, yaw = clamp_step((p, yaw0), side, target, target_yaw, LIMITS)
        assert xy == pytest.approx(target, abs=1e-12)
        assert yaw == pytest.approx(target_yaw, abs=1e-12)


def test_yaw_sign_convention():
    """Left stance: the right sole turning right (negative yaw) turns outward, up to yaw_out;
    turning left is inward, up to yaw_in. Mirrored for a right stance."""
    left_stance, right_stance = (np.zeros(3), 0.0), (np.zeros(3), 0.0)
    right_target, left_target = np.array([0.0, -0.2]), np.array([0.0, 0.2])
    assert clamp_step(left_stance, 1, right_target, -0.3, LIMITS)[1] == pytest.approx(-0.3)
    assert clamp_step(left_stance, 1, right_target, -0.9, LIMITS)[1] == pytest.approx(-0.4)
    assert clamp_step(left_stance, 1, right_target, 0.3, LIMITS)[1] == pytest.approx(0.2)
    assert clamp_step(right_stance, -1, left_target, 0.3, LIMITS)[1] == pytest.approx(0.3)
    assert clamp_step(right_stance, -1, left_target, 0.9, LIMITS)[1] == pytest.approx(0.4)
    assert clamp_step(right_stance, -1, left_target, -0.3, LIMITS)[1] == pytest.approx(-0.2)
    # across +-pi: a stance heading of pi - 0.1 and a target of -pi + 0.1 are 0.2 apart
    yaw = clamp_step((np.zeros(3), math.pi - 0.1), -1, np.array([0.0, -0.2]), -math.pi + 0.1,
                     LIMITS)[1]
    assert yaw == pytest.approx(math.pi + 0.1)


def test_a_swing_sole_on_the_wrong_side_is_put_back_outside():
    xy, _ = clamp_step((np.zeros(3), 0.0), 1, np.array([0.1, 0.3]), 0.0, LIMITS)
    assert xy == pytest.approx([0.1, -LIMITS.width_min])


# ------------------------------------------------------------------ from_velocity
T = 0.8


def _check_within(planner, feet, plan):
    """Every step within the limits against the sole standing when it swings."""
    feet = dict(feet)
    lim = planner.limits
    for step in plan:
        other = next(s for s in planner.soles if s != step.contact)
        side = 1 if other == planner.soles[0] else -1
        dx, width, turn = _relative(feet[other], step.position, step.yaw, side)
        assert -lim.backward - 1e-9 <= dx <= lim.forward + 1e-9
        assert lim.width_min - 1e-9 <= width <= lim.width_max + 1e-9
        assert -lim.yaw_in - 1e-9 <= turn <= lim.yaw_out + 1e-9
        assert step.position[2] == pytest.approx(feet[other][0][2])
        feet[step.contact] = (step.position, step.yaw)


def test_walking_forward_strides_two_steps_of_path(talos14, planner):
    """Each step the path moves v T; each sole lands on its side of it: a sole's stride is
    2 v T after its first step, the lead of the swing sole over the stance sole v T."""
    feet = _standing_feet(talos14)
    left, right = planner.soles
    v = 0.2
    assert v * T < planner.limits.forward  # a step within the limits: not clamped
    plan = planner.from_velocity(feet, left, (v, 0.0, 0.0), T, 8)
    assert [s.contact for s in plan] == [left, right] * 4
    mid = 0.5 * (feet[left][0] + feet[right][0])
    for k, step in enumerate(plan):
        assert step.position[0] == pytest.approx(mid[0] + v * T * (k + 1), abs=1e-9)
        assert step.yaw == pytest.approx(0.0, abs=1e-12)
    for a, b in zip(plan, plan[2:]):
        assert b.position[0] - a.position[0] == pytest.approx(2 * v * T, abs=1e-9)
    _check_within(planner, feet, plan)


@pytest.mark.parametrize("command", [(0.3, 0.0, 0.0), (0.2, 0.05, 0.15), (0.0, -0.2, 0.0)])
def test_re_planning_mid_walk_continues_the_same_steps(talos14, planner, command):
    """A plan made from the soles as they stand after any of its own steps is the rest of it:
    re-planning at every touchdown keeps the commanded pace."""
    feet = _standing_feet(talos14)
    plan = planner.from_velocity(feet, planner.soles[0], command, T, 8)
    for k in range(1, 5):
        now = dict(feet)
        for step in plan[:k]:
            now[step.contact] = (step.position, step.yaw)
        rest = planner.from_velocity(now, plan[k].contact, command, T, 8 - k)
        for a, b in zip(plan[k:], rest):
            assert b.contact == a.contact
            assert b.position == pytest.approx(a.position, abs=1e-9)
            assert b.yaw == pytest.approx(a.yaw, abs=1e-12)


def test_a_fast_command_saturates_at_the_longest_step(talos14, planner):
    feet = _standing_feet(talos14)
    plan = planner.from_velocity(feet, planner.soles[1], (3.0, 0.0, 0.0), T, 6)
    _check_within(planner, feet, plan)
    for a, b in zip(plan, plan[1:]):
        assert b.position[0] - a.position[0] == pytest.approx(planner.limits.forward, abs=1e-9)


def test_a_yaw_rate_turns_the_path_until_clamped(talos14, planner):
    feet = _standing_feet(talos14)
    rate = 0.2  # 0.16 rad a step: within yaw_in and yaw_out
    assert rate * T < planner.limits.yaw_in
    plan = planner.from_velocity(feet, planner.soles[0], (0.2, 0.0, rate), T, 6)
    for k, step in enumerate(plan):
        assert step.yaw == pytest.approx(rate * T * (k + 1), abs=1e-9)
    _check_within(planner, feet, plan)
    fast = planner.from_velocity(feet, planner.soles[0], (0.0, 0.0, 2.0), T, 6)
    _check_within(planner, feet, fast)
    turns = np.diff([0.0] + [s.yaw for s in fast])
    assert np.all(turns > 0) and np.all(turns < 2.0 * T)  # turning left, slower than asked


@pytest.mark.parametrize("vy", [0.3, -0.3, 1.0])
def test_a_lateral_command_keeps_the_soles_apart(talos14, planner, vy):
    feet = _standing_feet(talos14)
    plan = planner.from_velocity(feet, planner.soles[0], (0.0, vy, 0.0), T, 8)
    _check_within(planner, feet, plan)
    mid = 0.5 * (plan[-1].position + plan[-2].position)
    assert np.sign(mid[1]) == np.sign(vy) and abs(mid[1]) > 0.1


@pytest.mark.parametrize("command", [(0.0, 0.12, 0.0), (0.0, -0.12, 0.0), (0.1, 0.0, 0.35),
                                     (0.1, 0.0, -0.35)])
def test_sideways_and_turning_the_leading_sole_takes_what_the_follower_cannot(
        talos14, planner, command):
    """Beyond what the following sole can close in (nominal - narrowest width, yaw_in) the
    pair of steps still covers 2 v T sideways and 2 omega T of heading, inside the limits."""
    lim = planner.limits
    vy, rate = command[1], command[2]
    assert abs(vy) * T > lim.nominal_width - lim.width_min or abs(rate) * T > lim.yaw_in
    assert abs(vy) * 2 * T <= lim.width_max - lim.width_min
    assert abs(rate) * 2 * T <= lim.yaw_in + lim.yaw_out
    feet = _standing_feet(talos14)
    plan = planner.from_velocity(feet, planner.soles[0], command, T, 8)
    _check_within(planner, feet, plan)
    for a, b in zip(plan[1:], plan[3:]):  # the same sole two steps apart
        heading = np.array([math.cos(a.yaw), math.sin(a.yaw)])
        lateral = np.array([-math.sin(a.yaw), math.cos(a.yaw)])
        d = b.position[:2] - a.position[:2]
        if rate == 0.0:
            assert d @ lateral == pytest.approx(2 * vy * T, abs=1e-9)
            assert d @ heading == pytest.approx(0.0, abs=1e-9)
        assert b.yaw - a.yaw == pytest.approx(2 * rate * T, abs=1e-9)


def test_a_schedule_changes_the_steps_from_its_change_on(talos14, planner):
    feet = _standing_feet(talos14)
    steady = planner.from_velocity(feet, planner.soles[0], (0.2, 0.0, 0.0), T, 8)
    changed = planner.from_velocity(
        feet, planner.soles[0], lambda k: (0.2, 0.0, 0.0) if k < 4 else (0.2, 0.0, 0.15), T, 8)
    for a, b in zip(steady[:4], changed[:4]):
        assert a.position == pytest.approx(b.position) and a.yaw == pytest.approx(b.yaw)
    for a, b in zip(steady[4:], changed[4:]):
        assert b.yaw > a.yaw + 0.1


def test_a_zero_command_ends_with_the_soles_side_by_side(talos14, planner):
    feet = _standing_feet(talos14)
    plan = planner.from_velocity(
        feet, planner.soles[0], lambda k: (0.3, 0.1, 0.2) if k < 6 else (0.0, 0.0, 0.0), T, 8)
    a, b = plan[-2], plan[-1]
    assert a.yaw == pytest.approx(b.yaw, abs=1e-9)
    side = 1 if a.contact == planner.soles[0] else -1
    dx, width, _ = _relative((a.position, a.yaw), b.position, b.yaw, side)
    assert dx == pytest.approx(0.0, abs=1e-9)
    assert width == pytest.approx(planner.limits.nominal_width, abs=1e-9)
    # standing still: steps in place
    still = planner.from_velocity(feet, planner.soles[1], (0.0, 0.0, 0.0), T, 2)
    for step in still:
        assert step.position == pytest.approx(feet[step.contact][0], abs=1e-9)


def test_no_steps_is_an_empty_plan(talos14, planner):
    assert planner.from_velocity(_standing_feet(talos14), planner.soles[0], (0.1, 0, 0), T,
                                 0) == []


# ------------------------------------------------------------------ from_list
def test_from_list_clamps_each_step_against_the_previous_stance(talos14, planner):
    feet = _standing_feet(talos14)
    left, right = planner.soles
    lim = planner.limits
    p_right = feet[right][0]
    plan = planner.from_list(feet, [(left, (p_right[0] + 0.1, p_right[1] + 0.2), 0.0),
                                    (right, (p_right[0] + 5.0, p_right[1] + 0.3), -0.1),
                                    (left, (0.0, 0.0, 0.05), 0.0)])
    assert all(isinstance(s, Footstep) for s in plan)
    assert plan[0].position == pytest.approx([p_right[0] + 0.1, p_right[1] + 0.2, p_right[2]])
    assert plan[0].yaw == pytest.approx(0.0)
    dx, width, turn = _relative((plan[0].position, plan[0].yaw), plan[1].position, plan[1].yaw,
                                1)
    assert dx == pytest.approx(lim.forward) and width == pytest.approx(lim.width_min)
    assert turn == pytest.approx(0.1)  # the right sole turned right of the left one: outward
    assert plan[2].position[2] == pytest.approx(0.05)  # a given height is kept
    _check_within(planner, feet, plan[:2])


def test_from_list_refuses_a_sole_stepping_twice(talos14, planner):
    feet = _standing_feet(talos14)
    left, right = planner.soles
    with pytest.raises(ValueError, match=r"steps\[2\]"):
        planner.from_list(feet, [(left, (0.1, 0.1), 0.0), (right, (0.2, -0.1), 0.0),
                                 (right, (0.3, -0.1), 0.0)])
    with pytest.raises(ValueError, match=r"steps\[0\].*'foot'"):
        planner.from_list(feet, [("foot", (0.1, 0.1), 0.0)])


# ------------------------------------------------------------------ validation
@pytest.mark.parametrize("kwargs, match", [
    (dict(command=(math.nan, 0.0, 0.0)), "command"),
    (dict(command=(0.1, 0.0)), "command"),
    (dict(command=lambda k: (0.1, 0.0, math.inf if k == 3 else 0.0)), "command"),
    (dict(steps=-1), "steps"),
    (dict(step_period=0.0), "step_period"),
    (dict(step_period=math.nan), "step_period"),
    (dict(swing_first="foot"), "swing_first"),
])
def test_from_velocity_validation(talos14, planner, kwargs, match):
    args = dict(feet=_standing_feet(talos14), swing_first=planner.soles[0],
                command=(0.1, 0.0, 0.0), step_period=T, steps=5)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        planner.from_velocity(**args)


def test_unknown_soles_in_feet_are_refused(talos14, planner):
    feet = _standing_feet(talos14)
    feet["foot"] = feet.pop(planner.soles[0])
    with pytest.raises(ValueError, match="feet"):
        planner.from_velocity(feet, planner.soles[1], (0.1, 0.0, 0.0), T, 2)
    with pytest.raises(ValueError, match="feet"):
        planner.from_list(feet, [])


@pytest.mark.parametrize("kwargs, match", [(dict(share=1.5), "share"),
                                           (dict(margin=-0.1), "margin"),
                                           (dict(com_height_drop=math.nan), "com_height_drop")])
def test_from_robot_validation(talos14, kwargs, match):
    with pytest.raises(ValueError, match=match):
        StepLimits.from_robot(talos14, **kwargs)


def test_clamp_step_validation():
    with pytest.raises(ValueError, match="stance_side"):
        clamp_step((np.zeros(3), 0.0), 0, np.zeros(2), 0.0, LIMITS)


def test_reach_search_is_kept_per_posture_and_joint_limits():
    """StepLimits.from_robot keeps its reach search on the robot (``robot.derived``): asked again
    it gives what a fresh copy of the robot computes; with the legs' joint ranges narrowed on the
    same robot it searches again (a fresh copy with those ranges gives the same, shorter, limits);
    a height at which a sole cannot stand flat raises the same error every time."""
    robot = wb.load_robot("talos14")
    first = StepLimits.from_robot(robot)
    assert robot.derived
    fresh = copy.deepcopy(robot)
    fresh.derived.clear()
    assert StepLimits.from_robot(fresh) == StepLimits.from_robot(robot) == first
    model = robot.model
    for sole in biped_soles(robot):
        for name in leg_joints(robot, sole):
            joint = model.joints[model.getJointId(name)]
            i = joint.idx_q
            lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
            mid = robot.q_ref[i]
            model.lowerPositionLimit[i] = mid - 0.5 * (mid - lo)
            model.upperPositionLimit[i] = mid + 0.5 * (hi - mid)
    narrowed = StepLimits.from_robot(robot)
    assert narrowed.forward < first.forward - 0.01
    fresh = copy.deepcopy(robot)
    fresh.derived.clear()
    assert StepLimits.from_robot(fresh) == narrowed
    too_low = 0.9 * robot.q_ref[2]
    messages = []
    for _ in range(2):
        with pytest.raises(ValueError, match="cannot stand flat") as error:
            StepLimits.from_robot(robot, com_height_drop=too_low)
        messages.append(str(error.value))
    assert messages[0] == messages[1]
