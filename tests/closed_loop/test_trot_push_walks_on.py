"""``trot-push`` in the twin: HyQ pushed sideways in the middle of a trot's diagonal stance walks
on, and a push far beyond it is reported as a fall. The evidence is the simulator's: the base's
height and tilt, its path, the force it applied."""

import numpy as np
import pytest

from wholebody.scenarios import get_scenario

pytestmark = pytest.mark.slow


def test_hyq_walks_on_after_a_lateral_push(robots):
    robot = robots["hyq"]
    result = get_scenario("trot-push").run(robot, "passive", {"dv": "0.15", "angle": "90"})
    m, a = result.metrics, result.log.arrays()
    # the simulator applied m dv toward -y
    impulse = np.trapezoid(a["push_force"], a["t"], axis=0)
    np.testing.assert_allclose(impulse, [0.0, -robot.mass * 0.15, 0.0], atol=0.01 * robot.mass)
    assert result.success and m["survived"]
    assert not m["fell"] and m["failed_cycles"] == 0
    # walked on: the base moved forward by the commanded speed over the time after the push
    t, base = a["t"], a["q"][:, :3]
    after = t >= m["push_start_s"]
    moved = base[after][-1, 0] - base[after][0, 0]
    commanded = 0.4 * (t[after][-1] - t[after][0])  # HyQ's default trot speed
    assert moved >= 0.8 * commanded
    # the base stayed up throughout
    assert base[:, 2].min() > 0.8 * robot.q_ref[2]


def test_a_much_larger_push_is_reported_as_a_fall(robots):
    robot = robots["hyq"]
    result = get_scenario("trot-push").run(robot, "passive", {"dv": "1.0", "angle": "90"})
    m, a = result.metrics, result.log.arrays()
    assert not result.success and not m["survived"] and m["fell"]
    # the twin's base is down (below half its standing height) or tipped past 45 deg
    q = a["q"][-1]
    x, y, z, w = q[3:7]
    up_z = 1.0 - 2.0 * (x * x + y * y)
    assert q[2] < 0.5 * robot.q_ref[2] or up_z < np.cos(np.radians(45.0))
