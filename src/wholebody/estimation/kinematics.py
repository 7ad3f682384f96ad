"""The feet's positions relative to the IMU from the measured joint angles (Pinocchio forward
kinematics with the base at the identity): the measurement of a kinematic-inertial estimator; and
the feet's angular velocities, with which a ball foot rolls. One Pinocchio pass per reading gives
every joint's placement and world Jacobian; the feet's angular velocities are the Jacobians'
angular rows times the rates of the joints that carry each foot."""

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
        self._imu_rotation = self.imu_in_base.rotation.copy()
        self._imu_translation = self.imu_in_base.translation.copy()
        self._positions = np.zeros((len(self._frame_ids), 3))
        self._v = np.zeros(model.nv)
        # every joint one coordinate: the encoders are the configuration's joint part as they are
        self._one_coordinate = model.nq == model.nv + 1
        # (ncontact, nv): 1 where a velocity coordinate moves the contact's body
        self._support = np.zeros((len(self._frame_ids), model.nv))
        for i, frame_id in enumerate(self._frame_ids):
            for joint in model.supports[model.frames[frame_id].parentJoint][1:]:
                start = model.joints[joint].idx_v
                self._support[i, start:start + model.joints[joint].nv] = 1.0
        #: each contact's ball radius (m); 0 for a sole, which does not roll
        self.radii = np.array([c.spec.radius if c.dim == 3 else 0.0 for c in robot.contacts])

    @property
    def configuration(self) -> np.ndarray:
        """The last call's configuration: the base at the identity, the joints at the readings."""
        return self._q

    @property
    def count(self) -> int:
        return len(self._frame_ids)

    def feet_in_imu(self, joint_positions: np.ndarray, imu_angular_velocity: np.ndarray,
                    joint_velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions, angular velocities), each (ncontact, 3) in the IMU frame: each contact
        frame's origin, and the angular velocity of its body given the IMU's own."""
        rotation, translation = self._imu_rotation, self._imu_translation
        if self._one_coordinate:
            self._q[7:] = joint_positions
        else:
            self._q = self.robot.with_joint_angles(self._q, joint_positions)
        self._v[3:6] = rotation @ imu_angular_velocity
        self._v[6:] = joint_velocities
        model, data = self.robot.model, self._data
        pin.computeJointJacobians(model, data, self._q)
        pin.updateFramePlacements(model, data)
        placements = data.oMf
        for i, frame_id in enumerate(self._frame_ids):
            self._positions[i] = placements[frame_id].translation
        # a body's angular velocity (world axes, here the base's): the angular rows of the
        # Jacobians of the joints carrying it times their rates (with the base at the identity)
        rates = self._support @ (data.J[3:6] * self._v).T
        return (self._positions - translation) @ rotation, rates @ rotation
