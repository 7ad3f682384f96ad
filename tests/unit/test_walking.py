"""The walking controller's geometry and feedback, against independent evidence: the support
polygon's nearest point against SLSQP over convex combinations of the soles' corners, the DCM
feedback against the DCM law it implements (Englsberger et al. 2015), the step adjustment against
the LIPM's closed-form divergence of the capture point."""

import math

import numpy as np
import pytest
from scipy.optimize import minimize

import wholebody as wb
from wholebody.control.walking import SupportPolygon, Walking


@pytest.fixture(scope="module")
def walking():
    robot = wb.load_robot("talos14")
    return Walking(robot, engine="python")


def _nearest_by_slsqp(points, p):
    n = len(points)
    res = minimize(lambda w: np.sum((w @ points - p) ** 2), np.full(n, 1.0 / n), method="SLSQP",
                   bounds=[(0.0, 1.0)] * n,
                   constraints={"type": "eq", "fun": lambda w: np.sum(w) - 1.0},
                   options={"ftol": 1e-14, "maxiter": 500})
    return res.x @ points


def test_support_polygon_projection_is_the_nearest_point_of_the_hull():
    rng = np.random.default_rng(3)
    for _ in range(30):
        corners = rng.uniform(-0.3, 0.3, size=(8, 2))
        poly = SupportPolygon(corners)
        p = rng.uniform(-0.6, 0.6, size=2)
        expected = _nearest_by_slsqp(corners, p)
        assert np.allclose(poly.project(p), expected, atol=1e-6)
        assert poly.contains(poly.project(p) + 1e-9 * (expected - p)) or poly.contains(expected)


def test_support_polygon_contains_what_a_triangulation_of_the_hull_contains():
    """contains() against scipy's Delaunay triangulation of the corners (an independent test of
    the convex hull) for points off the boundary; points on an edge are in, points 1e-6 outside
    an edge (along its outward normal) are not."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(5)
    for _ in range(30):
        corners = rng.uniform(-0.3, 0.3, size=(int(rng.integers(3, 9)), 2))
        poly, hull = SupportPolygon(corners), Delaunay(corners)
        for p in rng.uniform(-0.5, 0.5, size=(200, 2)):
            d = p - poly.vertices
            cross = poly.edges[:, 0] * d[:, 1] - poly.edges[:, 1] * d[:, 0]
            edge = np.abs(cross) / np.linalg.norm(poly.edges, axis=1)  # distance to each line
            if edge.min() > 1e-9:
                assert poly.contains(p) == (hull.find_simplex(p) >= 0)
        for k in range(len(poly.vertices)):
            on = poly.vertices[k] + rng.uniform(0.0, 1.0) * poly.edges[k]
            assert poly.contains(on)
            normal = poly.normals[k] / np.linalg.norm(poly.normals[k])
            assert not poly.contains(on + 1e-6 * normal)


def test_feedback_is_the_dcm_law_inside_the_support(walking):
    """Inside the support, c'' makes xi' = xi_ref' - k (xi - xi_ref) with xi = c + c'/omega."""
    w, k = walking.omega, walking.config.dcm_gain * walking.omega
    ph = walking.phase
    rng = np.random.default_rng(0)
    for _ in range(10):
        c_ref = np.r_[rng.uniform(-0.01, 0.01, 2), 0.8]
        v_ref, a_ref = np.r_[rng.uniform(-0.02, 0.02, 2), 0.0], np.r_[rng.uniform(-0.05, 0.05, 2), 0]
        c = c_ref + np.r_[rng.uniform(-0.003, 0.003, 2), 0.0]
        v = v_ref + np.r_[rng.uniform(-0.01, 0.01, 2), 0.0]
        a = walking._horizontal_acceleration(ph, c_ref, v_ref, a_ref, c, v)
        xi, xi_ref = c[:2] + v[:2] / w, c_ref[:2] + v_ref[:2] / w
        xi_dot = v[:2] + a / w
        xi_ref_dot = v_ref[:2] + a_ref[:2] / w
        assert np.allclose(xi_dot, xi_ref_dot - k * (xi - xi_ref), atol=1e-12)


