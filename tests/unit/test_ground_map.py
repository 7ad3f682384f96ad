"""The known ground in the state estimate (``ground_map``): the twin's surface heights by ray
casts, and the EKF's stance-foot height measurement, checked against the twin's truth."""

from __future__ import annotations

import numpy as np
import pytest

import wholebody as wb
from wholebody.cli import main
from wholebody.control.standing import StandingController
from wholebody.estimation import TwinEstimation
from wholebody.scenarios.loop import run_closed_loop
from wholebody.sim.environment import Box, Environment
from wholebody.sim.simulator import Simulator


@pytest.fixture(scope="module")
def hyq():
    return wb.load_robot("hyq")


def test_ground_height_is_the_top_of_what_is_under_the_point(hyq):
    """The floor (z = 0), a box's top face, a tilted box's plane (from its pose: z of the top face
    at x), and nothing (no floor, beside the box) — never the robot's own geoms, which stand on
    the floor over the same points."""
    box = Box(center=(1.5, 0.0, 0.05), half_size=(0.2, 0.3, 0.05))
    angle = 0.2
    tilted = Box(center=(3.0, 0.0, 0.0), half_size=(0.5, 0.5, 0.05), rpy=(0.0, -angle, 0.0))
    sim = Simulator(hyq, environment=Environment(boxes=[box, tilted]))
    hyq.update(*sim.state())
    for contact in hyq.contact_names:
        x, y, _ = hyq.frame_placement(hyq.contact(contact).frame)[0]
        assert sim.ground_height(x, y) == pytest.approx(0.0, abs=1e-9)  # under a foot
    assert sim.ground_height(1.5, 0.1) == pytest.approx(0.1, abs=1e-9)
    x = 3.1  # the tilted top face: its centre 0.05 / cos up the normal, rising along +x
    expected = 0.05 / np.cos(angle) + np.tan(angle) * (x - 3.0)
    assert sim.ground_height(x, 0.0) == pytest.approx(expected, abs=1e-9)
    bare = Simulator(hyq, environment=Environment(floor=False, boxes=[box]))
    assert bare.ground_height(1.5, 0.0) == pytest.approx(0.1, abs=1e-9)
    assert bare.ground_height(-2.0, 0.0) == -np.inf


@pytest.mark.parametrize("ground_map", [False, True])
def test_a_height_error_is_corrected_only_on_the_known_ground(hyq, ground_map):
    """HyQ standing 0.5 s; right after the start the estimate (base and feet) is put 2 cm too low.
    The legs' kinematics cannot see it (the feet moved with the base); with the ground map the
    stance feet's heights pull it back to within 2 mm of the twin's true height, without it the
    error stays (the height is unobservable)."""
    estimation = TwinEstimation.for_robot(hyq, seed=1, ground_map=ground_map)
    sim = Simulator(hyq, observers=[estimation])
    ekf = estimation.estimator
    ekf.position = ekf.position - [0.0, 0.0, 0.02]
    ekf.feet = ekf.feet - [0.0, 0.0, 0.02]
    run_closed_loop(sim, StandingController(hyq), 0.5)
    error = estimation.current().q[2] - sim.state()[0][2]
    if ground_map:
        assert abs(error) < 2e-3
    else:
        assert error < -0.015


def test_ground_map_needs_an_estimator(capsys):
    """``--set ground_map=true`` on the exact state is refused before simulating (exit 2)."""
    assert main(["run", "stand", "--set", "ground_map=true", "--set", "duration=0.1"]) == 2
    assert "ground_map" in capsys.readouterr().err


def test_the_ground_map_is_on_by_default_under_real_conditions(hyq):
    """On defaults a scenario's estimator knows the ground under ``sensors`` and ``robot`` (and
    the exact state takes the default without complaint); ``ground_map=false`` turns it off."""
    from wholebody.scenarios import get_scenario
    from wholebody.scenarios.conditions import conditions_for

    crawl = get_scenario("crawl")
    assert crawl.validate(hyq, {})["ground_map"] is True  # exact: accepted, nothing to measure
    for level in ("sensors", "robot"):
        params = crawl.validate(hyq, {"realism": level})
        assert conditions_for(hyq, level, ground_map=params["ground_map"]).ground_map
    params = crawl.validate(hyq, {"realism": "sensors", "ground_map": "false"})
    assert not conditions_for(hyq, "sensors", ground_map=params["ground_map"]).ground_map


@pytest.mark.slow
def test_hyq_trots_on_the_estimate_with_the_ground_map():
    """The passive WBC trotting on the estimate of the twin's sensors (``realism=sensors``) with
    the ground map: no fall and every cycle solved (without it the estimate's height sinks by
    each touchdown and the trot falls)."""
    from wholebody.scenarios import get_scenario

    result = get_scenario("crawl").run(wb.load_robot("hyq"), "passive",
                                       {"gait": "trot", "realism": "sensors",
                                        "ground_map": "true", "duration": "8"})
    metrics = result.metrics["passive"]
    assert not metrics["fell"] and metrics["failed_cycles"] == 0
