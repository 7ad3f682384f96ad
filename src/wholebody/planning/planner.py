"""The gait planner: schedule + trunk reference + footholds + swing trajectories, once per cycle.

This is the "planner" box of Fahmi et al. 2019 (Fig. 1): from a user velocity command it
produces, every control cycle, what the whole-body controller consumes -- which feet are in stance
(eq. 10) and which swing (eqs. 11-12), the desired swing-foot position/velocity/acceleration (eqs.
5-6), the stance anchors ``x̂_st`` of the stance task (eq. 32: "a sample of the foot position at the
touchdown"), the terrain normals for the friction cones (eq. 13), and the trunk reference (eq. 4).

Per leg the planner keeps a small state: the stance anchor, and during a swing the trajectory
latched at lift-off (lift-off position -> touchdown target, computed once at lift-off with the
Raibert heuristic on the nominal trunk path). :meth:`GaitPlanner.update` must be called with
non-decreasing times (it detects lift-offs and touchdowns between calls; a swing skipped entirely
between two calls is taken to have landed on its target); it writes into one
preallocated :class:`PlanState` and returns it, so a caller that keeps samples must ``copy()`` them.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from ..robots.roles import contact_roles
from .footholds import Foothold, Footprint, raibert_foothold
from .gait import GaitSchedule
from .reach import foot_lift
from .swing import SwingTrajectory
from .terrain import Terrain
from .trunk import CrawlSway, StartShift, TrunkReference, TrunkState, VelocityCommand

log = logging.getLogger(__name__)


@dataclass
class PlanState:
    """Planner output at time ``t`` (world axes, legs in the schedule's order).

    ``contact``: stance flags; ``swing_phase``: progress of each swing in [0, 1) (NaN in stance);
    ``foot_position/velocity/acceleration``: desired foot-frame motion (the stance anchor with zero
    velocity/acceleration for stance feet); ``touchdown_position``: for a swinging foot its landing
    target, for a stance foot its anchor; ``touchdown_normal``: terrain normal there;
    ``touchdown_time``: end of the current swing, or of the next one for stance feet;
    ``lifted_off`` / ``touched_down``: events detected since the previous call; ``trunk``: the trunk
    reference.
    """

    legs: tuple[str, ...]
    t: float = 0.0
    contact: np.ndarray = None
    swing_phase: np.ndarray = None
    foot_position: np.ndarray = None
    foot_velocity: np.ndarray = None
    foot_acceleration: np.ndarray = None
    touchdown_position: np.ndarray = None
    touchdown_normal: np.ndarray = None
    touchdown_time: np.ndarray = None
    lifted_off: np.ndarray = None
    touched_down: np.ndarray = None
    trunk: TrunkState = field(default_factory=TrunkState)

    def __post_init__(self):
        n = len(self.legs)
        for name, shape, dtype in (("contact", (n,), bool), ("swing_phase", (n,), float),
                                   ("foot_position", (n, 3), float),
                                   ("foot_velocity", (n, 3), float),
                                   ("foot_acceleration", (n, 3), float),
                                   ("touchdown_position", (n, 3), float),
                                   ("touchdown_normal", (n, 3), float),
                                   ("touchdown_time", (n,), float), ("lifted_off", (n,), bool),
                                   ("touched_down", (n,), bool)):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros(shape, dtype=dtype))

    def stance_legs(self) -> tuple[str, ...]:
        return tuple(leg for leg, c in zip(self.legs, self.contact) if c)

    def swing_legs(self) -> tuple[str, ...]:
        return tuple(leg for leg, c in zip(self.legs, self.contact) if not c)

    def copy(self) -> "PlanState":
        return PlanState(self.legs, self.t, self.contact.copy(), self.swing_phase.copy(),
                         self.foot_position.copy(), self.foot_velocity.copy(),
                         self.foot_acceleration.copy(), self.touchdown_position.copy(),
                         self.touchdown_normal.copy(), self.touchdown_time.copy(),
                         self.lifted_off.copy(), self.touched_down.copy(), self.trunk.copy())


class GaitPlanner:
    """Ties a :class:`GaitSchedule`, a :class:`TrunkReference`, the nominal :class:`Footprint`,
    Raibert footholds and :class:`SwingTrajectory` swings together.

    ``clearance``: swing apex height above the higher endpoint [m]; ``feedback_gain``: Raibert
    feedback k in ``k (v - v_cmd)`` [s]; ``max_step``: clamp on the touchdown's horizontal distance
    from the hip (None: none); ``feet``: initial foot-frame positions (n, 3) (default: the nominal
    footprint under the trunk reference at ``t``); ``reach``: per leg, how far (m) its foot can
    rise along the trunk's z axis from its standing position (:func:`~.reach.foot_lift`; None: no
    limit). A swing's apex is then at most that far above where the standing foot would be at
    mid-swing under the trunk reference, and never below the higher endpoint: on a slope or under
    a lowered trunk the clearance shrinks rather than the leg folding onto its joint limits.
    """

    def __init__(self, schedule: GaitSchedule, trunk: TrunkReference, footprint: Footprint,
                 terrain: Terrain | None = None, clearance: float = 0.1,
                 feedback_gain: float = 0.0, max_step: float | None = None, feet=None,
                 t: float | None = None, reach=None):
        if tuple(schedule.legs) != tuple(footprint.legs):
            raise ValueError(f"schedule.legs {schedule.legs} and footprint.legs {footprint.legs} "
                             "must list the same legs in the same order")
        if not (np.isfinite(clearance) and clearance >= 0.0):
            raise ValueError(f"clearance: must be a finite height >= 0, got {clearance}")
        self.schedule = schedule
        self.trunk = trunk
        self.footprint = footprint
        self.terrain = trunk.terrain if terrain is None else terrain
        self.clearance = float(clearance)
        self.feedback_gain = float(feedback_gain)
        self.max_step = max_step
        self.legs = tuple(schedule.legs)
        n = len(self.legs)
        self._feet_from_com = footprint.feet_from_com()
        self._radius = np.asarray(footprint.foot_radius, dtype=float)
        self.reach = np.full(n, np.inf) if reach is None else np.asarray(reach, dtype=float)
        if self.reach.shape != (n,) or np.any(np.isnan(self.reach)) or np.any(self.reach < 0):
            raise ValueError(f"reach: expected {n} lifts >= 0 (m), got {reach}")
        self._anchor = np.zeros((n, 3))
        self._anchor_normal = np.zeros((n, 3))
        self._swing: list[SwingTrajectory | None] = [None] * n
        self._swing_k = [-1] * n
        self._swinging = np.zeros(n, dtype=bool)
        self._target = np.zeros((n, 3))
        self._target_normal = np.zeros((n, 3))
        self.state = PlanState(self.legs)
        self.reset(trunk.t0 if t is None else t, feet)

    # ------------------------------------------------------------------ construction
    @classmethod
    def for_robot(cls, robot, schedule: GaitSchedule, command: VelocityCommand | None = None,
                  terrain: Terrain | None = None, q=None, t0: float = 0.0,
                  clearance: float = 0.1, sway: str | CrawlSway | None = "auto",
                  sway_gain=(0.0, 1.0), sway_blend: float | None = None,
                  feedback_gain: float = 0.0, max_step: float | None = None,
                  terrain_alignment: float = 1.0, center_on_com: bool = True,
                  start_shift: bool = True, limit_swing: bool = True) -> "GaitPlanner":
        """A planner for ``robot`` starting at time ``t0`` from configuration ``q`` (default: the
        standing posture ``robot.q_ref``), the trunk at its current CoM height above ``terrain``.

        ``sway="auto"`` adds a :class:`CrawlSway` when the schedule never swings two legs at once
        (a crawl); ``None`` disables it; a :class:`CrawlSway` instance is used as given.
        ``center_on_com``: place the feet around the CoM rather than around the standing posture's
        feet (see :meth:`Footprint.centered_on_com`). ``start_shift``: when the gait starts on two
        feet (a trot) and no sway is used, add the :meth:`start_shift` to the trunk reference.
        ``terrain_alignment``: how far the trunk's orientation follows the terrain's inclination
        (:class:`TrunkReference`; 1: along its normal, 0: level). ``limit_swing``: cap each swing's
        apex by how far the leg can raise its foot within its joint limits (``reach``, from
        :func:`~.reach.foot_lift` at ``q``).
        """
        q = robot.q_ref if q is None else np.asarray(q, dtype=float)
        roles = contact_roles(robot)
        if set(schedule.legs) <= set(roles):  # a schedule of roles: to the robot's contacts
            schedule = replace(schedule, legs=tuple(roles[leg] for leg in schedule.legs))
        legs = tuple(schedule.legs)
        footprint = Footprint.from_robot(robot, q, legs)
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        base = q[:3]
        com0 = base + R @ footprint.com
        feet = base + footprint.feet @ R.T  # where the feet are now
        if center_on_com:
            footprint = footprint.centered_on_com()  # where they will be placed
        yaw0 = math.atan2(R[1, 0], R[0, 0])
        terrain = Terrain.flat() if terrain is None else terrain
        if isinstance(sway, str):
            if sway != "auto":
                raise ValueError(f"sway: expected 'auto', None or a CrawlSway, got '{sway}'")
            sway = (CrawlSway(schedule, footprint.feet_from_com(), sway_gain, sway_blend, t0)
                    if schedule.max_swing_legs() == 1 else None)
            first = min(schedule.liftoff_time(leg, 0) for leg in legs)
            if sway is not None and first - t0 < 0.125 * schedule.period:  # half a steady blend
                log.warning("crawl sway: only %.3f s between t0 and the first lift-off; the first CoM "
                            "shift will be abrupt (give the schedule a start delay)", first - t0)
        # the command moves the trunk once the gait starts: before, the feet stand where they are
        # and a reference walking away from them tilts the robot when the first legs lift off
        start = max(t0, schedule.start)
        trunk = TrunkReference(command, com0, yaw0, None, terrain, start, sway, terrain_alignment)
        reach = None
        if limit_swing:  # no higher than the base: a foot above it is no use to a swing
            reach = [foot_lift(robot, leg, q, up_to=footprint.base_height) for leg in legs]
        planner = cls(schedule, trunk, footprint, terrain, clearance, feedback_gain, max_step, feet,
                      t0, reach)
        if start_shift and sway is None:
            trunk.start_shift = planner.start_shift(t0)
        return planner

    # ------------------------------------------------------------------ footholds
    def hip(self, leg: str | int, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal nominal foot position under the hip of ``leg`` on the nominal trunk path at
        ``t`` (no sway) and its velocity: (xy, v_xy)."""
        i = self.schedule.index(leg)
        xy, v, _, psi, om = self.trunk.nominal(t)
        c, s = math.cos(psi), math.sin(psi)
        r = self._feet_from_com[i]
        rw = np.array([c * r[0] - s * r[1], s * r[0] + c * r[1]])
        return xy + rw, v + om * np.array([-rw[1], rw[0]])

    def touchdown_target(self, leg: str | int, t_touchdown: float, com_velocity=None,
                         t_now: float | None = None) -> Foothold:
        """Raibert foothold of ``leg`` for a touchdown at ``t_touchdown``: the hip at touchdown plus
        its commanded velocity times T_stance / 2 (of the stance that begins there), plus
        ``feedback_gain`` times the error between ``com_velocity`` (measured, if given) and the
        commanded CoM velocity at ``t_now``."""
        i = self.schedule.index(leg)
        hip, v_hip = self.hip(i, t_touchdown)
        velocity = None
        if com_velocity is not None and self.feedback_gain != 0.0:
            _, v_ref, _, _, _ = self.trunk.nominal(t_touchdown if t_now is None else t_now)
            velocity = v_hip + (np.asarray(com_velocity, dtype=float)[:2] - v_ref)
        return raibert_foothold(hip, v_hip, self.schedule.stance_duration(i, t_touchdown),
                                self.terrain, velocity, self.feedback_gain,
                                float(self._radius[i]), self.max_step)

    def swing_clearance(self, leg: str | int, p0, p1, swing, clearance: float | None = None
                        ) -> float:
        """The clearance of ``swing`` of ``leg`` from ``p0`` to ``p1``: ``clearance`` (default
        :attr:`clearance`), capped so that the apex is at most ``reach`` above the standing foot's
        height at mid-swing (the trunk reference there, the footprint's foot in the trunk's
        frame), and at least 0."""
        i = self.schedule.index(leg)
        clearance = self.clearance if clearance is None else float(clearance)
        if not np.isfinite(self.reach[i]):
            return clearance
        trunk = self.trunk.evaluate(0.5 * (swing.liftoff + swing.touchdown))
        R = trunk.rotation
        standing = trunk.position[2] + R[2] @ (self.footprint.feet[i] - self.footprint.com)
        top = standing + self.reach[i] * R[2, 2]
        return float(min(clearance, max(0.0, top - max(p0[2], p1[2]))))

    # ------------------------------------------------------------------ gait start
    def start_shift(self, t_begin: float | None = None) -> StartShift | None:
        """The CoM offset that starts a gait on two feet from the current stance anchors (the
        standing feet), or None if the gait does not start on two feet.

        The footholds are planned around the nominal CoM path, but the first support is two of the
        standing feet, and a robot's CoM need not stand over its feet's centroid (Go1's and A1's
        stand ~3 cm behind it, HyQ's ~4 cm ahead): the nominal CoM is then off the first support
        line, and no force on two point feet has a moment about that line, so gravity tips the
        trunk about it for the whole first stance. The offset, a :class:`StartShift`, moves the
        CoM reference

        * during the four-foot stance before the first lift-off ``t1`` (over one gait period,
          starting no earlier than ``t_begin``; None if that leaves less than a quarter period):
          onto the first support line (its nearest point);
        * during the first two-foot stance: along that line, to where it crosses the second support
          line (the feet of the first swing at their planned footholds) at the first hand-over;
        * during the second two-foot stance: back to the nominal path at the second hand-over.
        """
        sch = self.schedule
        n = len(self.legs)
        if all(d >= 1.0 for d in sch.duty):
            return None
        tol = 1e-6 * sch.period
        lifts = sorted(sch.liftoff_time(i, k) for i in range(n) for k in range(3)
                       if sch.duty[i] < 1.0)
        t1 = lifts[0]
        first = [i for i in range(n) if sch.in_stance(i, t1)]
        if len(first) != 2:
            return None

        def handover(t_lift):
            """(legs swinging at t_lift, end of their swings, the next lift-off after that)."""
            swung = [i for i in range(n) if sch.in_swing(i, t_lift)]
            t_td = max(sch.next_touchdown(i, t_lift) for i in swung)
            return swung, t_td, min(t for t in lifts if t > t_td - tol)

        swung, t_td, t2 = handover(t1)
        second = [i for i in range(n) if sch.in_stance(i, t2)]
        if len(second) != 2 or not set(swung) >= set(second):
            return None
        _, t_td2, t3 = handover(t2)
        t_h, t_h2 = 0.5 * (t_td + t2), 0.5 * (t_td2 + t3)
        a, b = self._anchor[first[0], :2], self._anchor[first[1], :2]
        c, d = (GaitPlanner.touchdown_target(self, i, sch.touchdown_time(i, 0)).position[:2]
                for i in second)
        p1 = self.trunk.nominal(t1)[0]
        u = (b - a) / np.linalg.norm(b - a)
        on_first = a + ((p1 - a) @ u) * u  # the nearest point of the first support line
        p_h = self.trunk.nominal(t_h)[0]
        A = np.column_stack([b - a, c - d])
        if abs(np.linalg.det(A)) < 1e-6 * np.linalg.norm(b - a) * np.linalg.norm(d - c):
            crossing = a + ((p_h - a) @ u) * u  # parallel lines: the nearest point of the first
        else:
            crossing = a + np.linalg.solve(A, c - a)[0] * (b - a)
        w = sch.period if t_begin is None else min(sch.period, t1 - t_begin)
        if w < 0.25 * sch.period:
            log.warning("start shift: only %.3f s before the first lift-off, too little to move the "
                        "CoM onto the first support line; not shifted (give the schedule a start "
                        "delay)", w)
            return None

        def heading_frame(t, offset):
            psi = self.trunk.heading(t)
            cs, sn = math.cos(psi), math.sin(psi)
            return np.array([cs * offset[0] + sn * offset[1], -sn * offset[0] + cs * offset[1]])

        return StartShift([t1 - w, t1, t_h, t_h2],
                          [np.zeros(2), heading_frame(t1, on_first - p1),
                           heading_frame(t_h, crossing - p_h), np.zeros(2)])

    # ------------------------------------------------------------------ per-cycle
    def reset(self, t: float, feet=None) -> None:
        """Forget every swing; stance anchors = ``feet`` (n, 3), or the nominal footprint under the
        trunk reference at ``t`` dropped on the terrain."""
        n = len(self.legs)
        for i in range(n):
            if feet is not None:
                p = np.asarray(feet, dtype=float)[i]
                self._anchor[i] = p
                self._anchor_normal[i] = self.terrain.normal(p[0], p[1])
            else:
                hip, _ = self.hip(i, t)
                fh = raibert_foothold(hip, np.zeros(2), 0.0, self.terrain,
                                      foot_radius=float(self._radius[i]))
                self._anchor[i] = fh.position
                self._anchor_normal[i] = fh.normal
            self._swing[i] = None
            self._swing_k[i] = -1
            self._swinging[i] = False
        self._t_last = -math.inf

    def update(self, t: float, feet=None, com_velocity=None) -> PlanState:
        """The plan at time ``t``. ``feet``: measured foot-frame positions (n, 3), used as the swing
        start at lift-off and as the stance anchor at touchdown (default: the planned ones);
        ``com_velocity``: measured CoM velocity for the Raibert feedback term."""
        if not math.isfinite(t):
            raise ValueError(f"t: expected a finite time, got {t!r}")
        if t < self._t_last:
            raise ValueError(f"t: planner times must not decrease ({t} < {self._t_last}); "
                             "call reset() to start over")
        self._t_last = t
        sch, st = self.schedule, self.state
        st.t = t
        for i in range(len(self.legs)):
            st.lifted_off[i] = st.touched_down[i] = False
            swing = sch.current_swing(i, t)
            # 1. a swing seen in progress at the last call has ended: the foot landed
            if self._swinging[i] and (swing is None or swing.index != self._swing_k[i]):
                self._swinging[i] = False
                measured = feet is not None and swing is None
                self._anchor[i] = np.asarray(feet[i], dtype=float) if measured else self._target[i]
                self._anchor_normal[i] = self._target_normal[i]
                st.touched_down[i] = True
            # 2. swings that started and ended between two calls (sparse calls): land them on
            #    their targets, so that the result does not depend on the call rate
            k_next = sch.swing_index(i, t)
            if k_next is not None:
                k_done = swing.index - 1 if swing is not None else k_next - 1
                if k_done > self._swing_k[i]:
                    fh = self.touchdown_target(i, sch.touchdown_time(i, k_done), com_velocity, t)
                    self._anchor[i] = fh.position
                    self._anchor_normal[i] = fh.normal
                    self._swing_k[i] = k_done
            if swing is not None:
                if self._swing_k[i] != swing.index:  # 3. a new swing: latch start and target
                    p0 = self._anchor[i] if feet is None else np.asarray(feet[i], dtype=float)
                    fh = self.touchdown_target(i, swing.touchdown, com_velocity, t)
                    clearance = self.swing_clearance(i, p0, fh.position, swing)
                    self._swing[i] = SwingTrajectory(p0, fh.position, swing.touchdown -
                                                     swing.liftoff, clearance, swing.liftoff)
                    self._swing_k[i] = swing.index
                    self._target[i] = fh.position
                    self._target_normal[i] = fh.normal
                    self._swinging[i] = True
                    st.lifted_off[i] = True
                self._swing[i].evaluate_into(t, st.foot_position[i], st.foot_velocity[i],
                                             st.foot_acceleration[i])
                st.contact[i] = False
                st.swing_phase[i] = sch.swing_phase(i, t)
                st.touchdown_position[i] = self._target[i]
                st.touchdown_normal[i] = self._target_normal[i]
                st.touchdown_time[i] = swing.touchdown
            else:
                st.contact[i] = True
                st.swing_phase[i] = math.nan
                st.foot_position[i] = self._anchor[i]
                st.foot_velocity[i] = 0.0
                st.foot_acceleration[i] = 0.0
                st.touchdown_position[i] = self._anchor[i]
                st.touchdown_normal[i] = self._anchor_normal[i]
                st.touchdown_time[i] = sch.next_touchdown(i, t)
        self.trunk.evaluate(t, st.trunk)
        return st
