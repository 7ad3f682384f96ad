"""Terrain courses, unstable foothold and passivity measurement on HyQ (Fahmi et al. 2019, Sects.
III, V-F to V-H): course geometry (simulator vs planner), gap-aware footholds, storage-function
bookkeeping, and short closed-loop runs judged on simulator measurements."""

import logging
import math

import numpy as np
import pinocchio as pin
import pytest
from conftest import ray_height

from wholebody.control.passivity import (StorageMeter, SwingFeedForwardOff,
                                         desired_generalized_velocity)
from wholebody.planning.courses import CoursePlanner, build_course, gap_course, ramp_course
from wholebody.planning.planner import GaitPlanner
from wholebody.planning.trunk import VelocityCommand
from wholebody.scenarios import get_scenario
from wholebody.scenarios.locomotion import course_environment, make_schedule, run_gait
from wholebody.scenarios.passivity import energy_balance, summarize
from wholebody.scenarios.unstable_foothold import environment as stone_environment
from wholebody.scenarios.unstable_foothold import stone_site, walk
from wholebody.sim.simulator import Simulator
from wholebody.tasks.wrench import TrunkImpedance


@pytest.fixture(scope="module")
def hyq(robots):
    return robots["hyq"]


@pytest.fixture(autouse=True)
def _quiet():
    logging.disable(logging.WARNING)
    yield
    logging.disable(logging.NOTSET)


# ---------------------------------------------------------------- courses (no closed loop)
@pytest.mark.parametrize("course", [ramp_course(15.0), gap_course(0.22, 0.07),
                                    build_course([("slope", 0.5, 0.2), ("step", -0.05),
                                                  ("flat", 0.3), ("gap", 0.1),
                                                  ("slope", 0.4, -0.3)])])
def test_simulator_surface_is_the_planner_terrain(hyq, course):
    """Ray casts onto the twin's boxes give the planner's height everywhere (holes: no hit), and
    the planner's normal is the slope of the simulated surface."""
    sim = Simulator(hyq, course_environment(course))
    for x in np.linspace(-1.5, 6.0, 301):
        for y in (-0.7, 0.3):
            z = ray_height(sim, x, y)
            if any(abs(x - e) < 1e-3 for s in course.strips for e in (s.x0, s.x1)):
                continue  # on an edge between strips
            if course.in_gap(x):  # a hole: nothing within 5 cm of the edges' level
                a, b = next(g for g in course.gaps if g[0] <= x <= g[1])
                edge = min(course.height(a - 1e-6), course.height(b + 1e-6))
                assert z < edge - 0.05, f"x={x}: something under the gap"
            else:
                assert z == pytest.approx(course.terrain.height(x, y), abs=1e-6), x
                h = 1e-3
                if not course.in_gap(x, 2 * h) and all(abs(x - s.x0) > 2 * h for s in course.strips):
                    slope = (ray_height(sim, x + h, y) - ray_height(sim, x - h, y)) / (2 * h)
                    n = course.terrain.normal(x, y)
                    assert -n[0] / n[2] == pytest.approx(slope, abs=1e-6)


def test_trunk_terrain_is_continuous_and_exact_away_from_features():
    course = ramp_course(15.0, up=1.6, top=1.2, down=1.6, x_start=0.8)
    w = course.smoothing
    xs = np.arange(-1.0, 7.0, 1e-3)
    h = np.array([course.trunk_terrain.height(x, 0.0) for x in xs])
    assert np.max(np.abs(np.diff(h))) < 1e-3 * math.tan(math.radians(15.0)) + 1e-9  # no jumps
    for x in (0.0, 0.8 + 0.8, 0.8 + 1.6 + 0.6, 0.8 + 1.6 + 1.2 + 0.8, 6.5):
        assert course.smooth_height(x) == pytest.approx(course.height(x), abs=1e-9)
        assert course.smooth_slope(x) == pytest.approx(course.slope(x), abs=1e-9)
    # numerical derivative of the smoothed height is the closed-form smoothed slope
    for x in np.linspace(0.3, 5.5, 27):
        fd = (course.smooth_height(x + 1e-5) - course.smooth_height(x - 1e-5)) / 2e-5
        assert fd == pytest.approx(course.smooth_slope(x), abs=1e-5)
    # gaps are bridged for the trunk: no dip over a hole
    gap = gap_course(0.22, 0.07)
    assert min(gap.smooth_height(x) for x in np.linspace(0.5, 1.2, 71)) >= -1e-12
    assert w > 0


