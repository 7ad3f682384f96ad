"""A humanoid on five-joint legs (no ankle roll) and narrow soles: talos14 with its ankle rolls
locked and soles 3 cm wide, as Unitree H1's. Along the direction the leg cannot move its sole
(its roll) the sole moves with the whole robot; eq. 2's constraint as the paper writes it keeps
that velocity and the robot rocks on its soles until it falls, at rest or after a push. With the
soles' velocity damped (:func:`wholebody.control.stacks.contact_constraint`) it recovers the
push. Judged by the simulator: sole tilt and slip, the CoG back."""

import pytest

import wholebody as wb
from wholebody.control.balance import MomentumBalance
from wholebody.scenarios import get_scenario
from wholebody.scenarios.measures import MAX_TILT_DEG
from wholebody.scenarios.push import with_peak_force
from wholebody.scenarios.pushes import controller_options, push_trial

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("controller", ["lqr", "pd"])
def test_five_joint_legs_on_narrow_soles_recover_a_push(tmp_path, controller):
    from conftest import talos14_five_joint_toml

    path = tmp_path / "talos14_five.toml"
    path.write_text(talos14_five_joint_toml(sole_half_width=0.015))
    robot = wb.load_robot(path)
    scenario = get_scenario("push")
    overrides = {"dv": "0.1", "duration": "6"}
    result = scenario.run(robot, controller, overrides)
    assert result.success, result.metrics
    assert result.metrics["max_foot_tilt_deg"] < 0.5, result.metrics

    params = with_peak_force(robot, scenario.validate(robot, overrides))
    undamped = MomentumBalance(robot, gains=controller, **controller_options(controller, params))
    undamped.stack.find("contacts").kd = 0.0  # eq. 2 as the paper writes it
    trial = push_trial(robot, controller, params, balance=undamped)
    # how far the rocking has grown by the end is chaotic (a push 1e-9 stronger or weaker ends
    # with the feet tilted anywhere from 9 to 180 degrees): what holds for every such push is
    # that the soles rock beyond flat
    assert not trial.success and trial.metrics["max_foot_tilt_deg"] > MAX_TILT_DEG, trial.metrics
