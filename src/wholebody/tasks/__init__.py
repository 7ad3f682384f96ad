"""Task and constraint library: each fills affine rows over y = [qdd, lambda, tau, aux] every cycle."""

from .base import Task, TaskRows
from .contact import (CenterOfPressure, ContactConstraint, ForceRegularizer, FrictionCone,
                      NormalForceBounds, tangent_basis)
from .dynamics import FullDynamics, NewtonEuler
from .limits import JointAccelerationLimits, TorqueLimits
from .momentum import MomentumForce, MomentumPD, momentum_map
from .motion import CoMTask, FrameTask, JointTrajectoryTask, PostureTask, SlackedFrameTask
from .regularization import AccelerationRegularizer, AuxiliaryRegularizer

__all__ = ["Task", "TaskRows", "CenterOfPressure", "ContactConstraint", "ForceRegularizer",
           "FrictionCone", "NormalForceBounds", "tangent_basis", "FullDynamics", "NewtonEuler",
           "JointAccelerationLimits", "TorqueLimits", "MomentumForce", "MomentumPD", "momentum_map",
           "CoMTask", "FrameTask", "JointTrajectoryTask", "PostureTask", "SlackedFrameTask",
           "AccelerationRegularizer", "AuxiliaryRegularizer"]
