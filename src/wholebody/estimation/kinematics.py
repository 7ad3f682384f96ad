"""The feet's positions relative to the IMU from the measured joint angles (Pinocchio forward
kinematics with the base at the identity): the measurement of a kinematic-inertial estimator; and
the feet's angular velocities, with which a ball foot rolls."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot import Robot


class LegKinematics:
    """Positions of ``robot``'s contact frames in the frame ``imu_frame`` (default: the base's
    frame) for measured joint angles; the contacts are the robot description's, in its order."""

    def __init__(self, robot: Robot, imu_frame: str | None = None):
        self.robot = robot
        self.imu_frame = imu_frame or robot.base_frame
        imu_id = robot.frame_id(self.imu_frame, "imu_frame")
        model = robot.model
        self._data = model.createData()
        self._frame_ids = [robot.contact(name).frame_id for name in robot.contact_names]
        self._q = pin.neutral(model)  # the base at the identity; joints overwritten each call
        pin.framesForwardKinematics(model, self._data, self._q)
        #: the IMU's placement in the free-flyer's (base joint's) frame
        self.imu_in_base: pin.SE3 = self._data.oMf[imu_id].copy()
        self._positions = np.zeros((len(self._frame_ids), 3))
        self._rates = np.zeros((len(self._frame_ids), 3))
        self._v = np.zeros(model.nv)
        #: each contact's ball radius (m); 0 for a sole, which does not roll
        self.radii = np.array([c.spec.radius if c.dim == 3 else 0.0 for c in robot.contacts])

    @property
    def count(self) -> int:
        return len(self._frame_ids)

    def feet_in_imu(self, joint_positions: np.ndarray, imu_angular_velocity: np.ndarray,
                    joint_velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions, angular velocities), each (ncontact, 3) in the IMU frame: each contact
        frame's origin, and the angular velocity of its body given the IMU's own."""
        rotation, translation = self.imu_in_base.rotation, self.imu_in_base.translation
        self._q = self.robot.with_joint_angles(self._q, joint_positions)
        self._v[3:6] = rotation @ imu_angular_velocity
        self._v[6:] = joint_velocities
        model, data = self.robot.model, self._data
        pin.forwardKinematics(model, data, self._q, self._v)
        for i, frame_id in enumerate(self._frame_ids):
            self._positions[i] = pin.updateFramePlacement(model, data, frame_id).translation
            self._rates[i] = pin.getFrameVelocity(model, data, frame_id,
                                                  pin.LOCAL_WORLD_ALIGNED).angular
        return (self._positions - translation) @ rotation, self._rates @ rotation
