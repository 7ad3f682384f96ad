"""Planning: gait schedules, swing trajectories, footholds, trunk references and the gait planner
(Fahmi et al. 2019: crawl and trot on HyQ; swing task eqs. 5-6; trunk task eq. 4).

Evidence is independent of the code under test wherever possible: duty factors and diagonal pairs by
sampling, derivatives by finite differences, the trunk path by numerically integrating the command
(scipy), the foothold on flat ground against Pinocchio's forward kinematics of the standing posture,
angular velocity against Pinocchio's log map, reachability of the planned feet by inverse kinematics.
"""

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

import wholebody as wb
from wholebody.planning import (
    LEGS, CrawlSway, Footprint, GaitPlanner, GaitSchedule, SwingTrajectory, Terrain,
    TrunkReference, VelocityCommand, crawl, raibert_foothold, stand, swing_trajectory, trot)
from wholebody.planning.blend import quintic_blend

LF, RF, LH, RH = LEGS
FAST = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def n_swinging(schedule, t):
    return sum(schedule.in_swing(leg, t) for leg in schedule.legs)


def triangle_margin(tri, p):
    """Signed distance from p to the nearest edge of triangle tri (3x2); > 0 inside."""
    out = math.inf
    for k in range(3):
        a, b, c = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
        e = b - a
        n = np.array([-e[1], e[0]]) / np.linalg.norm(e)
        if n @ (c - a) < 0:
            n = -n
        out = min(out, n @ (p - a))
    return out


# ====================================================================== schedules
def test_crawl_one_leg_at_a_time_in_the_classic_sequence():
    sch = crawl(start=0.3)
    ts = np.arange(0.0, 0.3 + 4 * sch.period, 1e-3)
    counts = np.array([n_swinging(sch, t) for t in ts])
    assert set(np.unique(counts)) == {0, 1}  # one leg or none, never two
    assert all(len(sch.stance_legs(t)) >= 3 for t in ts)
    assert np.all(counts[ts < 0.3 - 1e-9] == 0)  # start delay: all legs in stance first
    lifts = [e.leg for e in sch.events(0.0, 0.3 + 4 * sch.period) if e.kind == "liftoff"]
    assert lifts == [LH, LF, RH, RF] * 4
    # four-leg support windows exist between swings (duty > 0.75)
    assert np.mean(counts[ts > 0.3] == 0) == pytest.approx(4 * (sch.duty[0] - 0.75), abs=2e-3)
    assert sch.max_swing_legs() == 1


def test_trot_swings_diagonal_pairs_together():
    sch = trot()
    ts = np.arange(0.0, 5 * sch.period, 7e-4)
    for t in ts:
        assert sch.in_swing(LF, t) == sch.in_swing(RH, t)
        assert sch.in_swing(RF, t) == sch.in_swing(LH, t)
        assert not (sch.in_swing(LF, t) and sch.in_swing(RF, t))  # duty 0.5: one pair on the ground
    assert len({e.time for e in sch.events(0.0, 3.0) if e.leg in (LF, RH)}) == \
        len([e for e in sch.events(0.0, 3.0) if e.leg == LF])
    assert sch.max_swing_legs() == 2


@FAST
@given(period=st.floats(0.3, 3.0), duty=st.floats(0.3, 0.95),
       offsets=st.lists(st.floats(0.0, 0.999), min_size=4, max_size=4), start=st.floats(0.0, 2.0))
def test_duty_factor_measured_by_sampling(period, duty, offsets, start):
    sch = GaitSchedule(period, offsets, duty, start=start)
    n_cycles, per_cycle = 6, 4000
    t = start + period + (np.arange(n_cycles * per_cycle) + 0.5) * (period / per_cycle)
    for leg in sch.legs:
        stance = np.mean([sch.in_stance(leg, ti) for ti in t])
        assert stance == pytest.approx(duty, abs=2.0 / per_cycle)


@FAST
@given(t=st.floats(-5.0, 50.0), k=st.integers(1, 5))
def test_phases_wrap(t, k):
    sch = crawl(start=1.0)
    for leg in sch.legs:
        ph = sch.phase(leg, t)
        assert 0.0 <= ph < 1.0
        # periodic (up to the rounding of t + k * period)
        d = abs(sch.phase(leg, t + k * sch.period) - ph)
        assert min(d, 1.0 - d) < 1e-9
        sp = sch.swing_phase(leg, t)
        if sch.in_swing(leg, t):
            sw = sch.current_swing(leg, t)
            assert 0.0 <= sp < 1.0
            assert sp == pytest.approx((t - sw.liftoff) / sch.swing_duration(leg), abs=1e-6)
            assert math.isnan(sch.stance_phase(leg, t))
        else:
            assert math.isnan(sp)


def test_swing_phase_rises_from_zero_to_one_within_each_swing():
    sch = trot(start=0.2)
    for sw in sch.swings(0.2, 3.0):
        ts = np.linspace(sw.liftoff, sw.touchdown, 200, endpoint=False)
        ph = np.array([sch.swing_phase(sw.leg, t) for t in ts])
        assert ph[0] == pytest.approx(0.0, abs=1e-6) and np.all(np.diff(ph) > 0)
        assert np.all(ph < 1.0) and ph[-1] > 0.99


