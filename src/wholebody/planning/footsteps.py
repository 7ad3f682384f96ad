"""Footsteps for humanoid walking: where each sole lands, within what its legs can reach.

Conventions. A footstep is the world position of a sole's contact frame (the sole's centre) at
touchdown and the sole's heading (yaw about world z). A swing sole is bounded relative to the
stance sole, in the stance sole's heading frame: x forward, y toward the swing side, so that a
lateral distance is positive when the soles are apart. A relative yaw is "outward" when the
swing sole turns away from the stance side (a left swing sole turning left, a right one turning
right) and "inward" when it turns toward it, its toes toward the stance sole.

Limits (:class:`StepLimits`) come from the robot's own kinematics and soles. The base stands
level at the posture's height (lowered by the walking CoM drop), the soles flat on the floor
where they stand in the posture; :func:`sole_reach` measures how far each sole frame can slide on
the floor from there (a sequence of linear programs over the leg's joint steps, as
:func:`~.reach.foot_lift`), forward and backward along the soles' heading (the mean of their
yaws: the base's own axes need not point forward, iCub's faces backwards) and outward and inward
across it, its orientation held and its leg's joints ``margin`` of their range inside their
limits, or halfway to a limit from where the lowered stance has them if that leaves them more
room (:func:`_joint_bounds`: a joint the stance already holds within its margin is not pinned
there). With f and b the smaller of the two legs' reaches forward and backward:

* stride: a step of length L forward is bounded by both legs. The trailing leg: the double
  support carries the pelvis toward the leading sole and the swing sole leaves slowly while the
  pelvis moves on, so the trailing sole ends up about a whole step behind the pelvis (measured
  on talos14 and iCub: 0.6-0.7 L behind at lift-off, up to 0.85 L within 0.1 s after it), hence
  L <= b. The leading leg: it lands about half a step ahead of the pelvis (0.5-0.65 L measured),
  hence L <= 2 f. So ``forward = share * min(b, 2 f)``; a backward step swaps the legs' roles,
  ``backward = share * min(f, 2 b)``. Closed loop (capture-point walking of
  :class:`~wholebody.control.Walking`, 10 steps), Alexander (b < 2 f) walks with steps up to
  0.22 m (0.87 b) and falls with 0.24 m (0.95 b), with 0.27 m after 4 steps, its trailing knee
  straightened onto its limit; iCub (2 f < b) still walks with steps of 2 f, its ankles at their
  limits, and with share * 2 f no joint reaches a limit. A robot whose lowered stance holds a
  joint near its limit (romeo's ankle pitch, near its stop when its knees bend) has almost no
  reach that way, so almost no stride: flat soles cannot step further at that height, and it
  walks higher (:func:`~wholebody.control.walking.walking_com_drop` picks the height);
* width: the stance leg's sideways reach carries the pelvis over the stance sole, so only the
  swing leg's widens the step: at most the standing width plus its outward reach; at least the
  standing width minus its inward reach, and never so narrow that the soles' edges come closer
  than :data:`SOLE_GAP` of a sole's width (nor, whatever the soles, above the standing width);
  the standing width is the soles' distance across their heading;
* yaw: with the pelvis heading between the soles, a relative yaw turns both hip-yaw joints (the
  leg joint whose axis is nearest the base's vertical in the posture, within
  :data:`_YAW_AXIS_ANGLE`) by half of it, the same way (both outward or both inward): at most
  twice the smaller hip's range that way, capped at :data:`YAW_CAP`; turning inward is also at
  most :data:`YAW_IN_SHARE` of turning outward, as the toes would collide. A leg without a
  hip-yaw joint does not turn its sole.

The reaches are scaled by ``share`` (< 1): a leg at its full reach has a straight knee, a
singularity, and no margin left to balance with; Alexander's 0.87 b above is the most measured
to walk.

:class:`FootstepPlanner` turns a velocity command into footsteps with a unicycle path (the path
frame moves with the command, the soles land either side of it at the standing width) and
clamps each footstep against the stance sole (:func:`clamp_step`, also used to adjust a step
toward a capture point, Englsberger et al. 2015).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin
from scipy.optimize import linprog, lsq_linear

from ..robots.roles import biped_soles, joint_axis
from .reach import REACH_MARGIN, _angles, _leg, _moved
from .support_shift import joint_range

__all__ = ["Footstep", "FootstepPlanner", "SoleReach", "StepLimits", "clamp_step", "sole_reach"]

#: share of each measured reach a step may use
STEP_SHARE = 0.8
#: gap between the soles' edges at the narrowest step, as a share of a sole's width
SOLE_GAP = 0.1
#: largest relative yaw of the soles (rad), whatever the hips allow
YAW_CAP = 0.4
#: inward yaw as a share of outward yaw (the toes would collide)
YAW_IN_SHARE = 0.5
#: largest joint step of one linear program (rad or m)
_TRUST = 0.1
#: cost of a metre (or radian) of drift of the held coordinates against a metre of reach
_DRIFT_COST = 100.0
#: a hip-yaw joint's axis is within this angle of the base's vertical in the posture: more of
#: its turn is a yaw than a tilt (G1's, along the thigh, is 27 deg from it in the posture, 34 deg
#: at the walking CoM drop)
_YAW_AXIS_ANGLE = np.radians(45.0)


@dataclass(frozen=True)
class Footstep:
    """Where a sole lands: ``contact``'s frame at ``position`` (world, 3,) with heading ``yaw``."""

    contact: str
    position: np.ndarray
    yaw: float


