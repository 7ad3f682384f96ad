"""Quasi-static baseline of Fahmi et al. 2019 (their ref. [13], Focchi et al. 2017), Sect. V-E.

The desired CoM wrench (the same trunk impedance, eq. 4) is distributed to the stance feet by a QP
over the contact forces only — min ‖G F − W_com,d‖²_Q + ‖F‖²_R subject to the friction pyramid and
normal-force bounds — and mapped to torques by τ = g_j(q) − J_st,jᵀ F: gravity compensation of the
legs plus the static force map, with no joint accelerations and no leg dynamics. That map is affine
in F, so the stance legs' torque limits are linear rows on F in the same QP (ours: without them the
map asked beyond the limits of a heavy robot's joints and was clipped); when they cannot be met
together with friction, the forces are solved without them and the torques clipped (flagged).
Swing legs follow a Cartesian impedance τ = g_j + J_swᵀ (K Δx + D Δv) (eq. 5 without its
feed-forward). Same planner, same references, same limits clipping as
:class:`~wholebody.control.passive.PassiveWBC`.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import pinocchio as pin

from ..formulation import Solution, TaskReport
from ..guard import Outcome, guard_torque
from ..robot import Robot
from ..solvers.backends import DAQP_SENSE_EQ as EQ, DAQP_SENSE_INEQ as FREE, solve_daqp_qp
from ..tasks.contact import friction_faces, tangent_basis
from ..tasks.limits import TorqueLimits
from ..robots import reference
from ..robots.roles import leg_joints
from ..tasks.wrench import (TrunkImpedance, contact_wrench_map, force_bound, heading_weights,
                            trunk_weights)
from ..validation import nonnegative
from .base import PlannedController
from .passive import POSTURE_FREQUENCY, default_planner

log = logging.getLogger(__name__)


#: the baseline's Cartesian swing stiffness (N/m) and damping (N s/m) on HyQ
REFERENCE_SWING_K, REFERENCE_SWING_D = 2000.0, 50.0


def swing_gains(robot) -> tuple[float, float]:
    """(K, D) of the swing legs' Cartesian PD, force-level: HyQ's 2000 N/m and 50 N s/m times
    m / m_HyQ, so that a leg whose mass scales with the robot's keeps HyQ's swing frequency and
    damping ratio (the absolute gains left a 2.5 kg Solo12 beyond its torque limits in every
    swing)."""
    ratio = robot.mass / reference.MASS
    return REFERENCE_SWING_K * ratio, REFERENCE_SWING_D * ratio


class QuasiStaticController(PlannedController):
    """Centroidal force distribution + static torque map: ``compute(q, v, t) -> Solution``.

    ``swing_K``/``swing_D``: Cartesian swing-leg stiffness (N/m) and damping (N s/m), None: 2000 N/m
    and 50 N s/m on HyQ, scaled by the robot's mass on any other (:func:`swing_gains`);
    ``f_max`` None and ``impedance`` None: the robot-relative defaults of
    :class:`~wholebody.control.passive.PassiveWBC` (the paper's 2000 N and trunk gains on HyQ);
    ``Q`` (6) the trunk wrench weights about the heading frame, None: the robot-relative
    :func:`~wholebody.tasks.wrench.trunk_weights` of the passive WBC; ``posture_frequency`` ω
    (rad/s; None: the passive WBC's default) and ``posture_damping`` ζ: the PD that holds the null
    space of legs of more than three joints.
    """

    def __init__(self, robot: Robot, planner=None, mu: float | None = None, f_min: float = 0.0,
                 f_max: float | None = None, impedance: TrunkImpedance | None = None,
                 Q=None, R_force: float = 1e-4,
                 tangential_weight: float = 1e-3, swing_K: float | None = None,
                 swing_D: float | None = None,
                 torque_limit_override: dict[str, float] | None = None,
                 posture_frequency: float | None = None, posture_damping: float = 1.0):
        if any(c.dim != 3 for c in robot.contacts):
            raise ValueError(f"robot '{robot.name}': the quasi-static controller needs point feet")
        self.robot = robot
        self.contacts = robot.contact_names
        self.planner = planner if planner is not None else default_planner(robot)
        self._leg = [tuple(self.planner.legs).index(n) for n in self.contacts]
        self.mu = robot.friction if mu is None else float(mu)
        self._friction_cache: dict[tuple, tuple] = {}  # see _friction_rows
        self.f_min, self.f_max = f_min, force_bound(robot) if f_max is None else f_max
        self.impedance = impedance or TrunkImpedance.for_robot(robot)
        self.Q = np.broadcast_to(np.asarray(trunk_weights(robot) if Q is None else Q,
                                            dtype=float), 6).copy()
        self.R_force, self.tangential_weight = R_force, tangential_weight
        default_K, default_D = swing_gains(robot)
        self.swing_K = default_K if swing_K is None else nonnegative(swing_K, "swing_K")
        self.swing_D = default_D if swing_D is None else nonnegative(swing_D, "swing_D")
        self.torque_limits = TorqueLimits(upper_override=torque_limit_override)
        c = len(self.contacts)
        self.nf = 3 * c
        nj = robot.nv - 6
        #: rows: 5 per foot (friction pyramid, normal force), then one per joint (torque limits)
        self.A = np.zeros((5 * c + nj, self.nf))
        self.H = np.zeros((self.nf, self.nf))
        self.upper = np.zeros(self.nf + 5 * c + nj)
        self.lower = np.zeros(self.nf + 5 * c + nj)
        self.sense = np.zeros(self.nf + 5 * c + nj, dtype=np.int32)
        self._G = np.zeros((6, self.nf))
        omega = (POSTURE_FREQUENCY / reference.froude_ratio(robot) if posture_frequency is None
                 else nonnegative(posture_frequency, "posture_frequency"))
        zeta = nonnegative(posture_damping, "posture_damping")
        self.posture_K, self.posture_D = omega ** 2, 2.0 * zeta * omega
        #: joint indices of the legs with more than three joints (their null space is held)
        self._redundant_legs = [
            (i, np.array([robot.joint_names.index(j) for j in leg_joints(robot, name)]))
            for i, name in enumerate(self.contacts) if len(leg_joints(robot, name)) > 3]
        self.last_tau: np.ndarray | None = None
        self.last_plan = None

    def _friction_rows(self, normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pyramid faces (4, 3), unit normal, t1 t1ᵀ + t2 t2ᵀ) of a terrain ``normal`` at the
        friction coefficient ``mu`` (eq. 13 and the tangential regulariser), kept for the last
        normals met: the terrain's normals change at touchdowns only."""
        key = (normal.dtype.str, normal.tobytes(), self.mu)
        rows = self._friction_cache.get(key)
        if rows is None:
            if len(self._friction_cache) >= len(self.contacts) * 4:
                self._friction_cache.clear()
            t1, t2, nn = tangent_basis(normal)
            rows = (friction_faces(normal, self.mu), nn, np.outer(t1, t1) + np.outer(t2, t2))
            self._friction_cache[key] = rows
        return rows

    def _hold_leg_null_space(self, J, tau) -> None:
        """Legs of more than three joints: add N M_ll (K (q_ref − q) − D q̇) to their torques, N
        the projector onto the leg Jacobian's null space (torques that move no foot force): the
        posture PD of :class:`~wholebody.control.passive.PassiveWBC`'s regulariser where the
        static map leaves the leg free (ours; legs of three joints have no such space)."""
        robot = self.robot
        if not self._redundant_legs:
            return
        error = pin.difference(robot.model, robot.q, robot.q_ref)[6:]
        for i, cols in self._redundant_legs:
            Jl = J[3 * i:3 * i + 3, 6 + cols]
            N = np.eye(len(cols)) - np.linalg.pinv(Jl) @ Jl
            a = self.posture_K * error[cols] - self.posture_D * robot.v[6 + cols]
            tau[cols] += N @ (robot.M[np.ix_(6 + cols, 6 + cols)] @ a)

    def _swing_torques(self, plan, stance, tau) -> list[TaskReport]:
        """Add the swing legs' Cartesian PD to ``tau`` (eq. 5 without its feed-forward; only the
        leg's own columns of its Jacobian are nonzero) and return their tracking reports."""
        robot, reports = self.robot, []
        for i, name in enumerate(self.contacts):
            if stance[i]:
                continue
            leg = self._leg[i]
            Ji = robot.frame_jacobian(robot.contact(name).frame)[:3]
            pos = robot.data.oMf[robot.contact(name).frame_id].translation
            error = plan.foot_position[leg] - pos
            force = self.swing_K * error + self.swing_D * (plan.foot_velocity[leg] - Ji @ robot.v)
            tau += Ji[:, 6:].T @ force
            reports.append(TaskReport(f"swing {name}", 1, "eq", 3, float(np.linalg.norm(error))))
        return reports

    def _torque_rows(self, J, stance, tau0, lo_tau, hi_tau) -> None:
        """Rows lo − τ₀ ≤ −J_jᵀ F ≤ hi − τ₀ for the joints that carry a stance foot's force (τ₀:
        the torque that does not depend on F); the other joints' rows are left free."""
        n, rows = self.nf + 5 * len(self.contacts), self.A[5 * len(self.contacts):]
        rows[:] = -J[:, 6:].T
        stance_columns = np.repeat(stance, 3)
        rows[:, ~stance_columns] = 0.0
        carried = np.abs(rows).sum(axis=1) > 0.0
        self.upper[n:] = np.where(carried, hi_tau - tau0, np.inf)
        self.lower[n:] = np.where(carried, lo_tau - tau0, -np.inf)

    def solve(self, plan) -> Solution:
        t0 = time.perf_counter()
        self.last_plan = plan
        robot, nf, n = self.robot, self.nf, self.nf
        J = robot.stacked_contact_jacobian(self.contacts)
        G = contact_wrench_map(robot, self.contacts, self._G)
        W_d = self.impedance.wrench(robot, plan.trunk)
        GQ = G.T @ heading_weights(self.Q, plan.trunk.rotation)
        H = self.H
        H[:] = GQ @ G
        H.flat[::nf + 1] += self.R_force
        g = -GQ @ W_d
        up, lo, sense = self.upper, self.lower, self.sense
        stance = plan.contact[self._leg]
        for i in range(len(self.contacts)):
            leg, fi, rr = self._leg[i], 3 * i, 5 * i
            if stance[i]:
                faces, nn, tangential = self._friction_rows(plan.touchdown_normal[leg])
                self.A[rr:rr + 4, fi:fi + 3] = faces
                self.A[rr + 4, fi:fi + 3] = nn
                up[n + rr:n + rr + 4], lo[n + rr:n + rr + 4] = 0.0, -np.inf
                up[n + rr + 4], lo[n + rr + 4] = self.f_max, self.f_min
                up[fi:fi + 3], lo[fi:fi + 3] = np.inf, -np.inf
                sense[fi:fi + 3] = FREE
                H[fi:fi + 3, fi:fi + 3] += self.tangential_weight * tangential
            else:
                up[n + rr:n + rr + 5], lo[n + rr:n + rr + 5] = np.inf, -np.inf
                up[fi:fi + 3] = lo[fi:fi + 3] = 0.0
                sense[fi:fi + 3] = EQ
        tau0 = pin.computeGeneralizedGravity(robot.model, robot.data, robot.q)[6:].copy()
        self._hold_leg_null_space(J, tau0)
        swing_errors = self._swing_torques(plan, stance, tau0)
        lo_tau, hi_tau = self.torque_limits.bounds(robot)
        self._torque_rows(J, stance, tau0, lo_tau, hi_tau)
        result = solve_daqp_qp(H, g, self.A, up, lo, sense)
        status, fallback = "solved", ""
        if not result.ok:  # the torque limits out of reach with friction: forces without them
            torque_rows = slice(nf + 5 * len(self.contacts), None)
            up[torque_rows], lo[torque_rows] = np.inf, -np.inf
            result = solve_daqp_qp(H, g, self.A, up, lo, sense)
            status = fallback = "torque limits out of reach: forces solved without them"
        t1 = time.perf_counter()
        ok = result.ok
        F = np.array(result.x) if ok else np.zeros(nf)
        tau = tau0 - J[:, 6:].T @ F
        if not ok:
            status = f"{result.status}: zero forces"
            log.warning("quasi-static cycle %d: %s", robot.cycle, status)
        tau, outcome, status = guard_torque(tau, lo_tau, hi_tau,
                                            Outcome.SOLVED if ok else Outcome.HELD, status)
        if fallback and fallback not in status:
            status = f"{fallback}; {status}"
        self.last_tau = tau
        forces = {name: F[3 * i:3 * i + 3] for i, name in enumerate(self.contacts) if stance[i]}
        wrench_error = G @ F - W_d
        reports = [TaskReport("trunk wrench", 1, "eq", 6, float(np.linalg.norm(wrench_error))),
                   *swing_errors]
        return Solution(qdd=np.zeros(robot.nv), lam=F, tau=tau, forces=forces, outcome=outcome,
                        status=status, level_costs=np.array([float(wrench_error @ wrench_error)]),
                        tasks=reports, timings={"assemble": t1 - t0}, contacts=tuple(forces))
