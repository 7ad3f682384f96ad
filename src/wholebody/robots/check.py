"""What a user must know about a robot description before running anything (``wholebody
check-robot``): its size, its contacts and their roles, whether it stands on them in its posture,
and the problems of its model, each with a way out.

:func:`check_robot` loads the description and returns a :class:`RobotCheck`: facts (DoF, mass,
standing base height, contacts) and findings, each an error (the robot cannot stand or cannot be
loaded), a warning (something works, with a caveat) or a note.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull, QhullError

from .description import DescriptionError
from .roles import (GAIT_LEG_JOINTS, contact_roles, leg_joints, leg_missing_directions,
                    moving_leg_joints, role_in_name)

log = logging.getLogger(__name__)

#: a contact whose lowest point is this fraction of the standing base height above the floor in
#: the posture does not carry the robot
FLOATING_CONTACT_FRACTION = 0.01
#: a sole tilted by more than this (deg) in the posture does not stand flat
SOLE_TILT_DEG = 1.0
#: a point contact whose sphere's radius exceeds this fraction of the standing base height is a
#: wheel rather than a foot (feet of the example-robot-data quadrupeds: 4-8 %)
WHEEL_RADIUS_FRACTION = 0.1
#: a leg joint that moves its point foot by less than this fraction of the standing base height
#: per radian in the posture does not move it (its axis passes through the sphere's centre)
IDLE_JOINT_LEVER_FRACTION = 1e-3


@dataclass
class Finding:
    """One result: ``level`` error | warning | note, what was found and how to fix it."""

    level: str
    topic: str
    message: str
    fix: str = ""


@dataclass
class RobotCheck:
    """The facts about a robot and the findings of :func:`check_robot`."""

    source: str
    facts: dict[str, Any] = field(default_factory=dict)
    contacts: list[dict[str, Any]] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not any(f.level == "error" for f in self.findings)

    def add(self, level: str, topic: str, message: str, fix: str = "") -> None:
        self.findings.append(Finding(level, topic, message, fix))

    def as_dict(self) -> dict[str, Any]:
        return {"source": self.source, "ok": self.ok, "facts": self.facts,
                "contacts": self.contacts, "findings": [f.__dict__ for f in self.findings]}


class _Collect(logging.Handler):
    """Collects the warnings logged while the robot loads (e.g. placeholder effort limits)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def check_robot(name_or_path) -> RobotCheck:
    """Load ``name_or_path`` (a preset name or a description file) and check it (module
    docstring). A description that does not load gives one error finding with the loader's
    message (which names the field)."""
    from . import load_robot

    report = RobotCheck(str(name_or_path))
    collect = _Collect()
    robot_log = logging.getLogger("wholebody.robot")
    robot_log.addHandler(collect)
    propagate, robot_log.propagate = robot_log.propagate, False  # reported here, not logged too
    try:
        robot = load_robot(name_or_path)
    except DescriptionError as exc:
        report.add("error", "description", str(exc), "" if "fix" in str(exc) else
                   "fix the field named above (docs/robots.md lists every field)")
        return report
    except (ValueError, OSError) as exc:
        report.add("error", "description", str(exc))
        return report
    finally:
        robot_log.removeHandler(collect)
        robot_log.propagate = propagate
    for message in collect.messages:
        report.add("warning", "torque limits", message)
    inspect_robot(robot, report)
    _plant(robot, report)
    # the planners' searches below log each attempt that fails; their findings say what it means
    planning = logging.getLogger("wholebody.planning")
    quiet = _Collect()
    planning.addHandler(quiet)
    propagate, planning.propagate = planning.propagate, False
    try:
        if report.ok and len(robot.contacts) == 2 and all(c.spec.type == "rectangle"
                                                          for c in robot.contacts):
            _single_support(robot, report)
            _walking(robot, report)
        if report.ok and len(robot.contacts) == 4 and all(c.spec.type == "point"
                                                          for c in robot.contacts):
            _legs_reach(robot, report)
    finally:
        planning.removeHandler(quiet)
        planning.propagate = propagate
    if quiet.messages:
        log.debug("check-robot %s: %d planner message(s) summarised by the findings (first: %s)",
                  name_or_path, len(quiet.messages), quiet.messages[0])
    return report