class SoleReach(NamedTuple):
    """How far (m, >= 0) a sole frame slides on the floor from its standing place: forward and
    backward along the soles' heading, outward (away from the other sole) and inward across it."""

    forward: float
    backward: float
    outward: float
    inward: float


def _yaw_matrix(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _stance_configuration(robot, com_height_drop: float, margin: float):
    """The base level at the posture's height lowered by ``com_height_drop``, each leg solved
    (within its joint limits) so that its sole frame is where it stands in the posture, flat:
    ``(q, the joints' bounds (lo, hi) over q[7:] (:func:`_joint_bounds`), the soles' placements
    in the posture, flat)``. ValueError when a sole cannot be held."""
    model = robot.model
    data = model.createData()
    q_ref = robot.q_ref
    pin.framesForwardKinematics(model, data, q_ref)
    soles = {}
    for contact in biped_soles(robot):
        M = data.oMf[robot.contact(contact).frame_id]
        flat = pin.rpy.rpyToMatrix(0.0, 0.0, pin.rpy.matrixToRpy(M.rotation)[2])
        soles[contact] = pin.SE3(flat, M.translation.copy())
    yaw = pin.rpy.matrixToRpy(pin.Quaternion(q_ref[3:7]).normalized().toRotationMatrix())[2]
    q = q_ref.copy()
    q[2] -= com_height_drop
    q[3:7] = pin.Quaternion(pin.rpy.rpyToMatrix(0.0, 0.0, yaw)).coeffs()
    for contact, target in soles.items():
        frame = robot.contact(contact).frame_id
        iv, ranges, joints = _leg(robot, contact)
        lo, hi = ranges[:, 0], ranges[:, 1]
        for _ in range(100):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            error = pin.log6(data.oMf[frame].actInv(target)).vector
            if np.max(np.abs(error)) < 1e-12:
                break
            J = pin.getFrameJacobian(model, data, frame, pin.LOCAL)[:, iv]
            angles = _angles(q, joints)
            step = lsq_linear(J, error, bounds=(lo - angles, hi - angles + 1e-12))
            q = _moved(model, q, iv, np.clip(angles + step.x, lo, hi) - angles)
        pin.framesForwardKinematics(model, data, q)
        if np.max(np.abs(pin.log6(data.oMf[frame].actInv(target)).vector)) > 1e-6:
            raise ValueError(f"com_height_drop: {com_height_drop} m lower, {contact} cannot stand "
                             f"flat where it stands in the posture within its joint limits")
    return q, _joint_bounds(robot, margin, q), soles


def _joint_bounds(robot, margin: float, q) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) over q[7:]: each limited joint ``margin`` of its range inside its limits, or
    halfway from where ``q`` has it to the limit when that leaves it more room; the others
    unbounded. The half keeps a joint that the stance already holds within its margin from being
    pinned where it stands (its leg would then reach nowhere that way, although the joint has
    room left: iCub's hip roll stands within its margin in the posture) and is continuous in
    ``q``: a joint beyond twice the margin from a limit keeps the margin."""
    model = robot.model
    lo, hi = np.full(model.nv - 6, -np.inf), np.full(model.nv - 6, np.inf)
    for joint in model.joints[1:]:
        limits = joint_range(model, joint)
        if limits is None:
            continue
        (low, high), i, k = limits, joint.idx_q, joint.idx_v - 6
        inset = margin * (high - low)
        lo[k] = min(low + inset, 0.5 * (q[i] + low))
        hi[k] = max(high - inset, 0.5 * (q[i] + high))
    return lo, hi


def _slide(robot, contact: str, q, bounds, direction, iterations: int = 100) -> float:
    """How far ``contact``'s frame moves along the horizontal unit ``direction`` (world) from
    where it is in ``q``, its height, its lateral position and its orientation held, only its
    leg's joints moving within ``bounds`` (over q[7:])."""
    model = robot.model
    data = model.createData()
    q = q.copy()
    iv, _, joints = _leg(robot, contact)
    lo, hi = bounds[0][iv - 6], bounds[1][iv - 6]
    frame = robot.contact(contact).frame_id
    pin.framesForwardKinematics(model, data, q)
    start = data.oMf[frame].copy()
    d = np.array([direction[0], direction[1], 0.0])
    held = np.array([[-direction[1], direction[0], 0.0], [0.0, 0.0, 1.0]])  # lateral, height
    n = len(iv)
    # variables: joint steps (n), drift slacks s+ (5), s- (5); minimise -reach + cost * |drift|
    cost = np.concatenate([np.zeros(n), np.full(10, _DRIFT_COST)])
    for _ in range(iterations):
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        M = data.oMf[frame]
        J = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)[:, iv]
        drift = np.concatenate([held @ (M.translation - start.translation),
                                pin.log3(M.rotation @ start.rotation.T)])
        cost[:n] = -(d @ J[:3])
        A_eq = np.hstack([np.vstack([held @ J[:3], J[3:]]), -np.eye(5), np.eye(5)])
        angles = _angles(q, joints)
        step = linprog(cost, A_eq=A_eq, b_eq=-drift, method="highs",
                       bounds=[(max(lo[k] - a, -_TRUST), min(hi[k] - a, _TRUST))
                               for k, a in enumerate(angles)] + [(0.0, None)] * 10)
        if step.status != 0:
            break
        q = _moved(model, q, iv, np.clip(angles + step.x[:n], lo, hi) - angles)
        if np.max(np.abs(step.x[:n])) < 1e-9:
            break
    pin.framesForwardKinematics(model, data, q)
    return max(float(d @ (data.oMf[frame].translation - start.translation)), 0.0)


