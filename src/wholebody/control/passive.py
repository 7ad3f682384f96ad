"""Passive whole-body control for quadrupeds (Fahmi et al. 2019, seed 001, Sect. II and IV).

One QP per control cycle over u = [q̈, F_grf] (eq. 7), assembled here directly into preallocated
arrays (the generic :class:`~wholebody.formulation.Formulation` builds the same problem as a
two-level stack, see :meth:`PassiveWBC.as_stack`, but costs ~10x more per cycle):

* cost ‖W_com − W_com,d‖²_Q + ‖u‖²_R (eqs. 7a, 8): the trunk wrench task of eq. 4
  (:class:`~wholebody.tasks.wrench.TrunkImpedance`) plus a regulariser — either forces near the cone
  normals or, with ``regularization="torque"``, the joint torques of the contact forces with
  per-joint weights (Sect. V-D, footnote 16: R_F = J_st,j R_τ J_st,jᵀ);
* floating-base dynamics (eq. 9), here in Pinocchio's base coordinates (a linear change of rows of
  the paper's CoM coordinates: the constraint set is the same);
* stance feet: eq. 10, or the stance task of eq. 32 (``K_st``, ``D_st`` > 0, anchors at touchdown);
* swing feet: eq. 6/11-12 at the acceleration level; ``swing_slack`` = "per-direction" (eq. 33 with
  one slack per direction: at the optimum ε = |A u − b| so α‖ε‖² is exactly the weighted
  least-squares term α‖A_sw u − b_sw‖², no variables added), "single" (one slack per foot, its own
  variable and 6 rows: the ∞-norm coupling the paper warns about) or "none" (hard equality, eq. 11);
* friction pyramid and normal-force bounds about each foot's terrain normal (eqs. 13-14), torque
  limits with joint-dependent bounds τ_min(q), τ_max(q) (eq. 15), joint limits as acceleration
  bounds with Δt = 10 dt (eqs. 16-18);
* torques by eq. 19.

The QP is solved by DAQP with a fixed layout (swing-foot forces bounded to zero, unused rows free),
so its size never changes and the previous multipliers warm-start the next cycle.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import daqp
import numpy as np

from ..formulation import Solution, TaskReport
from ..robot import Robot
from ..tasks.contact import friction_faces, tangent_basis
from ..tasks.limits import JointAccelerationLimits, TorqueLimits
from ..tasks.wrench import TrunkImpedance, contact_wrench_map

log = logging.getLogger(__name__)

SLACKS = ("per-direction", "single", "none")
REGULARIZATIONS = ("force-normal", "torque")
_EQ, _FREE = 5, 0  # DAQP constraint senses
_INF = np.inf
_DAQP_OK = (1, 2)


@dataclass
class SwingGains:
    """Acceleration-level swing impedance of eq. 6 (Sect. V: K_sw = 2000, D_sw = 20)."""

    K: float = 2000.0
    D: float = 20.0


def measured_feet(robot: Robot, contacts) -> np.ndarray:
    """World positions (n, 3) of the contact frames at the robot's cached state."""
    return np.array([robot.data.oMf[robot.contact(n).frame_id].translation for n in contacts])


def default_planner(robot: Robot):
    """A planner that keeps every foot in stance under the standing posture."""
    from ..planning.gait import stand
    from ..planning.planner import GaitPlanner
    return GaitPlanner.for_robot(robot, stand(legs=robot.contact_names))


