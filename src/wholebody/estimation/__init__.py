"""Floating-base state estimation from an IMU and the legs' kinematics (Bloesch et al. 2013)."""

from .ekf import EstimatorNoise, KinematicInertialEKF, StateEstimate
from .kinematics import LegKinematics
from .twin import EstimationLog, OnEstimatedState, TwinEstimation

__all__ = ["EstimatorNoise", "KinematicInertialEKF", "StateEstimate", "LegKinematics",
           "EstimationLog", "OnEstimatedState", "TwinEstimation"]
