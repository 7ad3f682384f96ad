"""The stand scenario on every preset, robots of very different size, with the default,
robot-derived joint gains: a 2.5 kg Solo12 and a 13 kg Go1 stand like the 90 kg Talos and HyQ do;
the absolute gains made for Talos (kp = 1000, kd = 30) saturate the Solo12's 2.7 Nm joints on
nearly every cycle."""

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.robots import preset_names
from wholebody.scenarios import get_scenario

pytestmark = pytest.mark.slow

DURATION = 1.5  # s; the twin steps at 1 ms: 1500 cycles


def stand(robot, **overrides):
    return get_scenario("stand").run(robot, overrides={"duration": str(DURATION), **overrides})


@pytest.mark.parametrize("name", preset_names())
def test_every_preset_stands_on_default_gains(name):
    robot = wb.load_robot(name)
    result = stand(robot)
    m = result.metrics
    cycles = round(DURATION / 1e-3)
    assert result.success and not m["fell"], m
    assert m["torque_saturated_cycles"] <= 0.03 * cycles, m
    assert m["base_drift_max_m"] < 0.01 and m["foot_slip_max_m"] < 0.005, m
    # after settling, the floor carries the weight, every foot loaded (the simulator's forces)
    wrenches = result.log.arrays()["contact_wrenches"][500:]
    np.testing.assert_allclose(wrenches[:, :, 2].sum(axis=1), robot.mass * 9.81, rtol=0.02)
    assert np.all(wrenches[:, :, 2] > 0)


def test_absolute_talos_gains_saturate_solo12():
    """The contrast: the same run with the old absolute gains."""
    robot = wb.load_robot("solo12")
    m = stand(robot, kp="1000", kd="30").metrics
    assert m["torque_saturated_cycles"] > 0.5 * round(DURATION / 1e-3), m


def test_light_links_stand_on_gains_scaled_by_the_free_joint_inertia():
    """G1 (no preset; soles on its ankle links, docs/robots.md), no rotor inertia in its URDF: the
    default gains sit on each joint's inertia with the rest of the robot free, 1 / (M^-1)_ii, and
    it stands; the same frequency and damping ratio on M_ii (the inertia with the other joints
    held, twenty times larger at its hips) make its damper step kd dt / m reach 1.9 and it
    chatters against its torque limits."""
    from conftest import g1_description
    from wholebody.control.standing import StandingController
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot(g1_description())
    result = stand(robot)
    m = result.metrics
    assert result.success and not m["fell"], m
    assert m["torque_saturated_cycles"] <= 0.03 * round(DURATION / 1e-3), m
    assert m["base_drift_max_m"] < 0.01, m
    M = pin.crba(robot.model, robot.model.createData(), robot.q_ref)
    held = np.diag(M)[6:]
    omega = 2 * np.pi * 10.0
    ctrl = StandingController(robot, kp=omega ** 2 * held, kd=2 * 0.7 * omega * held)
    sim = Simulator(robot)
    lo, hi = robot.torque_bounds(robot.q_ref)
    saturated = 0
    for _ in range(round(DURATION / 1e-3)):
        q, v = sim.state()
        tau = ctrl.compute(q, v, sim.t).tau
        saturated += bool(np.any(np.abs(tau) >= hi - 1e-9))
        sim.step(tau)
    assert saturated > 0.5 * round(DURATION / 1e-3), saturated


def test_icub_from_one_file_stands():
    """iCub from example-robot-data, its zero inertias given in the description
    (``inertia_overrides``): it stands on the default gains."""
    from conftest import ICUB_RIGHT_LEG_INERTIAS, icub_description

    robot = wb.load_robot(icub_description(inertia_overrides=ICUB_RIGHT_LEG_INERTIAS))
    result = stand(robot)
    m = result.metrics
    assert result.success and not m["fell"], m
    assert m["torque_saturated_cycles"] <= 0.03 * round(DURATION / 1e-3), m
    assert m["base_drift_max_m"] < 0.01, m