def _plant(robot, report: RobotCheck) -> None:
    """The description's ``plant`` (the vendor's MJCF simulated in place of the twin): mapped to
    the robot as a run would (:func:`wholebody.sim.plant.check_plant`); an error naming what does
    not fit, else a note of how it is joined."""
    from ..sim.plant import PlantError, check_plant

    try:
        plant = check_plant(robot)
    except PlantError as exc:
        report.add("error", "plant", str(exc), "give the vendor's MJCF of this robot, or remove "
                   "the field to simulate the exact twin")
        return
    if plant is not None:
        report.add("note", "plant", f"{plant.label}: " + "; ".join(plant.notes))


def inspect_robot(robot, report: RobotCheck | None = None) -> RobotCheck:
    """The checks of :func:`check_robot` on a loaded robot (its findings added to ``report``, a new
    one by default): what ``wholebody run`` and ``sweep`` refuse to simulate when it has errors."""
    report = RobotCheck(robot.name) if report is None else report
    _facts(robot, report)
    _roles(robot, report)
    data = robot.model.createData()  # the posture's kinematics, for the checks below
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    _contacts_on_the_floor(robot, data, report)
    _joints_that_leave_the_feet(robot, data, report)
    _soles_the_legs_cannot_turn(robot, report)
    _support(robot, data, report)
    _gravity_torques(robot, report)
    return report


def _single_support(robot, report: RobotCheck) -> None:
    """A biped's CoG shift over each sole (single-support): whether a pose inside the joint
    limits has the CoG over the sole at its standing height, or how much lower it must go
    (:func:`~wholebody.planning.support_shift.shift_key_pose`). Not part of
    :func:`inspect_robot`: it solves a few least squares, which ``run`` need not repeat."""
    from ..planning.support_shift import (KEY_POSE_MARGIN, KEY_POSE_TOLERANCE, MAX_DROP,
                                          shift_key_pose)
    for stance, swing in (robot.contact_names, robot.contact_names[::-1]):
        drop, _, residual = shift_key_pose(robot, stance, swing, 0.0)
        if residual > KEY_POSE_TOLERANCE:
            report.add("warning", "single support",
                       f"no pose inside the joint limits (each joint {KEY_POSE_MARGIN:.0%} of its "
                       f"range inside them) puts the CoG over {stance}, down to {MAX_DROP:.0%} "
                       f"of its height below standing: single-support over it will not work",
                       "check the sole's placement and the legs' joint limits")
        elif drop > 0.0:
            report.add("note", "single support",
                       f"over {stance}, no pose inside the joint limits has the CoG at its "
                       f"standing height; one has it {1e3 * drop:.1f} mm lower (single-support "
                       f"lowers the CoG until such a pose exists)")


#: the share of a joint's torque limit that holding still on one sole may take before
#: check-robot warns that walking leaves it too little for the motion
WALKING_TORQUE_SHARE = 0.8