def sole_reach(robot, contact: str, com_height_drop: float = 0.0,
               margin: float = REACH_MARGIN) -> SoleReach:
    """How far ``contact``'s sole frame slides on the floor from where it stands in the posture,
    along the soles' heading (:func:`_heading`) and across it, the base level and
    ``com_height_drop`` lower than in the posture, the sole flat, each of its leg's joints
    ``margin`` of its range inside its limits or, when that leaves it more room, halfway from
    where the lowered stance has it to the limit (:func:`_joint_bounds`)."""
    q, bounds, soles = _stance_configuration(robot, com_height_drop, margin)
    return _reach(robot, contact, q, bounds, _heading(robot, soles))


def _heading(robot, soles) -> tuple[np.ndarray, np.ndarray]:
    """(x, y): the unit horizontal vectors (world) of the soles' heading, the mean of the two
    soles' yaws as they stand (``soles``: their placements), and of its left. The base's own axes
    need not be these: iCub's base frame faces backwards."""
    yaws = [math.atan2(soles[c].rotation[1, 0], soles[c].rotation[0, 0])
            for c in biped_soles(robot)]
    yaw = yaws[0] + 0.5 * _wrap(yaws[1] - yaws[0])
    return np.array([math.cos(yaw), math.sin(yaw)]), np.array([-math.sin(yaw), math.cos(yaw)])


