"""Contact switching to single support and leg swinging (Herzog et al. 2016 Sect. 5.4, Tables 2 and
4).

Phases of :class:`ContactSwitch`:

1. shift: the CoG reference moves (quintic, with its velocity and acceleration as the momentum
   feedforward) over the stance sole and as low as the swing leg's bend and the joint limits
   need (:mod:`~wholebody.planning.support_shift`), Table 2 hierarchy; the posture reference
   (joints and base) moves with it, along the same quintic, from the standing posture to the
   shift's key pose inside the joint limits
   (:func:`~wholebody.planning.support_shift.shift_key_pose`), which stays the posture
   reference of the later phases (ours: toward the standing posture, the posture task pulls the
   base back and the legs into their limits, e.g. a swing hip's abduction);
2. unload: a force regulariser drives the leaving sole's wrench from its value at the start of the
   phase to zero (a ramp of the target, not of the weight: ramping the weight over six decades gives
   large torque jumps per cycle). With LQR gains, the gains are blended over the same ramp from
   the double-support configuration to the single-support one (the Remark of Sect. 3.2:
   :meth:`~wholebody.control.lqr.MomentumLQR.blend`); each configuration's gains are computed once,
   at its key pose (double: the reference posture; single: the pose at the start of unloading, CoG
   over the stance sole);
3. single support: the contact is removed, the Table 4 hierarchy takes over with a Cartesian
   swing-foot task lifting the sole by ``lift`` metres (then held up, e.g. for pushes);
4. leg swinging: the swing foot task is swapped for a joint-space task on two joints of the swing
   leg tracking sines (the foot task fades out while the sine amplitude ramps in).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..cycle import ENGINES, HierarchyCycle
from ..formulation import Formulation
from ..planning.blend import quintic_blend, smoothstep
from ..planning.support_shift import automatic_swing_bend, shift_key_pose, swing_leg_drop
from ..robot import FREE_FLYER_NQ, FREE_FLYER_NV
from ..tasks import ForceRegularizer
from ..tasks.momentum import momentum_gain
from ..tasks.motion import JointTrajectoryTask
from ..variables import Variables
from .balance import lqr_q
from .base import FailureStreak
from .lqr import MomentumLQR
from .stacks import COP_MARGIN, POSTURE_PD, SWING_FOOT_PD, TORSION, table2_stack, table4_stack

GAINS = ("pd", "lqr")

#: Weight of the posture's three base-orientation rows in every stack of :class:`ContactSwitch`
#: (the other posture rows: 1e-1). The angular-momentum rows weigh 1e-4 (Table 2's angular
#: treatment), so the posture alone holds the trunk; at the posture's uniform 1e-1 a rad/s^2 of
#: trunk rotation costs what a rad/s^2 of one joint costs, and the cascade lifts the swing foot by
#: rolling the pelvis over the stance leg (a hip hike: it moves the foot up with the hip width as
#: lever, while the swing leg, its knee nearly straight after the CoG shift, moves it up slowly).
#: The trunk then leans and the stance knee bends. 1, the paper's next weight (Sect. 5.2.1), keeps
#: the trunk upright and leaves the lift to the swing leg.
BASE_ORIENTATION_WEIGHT = 1.0


@dataclass(frozen=True)
class ContactSwitchConfig:
    """Timing, swing and gain settings of :class:`ContactSwitch` (times in s, lengths in m, angles
    in rad).

    ``push_forces``, ``push_start``, ``push_interval``: the single-support hold with the foot up
    lasts ``push_start`` plus ``push_interval`` per push (peak forces, N; the pushes themselves
    are applied by the caller at :attr:`Timeline.pushes`). ``sine_time`` > 0 adds the leg swinging
    of ``sine_joints`` (two joints of the swing leg) with signed ``sine_amplitudes``, while the
    posture reference of ``held_joints`` (the swing leg's joints) moves to their lifted positions;
    ``sine_push_force`` > 0 schedules a push ``sine_push_at`` into it. ``q_angular``: eq. 26's
    angular weight (LQR); ``lqr_blend``: blend the LQR gains during the unloading (else switch
    them at the contact switch). ``swing_bend`` in [0, 1]: the shift lowers the CoG by this
    fraction of :func:`~wholebody.planning.support_shift.swing_leg_drop` (1: the swing leg keeps
    its standing bend; 0: the CoG keeps its standing height); None (default): the fraction
    :func:`~wholebody.planning.support_shift.automatic_swing_bend` finds from the legs'
    joint-limit margins. ``posture_gains``, ``swing_gains``: the posture's and the swing-foot
    task's (kp, kd) in every stack (:data:`~wholebody.control.stacks.POSTURE_PD`,
    :data:`~wholebody.control.stacks.SWING_FOOT_PD`).
    """

    shift_time: float
    unload_time: float
    lift_time: float
    lift: float
    push_forces: tuple[float, ...]
    push_start: float
    push_interval: float
    sine_time: float
    sine_frequency: float
    sine_amplitudes: tuple[float, float]
    sine_ramp: float
    sine_joints: tuple[str, str]
    held_joints: tuple[str, ...]
    sine_kp: float
    sine_kd: float
    sine_push_force: float
    sine_push_at: float
    settle: float
    q_angular: float
    lqr_blend: bool
    swing_bend: float | None = None
    posture_gains: tuple[float, float] = POSTURE_PD
    swing_gains: tuple[float, float] = SWING_FOOT_PD


@dataclass
class Timeline:
    """Phase times (s) of one run, from the configuration."""

    shift_end: float
    switch: float
    lift_end: float
    pushes: list[tuple[float, float]] = field(default_factory=list)  # (start, peak force)
    sine_start: float | None = None
    sine_push: float | None = None
    end: float = 0.0

    @classmethod
    def from_config(cls, c: ContactSwitchConfig) -> "Timeline":
        switch = c.shift_time + c.unload_time
        lift_end = switch + c.lift_time
        forces = list(c.push_forces)
        first = lift_end + c.push_start
        pushes = [(first + i * c.push_interval, f) for i, f in enumerate(forces)]
        t = first + len(forces) * c.push_interval if forces else lift_end
        sine_start = sine_push = None
        if c.sine_time > 0:
            sine_start = t if forces else lift_end + c.push_start
            if c.sine_push_force > 0 and c.sine_push_at < c.sine_time:
                sine_push = sine_start + c.sine_push_at
            t = sine_start + c.sine_time
        return cls(c.shift_time, switch, lift_end, pushes, sine_start, sine_push, t + c.settle)


class ContactSwitch:
    """Double support -> unloading -> single support (Table 4) -> joint-space leg swinging, as a
    ``compute(q, v, t)`` controller. ``gains`` is "pd" (eq. 22) or "lqr" (eqs. 23-24, one gain set
    per contact configuration, blended during the unloading as in the Remark of Sect. 3.2).
    ``torsion`` (default True): the soles' yaw-moment rows in the Table 2/4 stacks, and
    ``cop_margin`` their CoP rows' margin (:func:`~wholebody.control.stacks.table2_stack`).
    ``engine``: "auto" (default: native when built), "native" — each stack solved by a
    :class:`~wholebody.cycle.HierarchyCycle` (compiled rigid-body terms, rows and cascade, the
    same solution) — or "python" (``Formulation.solve``, the reference). The controller reads
    its robot every cycle (the LQR gains and feedforward, the swing foot's placement, the
    joints), so ``robot.update`` runs every cycle on both."""

    def __init__(self, robot, stance: str, config: ContactSwitchConfig, gains: str = "pd",
                 torsion: bool = TORSION, P=None, D=None, cop_margin: float = COP_MARGIN,
                 engine: str = "auto"):
        if gains not in GAINS:
            raise ValueError(f"gains: expected 'pd' or 'lqr', got '{gains}'")
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got {engine!r}")
        if gains != "pd" and (P is not None or D is not None):
            raise ValueError(f"P, D: eq. 22's gains are only used with gains='pd', got "
                             f"gains='{gains}'")
        P = None if P is None else momentum_gain(P, "P")
        D = None if D is None else momentum_gain(D, "D")
        if len(config.sine_joints) != 2:
            raise ValueError(f"sine_joints: expected two joints, got {list(config.sine_joints)}")
        swing_contact = next(n for n in robot.contact_names if n != stance)
        self.robot, self.config, self.gains_kind = robot, config, gains
        self.failures = FailureStreak("ContactSwitch")  # HELD cycles in a row, in the status
        self.stance, self.swing_contact = stance, swing_contact
        self.timeline = Timeline.from_config(config)
        self.swing_frame = robot.contact(swing_contact).frame
        self.formulation = Formulation(robot)
        lqr = gains == "lqr"
        self.double_contacts = tuple(robot.contact_names)
        bw = BASE_ORIENTATION_WEIGHT
        task_pd = {"posture_gains": config.posture_gains, "cop_margin": cop_margin}
        self.double = table2_stack(robot, lqr=lqr, base_orientation_weight=bw, torsion=torsion,
                                   **task_pd)
        self.double_vars = Variables(robot)
        self.unload = self.double.insert(
            2, ForceRegularizer(name="unload", contacts=[swing_contact], weight=0.0))
        task_pd["swing_gains"] = config.swing_gains
        self.single = table4_stack(robot, [stance], [self.swing_frame], lqr=lqr,
                                   base_orientation_weight=bw, torsion=torsion, **task_pd)
        self.single_vars = Variables(robot, [stance])
        self.swing = self.single.find(f"swing {self.swing_frame}")
        # Sect. 5.4: the Cartesian swing-foot task swapped for a joint-space task
        self.joints = tuple(config.sine_joints)
        self.joint_task = JointTrajectoryTask(self.joints, kp=config.sine_kp, kd=config.sine_kd,
                                              name="swing joints")
        self.swinging = table4_stack(robot, [stance], [], lqr=lqr, base_orientation_weight=bw,
                                     torsion=torsion, **task_pd)
        self.swinging.insert(2, self.joint_task, before="posture")
        self.swinging.insert(2, self.swing, before="posture")  # the foot task fades out (handover)
        self.swing_posture = self.swinging.find("posture")
        for stack in (self.double, self.single, self.swinging):  # eq. 22's gains, PD only
            momentum = stack.find("momentum")
            if P is not None:
                momentum.P = P
            if D is not None:
                momentum.D = D
        self.cycles = None  # stack id -> its compiled cycle
        if engine != "python":
            self.cycles = {id(st): HierarchyCycle(robot, st, engine=engine)
                           for st in (self.double, self.single, self.swinging)}
        self._sine_idx = FREE_FLYER_NQ + np.array([robot.joint_names.index(j) for j in self.joints])
        self._held_idx = FREE_FLYER_NQ + np.array([robot.joint_names.index(j)
                                                   for j in config.held_joints], dtype=int)
        # single support: the swing leg's joints are the foot task's (6 rows on its 6 joints); the
        # posture keeps their damping but no stiffness toward the standing posture, which the
        # lifted foot contradicts (the leg's posture stiffness comes back over the handover to the
        # leg swinging, toward the lifted leg)
        self._leg_mask = np.isin(robot.joint_names, config.held_joints).astype(float)
        single_posture = self.single.find("posture")
        self._posture_kp = single_posture.kp
        single_posture.kp = self._posture_kp * (1.0 - self._leg_mask)
        self._leg_cols = FREE_FLYER_NV + np.flatnonzero(self._leg_mask)
        self.com_lift = 0.0  # rise of the CoG reference over the lift (m), set at the switch
        robot.update(robot.q_ref, np.zeros(robot.nv))
        self.com_start = robot.com.copy()
        stance_pos = robot.frame_placement(robot.contact(stance).frame)[0]
        drop = 0.0
        if config.swing_bend is None or config.swing_bend > 0.0:
            full = swing_leg_drop(robot, stance, self.swing_contact)
            bend = (automatic_swing_bend(robot, stance, self.swing_contact, config.lift, full)
                    if config.swing_bend is None else config.swing_bend)
            drop = bend * full
        drop, self.key_pose, _ = shift_key_pose(robot, stance, self.swing_contact, drop)
        self.double_posture = self.double.find("posture")
        self.single.find("posture").q_ref = self.key_pose
        self.com_target = np.array([stance_pos[0], stance_pos[1], self.com_start[2] - drop])
        self.lqr = None
        if lqr:
            self.lqr = MomentumLQR(robot, self.double_contacts, Q=lqr_q(config.q_angular))
            self.lqr.gains(robot, self.double_contacts)  # key pose of double support
        self.unload_start: np.ndarray | None = None
        self.lift_start: np.ndarray | None = None
        self.sine_q0: np.ndarray | None = None
        self.held_q: np.ndarray | None = None
        self.alpha = 0.0  # blend weight of the single-support gains
        self.last = None

    @property
    def switch_time(self) -> float:
        return self.timeline.switch

    def com_reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """CoG reference, velocity and acceleration: quintic shift, then constant, then during the
        lift rising by :attr:`com_lift` with the lift's blend (the CoG rise that lifting the swing
        leg makes with the rest of the robot still; holding the CoG at its standing height instead
        would make the stance leg bend by as much)."""
        T = self.config.shift_time
        s, ds, dds = quintic_blend(t / T, T)
        delta = self.com_target - self.com_start
        c, dc, ddc = self.com_start + s * delta, ds * delta, dds * delta
        if self.com_lift and t > self.timeline.switch:
            L = self.config.lift_time
            u = min((t - self.timeline.switch) / L, 1.0)
            lift = np.array([0.0, 0.0, self.com_lift])
            c = c + smoothstep(u) * lift
            if u < 1.0:
                dc, ddc = dc + 6.0 * u * (1.0 - u) / L * lift, ddc + (6.0 - 12.0 * u) / L ** 2 * lift
        return c, dc, ddc

    def _lift_com_rise(self) -> float:
        """The CoG rise per metre of swing-foot lift made by the swing leg's joints alone (the
        least-norm joint rates that move the sole straight up, keeping its orientation, through
        the CoG Jacobian), at the current state, times the lift."""
        robot, cols = self.robot, self._leg_cols
        J = robot.frame_jacobian(self.swing_frame)[:, cols]
        dq = np.linalg.lstsq(J, np.r_[0.0, 0.0, 1.0, 0.0, 0.0, 0.0], rcond=None)[0]
        return float(robot.J_com[2, cols] @ dq) * self.config.lift

    def com_ref(self, t: float) -> np.ndarray:
        return self.com_reference(t)[0]

    def joint_reference(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """References of the swinging joints: q0 + e(t) A sin(w t), e a quintic ramp."""
        c = self.config
        tau = t - self.timeline.sine_start
        A = np.array(c.sine_amplitudes)
        w = 2.0 * np.pi * c.sine_frequency
        ramp = max(c.sine_ramp, 1e-6)
        e, de, dde = quintic_blend(tau / ramp, ramp)
        s, co = np.sin(w * tau), np.cos(w * tau)
        q = self.sine_q0 + A * e * s
        qd = A * (de * s + e * w * co)
        qdd = A * (dde * s + 2.0 * de * w * co - e * w * w * s)
        return q, qd, qdd

    def _set_momentum(self, stack, t: float, gains=None) -> None:
        robot = self.robot
        c, dc, ddc = self.com_reference(t)
        h_ref = np.concatenate([robot.mass * dc, np.zeros(3)])
        hdot_ref = np.concatenate([robot.mass * ddc, np.zeros(3)])
        task = stack.find("momentum")
        if self.lqr is None:
            task.com_ref, task.h_ref, task.hdot_ref = c, h_ref, hdot_ref
        else:
            # (the references are computed here: finite vectors of their sizes)
            task.K, task.k = self.lqr.force_law(robot, gains, c, h_ref, hdot_ref)

    def compute(self, q, v, t: float):
        robot, c, tl = self.robot, self.config, self.timeline
        robot.update(q, v)
        if t < tl.switch:
            s = quintic_blend(min(t / c.shift_time, 1.0), c.shift_time)[0]
            self.double_posture.q_ref = pin.interpolate(robot.model, robot.q_ref, self.key_pose, s)
            gains = self.lqr.gains(robot, self.double_contacts) if self.lqr else None
            if t >= c.shift_time:
                if self.unload_start is None:
                    self.unload_start = self.last.forces[self.swing_contact].copy()
                    if self.lqr:  # key pose of single support: CoG over the stance sole
                        self.lqr.gains(robot, (self.stance,))
                self.unload.weight = 1.0
                self.alpha = smoothstep((t - c.shift_time) / c.unload_time)
                self.unload.targets[self.swing_contact] = (1.0 - self.alpha) * self.unload_start
                if self.lqr and c.lqr_blend:
                    gains = self.lqr.blend(gains, self.lqr.gains(robot, (self.stance,)),
                                           self.alpha, contacts=self.double_contacts)
            stack, variables = self.double, self.double_vars
        else:
            self.alpha = 1.0
            gains = self.lqr.gains(robot, (self.stance,)) if self.lqr else None
            variables = self.single_vars
            if tl.sine_start is None or t < tl.sine_start:
                if self.lift_start is None:
                    self.lift_start, rotation = robot.frame_placement(self.swing_frame)
                    self.swing.rotation = rotation
                    self.com_lift = self._lift_com_rise()
                s = smoothstep((t - tl.switch) / c.lift_time)
                self.swing.position = self.lift_start + np.array([0.0, 0.0, c.lift * s])
                stack = self.single
            else:
                idx, leg = self._sine_idx, self._held_idx
                if self.sine_q0 is None:
                    self.sine_q0 = robot.q[idx].copy()
                    self.held_q = robot.q[leg].copy()
                qd, vd, ad = self.joint_reference(t)
                self.joint_task.position, self.joint_task.velocity = qd, vd
                self.joint_task.acceleration = ad
                # handover over the amplitude ramp: the Cartesian foot task fades out and the
                # posture reference of the swing leg moves from the key pose to the
                # lifted leg (the swinging joints: to their sine references), so the torques stay
                # continuous
                ramp = max(c.sine_ramp, 1e-6)
                e = quintic_blend((t - tl.sine_start) / ramp, ramp)[0]
                self.swing.weight = 1.0 - e
                q_post = self.key_pose.copy()
                q_post[leg] = (1.0 - e) * self.key_pose[leg] + e * self.held_q
                q_post[idx] = (1.0 - e) * self.key_pose[idx] + e * qd
                self.swing_posture.q_ref = q_post
                self.swing_posture.kp = self._posture_kp * (1.0 - (1.0 - e) * self._leg_mask)
                stack = self.swinging
        self._set_momentum(stack, t, gains)
        if self.cycles is None:
            sol = self.formulation.solve(stack, variables, diagnostics=False)
        else:
            sol = self.cycles[id(stack)].solve(q, v, variables)
        sol = self.failures.note(sol)
        self.last = sol
        return sol
