import numpy as np
import pytest


@pytest.fixture(autouse=True)
def _restore_robots(robots):
    """The robots are shared by the session: leave each at its reference posture, at rest."""
    yield
    for robot in robots.values():
        robot.update(robot.q_ref, np.zeros(robot.nv))