def _reach(robot, contact: str, q, bounds, heading) -> SoleReach:
    """:func:`sole_reach` from the stance ``q`` within ``bounds`` along ``heading`` = (x, y)."""
    x, y = heading
    side = 1.0 if contact == biped_soles(robot)[0] else -1.0
    return SoleReach(*(_slide(robot, contact, q, bounds, d)
                       for d in (x, -x, side * y, -side * y)))


def _hip_yaw_joint(robot, contact: str):
    """``contact``'s hip-yaw joint: its leg's joint whose axis is nearest the base's vertical in
    the posture, if within :data:`_YAW_AXIS_ANGLE` of it → its Pinocchio joint id, else None.
    Found in the posture, as :func:`~wholebody.robots.roles.pitch_joints` finds the pitch joints:
    lowering the stance tilts an axis along the thigh (G1's) further from the vertical."""
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, robot.q_ref)
    base = data.oMi[1].rotation
    best, best_z = None, math.cos(_YAW_AXIS_ANGLE)
    for i in _leg(robot, contact)[0]:
        jid = next(j for j in range(1, model.njoints) if model.joints[j].idx_v == i)
        z = abs((base.T @ data.oMi[jid].rotation @ joint_axis(robot, model.names[jid], data))[2])
        if z >= best_z:
            best, best_z = jid, z
    return best


def _hip_yaw_ranges(robot, q, bounds) -> tuple[float, float]:
    """(outward, inward): the smaller over the legs of how far (rad) each leg's hip-yaw joint
    (:func:`_hip_yaw_joint`) turns its sole away from and toward the other sole from ``q`` within
    ``bounds``, its range times its axis's vertical component in ``q`` (a tilted axis turns the
    sole less); (0, 0) when a leg has none."""
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    base = data.oMi[1].rotation
    outward, inward = np.inf, np.inf
    for side, contact in zip((1.0, -1.0), biped_soles(robot)):
        jid = _hip_yaw_joint(robot, contact)
        if jid is None:
            return 0.0, 0.0
        i, k = model.joints[jid].idx_q, model.joints[jid].idx_v
        vertical = (base.T @ data.oMi[jid].rotation @ joint_axis(robot, model.names[jid], data))[2]
        up, down = (abs(vertical) * (bounds[1][k - 6] - q[i]),
                    abs(vertical) * (q[i] - bounds[0][k - 6]))
        out, inn = (up, down) if side * vertical > 0 else (down, up)
        outward, inward = min(outward, max(out, 0.0)), min(inward, max(inn, 0.0))
    return float(outward), float(inward)