def test_course_planner_keeps_footholds_out_of_the_gap(hyq):
    course = gap_course(0.22, 0.07, x_start=0.7)
    command = VelocityCommand.speed_ramp(0.0, 0.1, 1.0, 3.0)
    planner = CoursePlanner.on_course(hyq, make_schedule(hyq, "crawl", 1.0), command, course)
    plain = GaitPlanner.for_robot(hyq, make_schedule(hyq, "crawl", 1.0), command, course.terrain)
    a, b = course.gaps[0]
    in_gap = moved = 0
    for leg in planner.legs:
        for k in range(8):
            t_td = planner.schedule.touchdown_time(leg, k)
            raw = plain.touchdown_target(leg, t_td).point
            fh = planner.touchdown_target(leg, t_td)
            in_gap += a <= raw[0] <= b
            moved += not np.allclose(raw, fh.point)
            assert not (a - planner.gap_margin + 1e-9 < fh.point[0] < b + planner.gap_margin - 1e-9)
            assert fh.point[2] == pytest.approx(course.height(fh.point[0]))
            assert np.allclose(fh.position, fh.point + hyq.contacts[0].spec.radius * fh.normal)
    assert in_gap > 0, "the test needs raw Raibert targets that land in the gap"
    assert moved >= in_gap


# ---------------------------------------------------------------- closed loop: terrain
def test_trot_climbs_a_15_degree_ramp_with_roll_pitch_error_below_0_2_rad(hyq):
    """Fig. 8 / Sect. V-H: the robot really climbs (simulator base and front feet rise) while the
    simulator's roll and pitch stay within 0.2 rad of the reference."""
    course = ramp_course(15.0, up=1.6, top=1.0, down=1.6, x_start=0.5)
    command = VelocityCommand.speed_ramp(0.0, 0.15, 1.0, 3.0)
    planner = CoursePlanner.on_course(hyq, make_schedule(hyq, "trot", 1.0), command, course)
    rpy = []

    def record(t, result, ctrl, sim):
        q, _ = sim.state()
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        rpy.append((pin.rpy.matrixToRpy(np.asarray(ctrl.last_plan.trunk.rotation)),
                    pin.rpy.matrixToRpy(R)))

    run = run_gait(hyq, "passive", duration=8.0, environment=course_environment(course),
                   planner=planner, on_cycle=record)
    q, _ = run.sim.state()
    assert not run.fell and run.failures == 0
    desired, actual = np.array([r[0] for r in rpy]), np.array([r[1] for r in rpy])
    err = np.abs(desired - actual)[:, :2]
    assert err.max() < 0.2
    assert desired[:, 1].min() < -0.15  # the reference did pitch up the ramp
    front = run.log["feet"][-1, :2]
    assert np.all(front[:, 2] > 0.12)  # simulator: front feet up on the ramp
    assert q[2] > run.sim.log.q[0][2] + 0.08  # the base rose


def test_crawl_front_legs_cross_the_gap_onto_the_step(hyq):
    """Fig. 7: the front feet cross a 22 cm gap onto a 7 cm step; no foot ever goes down into the
    hole (simulator foot heights) and the planner had to move footholds out of the gap."""
    course = gap_course(0.22, 0.07, x_start=0.5)
    command = VelocityCommand.speed_ramp(0.0, 0.1, 1.0, 3.0)
    planner = CoursePlanner.on_course(hyq, make_schedule(hyq, "crawl", 1.0), command, course)
    run = run_gait(hyq, "passive", duration=9.0, environment=course_environment(course),
                   planner=planner)
    assert not run.fell and run.failures == 0
    a, b = course.gaps[0]
    feet = run.log["feet"]
    r = hyq.contacts[0].spec.radius
    over = (feet[:, :, 0] > a) & (feet[:, :, 0] < b)
    assert np.any(over)
    assert feet[:, :, 2][over].min() > r - 0.01  # never below the edges' level over the hole
    final = feet[-1]
    assert np.all(final[:2, 0] > b + 0.03)  # LF, RF past the gap...
    assert np.allclose(final[:2, 2], 0.07 + r, atol=0.01)  # ...standing on the step
    assert planner.adjusted >= 1


# ---------------------------------------------------------------- closed loop: unstable foothold
def _uf_params(robot, **over):
    """The scenario's parameters for ``robot`` (robot-relative defaults resolved), with ``over``."""
    return get_scenario("unstable-foothold").validate(robot, {k: str(v) for k, v in over.items()})


def test_still_stone_does_not_move(hyq):
    p = _uf_params(hyq)
    env = stone_environment(np.array([0.8, -0.3, 0.0]), p, moving=False)
    for t in (0.0, 6.5, 7.0, 20.0):
        pos, rpy = env.platform.motion(t)
        assert np.allclose(pos, 0) and np.allclose(rpy, 0)
    assert env.support_height() == 0.0


