"""walk, push-step and walk-push: the capture-point walking controller in closed loop in the twin.

Every number asserted is measured on the simulator (base path, sole poses, falls) by the
scenarios; the criteria are talos14's, in proportion to the standing height on other robots.
"""

import pytest

from wholebody.scenarios import get_scenario
from wholebody.scenarios.measures import Thresholds

pytestmark = pytest.mark.slow

STRAIGHT = {"turn": "0", "side_distance": "0"}
#: a 0.5 m/s push on the front of the hip (backwards): beyond the feet-flat balance
FRONT_PUSH = {"dv": "0.5", "angle": "0"}


def _walked_and_stopped(robot, steps: int) -> dict:
    """The ``walk`` scenario straight ahead for ``steps`` step periods: no fall, no failed
    cycle, at least ``steps`` steps, no sole slipping while it stands, standing at the end."""
    m = get_scenario("walk").run(robot, overrides={"steps": str(steps), **STRAIGHT}).metrics
    assert not m["fallen"], m
    assert m["failed_cycles"] == 0, m
    assert m["steps"] >= steps, m
    assert m["max_sole_slip_per_stance_m"] < Thresholds.for_robot(robot).max_slip, m
    assert m["standing_at_end"], m
    return m


def test_talos14_walks_ten_steps_forward_and_stops(robots):
    m = _walked_and_stopped(robots["talos14"], 10)
    assert m["commanded_net_displacement_m"] == pytest.approx(m["commanded_forward_distance_m"],
                                                              rel=1e-2)
    assert m["net_displacement_m"] >= 0.8 * m["commanded_forward_distance_m"], m


def test_talos14_turns_by_the_commanded_heading(robots):
    """A 90° turn (two step periods forward first): the base's heading measured in the twin
    changes by the commanded amount to within 2°, though each sole lands a little more turned
    than planned."""
    m = get_scenario("walk").run(robots["talos14"],
                                 overrides={"steps": "2", "side_distance": "0"}).metrics
    assert not m["fallen"] and m["failed_cycles"] == 0, m
    assert m["commanded_heading_change_deg"] == pytest.approx(90.0, abs=1e-6)
    assert m["heading_change_deg"] == pytest.approx(90.0, abs=2.0), m
    assert m["standing_at_end"], m


def test_talos14_survives_a_front_push_by_stepping(robots):
    result = get_scenario("push-step").run(robots["talos14"], overrides=FRONT_PUSH)
    m = result.metrics
    assert m["survived"], m
    assert 1 <= m["steps_taken"] <= 3, m


def test_talos14_falls_from_the_same_push_without_stepping(robots):
    result = get_scenario("push-step").run(robots["talos14"],
                                           overrides={**FRONT_PUSH, "stepping": "false"})
    m = result.metrics
    assert m["fallen"], m  # the feet-flat balance alone cannot take it
    assert m["steps_taken"] == 0, m


def test_talos14_walks_on_after_a_side_push_mid_stride(robots):
    result = get_scenario("walk-push").run(robots["talos14"],
                                           overrides={"angles": "90", "steps_after": "4"})
    m = result.metrics["angles"]["90"]
    assert m["pushed_at_s"] is not None, m
    assert m["recovered"], m


def test_romeo_walks_six_steps_forward_and_stops(robots):
    """romeo's stride is short (its ankle pitch has little room; it walks with its knees
    straighter than standing, where its legs reach furthest): the net displacement is checked
    against what its step limit allows over the forward steps it took, not the command."""
    from wholebody.control.walking import Walking

    robot = robots["romeo"]
    m = _walked_and_stopped(robot, 6)
    stride = Walking(robot).limits.forward
    landed = [f["landed_xy_m"][0] for f in m["footsteps"]]
    # the soles end side by side, the body moved as far as the front sole
    assert m["net_displacement_m"] >= 0.8 * (max(landed) - min(landed)) > 4 * stride, m