def _walking(robot, report: RobotCheck) -> None:
    """A biped's walking on the defaults of :class:`~wholebody.control.walking.Walking`: the
    torques that hold it still on one sole at the walking height
    (:func:`~wholebody.control.walking.single_support_load`) against the limits, and the step
    length the legs' reach allows (:class:`~wholebody.planning.footsteps.StepLimits`) against
    what the ``walk`` scenario's default speed asks. Not part of :func:`inspect_robot` (a few
    least squares and LPs)."""
    from ..control.walking import WalkingConfig, single_support_load
    from ..planning.footsteps import StepLimits
    from ..scenarios.walk import PARAMETERS

    config = WalkingConfig.for_robot(robot)
    load = single_support_load(robot, config.com_drop)
    if load is None:
        return  # _single_support has said it
    report.facts["walking_com_drop_m"] = config.com_drop
    report.facts["walking_single_support_torque_max_fraction_of_limit"] = load.share
    if load.share > WALKING_TORQUE_SHARE:
        where = (f"{1e3 * config.com_drop:.0f} mm below standing" if config.com_drop >= 0
                 else f"{-1e3 * config.com_drop:.0f} mm above standing")
        report.add("warning", "walking",
                   f"standing still on {load.stance} at the walking height ({where}, the CoG "
                   f"over the sole) takes {load.torque:.1f} Nm on '{load.joint}', "
                   f"{load.share:.0%} of its {load.limit:.1f} Nm limit: walking on the defaults "
                   f"has little torque left to move and may fall",
                   "stronger joints (torque_limits) or a walking config with another com_drop")
    limits = StepLimits.from_robot(robot, com_height_drop=config.com_drop)
    period = config.single_support + config.double_support
    speed = next(p.default for p in PARAMETERS if p.name == "speed").value(robot)
    asked = speed * period
    report.facts["walking_step_limit_m"] = limits.forward
    if limits.forward < asked:
        report.add("note", "walking",
                   f"the legs' reach bounds a step to {limits.forward:.3f} m; the walk "
                   f"scenario's default speed asks {asked:.3f} m per step: it walks slower")


#: the slope check-robot reports a quadruped's trunk attitude for (the ramp scenario's default)
REPORTED_SLOPE_DEG = 15.0


def _legs_reach(robot, report: RobotCheck) -> None:
    """A quadruped's legs' reach, as the gait planner uses it: how high each foot can rise from
    the posture within the joint limits (:func:`~wholebody.planning.reach.foot_lift`, each swing's
    apex is capped by it) and, for legs a trot can use, which trunk attitude the ramp takes on a
    15° slope (:func:`~wholebody.planning.reach.terrain_alignment_for`). Not part of
    :func:`inspect_robot`: ``run`` computes what it needs itself."""
    from ..planning.reach import REACH_MARGIN, foot_lift, terrain_alignment_for
    moving = min(len(moving_leg_joints(robot, c.name)) for c in robot.contacts)
    if moving < GAIT_LEG_JOINTS["crawl"]:  # no walking scenario takes it (noted elsewhere)
        return
    lifts = [foot_lift(robot, c.name, up_to=float(robot.q_ref[2])) for c in robot.contacts]
    report.facts["foot_lift_m"] = lifts
    span = f"{min(lifts):.3f}" + (f"-{max(lifts):.3f}" if max(lifts) > min(lifts) + 5e-4 else "")
    report.add("note", "legs", f"each foot rises at most {span} m from its standing position with "
               f"every leg joint {REACH_MARGIN:.0%} of its range inside its limits: no swing is "
               f"planned higher")
    if moving < GAIT_LEG_JOINTS["trot"]:  # the ramp trots: it refuses such legs
        return
    share, changes = terrain_alignment_for(robot, math.radians(REPORTED_SLOPE_DEG))
    report.facts["ramp_terrain_alignment"] = share

    def moved(change):
        return "some foot out of reach" if not math.isfinite(change) else f"{change:.0%}"

    report.add("note", "legs", f"standing on {REPORTED_SLOPE_DEG:g} deg up or down moves a leg "
               f"joint by up to {moved(changes[1.0])} of its range with the trunk parallel to "
               f"the slope, {moved(changes[0.0])} with it level: the ramp takes it "
               f"{'level' if share == 0.0 else 'parallel'}")


def _facts(robot, report: RobotCheck) -> None:
    report.facts = {"name": robot.name, "actuated_dof": robot.na, "mass_kg": robot.mass,
                    "standing_base_height_m": float(robot.q_ref[2]),
                    "friction": robot.friction}


