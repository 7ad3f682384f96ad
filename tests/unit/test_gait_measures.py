"""What a gait run measures of the twin every cycle (:class:`TwinGait`): one forward-kinematics
pass on a Data of its own gives the numbers Robot.update's cycle gives — rotation, CoM and feet
bit for bit, the contact points' horizontal speeds (from the frames' velocities) equal to the
contact Jacobians times v — and leaves the robot's own cycle alone."""

import numpy as np
import pinocchio as pin
import pytest

from wholebody.scenarios.measures import TwinGait


@pytest.mark.parametrize("name", ["hyq", "talos14"])
def test_twin_gait_is_the_robot_cycles_numbers(robots, rng, name):
    robot = robots[name]
    legs = robot.contact_names
    twin = TwinGait(robot, legs)
    model = robot.model
    for _ in range(50):
        q = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq))
        q[:3] = rng.normal(size=3)
        v = rng.normal(size=model.nv)
        rotation, com, feet, speeds = twin.at(q, v)
        rotation, com, feet = rotation.copy(), com.copy(), [f.copy() for f in feet]
        robot.update(q, v)
        np.testing.assert_array_equal(rotation, robot.data.oMi[1].rotation)
        np.testing.assert_array_equal(com, robot.com)
        for n, foot in zip(legs, feet):
            np.testing.assert_array_equal(foot,
                                          robot.data.oMf[robot.contact(n).frame_id].translation)
        expected = [np.linalg.norm((robot.contact_jacobians[n] @ v)[:2]) for n in legs]
        np.testing.assert_allclose(speeds, expected, rtol=1e-12, atol=1e-12)
    before = robot.q.copy()
    twin.at(robot.q_ref, np.zeros(model.nv))
    np.testing.assert_array_equal(robot.q, before)  # the robot's cycle is left as it was
