"""HyQ crawls up and down stairs in the twin (the ramp scenario's course=stairs), judged on the
simulator's base and feet."""

import logging

import numpy as np
import pytest

import wholebody as wb
from wholebody.scenarios import get_scenario
from wholebody.scenarios.ramp import course_end, crossing, stance_edge_distances


@pytest.mark.slow
def test_hyq_crawls_up_and_down_three_15_cm_steps():
    logging.disable(logging.WARNING)
    try:
        hyq = wb.load_robot("hyq")
        params = get_scenario("ramp").validate(hyq, {"course": "stairs", "steps": "3"})
        run, course, _, _, p, _ = crossing(hyq, params)
    finally:
        logging.disable(logging.NOTSET)
    assert p["step_height"] == pytest.approx(0.15, abs=1e-3)
    assert not run.fell and run.failures == 0
    q = np.asarray(run.sim.log.q)
    # the base rose by about the three steps' height over the landing (the trunk stands h above
    # the course smoothed over its length), then came down again
    assert q[:, 2].max() - q[0, 2] > 0.8 * 3 * 0.15
    assert q[-1, 2] == pytest.approx(q[0, 2], abs=0.03)
    feet = run.log["feet"]
    r = hyq.contacts[0].spec.radius
    assert np.all(feet[-1, :, 0] > course_end(course) + 0.05)  # every foot past the last riser
    assert np.allclose(feet[-1, :, 2], r, atol=0.01)  # standing on the ground again
    assert stance_edge_distances(run.log, course).min() > r  # no stance on a riser's edge
