"""``push --set dv=…``: the push given as the velocity change it imparts. The evidence is the
simulator's own record of the force it applied, integrated over time."""

import numpy as np
import pytest

from wholebody.scenarios import get_scenario

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("location", ["front", "hip-left"])
def test_dv_sets_the_impulse_the_simulator_applies(robots, location):
    robot = robots["talos14"]
    result = get_scenario("push").run(robot, "pd", {"dv": "0.05", "location": location,
                                                    "duration": "1.0"})
    arrays = result.log.arrays()
    impulse = np.trapezoid(np.linalg.norm(arrays["push_force"], axis=1), arrays["t"])
    assert impulse / robot.mass == pytest.approx(0.05, rel=0.02)
    assert result.metrics["delta_v_mps"] == pytest.approx(0.05, rel=1e-9)