def test_feedback_zmp_stays_in_the_support(walking):
    ph = walking.phase
    c = np.r_[walking.com_ref[:2], walking.com_ref[2]]
    far = c + np.r_[1.0, 0.5, 0.0]  # a reference a metre away: a ZMP far outside the soles
    a = walking._horizontal_acceleration(ph, far, np.zeros(3), np.zeros(3), c, np.zeros(3))
    zmp = c[:2] - a / walking.omega ** 2
    assert walking.support(walking.soles, walking.config.cop_margin).contains(zmp + 0.0)


def test_step_adjustment_moves_the_footstep_by_the_predicted_dcm_error():
    """A capture-point error e in single support, tau before touchdown, moves the footstep by
    e^(omega tau) e (the LIPM with the ZMP on the stance sole), within the leg's reach."""
    robot = wb.load_robot("talos14")
    ctrl = Walking(robot, engine="python")
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    ctrl.set_command(0.2, 0.0, 0.0)
    t = 0.0
    while ctrl.phase.kind != "single":
        ctrl.compute(q, v, t)
        t += 0.001
    ph = ctrl.phase
    t_adjust = ph.start + 0.1
    xi_ref = ctrl.plan.dcm(t_adjust)[0]
    error = np.array([0.004, -0.003])
    ctrl._adjust_step(t_adjust, ph, xi_ref + error)
    tau = ph.end - t_adjust
    # the plan predicts its own DCM at touchdown: only the error moves the planned footstep
    shift = ctrl.swing.p1[:2] - ph.footstep.position[:2]
    assert np.allclose(shift, math.exp(ctrl.omega * tau) * error, atol=2e-4)


def test_in_double_support_the_soles_forces_put_the_cop_at_the_commanded_zmp():
    """The weight shifts of a walk's start in the twin (1.3 s): the CoP of the soles' solved
    wrenches (from the solution's forces and moments, about the soles' frames) lies where the
    commanded ZMP does along the line between the soles, to 2 cm of the 17-28 cm between them
    (the regulariser splits the normal forces; the soles' tilting moments, which the hierarchy
    leaves to its lighter rows, move the CoP by the rest), and the leaving sole carries less than 2 % of the weight at the double support's
    end (lift-off)."""
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot("talos14")
    ctrl, sim = Walking(robot), Simulator(robot)
    ctrl.set_command(0.2, 0.0, 0.0)
    weight = robot.mass * 9.81
    checked = 0
    while sim.t < 1.3:
        q, v = sim.state()
        sol = ctrl.compute(q, v, sim.t)
        ph = ctrl.phase
        if ph.kind == "double" and ph.leaving is not None:
            if sim.t + sim.dt >= ph.end:
                assert sol.forces[ph.leaving][2] < 0.02 * weight, sim.t
            robot.update(q, v)
            fz, cop = 0.0, np.zeros(2)
            for sole, w in sol.forces.items():
                p = robot.frame_placement(robot.contact(sole).frame)[0]
                fz += w[2]
                cop += p[:2] * w[2] + np.array([-w[4], w[3]])
            cop /= fz
            a, b = ctrl.feet[ph.leaving][0][:2], ctrl.feet[ctrl._other(ph.leaving)][0][:2]
            d = (a - b) / np.linalg.norm(a - b)
            assert (cop - b) @ d == pytest.approx((ctrl.zmp_command - b) @ d, abs=2e-2), sim.t
            checked += 1
        sim.step(sol.tau)
    assert checked > 500


def test_the_weight_is_handed_over_continuously_at_touchdown_and_lift_off():
    """Side-steps in the twin (the commanded ZMP leaves the soles' centres most): at every touchdown (the first double-support cycle) the leaving
    sole still carries the stance's whole wrench — at least 99 % of the soles' normal force and
    the landed sole at most 1 % of the weight in any force component (a ZMP-proportional split
    handed it 4 % at once when the ZMP stood off the stance sole's centre) — and in the last cycle
    before its lift-off at most 2 % of the weight, tangential forces included; so no wrench
    jumps from one sole to the other at a contact switch (the solution's forces, not the
    controller's targets)."""
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot("talos14")
    ctrl, sim = Walking(robot), Simulator(robot)
    ctrl.set_command(0.0, 0.12, 0.0)
    weight = robot.mass * 9.81
    touchdowns = lift_offs = 0
    previous = None
    while sim.t < 3.4:
        q, v = sim.state()
        sol = ctrl.compute(q, v, sim.t)
        ph = ctrl.phase
        if ph.kind == "double" and ph.leaving is not None and ph.stance is not None:
            leaving, landed = sol.forces[ph.leaving], sol.forces[ph.stance]
            if previous == "single":
                total = leaving[2] + landed[2]
                assert leaving[2] >= 0.99 * total, sim.t
                assert np.abs(landed[:3]).max() <= 0.01 * weight, sim.t
                touchdowns += 1
            if sim.t + sim.dt >= ph.end:
                assert np.abs(leaving[:3]).max() <= 0.02 * weight, sim.t
                lift_offs += 1
        previous = ph.kind
        sim.step(sol.tau)
    assert touchdowns >= 2 and lift_offs >= 3