@pytest.mark.parametrize("schedule", [crawl(start=0.4), trot(start=0.1), crawl(3.0, 0.9)])
def test_events_are_consistent_with_the_contact_state(schedule):
    sch = schedule
    events = sch.events(0.0, 4 * sch.period)
    assert events == sorted(events, key=lambda e: e.time)
    eps = 1e-7
    for e in events:
        after, before = e.time + eps, e.time - eps
        if e.kind == "liftoff":
            assert sch.in_swing(e.leg, after) and sch.in_stance(e.leg, before)
            assert sch.in_swing(e.leg, e.time)  # the event instant belongs to the new phase
            assert e.time == pytest.approx(sch.liftoff_time(e.leg, e.index))
        else:
            assert sch.in_stance(e.leg, after) and sch.in_swing(e.leg, before)
            assert sch.in_stance(e.leg, e.time)
            assert e.time == pytest.approx(sch.touchdown_time(e.leg, e.index))
    for leg in sch.legs:
        mine = [e for e in events if e.leg == leg]
        kinds = [e.kind for e in mine]
        assert kinds == ["liftoff", "touchdown"] * (len(kinds) // 2) + kinds[len(kinds) // 2 * 2:]
        for lo, td in zip(mine[0::2], mine[1::2]):
            assert td.time - lo.time == pytest.approx(sch.swing_duration(leg))
        # next_touchdown / next_liftoff / last_touchdown agree with the event list
        tds = [e.time for e in mine if e.kind == "touchdown"]
        los = [e.time for e in mine if e.kind == "liftoff"]
        for t in np.linspace(0.0, 3 * sch.period, 97):
            later = [x for x in tds if x > t + 1e-9]
            if later:
                assert sch.next_touchdown(leg, t) == pytest.approx(later[0])
            later = [x for x in los if x > t + 1e-9]
            if later:
                assert sch.next_liftoff(leg, t) == pytest.approx(later[0])
            earlier = [x for x in tds if x <= t]
            last = sch.last_touchdown(leg, t)
            assert (last is None) == (not earlier)
            if earlier:
                assert last == pytest.approx(earlier[-1])


def test_stand_never_swings_and_validation():
    sch = stand()
    assert all(sch.in_stance(leg, t) for leg in sch.legs for t in np.linspace(-1, 10, 50))
    assert sch.events(0.0, 10.0) == [] and sch.max_swing_legs() == 0
    assert sch.next_touchdown(LF, 1.0) == math.inf
    with pytest.raises(ValueError, match="duty"):
        crawl(duty=0.7)
    with pytest.raises(ValueError, match="duty"):
        GaitSchedule(1.0, (0, 0, 0, 0), 0.0)
    with pytest.raises(ValueError, match="leg"):
        sch.in_stance("tail", 0.0)


# ====================================================================== swing
vec3 = st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-0.3, 0.3)).map(np.array)


@FAST
@given(p0=vec3, p1=vec3, T=st.floats(0.1, 1.5), h=st.floats(0.0, 0.3), t0=st.floats(-2, 2))
def test_swing_endpoints_apex_and_derivatives(p0, p1, T, h, t0):
    sw = SwingTrajectory(p0, p1, T, h, t0)
    scale = 1.0 + np.abs(p1 - p0).max() + h
    for t, p in ((t0, p0), (t0 + T, p1)):
        pos, vel, acc = sw.evaluate(t)
        np.testing.assert_allclose(pos, p, atol=1e-12)
        np.testing.assert_allclose(vel, 0.0, atol=1e-12 * scale / T)
        np.testing.assert_allclose(acc, 0.0, atol=1e-12 * scale / T**2)
    ts = t0 + np.linspace(0.0, T, 2001)
    pos, vel, acc = sw.evaluate(ts)
    apex = max(p0[2], p1[2]) + h
    assert pos[:, 2].max() <= apex + 1e-12
    assert sw.position(t0 + T / 2)[2] == pytest.approx(apex, abs=1e-12)
    assert pos[:, 2].min() >= min(p0[2], p1[2]) - 1e-12
    # finite differences (independent of the analytic derivatives)
    d = 1e-5 * T
    tm = t0 + np.linspace(0.02, 0.98, 40) * T  # avoids mid-swing, where the jerk jumps
    np.testing.assert_allclose((sw.position(tm + d) - sw.position(tm - d)) / (2 * d),
                               sw.velocity(tm), atol=1e-6 * (1 + np.abs(p1 - p0).max() + h) / T)
    np.testing.assert_allclose((sw.velocity(tm + d) - sw.velocity(tm - d)) / (2 * d),
                               sw.acceleration(tm), atol=1e-5 * (1 + np.abs(p1 - p0).max() + h) / T**2)
    # C2 across mid-swing: the acceleration is continuous where the two height blends meet
    np.testing.assert_allclose(sw.acceleration(t0 + T / 2 - 1e-9), sw.acceleration(t0 + T / 2 + 1e-9),
                               atol=1e-5 * (1 + h) / T**2)
    # scalar in-place evaluation agrees with the vectorised one
    buf = [np.zeros(3) for _ in range(3)]
    for t in (t0 - 1.0, t0 + 0.3 * T, t0 + 0.7 * T, t0 + 2 * T):
        sw.evaluate_into(t, *buf)
        for a, b in zip(buf, sw.evaluate(t)):
            np.testing.assert_allclose(a, b, atol=1e-12)


@FAST
@given(p0=vec3, dxy=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.3, 0.3)),
       T=st.floats(0.2, 1.5), h=st.floats(0.01, 0.2), depth=st.floats(0.0, 0.02))