@dataclass(frozen=True)
class StepLimits:
    """Where a swing sole may land relative to the stance sole, in the stance sole's heading
    frame (x forward, y toward the swing side = outward positive); lengths in m, angles in rad.

    ``forward``/``backward``: largest displacement along x (:meth:`from_robot`: share * min(b,
    2 f) and share * min(f, 2 b), f and b the legs' reaches forward and backward: a step's
    trailing leg reaches about the whole step behind the pelvis, its leading leg about half of
    it ahead; module docstring); ``width_min``/``width_max``: lateral distance between the sole
    frames; ``nominal_width``: that distance standing in the posture; ``yaw_out``/``yaw_in``:
    largest relative yaw turning away from / toward the stance side."""

    forward: float
    backward: float
    width_min: float
    width_max: float
    nominal_width: float
    yaw_out: float
    yaw_in: float

    def __post_init__(self):
        for name in ("forward", "backward", "width_min", "width_max", "nominal_width",
                     "yaw_out", "yaw_in"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name}: expected a finite number >= 0, got {value!r}")
        if not self.width_min <= self.nominal_width <= self.width_max:
            raise ValueError(f"width_min <= nominal_width <= width_max expected, got "
                             f"{self.width_min}, {self.nominal_width}, {self.width_max}")

    @classmethod
    def from_robot(cls, robot, com_height_drop: float = 0.0, margin: float = REACH_MARGIN,
                   share: float = STEP_SHARE) -> "StepLimits":
        """The limits of ``robot``'s steps from its kinematics and soles (module docstring): the
        reaches of :func:`sole_reach` along and across the soles' heading (the smaller of the two
        legs'), the stride from the trailing leg's reach back and the leading leg's forward,
        times ``share``."""
        if not (math.isfinite(com_height_drop) and abs(com_height_drop) < robot.q_ref[2]):
            raise ValueError(f"com_height_drop: expected |drop| < the standing base height "
                             f"{robot.q_ref[2]:.3f} m (negative: higher), got {com_height_drop!r}")
        if not (math.isfinite(margin) and 0.0 <= margin < 0.5):
            raise ValueError(f"margin: expected 0 <= margin < 0.5, got {margin!r}")
        if not (math.isfinite(share) and 0.0 < share <= 1.0):
            raise ValueError(f"share: expected 0 < share <= 1, got {share!r}")
        left, right = biped_soles(robot)
        least, nominal, (out, inn) = _stance_reach(robot, com_height_drop, margin)
        half_widths = [robot.contact(c).spec.half_size[1] for c in (left, right)]
        # the sole frames are the soles' centres: their edges touch at the sum of half widths
        apart = sum(half_widths) + SOLE_GAP * 2.0 * max(half_widths)
        width_min = min(max(nominal - share * least.inward, apart), nominal)
        forward = share * min(least.backward, 2.0 * least.forward)
        backward = share * min(least.forward, 2.0 * least.backward)
        yaw_out = min(YAW_CAP, share * 2.0 * out)
        limits = dict(forward=forward, backward=backward, width_min=width_min,
                      width_max=nominal + share * least.outward, nominal_width=nominal,
                      yaw_out=yaw_out, yaw_in=min(YAW_IN_SHARE * yaw_out, share * 2.0 * inn))
        return cls(**{name: float(value) for name, value in limits.items()})


def _stance_reach(robot, com_height_drop: float, margin: float
                  ) -> tuple[SoleReach, float, tuple[float, float]]:
    """(the smaller of the two legs' :func:`sole_reach`, the soles' lateral distance standing in
    the posture, :func:`_hip_yaw_ranges`) at ``com_height_drop``, each joint ``margin`` inside its
    limits: what :meth:`StepLimits.from_robot` derives its limits from. Iterative (a linear
    program per Newton step and direction), so kept in ``robot.derived`` under the drop, the
    margin, the posture and the joint limits it was computed from (a ValueError too: a sole that
    cannot stand flat at that height)."""
    model = robot.model
    key = ("stance reach", float(com_height_drop), float(margin), robot.q_ref.tobytes(),
           model.lowerPositionLimit.tobytes(), model.upperPositionLimit.tobytes())
    if key not in robot.derived:
        try:
            left, right = biped_soles(robot)
            q, bounds, soles = _stance_configuration(robot, com_height_drop, margin)
            heading = _heading(robot, soles)
            reach = [_reach(robot, c, q, bounds, heading) for c in (left, right)]
            least = SoleReach(*(float(r) for r in np.min(np.array(reach), axis=0)))
            y = heading[1]
            nominal = abs(float(y @ (soles[left].translation - soles[right].translation)[:2]))
            robot.derived[key] = (least, nominal, _hip_yaw_ranges(robot, q, bounds))
        except ValueError as error:
            robot.derived[key] = error
    value = robot.derived[key]
    if isinstance(value, ValueError):
        raise ValueError(*value.args)
    return value


