from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

from wholebody.planning.trunk import TrunkState


def passive_plan(robot, rng, stance, *, swing_noise=(0.02, 0.1, 0.5), normal=(0.0, 0.0, 1.0)):
    """A plan for PassiveWBC at the robot's cached state: the trunk reference near the current
    trunk, swing targets near the current feet (position, velocity and acceleration drawn with the
    standard deviations ``swing_noise``), touchdown where the feet are, on ground of ``normal``."""
    legs = robot.contact_names
    feet = np.array([robot.data.oMf[robot.contact(n).frame_id].translation for n in legs])
    R = pin.Quaternion(robot.q[3:7]).normalized().toRotationMatrix()
    trunk = TrunkState(position=robot.com + rng.normal(scale=0.01, size=3),
                       velocity=rng.normal(scale=0.05, size=3),
                       acceleration=rng.normal(scale=0.2, size=3),
                       rotation=R @ pin.exp3(rng.normal(scale=0.02, size=3)),
                       angular_velocity=rng.normal(scale=0.05, size=3))
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    position, velocity, acceleration = swing_noise
    return SimpleNamespace(legs=legs, contact=np.array(stance, dtype=bool),
                           foot_position=feet + rng.normal(scale=position, size=feet.shape),
                           foot_velocity=rng.normal(scale=velocity, size=feet.shape),
                           foot_acceleration=rng.normal(scale=acceleration, size=feet.shape),
                           touchdown_position=feet.copy(),
                           touchdown_normal=np.tile(n, (len(legs), 1)), trunk=trunk)


@pytest.fixture
def plan_for():
    """:func:`passive_plan`, for tests that build PassiveWBC plans."""
    return passive_plan
