"""Robot-free solvers: priority levels, QP backends and the hierarchical cascade (Herzog et al. 2016, §2.2)."""

from .backends import solve_qp
from .hierarchy import HierarchySolution, evaluate_levels, row_normalised, solve_hierarchy
from .level import Level
from .settings import SolverSettings

__all__ = ["Level", "solve_hierarchy", "HierarchySolution", "evaluate_levels", "row_normalised", "solve_qp",
           "SolverSettings"]