def test_swing_with_a_floor_is_over_its_target_when_it_meets_the_floor(p0, dxy, T, h, depth):
    """A swing aimed ``depth`` below the floor: the time it passes the floor's height is found by
    bisection on its sampled height (independent of the closed-form share); there its horizontal
    position is the target's. Its height profile is the one without a floor, and its
    horizontal one that swing's stretched by one factor (the same blend and timing)."""
    floor = float(p0[2])
    p1 = np.array([p0[0] + dxy[0], p0[1] + dxy[1], floor - depth])
    sw = SwingTrajectory(p0, p1, T, h, 0.0, floor=floor)
    plain = SwingTrajectory(p0, p1, T, h, 0.0)
    lo, hi = 0.5 * T, T
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if sw.position(mid)[2] > floor else (lo, mid)
    np.testing.assert_allclose(sw.position(hi)[:2], p1[:2], atol=1e-9)
    ts = np.linspace(-0.1, 1.1, 61) * T
    np.testing.assert_allclose(sw.position(ts)[:, 2], plain.position(ts)[:, 2], atol=1e-12)
    stretch = 1.0 / quintic_blend(hi / T)[0]  # the plain swing's share of its move by then
    stretched, reference = sw.evaluate(ts), plain.evaluate(ts)
    for k, (a, b) in enumerate(zip(stretched, reference)):
        origin = p0[:2] if k == 0 else 0.0  # positions about the lift-off point
        np.testing.assert_allclose(a[:, :2] - origin, stretch * (b[:, :2] - origin),
                                   atol=1e-9 / T ** 2)
    buf = [np.zeros(3) for _ in range(3)]
    for t in (-1.0, 0.3 * T, 0.95 * T, 2 * T):
        sw.evaluate_into(t, *buf)
        for a, b in zip(buf, sw.evaluate(t)):
            np.testing.assert_allclose(a, b, atol=1e-12)
    with pytest.raises(ValueError, match="floor"):
        SwingTrajectory(p0, p1, T, h, floor=floor + h + 1.0)


@FAST
@given(p0=vec3, dxy=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.3, 0.3)),
       xy=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.3, 0.3)), T=st.floats(0.2, 1.5),
       h=st.floats(0.01, 0.2), depth=st.floats(0.0, 0.02), with_floor=st.booleans())
def test_swing_landing_moved_is_the_swing_built_for_it(p0, dxy, xy, T, h, depth, with_floor):
    """A swing's landing moved to another (x, y) (a step adjustment) is, bit for bit, the swing
    the constructor builds for that landing (same start, duration, heights, floor), and leaves
    the original swing as it was."""
    floor = float(p0[2]) if with_floor else None
    p1 = np.array([p0[0] + dxy[0], p0[1] + dxy[1], float(p0[2]) - depth])
    sw = SwingTrajectory(p0, p1, T, h, 0.3, floor=floor)
    before = [a.copy() for a in sw.evaluate(np.linspace(0.0, 1.0, 7) * T + 0.3)]
    target = np.array([p0[0] + xy[0], p0[1] + xy[1]])
    moved = sw.with_landing_xy(target)
    built = SwingTrajectory(p0, [*target, p1[2]], T, h, 0.3, floor=floor)
    ts = np.linspace(-0.1, 1.1, 37) * T + 0.3
    for a, b in zip(moved.evaluate(ts), built.evaluate(ts)):
        np.testing.assert_array_equal(a, b)
    buf, ref = [np.zeros(3) for _ in range(3)], [np.zeros(3) for _ in range(3)]
    for t in ts:
        moved.evaluate_into(t, *buf)
        built.evaluate_into(t, *ref)
        for a, b in zip(buf, ref):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(moved.p1, built.p1)
    assert (moved.t1, moved.floor_share, moved.apex_height) == (built.t1, built.floor_share,
                                                                built.apex_height)
    for a, b in zip(sw.evaluate(np.linspace(0.0, 1.0, 7) * T + 0.3), before):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(ValueError, match="xy"):
        sw.with_landing_xy([np.nan, 0.0])


def test_swing_holds_outside_and_functional_form():
    p0, p1 = np.array([0.0, 0.0, 0.02]), np.array([0.2, 0.05, 0.12])
    pos, vel, acc = swing_trajectory(p0, p1, 0.4, np.array([-0.1, 0.5]))
    np.testing.assert_allclose(pos, [p0, p1])
    np.testing.assert_allclose(vel, 0.0)
    np.testing.assert_allclose(acc, 0.0)
    assert swing_trajectory(p0, p1, 0.4, 0.2)[0][2] == pytest.approx(0.12 + 0.1)  # default 0.1 m
    with pytest.raises(ValueError):
        SwingTrajectory(p0, p1, 0.0)


# ====================================================================== footholds
def test_flat_zero_command_foothold_is_the_standing_foot(hyq):
    fp = Footprint.from_robot(hyq)
    hyq.update(hyq.q_ref, np.zeros(hyq.nv))
    base = hyq.q_ref[:3]
    for i, leg in enumerate(fp.legs):
        foot, _ = hyq.frame_placement(leg)  # independent: the robot's own forward kinematics
        fh = raibert_foothold(base + fp.feet[i], np.zeros(2), 1.5, foot_radius=fp.foot_radius[i])
        np.testing.assert_allclose(fh.position, foot, atol=1e-9)
        np.testing.assert_allclose(fh.point, [foot[0], foot[1], 0.0], atol=1e-9)
        np.testing.assert_allclose(fh.normal, [0, 0, 1])
    assert fp.foot_radius == pytest.approx(hyq.contact("lf_foot").spec.radius)
    np.testing.assert_allclose(base + fp.com, hyq.com, atol=1e-9)


