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

``engine="native"`` runs the same cycle — rigid-body terms, assembly, eq. 19 — in the compiled
``wholebody._passive_cycle`` (src/wholebody/native/passive_cycle.cpp, Pinocchio's C++ templates),
writing into the very arrays DAQP is called with; this Python assembly is its tested reference.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import daqp
import numpy as np

from ..formulation import Solution, TaskReport
from ..robot import Robot
from ..tasks.contact import friction_faces, tangent_basis
from ..tasks.limits import JointAccelerationLimits, TorqueLimits
from ..tasks.wrench import TrunkImpedance, contact_wrench_map
from .base import PlannedController

log = logging.getLogger(__name__)

SLACKS = ("per-direction", "single", "none")
ENGINES = ("python", "native")
REGULARIZATIONS = ("force-normal", "torque")
_EQ, _FREE = 5, 0  # DAQP constraint senses
_INF = np.inf
_DAQP_OK = (1, 2)


@dataclass(frozen=True)
class _Pattern:
    """What depends only on the stance/swing split of one cycle (see PassiveWBC._pattern)."""

    s3: np.ndarray  # stance mask per force component
    swing: np.ndarray  # indices (controller order) of the swing feet
    all_stance: bool
    swing_feet_rows: np.ndarray  # A rows of the swing feet's eq. 12
    swing_single_rows: np.ndarray  # their paired rows (single-slack layout)
    feet_sense: np.ndarray
    force_upper: np.ndarray
    force_lower: np.ndarray
    force_sense: np.ndarray
    fric_upper: np.ndarray
    fric_lower: np.ndarray
    tangential: np.ndarray  # tangential-force regulariser of the stance feet (unweighted)


@dataclass
class SwingGains:
    """Acceleration-level swing impedance of eq. 6 (Sect. V: K_sw = 2000, D_sw = 20);
    ``feedforward`` False drops v̇_sw,ff (Assumption 2 of the passivity analysis)."""

    K: float = 2000.0
    D: float = 20.0
    feedforward: bool = True


def default_planner(robot: Robot):
    """A planner that keeps every foot in stance under the standing posture."""
    from ..planning.gait import stand
    from ..planning.planner import GaitPlanner
    return GaitPlanner.for_robot(robot, stand(legs=robot.contact_names))


class PassiveWBC(PlannedController):
    """Passive whole-body controller: ``compute(q, v, t) -> Solution`` (Fahmi et al. 2019).

    ``planner`` (a :class:`~wholebody.planning.planner.GaitPlanner`, default: stand still) gives,
    every cycle, the stance/swing split, swing references, stance anchors, terrain normals and the
    trunk reference. ``solve(plan)`` runs one cycle on a given plan at the robot's cached state.

    Weights: ``Q`` (6, trunk wrench, N² / (Nm)²), ``slack_weight`` α of eq. 33, ``R_qdd`` and
    ``R_force`` (the ‖u‖²_R term), ``tangential_weight`` (force-normal scheme) or
    ``torque_weights`` (per joint, torque scheme). ``torque_limit_override`` lowers named joints'
    limits (e.g. the weak knee of Sect. V-C). ``control_period`` sets Δt = 10 dt of eq. 18 and
    the observer's time step. ``observer`` (a :class:`~wholebody.control.observer.MomentumObserver`,
    default none) estimates W_ext of eq. 4 every cycle from the centroidal momentum and the contact
    wrench commanded the cycle before, and writes it into ``impedance.external_wrench``.

    ``engine="native"`` computes each cycle in compiled code (about 5x faster, see
    benchmarks/bench_passive.py) with the same results; it supports the "per-direction" and "none"
    swing slacks. It keeps its own rigid-body terms: ``compute``/``cycle`` do not refresh
    ``robot``'s Python cache (``robot.M``, ``robot.com``... stay those of the last
    ``robot.update``). Its weights, gains and limits are copied when it is built: after changing
    any of them call :meth:`configure`.
    """

    def __init__(self, robot: Robot, planner=None, mu: float | None = None, f_min: float = 0.0,
                 f_max: float = 2000.0, impedance: TrunkImpedance | None = None,
                 swing: SwingGains | None = None, swing_slack: str = "per-direction",
                 slack_weight: float = 1e4, K_st: float = 200.0, D_st: float = 30.0,
                 Q=(1.0, 1.0, 1.0, 1.0, 1.0, 1.0), R_qdd: float = 1e-4, R_force: float = 1e-4,
                 regularization: str = "force-normal", tangential_weight: float = 1e-3,
                 torque_weights=None, torque_limit_override: dict[str, float] | None = None,
                 control_period: float = 0.004, observer=None, engine: str = "python"):
        if any(c.dim != 3 for c in robot.contacts):
            raise ValueError(f"robot '{robot.name}': PassiveWBC needs point contacts (3D forces)")
        if swing_slack not in SLACKS:
            raise ValueError(f"swing_slack: expected one of {SLACKS}, got '{swing_slack}'")
        if regularization not in REGULARIZATIONS:
            raise ValueError(f"regularization: expected one of {REGULARIZATIONS}, "
                             f"got '{regularization}'")
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got '{engine}'")
        if engine == "native" and swing_slack == "single":
            raise ValueError("engine: 'native' supports swing_slack 'per-direction' and 'none', "
                             "not 'single'")
        if not f_max > f_min >= 0.0:
            raise ValueError(f"f_min, f_max: need 0 <= f_min < f_max, got {f_min}, {f_max}")
        self.robot = robot
        self.contacts = robot.contact_names
        self.planner = planner if planner is not None else default_planner(robot)
        self._leg = np.array([tuple(self.planner.legs).index(n) for n in self.contacts])
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
        self._failing = 0  # length of the current streak of failed cycles
        self.observer = observer
        self._commanded_wrench: np.ndarray | None = None  # G F of the last solved cycle
        self.engine = engine
        self._native = None
        if engine == "native":
            self._native = self._build_native()

    # ------------------------------------------------------------------ layout
    def _allocate(self) -> None:
        nv, c = self.robot.nv, len(self.contacts)
        self.nf = 3 * c
        single = self.swing_slack == "single"
        self.n = nv + self.nf + (c if single else 0)
        # rows: dynamics 6 and torques na (together the nv rows M q̈ − Jᵀ F) | feet 3c |
        # friction 5c | (single slack: the paired swing rows 3c)
        self._r_tau = 6
        self._r_feet = nv
        self._r_fric = self._r_feet + 3 * c
        self._r_single = self._r_fric + 5 * c
        self.m = self._r_single + (3 * c if single else 0)
        self.A = np.zeros((self.m, self.n))
        self.H = np.zeros((self.n, self.n))
        self.g = np.zeros(self.n)
        self.upper = np.zeros(self.n + self.m)  # simple bounds on every variable, then rows
        self.lower = np.zeros(self.n + self.m)
        self.sense = np.zeros(self.n + self.m, dtype=np.int32)
        self._G = np.zeros((6, self.nf))
        self._normals = np.full((c, 3), np.nan)  # friction rows are rebuilt when these change
        self._swing_targets = np.zeros((c, 3))
        self._anchors = np.zeros((c, 3))  # stance task (eq. 32): contact points at touchdown
        self._was_stance = np.zeros(c, dtype=bool)
        self._dual = None
        self._friction_key = None
        self._tangential = np.zeros((self.nf, self.nf))
        self._patterns: dict[bytes, _Pattern] = {}  # per stance/swing split, see _pattern
        self._swing_names = [f"swing {name}" for name in self.contacts]
        self._override_key = None
        self._radii = np.array([self.robot.contact(name).spec.radius for name in self.contacts])
        self._contact_order = np.array([self.robot.contact_names.index(n) for n in self.contacts])
        self._cols_force = slice(nv, nv + self.nf)
        self._cols_slack = slice(nv + self.nf, self.n)
        n = self.n  # constant senses: dynamics rows are equalities, everything else inequalities
        self.sense[n:n + 6] = _EQ
        self.upper[:6], self.lower[:6] = _INF, -_INF  # the base accelerations are free
        if single:
            for i in range(c):  # slack columns of the paired rows: row1 - eps <= b, row2 + eps >= b
                self.A[self._r_feet + 3 * i:self._r_feet + 3 * i + 3, nv + self.nf + i] = -1.0
                self.A[self._r_single + 3 * i:self._r_single + 3 * i + 3, nv + self.nf + i] = 1.0

    def _pattern(self, stance: np.ndarray) -> "_Pattern":
        """Masks and bounds that depend only on which feet are in stance (cached per split; the
        cache is emptied when the friction rows change)."""
        key = stance.tobytes()
        pattern = self._patterns.get(key)
        if pattern is None:
            s3, s5 = np.repeat(stance, 3), np.repeat(stance, 5)
            swing = np.flatnonzero(~stance)
            feet_rows = self._r_feet + 3 * swing[:, None] + np.arange(3)
            pattern = _Pattern(
                s3=s3, swing=swing, all_stance=bool(stance.all()),
                swing_feet_rows=feet_rows.ravel(),
                swing_single_rows=(feet_rows + self._r_single - self._r_feet).ravel(),
                feet_sense=np.where(s3, _EQ, _FREE).astype(np.int32),
                force_upper=np.where(s3, _INF, 0.0), force_lower=np.where(s3, -_INF, 0.0),
                force_sense=np.where(s3, _FREE, _EQ).astype(np.int32),
                fric_upper=np.where(s5, self._fric_upper, _INF),
                fric_lower=np.where(s5, self._fric_lower, -_INF),
                tangential=self._tangential * s3[:, None])
            self._patterns[key] = pattern
        return pattern

    # ------------------------------------------------------------------ per cycle
    def solve(self, plan) -> Solution:
        """One QP (eq. 7) at the robot's cached state for ``plan`` (a PlanState-like object)."""
        if self._native is not None:
            self._native.update(self.robot.q, self.robot.v)
            return self._solve_native(plan)
        t0 = time.perf_counter()
        self.last_plan = plan
        robot, nv = self.robot, self.robot.nv
        A, H, g, up, lo, n = self.A, self.H, self.g, self.upper, self.lower, self.n
        M, h = robot.M, robot.h
        J = robot.stacked_contact_jacobian(self.contacts)
        stance = plan.contact[self._leg]
        normals = plan.touchdown_normal[self._leg]
        key = (self.mu, self.f_min, self.f_max)
        if key != self._friction_key or not np.array_equal(normals, self._normals):
            self._build_friction(normals, key)
        pat = self._pattern(stance)
        F, rf, rq = self._cols_force, self._r_feet, self._r_fric
        # eq. 9 and eq. 15 in one block: M q̈ − Jᵀ F = −h on the base rows, in [τ_min − h_j,
        # τ_max − h_j] on the joint rows (equality senses of the base rows set at allocation)
        A[:nv, :nv] = M
        A[:nv, F] = -J.T
        tau_lo, tau_hi = self._tau_bounds = self._torque_bounds()
        np.negative(h, out=up[n:n + nv])
        lo[n:n + nv] = up[n:n + nv]
        up[n + 6:n + nv] += tau_hi
        lo[n + 6:n + nv] += tau_lo
        # eqs. 16-18: joint accelerations as simple bounds (the base is free)
        lo[6:nv], up[6:nv] = self.joint_limits.bounds(robot)
        # stance feet, eq. 10 / 32, written for every foot (swing feet are overwritten below)
        points = robot.contact_points[self._contact_order]  # the bottoms of the foot spheres
        touchdown = stance & ~self._was_stance
        if touchdown.any():
            self._anchors[touchdown] = points[touchdown]  # x̂_st of eq. 32
        self._was_stance[:] = stance
        A[rf:rq, :nv] = J
        target = -robot.stacked_contact_drift(self.contacts)
        if self.K_st or self.D_st:
            target += self.K_st * (self._anchors - points).ravel()
            target -= self.D_st * (J @ robot.v)
        up[n + rf:n + rq] = lo[n + rf:n + rq] = target
        self.sense[n + rf:n + rq] = pat.feet_sense
        if not pat.all_stance:
            up[n + pat.swing_feet_rows] = _INF
            lo[n + pat.swing_feet_rows] = -_INF
        # eqs. 13-14: friction pyramid and normal-force bounds on stance feet; swing forces zero
        rs = self._r_single
        up[n + rq:n + rs], lo[n + rq:n + rs] = pat.fric_upper, pat.fric_lower
        up[F], lo[F], self.sense[F] = pat.force_upper, pat.force_lower, pat.force_sense
        # cost: ‖u‖²_R, the trunk wrench (eqs. 7a, 8), the force regulariser (Sect. V-D)
        H[:] = 0.0
        H.flat[::n + 1] = self._R_diagonal  # (flat-iterator assignment writes in place)
        g[:] = 0.0
        G = contact_wrench_map(robot, self.contacts, self._G, points)
        if self.observer is not None and self._commanded_wrench is not None:
            self.impedance.external_wrench = self.observer.update(
                robot.h_G, self._commanded_wrench, robot.mass, self.control_period)
        W_d = self.impedance.wrench(robot, plan.trunk)
        GQ = G.T * self.Q
        HF = GQ @ G
        g[F] = -GQ @ W_d
        if self.regularization == "torque":  # footnote 16: R_F = J_st,j R_τ J_st,jᵀ
            JjT = J[:, 6:].T * np.sqrt(self.torque_weights)[:, None]
            HF += JjT.T @ JjT
        elif self.tangential_weight:
            HF += self.tangential_weight * pat.tangential
        H[F, F] += HF
        if self.swing_slack == "single":
            self._single_slack_layout(stance)
        if not pat.all_stance:
            self._swing_rows(plan, pat)
        t1 = time.perf_counter()
        x, flag, iterations = self._solve_qp()
        t2 = time.perf_counter()
        return self._solution(x, flag, iterations, J, W_d, G, pat,
                              {"assemble": t1 - t0, "solve": t2 - t1})

    def _build_friction(self, normals: np.ndarray, key) -> None:
        """Rows of eqs. 13-14 about each foot's terrain normal; rebuilt when a normal, μ or the
        normal-force bounds change."""
        nv = self.robot.nv
        self._tangential[:] = 0.0
        for i, normal in enumerate(normals):
            rr, fi = self._r_fric + 5 * i, nv + 3 * i
            self.A[rr:rr + 4, fi:fi + 3] = friction_faces(normal, self.mu)
            t1, t2, nn = tangent_basis(normal)
            self.A[rr + 4, fi:fi + 3] = nn
            self._tangential[3 * i:3 * i + 3, 3 * i:3 * i + 3] = np.outer(t1, t1) + np.outer(t2, t2)
        c = len(self.contacts)
        self._fric_upper = np.tile([0.0, 0.0, 0.0, 0.0, self.f_max], c)
        self._fric_lower = np.tile([-_INF, -_INF, -_INF, -_INF, self.f_min], c)
        self._normals[:] = normals
        self._friction_key = key
        self._patterns.clear()

    def _single_slack_layout(self, stance: np.ndarray) -> None:
        """Single-slack layout: a stance foot's slack is pinned at 0 and its paired rows are free;
        a swing foot's slack is in [0, inf) with cost α ε² (its rows are set in _swing_rows)."""
        n, e, rs = self.n, self._cols_slack, self._r_single
        self.upper[e] = np.where(stance, 0.0, _INF)
        self.lower[e] = 0.0
        self.sense[e] = np.where(stance, _EQ, _FREE)
        cols = np.arange(e.start, e.stop)  # H[e, e] = v with a slice would fill the whole block
        self.H[cols, cols] = np.where(stance, 1.0, self.slack_weight)  # 1: keeps H definite
        self.upper[n + rs:n + self.m], self.lower[n + rs:n + self.m] = _INF, -_INF

    def _swing_rows(self, plan, pat: "_Pattern") -> None:
        """Swing feet: eq. 6 (desired foot acceleration) and eq. 12 rows J q̈ = v̇_d − J̇ v — hard
        (eq. 11), a weighted least-squares term (per-direction slacks, eq. 33) or a single slack.
        All swing feet at once; the planner's swing trajectory is the foot frame's."""
        robot, nv, n = self.robot, self.robot.nv, self.n
        sw = pat.swing
        idx = self._contact_order[sw]
        legs = self._leg[sw]
        Jsw = robot.contact_frame_jacobians[idx, :3]  # (k, 3, nv), frame origins (sphere centres)
        pos = robot.contact_points[idx]
        pos[:, 2] += self._radii[sw]
        a_d = self.swing.K * (plan.foot_position[legs] - pos)
        a_d += self.swing.D * (plan.foot_velocity[legs] - Jsw @ robot.v)
        if self.swing.feedforward:
            a_d += plan.foot_acceleration[legs]
        target = a_d - robot.contact_frame_drifts[idx, :3]
        self._swing_targets[sw] = target
        Jrows, b = Jsw.reshape(-1, nv), target.reshape(-1)
        rows = n + pat.swing_feet_rows
        if self.swing_slack == "per-direction":  # rows stay free: α‖J q̈ − b‖² in the cost
            alpha = self.slack_weight
            self.H[:nv, :nv] += alpha * (Jrows.T @ Jrows)
            self.g[:nv] -= alpha * (Jrows.T @ b)
            return
        self.A[pat.swing_feet_rows, :nv] = Jrows
        if self.swing_slack == "none":
            self.upper[rows] = self.lower[rows] = b
            self.sense[rows] = _EQ
        else:  # single: J q̈ − ε <= b and J q̈ + ε >= b
            self.A[pat.swing_single_rows, :nv] = Jrows
            self.upper[rows] = b
            self.lower[n + pat.swing_single_rows] = b

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

    def _torque_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """τ_min(q), τ_max(q) of eq. 15 with the weak-joint overrides (indices cached)."""
        limits, robot = self.torque_limits, self.robot
        key = tuple(limits.upper_override.items())
        if key != self._override_key:
            limits.bounds(robot)  # validates the joint names
            self._override_index = np.array([robot.joint_names.index(j) for j, _ in key], int)
            self._override_value = np.array([value for _, value in key], float)
            self._override_key = key
        hi = robot.torque_limits.upper(robot.q[7:]) * limits.scale
        if self._override_index.size:
            hi[self._override_index] = np.minimum(hi[self._override_index], self._override_value)
        return -hi, hi

    def _solution(self, x, flag, iterations, J, W_d, G, pat, timings) -> Solution:
        robot, nv, nf = self.robot, self.robot.nv, self.nf
        tau_lo, tau_hi = self._tau_bounds
        ok = flag in _DAQP_OK and math.isfinite(x.sum())
        swing_errors = None
        if ok:
            qdd, F = x[:nv], x[nv:nv + nf]
            tau = robot.M[6:] @ qdd + robot.h[6:] - J[:, 6:].T @ F  # eq. 19
            excess = max((tau - tau_hi).max(), (tau_lo - tau).max())
            status = self._excess_status(excess)
            if excess > 0.0:  # within DAQP's primal tolerance unless something is wrong
                tau = np.clip(tau, tau_lo, tau_hi)
            if not pat.all_stance:
                swing_errors = np.zeros(len(self.contacts))
                residuals = (robot.contact_frame_jacobians[self._contact_order[pat.swing], :3] @ qdd
                             - self._swing_targets[pat.swing])
                swing_errors[pat.swing] = np.sqrt(np.einsum("ij,ij->i", residuals, residuals))
        else:
            qdd, F, tau, status = self._failed(flag, robot.h[6:])
        timings["iterations"] = iterations
        return self._report(ok, qdd, F, tau, status, G @ F, W_d, pat.s3[::3], swing_errors,
                            timings)

    @staticmethod
    def _excess_status(excess: float) -> str:
        if excess > 1e-6:  # torques beyond DAQP's primal tolerance: reported, then clipped
            status = f"torque {excess:.2e} Nm outside limits after solve; clipped"
            log.debug(status)
            return status
        return "solved"

    def _failed(self, flag, gravity_torque):
        """A failed solve: hold the previous torque (or the nonlinear effects), clipped."""
        tau_lo, tau_hi = self._tau_bounds
        previous = self.last_tau if self.last_tau is not None else gravity_torque
        tau = np.clip(np.nan_to_num(previous), tau_lo, tau_hi)
        status = f"daqp exit flag {flag}: previous torque held (clipped to limits)"
        if self._failing == 0:  # one warning per streak of failed cycles, not one per cycle
            log.warning("PassiveWBC cycle %d: %s", self.robot.cycle, status)
        return np.zeros(self.robot.nv), np.zeros(self.nf), tau, status

    def _report(self, ok, qdd, F, tau, status, commanded, W_d, stance, swing_errors,
                timings) -> Solution:
        """The Solution of one cycle (both engines): failure streaks, the observer's input, task
        reports (trunk wrench; swing feet when the solve succeeded)."""
        if ok and self._failing:
            log.warning("PassiveWBC cycle %d: solved again after %d failed cycles",
                        self.robot.cycle, self._failing)
        self._failing = 0 if ok else self._failing + 1
        self.last_tau = tau
        self._commanded_wrench = commanded if ok else None
        if not ok and self.observer is not None:  # the applied wrench is unknown: start afresh
            self.observer.reset()
        wrench_error = commanded - W_d
        reports = [TaskReport("trunk wrench", 2, "eq", 6, math.sqrt(wrench_error @ wrench_error))]
        in_stance = stance.tolist()  # Python bools: iterating a numpy array is slow per item
        if swing_errors is not None:
            errors = swing_errors.tolist()
            reports += [TaskReport(self._swing_names[i], 2, "eq", 3, errors[i])
                        for i, st in enumerate(in_stance) if not st]
        per_foot = F.reshape(-1, 3)
        forces = {name: per_foot[i] for i, name in enumerate(self.contacts) if in_stance[i]}
        return Solution(qdd=qdd, lam=F, tau=tau, forces=forces, ok=ok, status=status,
                        level_costs=np.array([wrench_error @ (self.Q * wrench_error)]),
                        tasks=reports, timings=timings, contacts=tuple(forces))

    # ------------------------------------------------------------------ native engine
    def _build_native(self):
        try:
            from .. import _passive_cycle
        except ImportError as exc:
            raise RuntimeError(
                "engine: 'native' needs the compiled cycle wholebody._passive_cycle, which was not "
                "built with this install (it needs a C++17 compiler at 'pip install' time; "
                "WHOLEBODY_NO_NATIVE=1 skips it); use engine='python'") from exc
        cycle = _passive_cycle.PassiveCycle(self._native_spec())
        robot, c = self.robot, len(self.contacts)
        self._nb = {  # the arrays the compiled cycle writes (the QP's are this object's own)
            "H": self.H, "g": self.g, "A": self.A, "upper": self.upper, "lower": self.lower,
            "sense": self.sense, "feet": np.zeros((len(self.planner.legs), 3)),
            "tau": np.zeros(robot.na), "tau_lo": np.zeros(robot.na), "tau_hi": np.zeros(robot.na),
            "h": np.zeros(robot.nv), "h_G": np.zeros(6), "wrench_d": np.zeros(6),
            "commanded": np.zeros(6), "errors": self.impedance.last_errors,
            "swing_residual": np.zeros(c), "qdd": np.zeros(robot.nv), "forces": np.zeros(self.nf)}
        cycle.bind(self._nb)
        self._compact_views: dict[tuple[int, int], tuple] = {}
        return cycle

    def _compact_qp(self, k: int, rows: int) -> tuple:
        """Views of the bound arrays holding the compiled cycle's compact QP (k variables, rows
        rows: the swing feet's forces and the free rows left out, see passive_cycle.cpp)."""
        return (self.H.reshape(-1)[:k * k].reshape(k, k), self.g[:k],
                self.A.reshape(-1)[:rows * k].reshape(rows, k), self.upper[:k + rows],
                self.lower[:k + rows], self.sense[:k + rows])

    def _native_spec(self) -> dict:
        """Model, contacts, weights, gains and limits for the compiled cycle (copied, not shared)."""
        robot, model = self.robot, self.robot.model
        frames = [model.frames[robot.contact(n).frame_id] for n in self.contacts]
        limits = robot.torque_limits
        linkage_rows, linkage_params = limits.linkage
        cap = np.full(robot.na, np.inf)
        for joint, value in self.torque_limits.upper_override.items():
            if joint not in robot.joint_names:
                raise ValueError(f"upper_override: unknown joint '{joint}'")
            i = robot.joint_names.index(joint)
            cap[i] = min(cap[i], float(value))
        imp, lim = self.impedance, self.joint_limits
        return robot.native_model_spec() | {
            "contact_joints": [int(f.parentJoint) for f in frames],
            "contact_placements": np.array([f.placement.homogeneous for f in frames]),
            "radii": self._radii, "leg": [int(i) for i in self._leg],
            "n_legs": len(self.planner.legs), "q_min": robot.q_min, "q_max": robot.q_max,
            "torque_constant": limits.constant, "linkage_rows": [int(i) for i in linkage_rows],
            "linkage_params": linkage_params.ravel(),
            "torque_scale": limits.scale * self.torque_limits.scale, "torque_cap": cap,
            "swing_slack": self.swing_slack, "slack_weight": self.slack_weight,
            "K_st": float(self.K_st), "D_st": float(self.D_st), "Q": self.Q,
            "R_qdd": float(self.R_qdd), "R_force": float(self.R_force),
            "regularization": self.regularization,
            "tangential_weight": float(self.tangential_weight),
            "torque_weights": self.torque_weights, "mu": self.mu, "f_min": float(self.f_min),
            "f_max": float(self.f_max), "swing_K": float(self.swing.K),
            "swing_D": float(self.swing.D), "swing_feedforward": bool(self.swing.feedforward),
            "K_x": imp.K_x, "D_x": imp.D_x, "K_theta": imp.K_theta, "D_theta": imp.D_theta,
            "trunk_feedforward": bool(imp.feedforward), "mass": robot.mass,
            "limits_mode": lim.mode, "horizon": float(lim.horizon), "a_max": float(lim.a_max),
            "steepness": float(lim.steepness)}

    def configure(self) -> None:
        """Hand changed weights, gains or limits to the native engine (no-op for "python")."""
        if self._native is not None:
            self._native.configure(self._native_spec())
            if self._nb["errors"] is not self.impedance.last_errors:  # a new impedance object
                self._nb["errors"] = self.impedance.last_errors
                self._native.bind(self._nb)

    def compute(self, q, v, t: float = 0.0) -> Solution:
        """Torques for the state (q, v) at time ``t`` (see PlannedController.compute)."""
        if self._native is None:
            return super().compute(q, v, t)
        self._native.update(q, v)
        return self._solve_native(self.planner.update(t, feet=self._nb["feet"].copy()))

    def cycle(self, q, v, plan) -> Solution:
        """One cycle at the state (q, v) for a given ``plan``: update + QP + torques."""
        if self._native is None:
            self.robot.update(q, v)
            return self.solve(plan)
        self._native.update(q, v)
        return self._solve_native(plan)

    def _solve_native(self, plan) -> Solution:
        t0 = time.perf_counter()
        self.last_plan = plan
        nb, trunk = self._nb, plan.trunk
        if self.observer is not None and self._commanded_wrench is not None:
            self.impedance.external_wrench = self.observer.update(
                nb["h_G"], self._commanded_wrench, self.robot.mass, self.control_period)
        shape = self._native.assemble(plan.contact, plan.touchdown_normal, plan.foot_position,
                              plan.foot_velocity, plan.foot_acceleration, trunk.position,
                              trunk.velocity, trunk.acceleration, trunk.rotation,
                              trunk.angular_velocity, trunk.angular_acceleration,
                              self.impedance.external_wrench)
        t1 = time.perf_counter()
        qp = self._compact_views.get(shape)
        if qp is None:
            qp = self._compact_views[shape] = self._compact_qp(*shape)
        x, _, flag, info = daqp.solve(*qp)
        self.last_x = x
        t2 = time.perf_counter()
        iterations = info.get("iterations", 0)
        self._tau_bounds = nb["tau_lo"], nb["tau_hi"]
        ok = flag in _DAQP_OK
        excess = self._native.finish(x) if ok else math.nan
        ok = ok and excess == excess  # NaN: x not finite
        if ok:
            qdd, F, tau = nb["qdd"].copy(), nb["forces"].copy(), nb["tau"].copy()
            status = self._excess_status(excess)
            commanded = nb["commanded"].copy()
        else:
            qdd, F, tau, status = self._failed(flag, nb["h"][6:])
            commanded = np.zeros(6)
        stance = plan.contact[self._leg]
        swing_errors = nb["swing_residual"] if ok else None
        return self._report(ok, qdd, F, tau, status, commanded, nb["wrench_d"].copy(), stance,
                            swing_errors, {"assemble": t1 - t0, "solve": t2 - t1,
                                           "iterations": iterations})

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