@pytest.mark.parametrize("turn, yaw_rate, side, lateral",
                         [(90.0, 0.35, 1.0, 0.12), (-45.0, 0.5, -0.3, 0.1), (30.0, 2.0, 0.01, 1.0)])
def test_the_walk_schedule_turns_and_side_steps_exactly_in_whole_step_periods(
        turn, yaw_rate, side, lateral):
    """The controller reads its command once a step: the turn and the side-step of the ``walk``
    schedule last whole step periods (at least one), at a rate within half a period's worth of
    the asked one, and the command integrated over them (a rectangle rule at 0.1 ms, apart
    from the schedule's own integration) gives the asked heading change and distance."""
    from wholebody.scenarios import get_scenario
    from wholebody.scenarios.walking_runs import schedule, step_period

    robot = wb.load_robot("talos14")
    params = get_scenario("walk").validate(robot, {"turn": turn, "yaw_rate": yaw_rate,
                                                   "side_distance": side, "lateral": lateral})
    period = step_period(robot, params)
    parts = {p.name: p for p in schedule(robot, params)}
    for name, amount, rate, axis in (("turn", math.radians(turn), yaw_rate, 2),
                                     ("side", side, lateral, 1)):
        part = parts[name]
        n = (part.end - part.start) / period
        assert n >= 1.0 - 1e-9 and abs(n - round(n)) < 1e-9
        asked = abs(amount) / rate
        assert abs(part.end - part.start - asked) <= 0.5 * period + 1e-9 or round(n) == 1
        samples = round((part.end - part.start) / 1e-4)
        dt = (part.end - part.start) / samples
        t = part.start + (np.arange(samples) + 0.5) * dt
        assert sum(part.command(x)[axis] for x in t) * dt == pytest.approx(amount, rel=1e-6)


def test_a_replan_from_a_dcm_the_first_knot_cannot_reach_starts_at_it():
    """A re-plan from a measured DCM so far ahead that the knot halfway through the first double
    support would leave the soles: that knot is held inside them, and the plan still starts at
    the measured DCM (the plan's DCM at t, the LIPM's closed form, equals it) by moving the next
    knot — where single support starts — which stays inside the stance sole."""
    from wholebody.planning.footsteps import Footstep

    robot = wb.load_robot("talos14")
    ctrl = Walking(robot, engine="python")
    stance, swing = ctrl.soles
    com = np.r_[ctrl._support_center(), robot.com[2]]
    stance_xy = ctrl.feet[stance][0][:2]
    step = Footstep(swing, ctrl.feet[swing][0] + np.r_[0.2, 0.0, 0.0], 0.0)
    soles = ctrl.support(ctrl.soles, ctrl.config.cop_margin)
    sole = ctrl.support([stance], ctrl.config.cop_margin)
    t, moved = 3.0, 0
    for ahead in np.linspace(0.0, 0.06, 13):  # the measured DCM, ahead of the stance sole
        dcm = np.r_[stance_xy + np.r_[ahead, 0.0], com[2]]
        ctrl.zmp_command = ctrl._support_center()
        ctrl._replan(t, com, dcm, stance, ctrl.config.double_support, [step])
        knots = ctrl.plan.zmp_knots
        np.testing.assert_allclose(soles.project(knots[1]), knots[1], atol=1e-9)
        if not np.allclose(knots[2], stance_xy, atol=1e-9):  # the later knot was solved
            moved += 1
            np.testing.assert_allclose(ctrl.plan.dcm(t)[0], dcm[:2], atol=1e-9)
            np.testing.assert_allclose(sole.project(knots[2]), knots[2], atol=1e-9)
    assert moved, "no draw needed the later knot: the test did not reach the case"