@pytest.mark.parametrize("v", [(0.15, 0.0), (0.1, -0.05), (-0.08, 0.03)])
def test_forward_command_moves_the_foothold_by_half_the_stance_travel(v):
    hip = np.array([0.37, 0.32])
    T_stance = 2.125
    fh = raibert_foothold(hip, v, T_stance)
    np.testing.assert_allclose(fh.point[:2], hip + np.array(v) * T_stance / 2, atol=1e-12)
    # Raibert feedback: k (v_measured - v_cmd)
    fb = raibert_foothold(hip, v, T_stance, velocity=np.array(v) + [0.1, -0.2], gain=0.3)
    np.testing.assert_allclose(fb.point[:2] - fh.point[:2], [0.03, -0.06], atol=1e-12)
    clamped = raibert_foothold(hip, v, T_stance, max_offset=0.05)
    assert np.linalg.norm(clamped.point[:2] - hip) == pytest.approx(0.05)


def test_raibert_feedback_is_read_at_lift_off_and_held_through_the_swing(hyq):
    """The planner's foothold feedback (Fahmi et al. 2019's planner, ref. [20]): a foot lifting
    off at t is sent k (v_measured(t) - v_cmd(t)) beyond its feedback-free target (the hip at
    touchdown plus v_cmd T_stance / 2, tested above), touching down (1 - duty) periods later; a
    velocity measured during the swing does not move it, the next lift-off reads a new one."""
    k, period, start = 0.3, 0.8, 0.5
    command = VelocityCommand((0.2, 0.0), (0.2, 0.0), (0.0, 1.0))
    planner = GaitPlanner.for_robot(hyq, trot(period, start=start), command, feedback_gain=k,
                                    start_shift=False)
    free = GaitPlanner.for_robot(hyq, trot(period, start=start), command, start_shift=False)
    measured = np.array([0.25, -0.3, 0.0])

    def expected(leg, t_td, t):
        return (free.touchdown_target(leg, t_td).position[:2]
                + k * (measured[:2] - np.array([0.2, 0.0])))

    t = start + 1e-4
    plan = planner.update(t, com_velocity=measured)
    swinging = [i for i in range(4) if not plan.contact[i]]
    assert swinging == [0, 3]  # the first diagonal: left-front, right-hind
    targets = {}
    for i in swinging:
        assert plan.touchdown_time[i] == pytest.approx(start + 0.5 * period)
        targets[i] = plan.touchdown_position[i].copy()
        np.testing.assert_allclose(targets[i][:2], expected(planner.legs[i],
                                                            plan.touchdown_time[i], t),
                                   atol=1e-9)
    plan = planner.update(t + 0.2, com_velocity=np.array([-1.0, 2.0, 0.0]))  # mid-swing
    for i in swinging:
        np.testing.assert_allclose(plan.touchdown_position[i], targets[i], atol=1e-12)
    t = start + period + 1e-4  # the same legs' next lift-off
    plan = planner.update(t, com_velocity=measured)
    for i in swinging:
        np.testing.assert_allclose(plan.touchdown_position[i][:2], expected(
            planner.legs[i], plan.touchdown_time[i], t), atol=1e-9)
        assert not np.allclose(plan.touchdown_position[i], targets[i])


@pytest.mark.parametrize("with_normal", [False, True])
def test_foothold_on_a_ramp_lies_on_it_with_the_ramp_normal(with_normal):
    a = math.radians(20.0)  # ramp climbing along +x, rotated 30 deg about z
    yaw = math.radians(30.0)
    d = np.array([math.cos(yaw), math.sin(yaw)])

    def height(x, y):
        return 0.1 + math.tan(a) * (d[0] * x + d[1] * y)

    normal = np.array([-math.sin(a) * d[0], -math.sin(a) * d[1], math.cos(a)])
    terrain = Terrain(height, (lambda x, y: 3.0 * normal) if with_normal else None)
    r = 0.02175
    fh = raibert_foothold([0.4, -0.3], [0.15, 0.05], 1.0, terrain, foot_radius=r)
    x, y = 0.4 + 0.075, -0.3 + 0.025
    np.testing.assert_allclose(fh.point, [x, y, height(x, y)], atol=1e-12)
    np.testing.assert_allclose(fh.normal, normal, atol=1e-8)
    np.testing.assert_allclose(fh.position, fh.point + r * normal, atol=1e-8)
    plane = Terrain.plane(normal, (0.0, 0.0, 0.1))
    assert plane.height(x, y) == pytest.approx(height(x, y))


# ====================================================================== trunk
def integrate_command(cmd, com0, yaw0, t_end):
    """x, y, yaw from dp/dt = R(yaw) v_cmd(t), dyaw/dt = yaw_rate -- by scipy, not the closed form."""
    def f(t, s):
        c, sn = math.cos(s[2]), math.sin(s[2])
        u = cmd.velocity(t)
        return [c * u[0] - sn * u[1], sn * u[0] + c * u[1], cmd.yaw_rate]
    bps = sorted({0.0, t_end} | {b for b in cmd.ramp if 0.0 < b < t_end})
    s = np.array([com0[0], com0[1], yaw0])
    for a, b in zip(bps[:-1], bps[1:]):
        if b > a:
            s = solve_ivp(f, (a, b), s, rtol=1e-11, atol=1e-12).y[:, -1]
    return s


