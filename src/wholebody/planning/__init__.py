"""Planning: gait schedules (crawl, trot), swing trajectories, footholds and trunk references.

The references consumed by the passive whole-body controller of Fahmi et al. 2019: the
contact schedule (which feet are in stance, eq. 10, and which swing, eqs. 11-12), the desired
swing-foot position/velocity/acceleration (eqs. 5-6), touchdown targets and terrain normals (eq. 13,
eq. 32), and the trunk reference -- CoM position/velocity/acceleration and trunk orientation/angular
velocity/acceleration (eq. 4).

Typical use::

    import wholebody as wb
    from wholebody.planning import GaitPlanner, VelocityCommand, crawl

    robot = wb.load_robot("hyq")
    planner = GaitPlanner.for_robot(robot, crawl(start=0.5), VelocityCommand.constant(0.1))
    plan = planner.update(t)          # every control cycle, non-decreasing t
    plan.contact, plan.foot_position, plan.trunk.position, plan.trunk.rotation, ...
"""

from .courses import (Course, CoursePlanner, HeightField, build_course, gap_course, ramp_course,
                      rough_course, stairs_course)
from .footholds import Foothold, Footprint, raibert_foothold
from .gait import LEGS, GaitEvent, GaitSchedule, Swing, crawl, stand, trot
from .planner import GaitPlanner, PlanState
from .swing import SwingTrajectory, quintic_blend, swing_trajectory
from .terrain import Terrain
from .trunk import (CommandPhase, CommandSchedule, CrawlSway, StartShift, TrunkReference,
                    TrunkState, VelocityCommand)

__all__ = [
    "CommandPhase", "CommandSchedule", "Course", "CoursePlanner", "build_course", "gap_course", "ramp_course",
    "HeightField", "rough_course", "stairs_course",
    "CrawlSway", "Foothold", "Footprint", "GaitEvent", "GaitPlanner",
    "GaitSchedule", "LEGS", "PlanState", "StartShift", "Swing", "SwingTrajectory", "Terrain",
    "TrunkReference", "TrunkState", "VelocityCommand", "crawl", "quintic_blend",
    "raibert_foothold", "stand", "swing_trajectory", "trot",
]