def _roles(robot, report: RobotCheck) -> None:
    try:
        roles = {name: role for role, name in contact_roles(robot).items()}
    except DescriptionError as exc:  # a quadruped or biped whose contacts can't be told apart
        roles, ambiguous = {}, True
        report.add("error", "roles", str(exc))
    else:
        ambiguous = False
    kinds = sorted({c.spec.type for c in robot.contacts})
    declared = all(c.spec.role is not None for c in robot.contacts)
    if declared:
        why, fix = "its declared role", "check the contacts' roles and names"
    else:
        why = "where it is in the posture, with the base frame's x forward and y left"
        fix = ("declare role = \"...\" on every contact (the robot's forward axis may not be its "
               "base frame's x)")
    for c in robot.contacts:
        named = role_in_name(c.name, c.spec.type)
        if c.name in roles and named is not None and named != roles[c.name]:
            report.add("warning", "roles", f"contact '{c.name}' is named like the {named} "
                       f"{_part(c)} but is the {roles[c.name]} one by {why}", fix)
    if len(roles) == 4:
        joints = {name: len(moving_leg_joints(robot, name)) for name in roles}
        short = {name: n for name, n in joints.items() if n < GAIT_LEG_JOINTS["trot"]}
        if not short:
            report.add("note", "class", "a quadruped (four point feet): the quadruped scenarios "
                       "(crawl, ramp, ...) and stand apply")
        else:
            listed = ", ".join(f"{name}: {n}" for name, n in short.items())
            report.add("warning", "class",
                       f"legs with fewer than 3 moving joints ({listed}; joints with equal limits "
                       f"do not count): a foot cannot move sideways without the body, so the "
                       f"stance feet's position rows (the contact constraint, eq. 32's stance "
                       f"task) are linearly dependent; the passive WBC replaces them by an "
                       f"independent set every cycle (on either engine) and "
                       f"the trunk's sideways sway is out of reach. The trotting scenarios (crawl --set gait=trot, "
                       f"ramp) refuse such a robot; the crawl needs 2 moving joints per leg",
                       "give each leg three joints (e.g. a hip abduction) to trot")
    elif len(roles) == 2:
        report.add("note", "class", "a biped (two soles): the humanoid scenarios (push, squat, "
                   "...) and stand apply")
    elif not ambiguous:
        report.add("warning", "class", f"{len(robot.contacts)} contact(s) of type "
                   f"{'/'.join(kinds)}: neither a quadruped (four point feet) nor a biped (two "
                   f"soles); only stand applies",
                   "describe the feet as four point contacts or the soles as two rectangles")
    for c in robot.contacts:
        size = ({"radius_m": c.spec.radius} if c.spec.type == "point"
                else {"half_size_m": list(c.spec.half_size)})
        report.contacts.append({"name": c.name, "frame": c.spec.frame, "type": c.spec.type,
                                **size, "offset_m": list(c.spec.offset), "role": roles.get(c.name),
                                "leg_joints": list(leg_joints(robot, c.name))})


def _part(contact) -> str:
    return "foot" if contact.spec.type == "point" else "sole"


