"""wholebody: whole-body control of torque-controlled legged robots.

Hierarchical inverse dynamics with momentum control (Herzog et al. 2016) and passive whole-body
control (Fahmi et al. 2019), checked in closed loop in a MuJoCo twin of the Pinocchio model.
"""

from .robot import Contact, Robot
from .robots import RobotDescription, load_robot, preset_names
from .solvers import SolverSettings

__version__ = "0.1.0"
__all__ = ["Contact", "Robot", "RobotDescription", "load_robot", "preset_names", "SolverSettings",
           "__version__"]