def clamp_step(stance, stance_side: int, target_xy, target_yaw: float, limits: StepLimits
               ) -> tuple[np.ndarray, float]:
    """The nearest footstep to (``target_xy``, ``target_yaw``) within ``limits`` of the stance
    sole ``stance`` = (position, yaw) → (xy (2,), yaw): the relative yaw clamped to
    [-yaw_in, yaw_out] (outward positive), then the position, in the stance sole's heading frame,
    clamped to [-backward, forward] along it and [width_min, width_max] outward. ``stance_side``:
    +1 when the stance sole is the left one, -1 the right."""
    if stance_side not in (1, -1):
        raise ValueError(f"stance_side: expected +1 (left stance) or -1 (right), got "
                         f"{stance_side!r}")
    position, yaw0 = stance
    p0 = np.asarray(position, dtype=float)[:2]
    target = np.asarray(target_xy, dtype=float)[:2]
    if not (np.all(np.isfinite(target)) and math.isfinite(target_yaw)):
        raise ValueError(f"target: expected finite values, got {target_xy!r}, {target_yaw!r}")
    outward_yaw = -stance_side * _wrap(float(target_yaw) - float(yaw0))
    outward_yaw = min(max(outward_yaw, -limits.yaw_in), limits.yaw_out)
    R = _yaw_matrix(float(yaw0))
    dx, dy = R.T @ (target - p0)
    dx = min(max(dx, -limits.backward), limits.forward)
    width = min(max(-stance_side * dy, limits.width_min), limits.width_max)
    xy = p0 + R @ np.array([dx, -stance_side * width])
    return xy, float(yaw0) - stance_side * outward_yaw


def _command_at(command, k: int) -> np.ndarray:
    value = command(k) if callable(command) else command
    try:
        c = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        c = np.full(1, np.nan)
    if c.shape != (3,) or not np.all(np.isfinite(c)):
        raise ValueError(f"command: expected finite (vx, vy, yaw_rate), got {value!r}"
                         + (f" for step {k}" if callable(command) else ""))
    return c