def test_stone_rolls_away_under_rf_foot_and_robot_keeps_walking(hyq):
    """Fig. 6: the stone under the RF foot (where the planner put it) goes at 6.5 s; in the
    simulator the RF foot drops into the pit and unloads, the robot keeps walking without falling
    and its horizontal CoM stays within 3 cm of the reference."""
    p = _uf_params(hyq, duration=8.0)
    point, t_td = stone_site(hyq, p)
    run, _, _ = walk(hyq, p, moving=True)
    leg = hyq.contact_names.index("rf_foot")
    t = run.log["t"]
    feet = run.log["feet"]
    on_stone = (t > t_td + 0.2) & (t < 6.5)
    assert np.linalg.norm(feet[on_stone, leg, :2].mean(axis=0) - point[:2]) < 0.5 * p["size"]
    z0 = feet[on_stone, leg, 2].mean()
    after = (t > 6.5 + p["roll_time"]) & (t < 7.8)
    assert z0 - feet[after, leg, 2].max() > 0.04  # dropped into the pit (6 cm)
    sim = run.sim.log.arrays()
    rolling = (sim["t"] > 6.5) & (sim["t"] < 6.5 + p["roll_time"])
    assert sim["contact_wrenches"][rolling, leg, 2].min() < 20.0  # the foothold gave way
    assert not run.fell and run.failures == 0
    assert run.distance > 0.45
    sel = t >= 6.5
    assert np.linalg.norm(run.log["com_error"][sel, :2], axis=1).max() < 0.03


# ---------------------------------------------------------------- passivity (Sect. III)
def test_desired_generalized_velocity_realises_the_desired_task_velocities(hyq, rng):
    planner = GaitPlanner.for_robot(hyq, make_schedule(hyq, "trot", 0.0),
                                    VelocityCommand.constant(0.2))
    plan = planner.update(0.2).copy()  # LF, RH swinging
    assert plan.contact.tolist() == [False, True, True, False]
    q = hyq.q_ref.copy()
    q[7:] += rng.normal(scale=0.05, size=hyq.na)
    hyq.update(q, rng.normal(scale=0.3, size=hyq.nv))
    nu, residual = desired_generalized_velocity(hyq, plan, planner.legs)
    assert residual < 1e-10
    R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
    assert np.allclose(hyq.J_com @ nu, plan.trunk.velocity)
    assert np.allclose(R @ nu[3:6], plan.trunk.angular_velocity)
    for i, name in enumerate(planner.legs):
        if plan.contact[i]:
            assert np.allclose(hyq.contact_jacobians[name] @ nu, 0.0, atol=1e-10)
        else:
            J = hyq.frame_jacobian(hyq.contact(name).frame)[:3]
            assert np.allclose(J @ nu, plan.foot_velocity[i])


def test_swing_feedforward_off_wrapper_only_zeroes_the_acceleration(hyq):
    inner = GaitPlanner.for_robot(hyq, make_schedule(hyq, "trot", 0.0), VelocityCommand.constant(0.2))
    twin = GaitPlanner.for_robot(hyq, make_schedule(hyq, "trot", 0.0), VelocityCommand.constant(0.2))
    wrapped = SwingFeedForwardOff(inner)
    assert wrapped.legs == inner.legs
    nonzero = 0
    for t in (0.05, 0.1, 0.2, 0.3):
        a, b = wrapped.update(t), twin.update(t)
        assert np.all(a.foot_acceleration == 0.0)
        nonzero += np.any(np.abs(b.foot_acceleration) > 1e-3)
        assert np.allclose(a.foot_position, b.foot_position)
        assert np.allclose(a.foot_velocity, b.foot_velocity)
    assert nonzero >= 2  # the unwrapped plan does carry a swing feed-forward


def test_storage_function_bookkeeping_in_closed_loop(hyq):
    """Crawl with the feed-forward terms off: the finite-difference rate of the recorded storage
    function matches its analytic rate Δv_comᵀ∇V_com + Δv_swᵀ∇V_sw (so V is what eq. 23 says),
    and the supply is integrated over every WBC interval from the simulator's log."""
    impedance = TrunkImpedance(feedforward=False)
    planner = SwingFeedForwardOff(GaitPlanner.for_robot(
        hyq, make_schedule(hyq, "crawl", 1.0), VelocityCommand.speed_ramp(0.0, 0.1, 1.0, 3.0)))
    meter = StorageMeter(hyq, impedance, 2000.0, 20.0)
    run = run_gait(hyq, "passive", duration=3.5, planner=planner, on_cycle=meter,
                   controller_options={"impedance": impedance})
    assert not run.fell and run.failures == 0
    storage = meter.log.arrays()
    assert np.any(storage["V_swing"] > 0)  # a swing happened and was accounted
    assert np.all(storage["solve_residual"] < 1e-8)
    balance = energy_balance(storage, run.sim.log.arrays())
    stats = summarize(balance, t_from=0.5)
    assert stats["rate_check_rel_rms"] < 0.1
    # intervals are judged on the simulator's 1 kHz torques: one WBC interval = 4 simulator steps
    assert np.allclose(balance["dt"], 0.004)
    assert np.all(np.isfinite(balance["supply"][:-1]))
