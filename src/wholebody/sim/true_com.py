"""The simulated robot's own centre of mass and mass, from the twin's (possibly mismatched) MuJoCo
model: what a push-recovery criterion must judge when the controller's model is wrong."""

from __future__ import annotations

import mujoco
import numpy as np

from .simulator import Simulator


class TrueCoM:
    """The simulated robot's centre of mass from the twin's own (possibly mismatched) MuJoCo model.

    Uses a private ``MjData`` so that the simulator's data are not touched: positions copied from
    the simulator, forward kinematics, then ``subtree_com`` of the robot's root body.
    """

    def __init__(self, sim: Simulator):
        self.sim = sim
        self.data = mujoco.MjData(sim.model)
        self.root = sim.twin.joint_bodies[sim.robot.model.names[1]]

    @property
    def mass(self) -> float:
        return float(self.sim.model.body_subtreemass[self.root])

    def __call__(self) -> np.ndarray:
        self.data.qpos[:] = self.sim.data.qpos
        mujoco.mj_kinematics(self.sim.model, self.data)
        mujoco.mj_comPos(self.sim.model, self.data)
        return self.data.subtree_com[self.root].copy()
