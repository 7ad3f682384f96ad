"""The feet's points relative to the IMU from the measured joint angles (Pinocchio forward
kinematics with the base at the identity): the measurement of a kinematic-inertial estimator; and
the feet's angular velocities, with which a ball foot rolls. One Pinocchio pass per reading gives
every joint's placement and world Jacobian; the feet's angular velocities are the Jacobians'
angular rows times the rates of the joints that carry each foot.

A point foot is one point, its contact frame's origin. A sole is two: its heel and its toe (the
sole's centre minus and plus its half length along the sole's x axis). Two points of one sole
on the ground fix its heading, which one point cannot: with a point per sole, a humanoid's
heading in single support rests on the gyro alone."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot import Robot


class LegKinematics:
    """Positions of ``robot``'s contact points in the frame ``imu_frame`` (default: the base's
    frame) for measured joint angles: the contacts are the robot description's, in its order, a
    point foot's one point, a sole's two (heel, toe); ``contact_of[k]`` is point k's contact."""

    def __init__(self, robot: Robot, imu_frame: str | None = None):
        self.robot = robot
        self.imu_frame = imu_frame or robot.base_frame
        imu_id = robot.frame_id(self.imu_frame, "imu_frame")
        # each point a frame: a point foot's its contact frame; a sole's heel and toe frames
        # added to a copy of the model, so that one frame pass places every point
        model = pin.Model(robot.model)
        contact_of, frame_ids = [], []
        for i, contact in enumerate(robot.contacts):
            if contact.dim == 3:
                contact_of.append(i)
                frame_ids.append(contact.frame_id)
                continue
            frame = model.frames[contact.frame_id]
            centre = np.asarray(contact.spec.offset, dtype=float)
            half_length = np.array([contact.spec.half_size[0], 0.0, 0.0])
            for end, point in (("heel", centre - half_length), ("toe", centre + half_length)):
                placement = frame.placement * pin.SE3(np.eye(3), point)
                frame_ids.append(model.addFrame(pin.Frame(
                    f"{contact.name}_estimator_{end}", frame.parentJoint, contact.frame_id,
                    placement, pin.FrameType.OP_FRAME)))
                contact_of.append(i)
        #: the contact (index in the robot's contacts) of every point
        self.contact_of = np.array(contact_of, dtype=int)
        self._model = model
        self._frame_ids = frame_ids
        self._data = model.createData()
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
        # (npoint, nv): 1 where a velocity coordinate moves the point's body
        self._support = np.zeros((len(self._frame_ids), model.nv))
        for i, frame_id in enumerate(self._frame_ids):
            for joint in model.supports[model.frames[frame_id].parentJoint][1:]:
                start = model.joints[joint].idx_v
                self._support[i, start:start + model.joints[joint].nv] = 1.0
        #: each point's ball radius (m); 0 on a sole, which does not roll
        self.radii = np.array([robot.contacts[i].spec.radius if robot.contacts[i].dim == 3
                               else 0.0 for i in contact_of])

    @property
    def configuration(self) -> np.ndarray:
        """The last call's configuration: the base at the identity, the joints at the readings."""
        return self._q

    @property
    def count(self) -> int:
        """The number of points."""
        return len(self._frame_ids)

    def feet_in_imu(self, joint_positions: np.ndarray, imu_angular_velocity: np.ndarray,
                    joint_velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions, angular velocities), each (npoint, 3) in the IMU frame: each point, and
        the angular velocity of its body given the IMU's own."""
        rotation, translation = self._imu_rotation, self._imu_translation
        if self._one_coordinate:
            self._q[7:] = joint_positions
        else:
            self._q = self.robot.with_joint_angles(self._q, joint_positions)
        self._v[3:6] = rotation @ imu_angular_velocity
        self._v[6:] = joint_velocities
        model, data = self._model, self._data
        pin.computeJointJacobians(model, data, self._q)
        pin.updateFramePlacements(model, data)
        placements = data.oMf
        for i, frame_id in enumerate(self._frame_ids):
            self._positions[i] = placements[frame_id].translation
        # a body's angular velocity (world axes, here the base's): the angular rows of the
        # Jacobians of the joints carrying it times their rates (with the base at the identity)
        rates = self._support @ (data.J[3:6] * self._v).T
        return (self._positions - translation) @ rotation, rates @ rotation