@pytest.mark.parametrize("cmd", [
    VelocityCommand.constant(0.12, 0.03, 0.0),
    VelocityCommand.constant(0.1, -0.02, 0.4),
    VelocityCommand((0.04, 0.0), (0.15, 0.05), (1.0, 6.0), yaw_rate=0.25),
    VelocityCommand((0.0, 0.0), (0.15, 0.0), (2.0, 2.0), yaw_rate=1e-7),  # step, near-zero yaw rate
])
def test_integrating_the_command_reproduces_the_position_reference(cmd):
    com0, yaw0 = np.array([0.1, -0.2, 0.55]), 0.3
    tr = TrunkReference(cmd, com0, yaw0)
    for t_end in (0.5, 3.7, 9.0):
        x, y, yaw = integrate_command(cmd, com0, yaw0, t_end)
        s = tr.evaluate(t_end)
        np.testing.assert_allclose(s.position, [x, y, 0.55], atol=1e-8)
        assert s.yaw == pytest.approx(yaw, abs=1e-9)
    # velocity/acceleration = finite differences of position/velocity (away from ramp corners)
    d = 1e-5
    for t in (0.7, 3.3, 7.9):
        dp = (tr.evaluate(t + d).position - tr.evaluate(t - d).position) / (2 * d)
        np.testing.assert_allclose(tr.evaluate(t).velocity, dp, atol=1e-7)
        dv = (tr.evaluate(t + d).velocity - tr.evaluate(t - d).velocity) / (2 * d)
        np.testing.assert_allclose(tr.evaluate(t).acceleration, dv, atol=1e-6)


def test_speed_ramp_hits_its_end_speed():
    cmd = VelocityCommand.speed_ramp(0.04, 0.15, t_start=1.0, t_end=12.0)
    tr = TrunkReference(cmd, (0, 0, 0.55))
    speed = lambda t: np.linalg.norm(tr.evaluate(t).velocity)  # noqa: E731
    assert speed(0.5) == pytest.approx(0.04)
    assert speed(6.5) == pytest.approx(0.095)
    assert speed(12.0) == pytest.approx(0.15) and speed(30.0) == pytest.approx(0.15)
    assert tr.evaluate(6.5).acceleration[0] == pytest.approx(0.11 / 11.0)
    assert tr.evaluate(13.0).acceleration[0] == 0.0
    # distance = area under the speed profile
    assert tr.evaluate(12.0).position[0] == pytest.approx(0.04 * 1.0 + (0.04 + 0.15) / 2 * 11.0)


def log_rate(tr, t, d=1e-4):
    """World angular velocity from Pinocchio's log map of the relative rotation."""
    Rm, Rp = tr.evaluate(t - d).rotation, tr.evaluate(t + d).rotation
    return tr.evaluate(t).rotation @ pin.log3(Rm.T @ Rp) / (2 * d)


def test_orientation_is_a_proper_rotation_following_yaw_and_terrain():
    a = math.radians(15.0)
    ramp = Terrain(lambda x, y: math.tan(a) * x)  # no normal given: from the height's gradient
    n = np.array([-math.sin(a), 0.0, math.cos(a)])
    cmd = VelocityCommand.constant(0.1, 0.0, 0.3)
    tr = TrunkReference(cmd, (0.0, 0.0, 0.55), yaw0=0.2, terrain=ramp)
    for t in np.linspace(0.0, 6.0, 13):
        s = tr.evaluate(t)
        R = s.rotation
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(R[:, 2], n, atol=1e-7)  # trunk z along the ramp normal
        yaw = pin.rpy.matrixToRpy(R)[2]  # ZYX yaw of the trunk = the integrated heading
        assert abs(math.remainder(yaw - (0.2 + 0.3 * t), 2 * math.pi)) < 1e-9
        assert s.yaw == pytest.approx(0.2 + 0.3 * t)
        # height held above the ramp, its rate = finite difference
        assert s.position[2] - ramp.height(*s.position[:2]) == pytest.approx(0.55)
        if 0.01 < t:
            np.testing.assert_allclose(s.angular_velocity, log_rate(tr, t), atol=1e-6)
            d = 1e-4
            np.testing.assert_allclose(
                s.angular_acceleration,
                (tr.evaluate(t + d).angular_velocity - tr.evaluate(t - d).angular_velocity) / (2 * d),
                atol=1e-4)
            vz = (tr.evaluate(t + d).position[2] - tr.evaluate(t - d).position[2]) / (2 * d)
            assert s.velocity[2] == pytest.approx(vz, abs=1e-7)
    # flat ground: yaw about +z only
    flat = TrunkReference(cmd, (0.0, 0.0, 0.55), yaw0=0.2)
    s = flat.evaluate(2.0)
    np.testing.assert_allclose(s.angular_velocity, [0, 0, 0.3])
    np.testing.assert_allclose(s.rotation, pin.rpy.rpyToMatrix(0, 0, 0.2 + 0.6), atol=1e-12)
    np.testing.assert_allclose(log_rate(flat, 2.0), [0, 0, 0.3], atol=1e-8)