def _contacts_on_the_floor(robot, data, report: RobotCheck) -> None:
    """Every contact touches the floor in the posture (the robot is placed so that the lowest
    does), and soles lie flat."""
    gap_limit = FLOATING_CONTACT_FRACTION * float(robot.q_ref[2])
    for c, row in zip(robot.contacts, report.contacts):
        placement = data.oMf[c.frame_id]
        height = float(robot.contact_lowest_point(c, placement)[2])
        row["height_above_floor_m"] = height
        row["touches_floor"] = height <= gap_limit
        if height > gap_limit:
            report.add("error", "posture", f"contact '{c.name}' is {1000 * height:.1f} mm above "
                       f"the floor in the posture: the robot does not stand on it",
                       "choose a posture (SRDF state or a joint table) with all feet down, or "
                       "check the contact's frame, offset and radius/half_size")
        wheel = WHEEL_RADIUS_FRACTION * float(robot.q_ref[2])
        if c.spec.type == "point" and c.spec.radius > wheel:
            report.add("note", "contacts", f"contact '{c.name}' is a sphere of radius "
                       f"{c.spec.radius:.3g} m, {c.spec.radius / float(robot.q_ref[2]):.0%} of the "
                       f"standing height: it rolls when its leg turns it and carries no moment, "
                       f"which slopes may need (docs/robots.md, wheels)")
        if c.spec.type == "rectangle":
            tilt = math.degrees(math.acos(min(1.0, abs(float(placement.rotation[2, 2])))))
            row["tilt_deg"] = tilt
            if tilt > SOLE_TILT_DEG:
                report.add("warning", "posture", f"sole '{c.name}' is tilted {tilt:.1f} deg in "
                           f"the posture: it touches the floor with an edge",
                           "adjust the ankle joints of the posture until the soles are flat")


def _joints_that_leave_the_feet(robot, data, report: RobotCheck) -> None:
    """Leg joints that do not move their point foot in the posture (an axis through the sphere's
    centre, like Centauro's ankle yaws through its wheels): no foot task determines them; the
    passive WBC's posture regulariser holds them, the quasi-static baseline's static map only
    through a PD without the legs' dynamics."""
    pin.computeJointJacobians(robot.model, data, robot.q_ref)  # the posture's, as in ``data``
    lever = IDLE_JOINT_LEVER_FRACTION * float(robot.q_ref[2])
    idle = []
    for c in robot.contacts:
        if c.spec.type != "point":
            continue
        J = pin.getFrameJacobian(robot.model, data, c.frame_id, pin.LOCAL_WORLD_ALIGNED)[:3]
        for joint in leg_joints(robot, c.name):
            column = 6 + robot.joint_names.index(joint)
            if np.linalg.norm(J[:, column]) < lever:
                idle.append(joint)
    if idle:
        report.add("note", "contacts", f"joint(s) {', '.join(idle)} turn their foot about the "
                   f"sphere's centre (the axis passes through it): no foot task moves them, only "
                   f"the posture regulariser holds them",
                   "lock them (locked_joints) unless the robot needs them")


#: the sole motions a leg's Jacobian can miss, by the largest component (sole frame)
_SOLE_MOTIONS = ("slide it along its x axis", "slide it along its y axis", "lift it",
                 "roll it (about its x axis: no ankle roll)", "pitch it (about its y axis)",
                 "yaw it (about its normal)")


def _soles_the_legs_cannot_turn(robot, report: RobotCheck) -> None:
    """A sole whose leg moves it in fewer than 6 directions (a five-joint leg: no ankle roll).
    Along the missing direction u (:func:`~wholebody.robots.roles.leg_missing_directions`: the
    left null space of the leg's Jacobian in the sole frame) a contact wrench costs no joint
    torque: the leg cannot set that part of the sole's wrench (with no ankle roll, the sole's
    moment about its x axis, i.e. its lateral CoP), which then follows from the trunk's motion;
    the sole cannot stay flat while the trunk moves along u relative to it, so single support
    over it cannot hold the trunk's pose."""
    for c in robot.contacts:
        if c.spec.type != "rectangle":
            continue
        joints = leg_joints(robot, c.name)
        if not joints:
            continue
        directions = leg_missing_directions(robot, c.name)
        if not len(directions):
            continue
        rank = 6 - len(directions)
        missing = directions[0]
        roll = abs(missing[3]) > 0.3  # a roll, possibly with a sideways slide
        what = (_SOLE_MOTIONS[3] + (" with a sideways slide" if abs(missing[1]) > 0.3 else "")
                if roll else _SOLE_MOTIONS[int(np.argmax(np.abs(missing)))])
        report.add(
            "warning", "legs",
            f"sole '{c.name}': its leg ({len(joints)} joint(s): {', '.join(joints)}) moves the sole "
            f"in {rank} of 6 directions; it cannot {what} relative to the trunk. A contact wrench "
            f"along that direction costs the leg no torque, so the controllers cannot set it"
            + (": this sole's lateral CoP follows the trunk, the lateral CoP moves only by "
               "shifting weight to the other sole, and single support on it cannot hold the "
               "trunk upright" if roll else "; single support on it cannot hold the trunk's pose"),
            "expect double support only (stand, push); single support and stepping need a "
            "6-joint leg")


