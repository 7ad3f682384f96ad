"""Stairs and rough-ground courses: geometry from their formulas, the seeded height field, the
planner's terrain against the twin's surface (MuJoCo ray casts), footholds off the edges and swings
over the terrain under them."""

import logging

import numpy as np
import pytest
from conftest import ray_height

import wholebody as wb
from wholebody.planning.courses import CoursePlanner, rough_course, stairs_course
from wholebody.planning.planner import GaitPlanner
from wholebody.planning.trunk import VelocityCommand
from wholebody.scenarios import get_scenario
from wholebody.scenarios.locomotion import course_environment, make_schedule
from wholebody.sim.simulator import Simulator

MARGIN = 0.06


@pytest.fixture(scope="module")
def hyq():
    logging.disable(logging.WARNING)
    yield wb.load_robot("hyq")
    logging.disable(logging.NOTSET)


# ---------------------------------------------------------------- geometry
@pytest.mark.parametrize("n, rise, tread, landing, x0", [(5, 0.15, 0.5, 1.0, 0.8),
                                                         (3, 0.07, 0.23, 0.4, 0.3), (1, 0.2, 0.4,
                                                                                     0.6, 0.0)])
def test_stairs_rise_and_tread_follow_the_formula(n, rise, tread, landing, x0):
    course = stairs_course(n, rise, tread, landing, x_start=x0)
    top_end = x0 + (n - 1) * tread + landing
    up = [x0 + k * tread for k in range(n)]
    down = [top_end + k * tread for k in range(n)]
    assert course.edges == pytest.approx(up + down)
    assert course.edges[0] == pytest.approx(x0) and course.edges[-1] == pytest.approx(
        top_end + (n - 1) * tread)
    for k in range(n):  # the middle of each tread: k + 1 rises up, then down again
        assert course.height(up[k] + 0.5 * (tread if k < n - 1 else landing)) == pytest.approx(
            (k + 1) * rise)
        assert course.height(down[k] + 0.5 * tread) == pytest.approx((n - 1 - k) * rise, abs=1e-12)
    assert course.height(x0 - 1e-6) == 0.0
    assert course.height(down[-1] + 1.0) == pytest.approx(0.0, abs=1e-12)
    assert course.terrain.normal(up[0] + 0.1, 0.3) == pytest.approx([0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="steps"):
        stairs_course(0)


def test_rough_field_is_seeded_and_bounded():
    a, b = rough_course(3.0, 0.05, 0.2, seed=7), rough_course(3.0, 0.05, 0.2, seed=7)
    c = rough_course(3.0, 0.05, 0.2, seed=8)
    fa, fb, fc = (k.strips[1].field for k in (a, b, c))
    assert np.array_equal(fa.heights, fb.heights)
    assert not np.array_equal(fa.heights, fc.heights)
    assert fa.heights.shape == (15, 15)  # 3 m x 3 m (the course's width) in 0.2 m cells
    assert np.all(np.abs(fa.heights) <= 0.05) and np.ptp(fa.heights) > 0.08  # uses its range
    rng = np.random.default_rng(0)
    for x, y in rng.uniform([0.8, -1.49], [3.8, 1.49], (200, 2)):
        z = a.terrain.height(x, y)
        assert abs(z) <= 0.05
        assert z == b.terrain.height(x, y)
        i, j = int((x - 0.8) // 0.2), int((y + 1.5) // 0.2)
        assert z == fa.heights[i, j]
    assert a.height(0.7, 0.0) == 0.0 and a.height(3.9, 0.0) == 0.0  # level before and after


# ---------------------------------------------------------------- planner terrain = twin surface
@pytest.mark.parametrize("course", [stairs_course(5, 0.15, 0.5, 1.0),
                                    rough_course(2.0, 0.05, 0.2, seed=3)],
                         ids=["stairs", "rough"])
def test_planner_terrain_is_the_twin_surface(hyq, course):
    """At random points, a ray cast down onto the twin's boxes hits the planner's height."""
    sim = Simulator(hyq, course_environment(course))
    rng = np.random.default_rng(1)
    checked = 0
    for x, y in rng.uniform([-0.5, -1.4], [5.5, 1.4], (400, 2)):
        if course.edge_distance(x, y) < 1e-3:
            continue  # on an edge: either side is right
        assert ray_height(sim, x, y) == pytest.approx(course.terrain.height(x, y), abs=1e-6)
        checked += 1
    assert checked > 390


# ---------------------------------------------------------------- footholds and swings
def _planners(robot, course, gait):
    command = VelocityCommand.speed_ramp(0.0, 0.1, 1.0, 3.0)
    schedule = make_schedule(robot, gait, 1.0)
    return (CoursePlanner.on_course(robot, schedule, command, course, gap_margin=MARGIN),
            GaitPlanner.for_robot(robot, schedule, command, course.terrain))


@pytest.mark.parametrize("gait", ["crawl", "trot"])
def test_stair_footholds_keep_off_the_risers(hyq, gait):
    course = stairs_course(5, 0.15, 0.5, 1.0, x_start=0.8)
    planner, plain = _planners(hyq, course, gait)
    near = 0
    for leg in planner.legs:
        for k in range(60 if gait == "trot" else 20):
            t_td = planner.schedule.touchdown_time(leg, k)
            raw = plain.touchdown_target(leg, t_td).point
            fh = planner.touchdown_target(leg, t_td)
            near += min(abs(raw[0] - e) for e in course.edges) < MARGIN
            assert min(abs(fh.point[0] - e) for e in course.edges) >= MARGIN - 1e-9
            assert fh.point[2] == pytest.approx(course.height(fh.point[0]))
            assert abs(fh.point[0] - raw[0]) <= MARGIN + 1e-9  # moved no further than needed
    assert near > 0, "the test needs raw Raibert targets near a riser"


def test_rough_footholds_keep_off_the_cell_sides(hyq):
    course = rough_course(3.0, 0.05, 0.2, seed=0)
    planner, _ = _planners(hyq, course, "trot")
    f = course.strips[1].field
    for leg in planner.legs:
        for k in range(60):
            fh = planner.touchdown_target(leg, planner.schedule.touchdown_time(leg, k))
            x, y = fh.point[:2]
            if f.x0 <= x <= f.x0 + f.heights.shape[0] * f.cx:
                u, v = (x - f.x0) / f.cx, (y - f.y0) / f.cy  # in cells: away from integers
                assert min(abs(u - round(u)) * f.cx, abs(v - round(v)) * f.cy) >= MARGIN - 1e-9
            assert fh.point[2] == course.height(x, y)


@pytest.mark.parametrize("course, gait", [(stairs_course(5, 0.15, 0.5, 1.0), "crawl"),
                                          (stairs_course(5, 0.15, 0.5, 1.0), "trot"),
                                          (rough_course(3.0, 0.05, 0.2, seed=0), "trot")],
                         ids=["stairs-crawl", "stairs-trot", "rough-trot"])
def test_planned_swings_stay_above_the_terrain(hyq, course, gait):
    """Every planned swing foot (a sphere of radius r) stays above the course, sampled every
    10 ms over the whole course: each point of the sphere's lower half above the height
    there (the apex clears the higher tread or cell, and a riser is crossed high enough)."""
    planner, _ = _planners(hyq, course, gait)
    r = hyq.contacts[0].spec.radius
    a, b = np.meshgrid(np.linspace(0.0, 0.5 * np.pi, 4), np.linspace(0.0, 2 * np.pi, 8,
                                                                      endpoint=False))
    sphere = r * np.column_stack([(np.sin(a) * np.cos(b)).ravel(), (np.sin(a) * np.sin(b)).ravel(),
                                  -np.cos(a).ravel()])
    worst = np.inf
    for t in np.arange(0.0, 60.0, 0.01):
        st = planner.update(t)
        for i in np.flatnonzero(~st.contact):
            x, y, z = st.foot_position[i]
            if z - r > max(course.height(x + dx, y + dy) for dx in (-r, r) for dy in (-r, r)):
                continue  # above everything under it (the course is level between its edges)
            for x, y, z in st.foot_position[i] + sphere:
                worst = min(worst, z - course.height(x, y))
    assert worst > -1e-6


def test_stairs_refuse_a_rise_the_legs_cannot_reach(hyq):
    scenario = get_scenario("ramp")
    scenario.validate(hyq, {"course": "stairs"})  # HyQ's 15 cm
    with pytest.raises(ValueError, match=r"--set step_height: 0\.28 m"):
        scenario.validate(hyq, {"course": "stairs", "step_height": "0.28"})
    with pytest.raises(ValueError, match=r"--set tread: 0\.1 m"):
        scenario.validate(hyq, {"course": "stairs", "tread": "0.1"})
    with pytest.raises(ValueError, match=r"--set cell: 0\.1 m"):
        scenario.validate(hyq, {"course": "rough", "cell": "0.1"})