def test_crawl_sway_derivatives_and_targets(hyq):
    fp = Footprint.from_robot(hyq)
    sch = crawl(start=0.6)
    sway = CrawlSway(sch, fp.feet_from_com())
    feet = fp.feet_from_com()
    for leg in sch.legs:  # during a swing the lateral offset is the centroid of the other 3 feet
        i = sch.index(leg)
        sw = [s for s in sch.swings(3.0, 6.0) if s.leg == leg][0]
        o, do, ddo = sway(sw.mid)
        assert o[1] == pytest.approx(np.delete(feet, i, axis=0)[:, 1].mean())
        assert o[0] == 0.0
    cmd = VelocityCommand.constant(0.1, 0.0, 0.2)
    tr = TrunkReference(cmd, (0, 0, 0.55), sway=sway)
    d = 1e-5
    for t in np.linspace(0.05, 6.0, 60):
        dv = (tr.evaluate(t + d).velocity - tr.evaluate(t - d).velocity) / (2 * d)
        np.testing.assert_allclose(tr.evaluate(t).acceleration, dv, atol=2e-5)
        dp = (tr.evaluate(t + d).position - tr.evaluate(t - d).position) / (2 * d)
        np.testing.assert_allclose(tr.evaluate(t).velocity, dp, atol=1e-7)


# ====================================================================== planner
def run(planner, t_end, dt=4e-3):
    return [planner.update(t).copy() for t in np.arange(0.0, t_end, dt)]


def check_swings_land_on_target(planner, plans, terrain):
    """Each swing lands at the touchdown target latched at its lift-off; feet stay above ground."""
    sch = planner.schedule
    n_landed = 0
    for i, leg in enumerate(planner.legs):
        r = planner.footprint.foot_radius[i]
        for k in range(1, len(plans)):
            prev, cur = plans[k - 1], plans[k]
            # the foot sphere never enters the terrain: centre at least r above it along the normal
            p = cur.foot_position[i]
            n = terrain.normal(p[0], p[1])
            assert (p[2] - terrain.height(p[0], p[1])) * n[2] >= r - 1e-9
            assert cur.contact[i] == sch.in_stance(leg, cur.t)
            if prev.contact[i] and not cur.contact[i]:
                assert cur.lifted_off[i]
                target = cur.touchdown_position[i].copy()
                lift_pos = prev.foot_position[i]
            if not prev.contact[i] and cur.contact[i]:
                assert cur.touched_down[i]
                np.testing.assert_allclose(prev.touchdown_position[i], target)  # unchanged in swing
                np.testing.assert_allclose(cur.foot_position[i], target, atol=1e-12)
                # just before touchdown the desired foot is at the target and at rest
                np.testing.assert_allclose(prev.foot_position[i], target, atol=1e-4)
                assert np.linalg.norm(prev.foot_velocity[i]) < 0.02
                # the target is on the terrain, one radius off it along the normal
                pt = target - r * prev.touchdown_normal[i]
                assert pt[2] == pytest.approx(terrain.height(pt[0], pt[1]), abs=1e-9)
                # apex of this swing: clearance above the higher endpoint
                zs = [pl.foot_position[i][2] for pl in plans
                      if not pl.contact[i] and pl.touchdown_time[i] == prev.touchdown_time[i]]
                assert max(zs) == pytest.approx(max(lift_pos[2], target[2]) + planner.clearance,
                                                abs=2e-4)
                n_landed += 1
    return n_landed


def test_planner_crawl_on_hyq_flat(hyq):
    sch = crawl(start=0.6)
    cmd = VelocityCommand((0.0, 0.0), (0.15, 0.0), (0.6, 0.6 + 2 * sch.period))
    planner = GaitPlanner.for_robot(hyq, sch, cmd)
    plans = run(planner, 0.6 + 3 * sch.period)
    assert check_swings_land_on_target(planner, plans, Terrain.flat()) == 12  # 3 cycles x 4 legs
    # the touchdown target is the Raibert foothold on the nominal trunk path (independent recompute)
    fp = Footprint.from_robot(hyq).centered_on_com()  # the planner default
    for pl in plans:
        for i in np.flatnonzero(pl.lifted_off):
            t_td = pl.touchdown_time[i]
            x_nom = planner.trunk.nominal(t_td)
            hip = x_nom[0] + fp.feet_from_com()[i]  # yaw = 0
            expect = hip + x_nom[1] * sch.stance_duration(i) / 2
            np.testing.assert_allclose(pl.touchdown_position[i][:2], expect, atol=1e-12)
    # quasi-static crawl: the CoM reference is inside the support triangle of every swing
    margins = [triangle_margin(pl.foot_position[pl.contact][:, :2], pl.trunk.position[:2])
               for pl in plans if pl.contact.sum() == 3]
    assert min(margins) > 0.02
    # the trunk moved forward by about the integrated command
    assert plans[-1].trunk.position[0] - plans[0].trunk.position[0] == pytest.approx(
        0.15 * (len(plans) * 4e-3 - 0.6) - 0.15 * sch.period, abs=0.02)


def test_trunk_reference_waits_for_the_gait(hyq):
    """A command that already asks for speed before the gait starts moves the trunk only once the
    legs step: until then the feet stand still and the CoM reference stays over them."""
    sch = trot(start=1.0)
    planner = GaitPlanner.for_robot(hyq, sch, VelocityCommand.constant(0.1))
    x0 = planner.trunk.nominal(0.0)[0]
    for t in (0.5, 0.999):
        xy, v, *_ = planner.trunk.nominal(t)
        np.testing.assert_array_equal(xy, x0)
        assert np.all(v == 0.0)
    xy, v, *_ = planner.trunk.nominal(1.5)
    np.testing.assert_allclose(xy - x0, [0.05, 0.0], atol=1e-12)  # 0.1 m/s for 0.5 s
    np.testing.assert_allclose(v, [0.1, 0.0], atol=1e-12)