def _support(robot, data, report: RobotCheck) -> None:
    """The CoM lies over the polygon of the contacts that touch the floor in the posture (margin
    to its nearest edge)."""
    com = pin.centerOfMass(robot.model, data, robot.q_ref)
    points = []
    for c, row in zip(robot.contacts, report.contacts):
        if not row["touches_floor"]:
            continue
        placement = data.oMf[c.frame_id]
        if c.spec.type == "point":
            points.append(placement.translation[:2])
        else:
            hx, hy = c.spec.half_size
            for sx in (-1, 1):
                for sy in (-1, 1):
                    points.append((placement.act(np.array([sx * hx, sy * hy, 0.0])))[:2])
    try:
        hull = ConvexHull(np.array(points))
    except (QhullError, ValueError):
        report.add("error", "support", "the contacts span no support area (fewer than three "
                   "points, or all on a line)", "add contacts or give the soles their size")
        return
    # hull.equations: n . x + d <= 0 inside; the margin is the smallest distance to an edge
    margin = float(-np.max(hull.equations[:, :2] @ com[:2] + hull.equations[:, 2]))
    report.facts["com_support_margin_m"] = margin
    if margin <= 0:
        report.add("error", "support", f"the CoM is not inside the polygon of the contacts on "
                   f"the floor in the posture (margin {1000 * margin:.1f} mm): the robot cannot "
                   f"stand", "choose another posture, or check the contacts' frames")


def _gravity_torques(robot, report: RobotCheck) -> None:
    """The torques that hold the robot still in its posture (contact-consistent gravity
    compensation) lie within its limits."""
    from ..control.standing import gravity_compensation

    robot.update(robot.q_ref, np.zeros(robot.nv))
    need, _ = gravity_compensation(robot)
    lo, hi = robot.torque_bounds(robot.q_ref)
    ratio = np.maximum(need / np.maximum(hi, 1e-12), need / np.minimum(lo, -1e-12))
    worst = int(np.argmax(ratio))
    report.facts["holding_torque_max_fraction_of_limit"] = float(ratio[worst])
    if ratio[worst] > 1.0:
        report.add("error", "torque limits", f"holding the posture needs {need[worst]:.1f} Nm on "
                   f"'{robot.joint_names[worst]}', beyond its limit "
                   f"[{lo[worst]:.1f}, {hi[worst]:.1f}] Nm",
                   "check torque_limits (scale, overrides) or choose a less crouched posture")


def load_fit_robot(name_or_path: str):
    """Load a preset or description file for a simulation: ValueError (naming the file) for a file
    that cannot be read, DescriptionError for a bad description, and ValueError with the first
    error of :func:`inspect_robot` (a contact off the floor, the CoM outside the support, holding
    torques beyond the limits: such a robot falls whatever the scenario)."""
    from . import load_robot

    try:
        robot = load_robot(name_or_path)
    except UnicodeDecodeError as exc:
        raise ValueError(f"robot file {name_or_path}: not UTF-8 text ({exc.reason})") from None
    except OSError as exc:
        raise ValueError(f"robot {name_or_path}: {exc.strerror or exc}"
                         f"{f' ({exc.filename})' if exc.filename else ''}") from None
    errors = [f for f in inspect_robot(robot).findings if f.level == "error"]
    if errors:
        raise ValueError(f"robot '{robot.name}': {errors[0].topic}: {errors[0].message} (see "
                         f"`wholebody check-robot {name_or_path}`)")
    return robot
