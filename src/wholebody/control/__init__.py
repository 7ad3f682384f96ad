"""Controllers and their building blocks: each controller turns a robot state into joint torques
(``compute(q, v, t)``); ``stacks`` builds the hierarchies of Herzog et al. 2016; ``lqr`` computes
its momentum gains."""

from .base import ControlResult
from .lqr import MomentumLQR, lqr_gains, momentum_model
from .observer import MomentumObserver
from .stacks import table1_stack, table2_stack, table4_stack
from .standing import StandingController

__all__ = ["ControlResult", "MomentumLQR", "MomentumObserver", "lqr_gains", "momentum_model", "StandingController",
           "table1_stack", "table2_stack", "table4_stack"]