def test_planned_crawl_is_reachable_by_hyq(hyq):
    """At lift-off, mid-swing and touchdown instants of a 0.15 m/s crawl, inverse kinematics with the
    base on the trunk reference reaches all four planned feet within HyQ's joint limits."""
    sch = crawl(start=0.6)
    planner = GaitPlanner.for_robot(hyq, sch, VelocityCommand.constant(0.15))
    fp = Footprint.from_robot(hyq)
    model, data = hyq.model, hyq.model.createData()
    ids = [hyq.contact(leg).frame_id for leg in planner.legs]
    q = hyq.q_ref.copy()
    times = sorted({t for sw in sch.swings(3.0, 3.0 + sch.period)
                    for t in (sw.liftoff + 1e-6, sw.mid, sw.touchdown - 1e-6)})
    for t in times:
        pl = planner.update(t)
        R = pl.trunk.rotation
        q[:3] = pl.trunk.position - R @ fp.com
        q[3:7] = pin.Quaternion(R).coeffs()
        for _ in range(30):  # Gauss-Newton on the 12 joints, base fixed
            pin.framesForwardKinematics(model, data, q)
            err = np.concatenate([pl.foot_position[i] - data.oMf[f].translation
                                  for i, f in enumerate(ids)])
            if np.linalg.norm(err) < 1e-9:
                break
            J = np.vstack([pin.computeFrameJacobian(model, data, q, f, pin.LOCAL_WORLD_ALIGNED)[:3, 6:]
                           for f in ids])
            q[7:] += np.linalg.solve(J, err)
        assert np.linalg.norm(err) < 1e-6, f"t={t}: feet unreachable ({np.linalg.norm(err):.3g} m)"
        assert np.all(q[7:] > hyq.q_min) and np.all(q[7:] < hyq.q_max), f"t={t}: joint limit"


def test_planner_crawl_up_a_ramp(hyq):
    a = math.radians(12.0)
    terrain = Terrain(lambda x, y: math.tan(a) * x)
    fp = Footprint.from_robot(hyq)
    sch = crawl(start=0.6, legs=hyq.contact_names)  # the constructor takes the footprint's legs
    com0 = hyq.q_ref[:3] + fp.com
    com0[2] += terrain.height(com0[0], com0[1])
    trunk = TrunkReference(VelocityCommand.constant(0.1), com0, terrain=terrain,
                           sway=CrawlSway(sch, fp.feet_from_com()))
    planner = GaitPlanner(sch, trunk, fp, terrain, clearance=0.08)
    plans = run(planner, 0.6 + 2 * sch.period)
    assert check_swings_land_on_target(planner, plans, terrain) == 8
    n = np.array([-math.sin(a), 0.0, math.cos(a)])
    for pl in plans[::25]:
        np.testing.assert_allclose(pl.touchdown_normal, np.tile(n, (4, 1)), atol=1e-7)
        np.testing.assert_allclose(pl.trunk.rotation[:, 2], n, atol=1e-7)


def test_planner_trot_and_interface(hyq):
    sch = trot(start=0.2)
    planner = GaitPlanner.for_robot(hyq, sch, VelocityCommand.constant(0.3, 0.0, 0.2))
    assert planner.trunk.sway is None  # no quasi-static sway in a trot
    plans = run(planner, 0.2 + 3 * sch.period, dt=2e-3)
    assert check_swings_land_on_target(planner, plans, Terrain.flat()) == 12
    for pl in plans:
        assert pl.contact[0] == pl.contact[3] and pl.contact[1] == pl.contact[2]
        assert pl.contact.sum() in (2, 4)
        np.testing.assert_allclose(pl.foot_velocity[pl.contact], 0.0)
    # the returned state is reused (no per-call allocation); copies are independent
    a = planner.update(2.7)
    b = planner.update(2.8)
    assert a is b and a.trunk is b.trunk
    with pytest.raises(ValueError, match="decrease"):
        planner.update(2.75)
    # measured feet at lift-off become the swing start; at touchdown, the stance anchor
    planner.reset(3.0)
    feet = plans[0].foot_position + [0.01, -0.02, 0.0]
    swung = None
    for t in np.arange(3.0, 3.0 + sch.period, 2e-3):
        pl = planner.update(t, feet=feet)
        for i in np.flatnonzero(pl.lifted_off):
            swung = i
            np.testing.assert_allclose(pl.foot_position[i], feet[i], atol=5e-3)
        for i in np.flatnonzero(pl.touched_down):
            np.testing.assert_allclose(pl.foot_position[i], feet[i])
    assert swung is not None


def test_planner_output_does_not_depend_on_the_call_rate(hyq):
    """Calls every 4 ms and calls once every 0.7 s (skipping whole swings) agree where they meet."""
    sch = crawl(start=0.6)
    cmd = VelocityCommand.constant(0.12, 0.02, 0.1)
    dense = GaitPlanner.for_robot(hyq, sch, cmd)
    sparse = GaitPlanner.for_robot(hyq, sch, cmd)
    checks = {round(t, 6) for t in np.arange(0.0, 9.0, 0.7)}
    for t in np.arange(0.0, 9.0, 4e-3):
        a = dense.update(t)
        if round(t, 6) in checks:
            b = sparse.update(t)
            np.testing.assert_array_equal(a.contact, b.contact)
            np.testing.assert_allclose(a.foot_position, b.foot_position, atol=1e-12)
            np.testing.assert_allclose(a.foot_velocity, b.foot_velocity, atol=1e-12)
            np.testing.assert_allclose(a.touchdown_position, b.touchdown_position, atol=1e-12)
            np.testing.assert_allclose(a.trunk.position, b.trunk.position, atol=1e-12)
    snapshot = a.copy()
    dense.update(9.5)
    assert snapshot.t != dense.state.t and snapshot.foot_position is not dense.state.foot_position