class FootstepPlanner:
    """Footsteps of ``robot``'s two soles within ``limits`` (default
    :meth:`StepLimits.from_robot`): from a velocity command or from a list."""

    def __init__(self, robot, limits: StepLimits | None = None):
        self.robot = robot
        self.soles = biped_soles(robot)
        self.limits = StepLimits.from_robot(robot) if limits is None else limits

    def _side(self, contact: str) -> int:
        return 1 if contact == self.soles[0] else -1

    def _other(self, contact: str) -> str:
        return self.soles[1] if contact == self.soles[0] else self.soles[0]

    def _feet(self, feet) -> dict[str, tuple[np.ndarray, float]]:
        if not isinstance(feet, dict) or set(feet) != set(self.soles):
            names = list(feet) if isinstance(feet, dict) else feet
            raise ValueError(f"feet: expected the poses of the soles {list(self.soles)}, got "
                             f"{names!r}")
        out = {}
        for name, (position, yaw) in feet.items():
            p = np.asarray(position, dtype=float).reshape(-1)
            if p.shape != (3,) or not (np.all(np.isfinite(p)) and math.isfinite(yaw)):
                raise ValueError(f"feet[{name!r}]: expected a finite (position (3,), yaw), got "
                                 f"{(position, yaw)!r}")
            out[name] = (p, float(yaw))
        return out

    def _place(self, feet, contact: str, xy, yaw: float, z: float | None = None) -> Footstep:
        """``contact`` toward (xy, yaw), clamped against the other sole in ``feet``; updates
        ``feet``."""
        stance = feet[self._other(contact)]
        xy, yaw = clamp_step(stance, -self._side(contact), xy, yaw, self.limits)
        step = Footstep(contact, np.array([xy[0], xy[1], stance[0][2] if z is None else z]), yaw)
        feet[contact] = (step.position, step.yaw)
        return step

    def from_velocity(self, feet, swing_first: str, command, step_period: float,
                      steps: int) -> list[Footstep]:
        """``steps`` footsteps, the soles alternating from ``swing_first``, following ``command``:
        (vx, vy, yaw_rate) in the path frame (m/s, m/s, rad/s), or a callable k -> that for step
        k. ``feet``: {sole: (position (3,), yaw)} now.

        The path frame starts half the standing width inward of the stance sole (the other than
        ``swing_first``), at its heading: the soles' midpoint when they stand side by side, and
        where the previous plan's path was when re-planning mid-walk. Each step it turns by
        yaw_rate T and moves by its velocity times T along its heading halfway through the
        turn (T = ``step_period``), and the swing sole is aimed half the standing width to its
        side of it, at its heading, then clamped (:func:`clamp_step`) against the stance sole, at
        its height; sideways and turning, the leading sole takes the share of the motion that
        the following one cannot (:meth:`_lead_and_follow`). The path frame then follows the sole as landed, so a command beyond the
        limits saturates the steps instead of leaving the feet behind. A zero command steps in
        place: two steps bring the soles side by side at the standing width."""
        feet = self._feet(feet)
        if swing_first not in self.soles:
            raise ValueError(f"swing_first: expected one of {list(self.soles)}, got "
                             f"{swing_first!r}")
        if not (isinstance(step_period, (int, float)) and math.isfinite(step_period)
                and step_period > 0.0):
            raise ValueError(f"step_period: expected a finite number > 0, got {step_period!r}")
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 0:
            raise ValueError(f"steps: expected an integer >= 0, got {steps!r}")
        if not callable(command):
            _command_at(command, 0)
        half = 0.5 * self.limits.nominal_width
        stance_position, yaw = feet[self._other(swing_first)]
        path = stance_position[:2] - _yaw_matrix(yaw) @ np.array(
            [0.0, self._side(self._other(swing_first)) * half])
        swing, plan = swing_first, []
        for k in range(int(steps)):
            vx, vy, rate = _command_at(command, k)
            side = self._side(swing)
            vy, rate = self._lead_and_follow(side, vy, rate, step_period)
            path = path + _yaw_matrix(yaw + 0.5 * rate * step_period) @ np.array([vx, vy]) \
                * step_period
            yaw += rate * step_period
            step = self._place(feet, swing, path + _yaw_matrix(yaw) @ np.array([0.0, side * half]),
                               yaw)
            plan.append(step)
            yaw = step.yaw
            path = step.position[:2] - _yaw_matrix(yaw) @ np.array([0.0, side * half])
            swing = self._other(swing)
        return plan

    def _lead_and_follow(self, side: int, vy: float, rate: float,
                         step_period: float) -> tuple[float, float]:
        """(lateral speed, yaw rate) of the path during a step of the sole on ``side``.

        Sideways and turning, the sole on the side of the motion leads and the other follows;
        the follower can close in only down to the narrowest width and turn in only by
        ``yaw_in``. What it cannot take of its share (v T, omega T) the leader takes on top of
        its own, so the pair still covers 2 v T and 2 omega T while both stay in reach."""
        lim = self.limits
        spare = {"vy": lim.nominal_width - lim.width_min, "rate": lim.yaw_in}
        out = {"vy": vy, "rate": rate}
        for key, value in out.items():
            excess = max(0.0, abs(value) * step_period - spare[key]) / step_period
            leads = np.sign(value) == side
            out[key] = value + math.copysign(excess, value) * (1.0 if leads else -1.0)
        return out["vy"], out["rate"]

    def from_list(self, feet, steps) -> list[Footstep]:
        """Explicit footsteps ``steps`` = [(sole, xy or xyz, yaw), ...], taken in order from
        ``feet`` ({sole: (position (3,), yaw)}), each clamped (:func:`clamp_step`) against the
        sole standing when it swings; it lands at the stance sole's height unless a z is given.
        ValueError for an unknown sole or a sole that steps twice in a row."""
        feet = self._feet(feet)
        plan, previous = [], None
        for k, entry in enumerate(steps):
            try:
                contact, position, yaw = entry
                p = np.asarray(position, dtype=float).reshape(-1)
                yaw = float(yaw)
            except (TypeError, ValueError):
                raise ValueError(f"steps[{k}]: expected (sole, xy or xyz, yaw), got "
                                 f"{entry!r}") from None
            if contact not in self.soles:
                raise ValueError(f"steps[{k}]: unknown sole {contact!r}; expected one of "
                                 f"{list(self.soles)}")
            if contact == previous:
                raise ValueError(f"steps[{k}]: {contact!r} steps twice in a row (steps[{k - 1}] "
                                 f"is the same sole); the soles alternate")
            if p.shape not in ((2,), (3,)) or not (np.all(np.isfinite(p)) and math.isfinite(yaw)):
                raise ValueError(f"steps[{k}]: expected a finite xy or xyz and yaw, got "
                                 f"{entry!r}")
            plan.append(self._place(feet, contact, p[:2], yaw, p[2] if p.shape == (3,) else None))
            previous = contact
        return plan