class PassiveWBC:
    """Passive whole-body controller: ``compute(q, v, t) -> Solution`` (Fahmi et al. 2019).

    ``planner`` (a :class:`~wholebody.planning.planner.GaitPlanner`, default: stand still) gives,
    every cycle, the stance/swing split, swing references, stance anchors, terrain normals and the
    trunk reference. ``solve(plan)`` runs one cycle on a given plan at the robot's cached state.

    Weights: ``Q`` (6, trunk wrench, N² / (Nm)²), ``slack_weight`` α of eq. 33, ``R_qdd`` and
    ``R_force`` (the ‖u‖²_R term), ``tangential_weight`` (force-normal scheme) or
    ``torque_weights`` (per joint, torque scheme). ``torque_limit_override`` lowers named joints'
    limits (e.g. the weak knee of Sect. V-C). ``control_period`` sets Δt = 10 dt of eq. 18.
    """

    def __init__(self, robot: Robot, planner=None, mu: float | None = None, f_min: float = 0.0,
                 f_max: float = 2000.0, impedance: TrunkImpedance | None = None,
                 swing: SwingGains | None = None, swing_slack: str = "per-direction",
                 slack_weight: float = 1e4, K_st: float = 200.0, D_st: float = 30.0,
                 Q=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0), R_qdd: float = 1e-4, R_force: float = 1e-4,
                 regularization: str = "force-normal", tangential_weight: float = 1e-3,
                 torque_weights=None, torque_limit_override: dict[str, float] | None = None,
                 control_period: float = 0.004):
        if any(c.dim != 3 for c in robot.contacts):
            raise ValueError(f"robot '{robot.name}': PassiveWBC needs point contacts (3D forces)")
        if swing_slack not in SLACKS:
            raise ValueError(f"swing_slack: expected one of {SLACKS}, got '{swing_slack}'")
        if regularization not in REGULARIZATIONS:
            raise ValueError(f"regularization: expected one of {REGULARIZATIONS}, "
                             f"got '{regularization}'")
        if not f_max > f_min >= 0.0:
            raise ValueError(f"f_min, f_max: need 0 <= f_min < f_max, got {f_min}, {f_max}")
        self.robot = robot
        self.contacts = robot.contact_names
        self.planner = planner if planner is not None else default_planner(robot)
        self._leg = [tuple(self.planner.legs).index(n) for n in self.contacts]
        self.mu = robot.friction if mu is None else float(mu)
        self.f_min, self.f_max = f_min, f_max
        self.impedance = impedance or TrunkImpedance()
        self.swing = swing or SwingGains()
        self.swing_slack = swing_slack
        self.slack_weight = float(slack_weight)
        self.K_st, self.D_st = K_st, D_st
        self.Q = np.broadcast_to(np.asarray(Q, dtype=float), 6).copy()
        self.R_qdd, self.R_force = R_qdd, R_force
        self.regularization = regularization
        self.tangential_weight = tangential_weight
        na = robot.na
        self.torque_weights = (np.ones(na) * 1e-4 if torque_weights is None
                               else np.broadcast_to(np.asarray(torque_weights, float), na).copy())
        self.torque_limits = TorqueLimits(upper_override=torque_limit_override)
        self.joint_limits = JointAccelerationLimits(mode="braking", horizon=10 * control_period)
        self.control_period = control_period
        self._allocate()
        self._R_diagonal = np.zeros(self.n)
        self._R_diagonal[:robot.nv] = R_qdd
        self._R_diagonal[robot.nv:robot.nv + self.nf] = R_force
        self.last_tau: np.ndarray | None = None
        self.last_plan = None

    # ------------------------------------------------------------------ layout
    def _allocate(self) -> None:
        nv, c = self.robot.nv, len(self.contacts)
        self.nf = 3 * c
        single = self.swing_slack == "single"
        self.n = nv + self.nf + (c if single else 0)
        # rows: dynamics 6 | feet 3c | friction 5c | torque na | (single: second swing rows 3c)
        self._r_feet = 6
        self._r_fric = self._r_feet + 3 * c
        self._r_tau = self._r_fric + 5 * c
        self._r_single = self._r_tau + self.robot.na
        self.m = self._r_single + (3 * c if single else 0)
        self.A = np.zeros((self.m, self.n))
        self.H = np.zeros((self.n, self.n))
        self.g = np.zeros(self.n)
        self.upper = np.zeros(self.n + self.m)  # simple bounds on every variable, then rows
        self.lower = np.zeros(self.n + self.m)
        self.sense = np.zeros(self.n + self.m, dtype=np.int32)
        self._G = np.zeros((6, self.nf))
        self._normals = np.full((c, 3), np.nan)  # friction rows are rebuilt when these change
        self._mu = np.full(c, np.nan)
        self._tangential = np.zeros((c, 3, 3))
        self._swing_targets = np.zeros((c, 3))
        self._anchors = np.zeros((c, 3))  # stance task (eq. 32): contact points at touchdown
        self._was_stance = np.zeros(c, dtype=bool)
        self._dual = None
        if single:
            for i in range(c):  # slack columns of the paired rows: row1 - eps <= b, row2 + eps >= b
                self.A[self._r_feet + 3 * i:self._r_feet + 3 * i + 3, nv + self.nf + i] = -1.0
                self.A[self._r_single + 3 * i:self._r_single + 3 * i + 3, nv + self.nf + i] = 1.0

    # ------------------------------------------------------------------ per cycle
    def compute(self, q, v, t: float = 0.0) -> Solution:
        """Torques for the state (q, v) (Pinocchio convention) at time ``t``."""
        robot = self.robot
        robot.update(q, v)
        plan = self.planner.update(t, feet=measured_feet(robot, self.planner.legs))
        return self.solve(plan)

    def solve(self, plan) -> Solution:
        """One QP (eq. 7) at the robot's cached state for ``plan`` (a PlanState-like object)."""
        t0 = time.perf_counter()
        self.last_plan = plan
        robot, nv, nf, na = self.robot, self.robot.nv, self.nf, self.robot.na
        A, H, g, up, lo, sense, n = self.A, self.H, self.g, self.upper, self.lower, self.sense, self.n
        M, h = robot.M, robot.h
        J = robot.stacked_contact_jacobian(self.contacts)
        drift = robot.stacked_contact_drift(self.contacts)
        stance = plan.contact[self._leg]
        # eq. 9: floating-base rows  M_b q̈ − J_bᵀ F = −h_b
        A[0:6, :nv] = M[:6]
        A[0:6, nv:nv + nf] = -J[:, :6].T
        up[n:n + 6] = lo[n:n + 6] = -h[:6]
        sense[n:n + 6] = _EQ
        # eq. 15: torque rows  M_j q̈ − J_jᵀ F  in  [τ_min − h_j, τ_max − h_j]
        r = self._r_tau
        A[r:r + na, :nv] = M[6:]
        A[r:r + na, nv:nv + nf] = -J[:, 6:].T
        tau_lo, tau_hi = self._tau_bounds = self.torque_limits.bounds(robot)
        up[n + r:n + r + na] = tau_hi - h[6:]
        lo[n + r:n + r + na] = tau_lo - h[6:]
        # eqs. 16-18: joint accelerations as simple bounds; base free
        up[:6], lo[:6] = _INF, -_INF
        lo[6:nv], up[6:nv] = self.joint_limits.bounds(robot)
        sense[:n] = _FREE
        # cost: ‖u‖²_R, trunk wrench (eqs. 7a, 8), regulariser
        H[:] = 0.0
        H.flat[::n + 1] = self._R_diagonal  # (flat-iterator assignment writes in place)
        g[:] = 0.0
        G = contact_wrench_map(robot, self.contacts, self._G)
        W_d = self.impedance.wrench(robot, plan.trunk)
        GQ = G.T * self.Q
        H[nv:nv + nf, nv:nv + nf] += GQ @ G
        g[nv:nv + nf] = -GQ @ W_d
        if self.regularization == "torque":
            JjT = J[:, 6:].T * np.sqrt(self.torque_weights)[:, None]  # footnote 16
            H[nv:nv + nf, nv:nv + nf] += JjT.T @ JjT
        swing_rows, swing_targets = [], []
        K_sw, D_sw = self.swing.K, self.swing.D
        for i, name in enumerate(self.contacts):
            leg = self._leg[i]
            rf, rr, fi = self._r_feet + 3 * i, self._r_fric + 5 * i, nv + 3 * i
            if stance[i]:
                Ji = J[3 * i:3 * i + 3]  # the contact point (bottom of the foot sphere)
                A[rf:rf + 3, :nv] = Ji
                target = -drift[3 * i:3 * i + 3]
                point = robot.contact_point(name)
                if not self._was_stance[i]:  # touchdown: x̂_st of eq. 32
                    self._anchors[i] = point
                if self.K_st or self.D_st:  # eq. 32: hold the touchdown position
                    target = target + self.K_st * (self._anchors[i] - point) - self.D_st * (Ji @ robot.v)
                up[n + rf:n + rf + 3] = lo[n + rf:n + rf + 3] = target
                sense[n + rf:n + rf + 3] = _EQ
                normal = plan.touchdown_normal[leg]
                if not np.array_equal(normal, self._normals[i]) or self._mu[i] != self.mu:
                    A[rr:rr + 4, fi:fi + 3] = friction_faces(normal, self.mu)
                    t1, t2, nn = tangent_basis(normal)
                    A[rr + 4, fi:fi + 3] = nn
                    self._tangential[i] = np.outer(t1, t1) + np.outer(t2, t2)
                    self._normals[i], self._mu[i] = normal, self.mu
                up[n + rr:n + rr + 4], lo[n + rr:n + rr + 4] = 0.0, -_INF
                up[n + rr + 4], lo[n + rr + 4] = self.f_max, self.f_min
                sense[n + rr:n + rr + 5] = _FREE
                up[fi:fi + 3], lo[fi:fi + 3] = _INF, -_INF
                if self.swing_slack == "single":
                    self._no_slack(i)
                if self.regularization == "force-normal":
                    H[fi:fi + 3, fi:fi + 3] += self.tangential_weight * self._tangential[i]
            else:
                # eq. 6: desired acceleration of the foot frame (the planner's swing trajectory);
                # eq. 12: J q̈ = v̇_d − J̇ v
                frame = robot.contact(name).spec.frame
                Ji = robot.frame_jacobian(frame)[:3]
                A[rf:rf + 3, :nv] = Ji
                pos = robot.data.oMf[robot.contact(name).frame_id].translation
                a_d = (plan.foot_acceleration[leg] + K_sw * (plan.foot_position[leg] - pos)
                       + D_sw * (plan.foot_velocity[leg] - Ji @ robot.v))
                target = a_d - robot.frame_drift(frame)[:3]
                self._swing_targets[i] = target
                self._swing_row(i, rf, Ji, target, swing_rows, swing_targets)
                up[n + rr:n + rr + 5], lo[n + rr:n + rr + 5] = _INF, -_INF
                sense[n + rr:n + rr + 5] = _FREE
                up[fi:fi + 3] = lo[fi:fi + 3] = 0.0  # no force on a swing foot
                sense[fi:fi + 3] = _EQ
        self._was_stance[:] = stance
        if swing_rows:  # per-direction slacks == weighted least squares (see module docstring)
            Jsw = np.vstack(swing_rows)
            H[:nv, :nv] += self.slack_weight * (Jsw.T @ Jsw)
            g[:nv] -= self.slack_weight * (Jsw.T @ np.concatenate(swing_targets))
        t1 = time.perf_counter()
        x, flag, iterations = self._solve_qp()
        t2 = time.perf_counter()
        return self._solution(x, flag, iterations, J, W_d, G, plan,
                              {"assemble": t1 - t0, "solve": t2 - t1})

    def _swing_row(self, i, rf, Ji, target, swing_rows, swing_targets) -> None:
        """Rows of swing foot i: hard (eq. 11), per-direction slack (LS term) or single slack."""
        n, nv, nf = self.n, self.robot.nv, self.nf
        up, lo, sense = self.upper, self.lower, self.sense
        if self.swing_slack == "none":
            up[n + rf:n + rf + 3] = lo[n + rf:n + rf + 3] = target
            sense[n + rf:n + rf + 3] = _EQ
        elif self.swing_slack == "per-direction":
            up[n + rf:n + rf + 3], lo[n + rf:n + rf + 3] = _INF, -_INF
            sense[n + rf:n + rf + 3] = _FREE
            swing_rows.append(Ji)
            swing_targets.append(target)
        else:  # single: J q̈ − ε <= b and J q̈ + ε >= b, cost α ε²
            rs = self._r_single + 3 * i
            self.A[rs:rs + 3, :nv] = Ji
            up[n + rf:n + rf + 3], lo[n + rf:n + rf + 3] = target, -_INF
            up[n + rs:n + rs + 3], lo[n + rs:n + rs + 3] = _INF, target
            sense[n + rf:n + rf + 3] = sense[n + rs:n + rs + 3] = _FREE
            e = nv + nf + i
            up[e], lo[e] = _INF, 0.0
            self.H[e, e] += self.slack_weight

    def _no_slack(self, i: int) -> None:
        """Single-slack layout, stance foot i: its slack is fixed at 0 and its paired rows are free."""
        n, nv, nf = self.n, self.robot.nv, self.nf
        rs, e = self._r_single + 3 * i, nv + nf + i
        self.upper[e] = self.lower[e] = 0.0
        self.sense[e] = _EQ
        self.upper[n + rs:n + rs + 3], self.lower[n + rs:n + rs + 3] = _INF, -_INF
        self.sense[n + rs:n + rs + 3] = _FREE
        self.H[e, e] += 1.0  # keeps H positive definite; the variable is pinned anyway

    def _solve_qp(self):
        args = (self.H, self.g, self.A, self.upper, self.lower, self.sense)
        if self._dual is not None:
            x, _, flag, info = daqp.solve(*args, dual_start=self._dual)
            if flag not in _DAQP_OK:
                x, _, flag, info = daqp.solve(*args)
        else:
            x, _, flag, info = daqp.solve(*args)
        self.last_x = x  # the raw QP solution (slack variables last in the single-slack layout)
        if flag in _DAQP_OK:
            self._dual = info["lam"]
        else:
            self._dual = None
        return x, flag, info.get("iterations", 0)

    def _solution(self, x, flag, iterations, J, W_d, G, plan, timings) -> Solution:
        robot, nv, nf = self.robot, self.robot.nv, self.nf
        tau_lo, tau_hi = self._tau_bounds
        ok = flag in _DAQP_OK and np.all(np.isfinite(x))
        if ok:
            qdd, F = x[:nv].copy(), x[nv:nv + nf].copy()
            tau = robot.M[6:] @ qdd + robot.h[6:] - J[:, 6:].T @ F  # eq. 19
            status = "solved"
            if np.any(tau > tau_hi + 1e-6) or np.any(tau < tau_lo - 1e-6):
                status = "torque outside limits after solve; clipped"
                log.debug(status)
            tau = np.clip(tau, tau_lo, tau_hi)
        else:
            qdd, F = np.zeros(nv), np.zeros(nf)
            previous = self.last_tau if self.last_tau is not None else robot.h[6:]
            tau = np.clip(np.nan_to_num(previous), tau_lo, tau_hi)
            status = f"daqp exit flag {flag}: previous torque held (clipped to limits)"
            log.warning("PassiveWBC cycle %d: %s", robot.cycle, status)
        self.last_tau = tau
        wrench_error = G @ F - W_d
        reports = [TaskReport("trunk wrench", 2, "eq", 6, float(np.linalg.norm(wrench_error)))]
        for i, name in enumerate(self.contacts):
            if not plan.contact[self._leg[i]] and ok:
                rf = self._r_feet + 3 * i
                residual = self.A[rf:rf + 3, :nv] @ qdd - self._swing_targets[i]
                reports.append(TaskReport(f"swing {name}", 2, "eq", 3,
                                          float(np.linalg.norm(residual))))
        forces = {name: F[3 * i:3 * i + 3] for i, name in enumerate(self.contacts)
                  if plan.contact[self._leg[i]]}
        timings = dict(timings, iterations=iterations)
        return Solution(qdd=qdd, lam=F, tau=tau, forces=forces, ok=ok, status=status,
                        level_costs=np.array([float(wrench_error @ (self.Q * wrench_error))]),
                        tasks=reports, timings=timings, contacts=tuple(forces))

    # ------------------------------------------------------------------ the same problem as a stack
    def as_stack(self, plan):
        """The QP of :meth:`solve` for ``plan`` as a two-level stack of library tasks — hard
        constraints, then the weighted objective — for ``Formulation.solve(method="weighted")``.
        Returns (stack, variables). Needs a prior :meth:`solve` on the same plan (stance anchors).
        The single-slack mode has no stack form (its cost is an ∞-norm, not a weighted task)."""
        from ..formulation import Stack
        from ..tasks import (ContactConstraint, ForceRegularizer, FrameTask, FrictionCone,
                             NewtonEuler, NormalForceBounds)
        from ..tasks.regularization import (AccelerationRegularizer, ContactTorqueRegularizer,
                                            TangentialForceRegularizer)
        from ..tasks.wrench import TrunkWrenchTask
        from ..variables import Variables
        if self.swing_slack == "single":
            raise ValueError("swing_slack: 'single' has no two-level stack form")
        robot = self.robot
        stance = [n for i, n in enumerate(self.contacts) if plan.contact[self._leg[i]]]
        swing = [(i, n) for i, n in enumerate(self.contacts) if not plan.contact[self._leg[i]]]
        normals = {n: plan.touchdown_normal[self._leg[self.contacts.index(n)]] for n in stance}
        contact = ContactConstraint(contacts=stance, kp=self.K_st, kd=self.D_st)
        for n in stance:  # the task anchors frame origins; ours are the sphere bottoms
            i = self.contacts.index(n)
            contact.anchors[n] = self._anchors[i] + [0.0, 0.0, robot.contact(n).spec.radius]
        hard = [NewtonEuler(), contact, FrictionCone(self.mu, contacts=stance, normals=normals),
                NormalForceBounds(self.f_min, self.f_max, contacts=stance, normals=normals),
                self.torque_limits, self.joint_limits]
        wrench = TrunkWrenchTask(self.impedance, weight=np.sqrt(self.Q), contacts=stance)
        wrench.reference = plan.trunk
        objective = [wrench, AccelerationRegularizer(weight=np.sqrt(self.R_qdd)),
                     ForceRegularizer(weight=np.sqrt(self.R_force), contacts=stance)]
        if self.regularization == "torque":
            objective.append(ContactTorqueRegularizer(weight=np.sqrt(self.torque_weights),
                                                      contacts=stance))
        elif self.tangential_weight:
            objective.append(TangentialForceRegularizer(weight=np.sqrt(self.tangential_weight),
                                                        contacts=stance, normals=normals))
        for i, n in swing:
            leg = self._leg[i]
            task = FrameTask(robot.contact(n).spec.frame, kp=self.swing.K, kd=self.swing.D,
                             mask="position", name=f"swing {n}",
                             weight=1.0 if self.swing_slack == "none" else np.sqrt(self.slack_weight))
            task.position = np.array(plan.foot_position[leg], dtype=float)
            task.velocity[:3] = plan.foot_velocity[leg]
            task.acceleration[:3] = plan.foot_acceleration[leg]
            (hard if self.swing_slack == "none" else objective).append(task)
        return Stack([hard, objective]), Variables(robot, stance)