@pytest.mark.parametrize("t", [math.nan, math.inf])
def test_planner_rejects_a_time_that_is_not_finite(hyq, t):
    planner = GaitPlanner.for_robot(hyq, trot(start=0.2), VelocityCommand.constant(0.3))
    with pytest.raises(ValueError, match="t: expected a finite time"):
        planner.update(t)


def polygon_margin(poly, p):
    """Signed distance from p to the nearest edge of the convex polygon poly (k x 2); > 0 inside."""
    centre = poly.mean(axis=0)
    out = math.inf
    for k in range(len(poly)):
        a, b = poly[k], poly[(k + 1) % len(poly)]
        n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
        out = min(out, (n if n @ (centre - a) > 0 else -n) @ (p - a))
    return out


def _line_offset(p, a, b):
    """Signed distance of p from the line through a and b, and where along a -> b p projects
    (0 at a, 1 at b)."""
    d = b - a
    n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
    return float(n @ (p - a)), float(d @ (p - a) / (d @ d))


@pytest.mark.parametrize("name", ["go1", "hyq"])
def test_trot_start_puts_the_com_reference_on_the_first_support_line(name):
    """Go1's CoM stands 3 cm behind its feet's centroid, HyQ's 4 cm ahead: the nominal CoM is off
    the line of the first two stance feet, about which two point feet can make no moment. With
    the start shift the CoM reference stands on that line for the whole first stance (feet from
    Pinocchio's forward kinematics of the standing posture), reaches it inside the four feet, and
    rejoins the unshifted reference after the second hand-over; the footholds are unchanged."""
    robot = wb.load_robot(name)
    h = float(robot.q_ref[2])
    sch = trot(0.8 * math.sqrt(h / 0.599), start=1.0, legs=robot.contact_names)
    cmd = VelocityCommand.speed_ramp(0.05, 0.1, 1.0, 3.0)
    shifted = GaitPlanner.for_robot(robot, sch, cmd)
    plain = GaitPlanner.for_robot(robot, sch, cmd, start_shift=False)
    assert shifted.trunk.start_shift is not None and plain.trunk.start_shift is None
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    feet = np.array([data.oMf[robot.contact(n).frame_id].translation[:2]
                     for n in robot.contact_names])
    hull = feet[[0, 1, 3, 2]]  # LF, RF, RH, LH around the body
    first = [i for i in range(4) if sch.in_stance(i, 1.0)]  # RF and LH: the first support
    t1, t_td, t_h2 = 1.0, 1.0 + 0.5 * sch.period, 1.0 + 1.25 * sch.period
    with_shift, without = [], []
    for t in np.arange(0.0, 1.0 + 4 * sch.period, 2e-3):
        a, b = shifted.update(t).copy(), plain.update(t).copy()
        np.testing.assert_allclose(a.touchdown_position, b.touchdown_position, atol=1e-12)
        np.testing.assert_array_equal(a.contact, b.contact)
        p = a.trunk.position[:2]
        if t < t1:  # four feet: the reference inside their quadrilateral
            assert polygon_margin(hull, p) > 0.05 * h
        elif t < t_td:  # the first two-foot stance
            off, along = _line_offset(p, feet[first[0]], feet[first[1]])
            with_shift.append(abs(off))
            without.append(abs(_line_offset(b.trunk.position[:2], *feet[first])[0]))
            assert 0.2 < along < 0.8
        elif t > t_h2 + 1e-9:
            np.testing.assert_allclose(a.trunk.position, b.trunk.position, atol=1e-12)
            np.testing.assert_allclose(a.trunk.velocity, b.trunk.velocity, atol=1e-12)
    assert without[0] > 0.04 * h  # the problem: at lift-off the nominal CoM is off the support line
    assert max(with_shift) < 0.008 * h  # the fix: on it, within a few mm


def test_start_shift_is_smooth_and_only_for_two_foot_supports(hyq):
    sch = trot(start=1.0)
    planner = GaitPlanner.for_robot(hyq, sch, VelocityCommand.constant(0.1))
    shift = planner.trunk.start_shift
    ts = np.linspace(shift.times[0] - 0.05, shift.end + 0.05, 400)
    d = 1e-5
    for t in ts:  # derivatives by central differences; C1 offsets (C2: the acceleration too)
        o, do, ddo = shift(t)
        np.testing.assert_allclose((shift(t + d)[0] - shift(t - d)[0]) / (2 * d), do, atol=1e-6)
        np.testing.assert_allclose((shift(t + d)[1] - shift(t - d)[1]) / (2 * d), ddo, atol=1e-4)
    np.testing.assert_allclose(shift(shift.times[0] - 1.0)[0], 0.0)
    np.testing.assert_allclose(shift(shift.end + 1.0)[0], 0.0)
    # a crawl has its sway and no start shift; a crawl never stands on two feet
    assert GaitPlanner.for_robot(hyq, crawl(start=1.0)).trunk.start_shift is None
    assert GaitPlanner.for_robot(hyq, crawl(start=1.0), sway=None).start_shift() is None
    assert GaitPlanner.for_robot(hyq, stand()).trunk.start_shift is None
