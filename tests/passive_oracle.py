"""The passive WBC's QP (Fahmi et al. 2019, eq. 7) assembled by hand in DAQP's form: the tests'
independent oracle of the QP ``PassiveWBC`` poses as a stack of library tasks
(wholebody/control/passive_stack.py) and solves on either engine.

Variables u = [q̈ (nv), F (3 per foot), ε (one per foot, "single" swing slacks only)]; simple bounds
on every variable (the base accelerations free, joint accelerations by eqs. 16-18, swing-foot forces
pinned to zero) come first in ``upper``/``lower``/``sense``, then the rows of ``A``:

* dynamics, nv rows M q̈ − Jᵀ F: the 6 base rows equal to −h (eq. 9), the joint rows in
  [τ_min − h_j, τ_max − h_j] (eq. 15 with τ from eq. 19);
* feet, 3 per foot: J q̈ = target for stance feet (eq. 10/32), swing rows free or eq. 11/12;
* friction, 5 per foot: the pyramid (eq. 13) and the normal-force bounds (eq. 14), free on swing
  feet;
* "single" slacks only, 3 per foot: the paired rows of the swing rows, J q̈ + ε ≥ b.

The layout never changes with the stance split, so DAQP's multipliers warm-start the next cycle.
:func:`hand_assembled` writes it at the robot's cached state from a controller's settings and the
references of the cycle it just solved (stance anchors, W_d, τ bounds: the controller's state,
checked by their own tests) and solves it.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from wholebody.control.passive import STANCE_RANK_TOLERANCE
from wholebody.solvers.backends import DAQP_SENSE_EQ as EQ, DAQP_SENSE_INEQ as FREE
from wholebody.solvers.backends import DaqpResult, solve_daqp_qp
from wholebody.tasks.contact import (friction_faces, independent_rows, lean_rows, tangent_basis,
                                     tangent_rows)
from wholebody.tasks.wrench import contact_wrench_map, heading_weights

_INF = np.inf


@dataclass(frozen=True)
class StancePattern:
    """Masks and bounds that depend only on the stance/swing split of one cycle."""

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


class PassiveQP:
    """The arrays ``H, g, A, upper, lower, sense`` of eq. 7 for ``nv`` velocities and
    ``n_feet`` point feet, their row blocks, and the DAQP solve with warm start."""

    def __init__(self, nv: int, n_feet: int, single_slack: bool = False):
        c = n_feet
        self.nv, self.n_feet, self.single_slack = nv, c, single_slack
        self.nf = 3 * c
        self.n = nv + self.nf + (c if single_slack else 0)
        self.r_feet = nv  # the dynamics rows come first (6 base rows, then na joint rows)
        self.r_fric = self.r_feet + 3 * c
        self.r_single = self.r_fric + 5 * c
        self.m = self.r_single + (3 * c if single_slack else 0)
        self.A = np.zeros((self.m, self.n))
        self.H = np.zeros((self.n, self.n))
        self.g = np.zeros(self.n)
        self.upper = np.zeros(self.n + self.m)  # simple bounds on every variable, then rows
        self.lower = np.zeros(self.n + self.m)
        self.sense = np.zeros(self.n + self.m, dtype=np.int32)
        self.cols_force = slice(nv, nv + self.nf)
        self.cols_slack = slice(nv + self.nf, self.n)
        self.dual: np.ndarray | None = None  # multipliers of the last successful solve
        self._normals = np.full((c, 3), np.nan)  # friction rows are rebuilt when these change
        self._bases = np.zeros((c, 3, 3))  # per foot [t1; t2; n] of its terrain normal
        self._leaning = np.zeros((self.nf, self.nf))  # leaning_tangential's output
        self._friction_key = None
        self._tangential = np.zeros((self.nf, self.nf))
        self._patterns: dict[bytes, StancePattern] = {}
        n = self.n  # constant senses: dynamics rows are equalities, everything else inequalities
        self.sense[n:n + 6] = EQ
        self.upper[:6], self.lower[:6] = _INF, -_INF  # the base accelerations are free
        if single_slack:
            for i in range(c):  # slack columns of the paired rows: row1 - eps <= b, row2 + eps >= b
                self.A[self.r_feet + 3 * i:self.r_feet + 3 * i + 3, nv + self.nf + i] = -1.0
                self.A[self.r_single + 3 * i:self.r_single + 3 * i + 3, nv + self.nf + i] = 1.0

    # ------------------------------------------------------------------ per stance split
    def pattern(self, stance: np.ndarray) -> StancePattern:
        """Masks and bounds for the split ``stance`` (cached per split; the cache is emptied when
        the friction rows change)."""
        key = stance.tobytes()
        pattern = self._patterns.get(key)
        if pattern is None:
            s3, s5 = np.repeat(stance, 3), np.repeat(stance, 5)
            swing = np.flatnonzero(~stance)
            feet_rows = self.r_feet + 3 * swing[:, None] + np.arange(3)
            pattern = StancePattern(
                s3=s3, swing=swing, all_stance=bool(stance.all()),
                swing_feet_rows=feet_rows.ravel(),
                swing_single_rows=(feet_rows + self.r_single - self.r_feet).ravel(),
                feet_sense=np.where(s3, EQ, FREE).astype(np.int32),
                force_upper=np.where(s3, _INF, 0.0), force_lower=np.where(s3, -_INF, 0.0),
                force_sense=np.where(s3, FREE, EQ).astype(np.int32),
                fric_upper=np.where(s5, self._fric_upper, _INF),
                fric_lower=np.where(s5, self._fric_lower, -_INF),
                tangential=self._tangential * s3[:, None])
            self._patterns[key] = pattern
        return pattern

    def set_friction(self, normals: np.ndarray, mu: float, f_min: float, f_max: float) -> None:
        """Rows of eqs. 13-14 about each foot's terrain normal; rebuilt only when a normal, μ or
        the normal-force bounds changed."""
        key = (mu, f_min, f_max)
        if key == self._friction_key and np.array_equal(normals, self._normals):
            return
        nv = self.nv
        self._tangential[:] = 0.0
        for i, normal in enumerate(normals):
            rr, fi = self.r_fric + 5 * i, nv + 3 * i
            self.A[rr:rr + 4, fi:fi + 3] = friction_faces(normal, mu)
            self._bases[i] = tangent_basis(normal)
            self.A[rr + 4, fi:fi + 3] = self._bases[i, 2]
            rows = tangent_rows(normal)
            self._tangential[3 * i:3 * i + 3, 3 * i:3 * i + 3] = rows.T @ rows
        c = self.n_feet
        self._fric_upper = np.tile([0.0, 0.0, 0.0, 0.0, f_max], c)
        self._fric_lower = np.tile([-_INF, -_INF, -_INF, -_INF, f_min], c)
        self._normals[:] = normals
        self._friction_key = key
        self._patterns.clear()

    def leaning_tangential(self, stance: np.ndarray, lean: np.ndarray, mu: float) -> np.ndarray:
        """The tangential regulariser (unweighted, stance feet) with each force's tangential part
        measured from the direction of ``lean`` (:func:`~wholebody.tasks.contact.lean_rows` for
        all stance feet at once); the returned array is reused by the next call."""
        feet = np.flatnonzero(stance)
        rows = lean_rows(self._bases[feet, :2], self._bases[feet, 2], lean, mu)
        out = self._leaning
        out[:] = 0.0
        index = 3 * feet[:, None] + np.arange(3)
        out[index[:, :, None], index[:, None, :]] = np.einsum("sij,sik->sjk", rows, rows)
        return out

    # ------------------------------------------------------------------ row blocks
    def set_dynamics(self, M, J, h, tau_lo, tau_hi) -> None:
        """Eq. 9 and eq. 15 in one block: M q̈ − Jᵀ F = −h on the base rows, in
        [τ_min − h_j, τ_max − h_j] on the joint rows."""
        nv, n, up, lo = self.nv, self.n, self.upper, self.lower
        self.A[:nv, :nv] = M
        self.A[:nv, self.cols_force] = -J.T
        np.negative(h, out=up[n:n + nv])
        lo[n:n + nv] = up[n:n + nv]
        up[n + 6:n + nv] += tau_hi
        lo[n + 6:n + nv] += tau_lo

    def set_joint_bounds(self, qdd_lo, qdd_hi) -> None:
        """Eqs. 16-18: joint accelerations as simple bounds (the base stays free)."""
        self.lower[6:self.nv], self.upper[6:self.nv] = qdd_lo, qdd_hi

    def set_feet(self, J, target, pat: StancePattern) -> None:
        """Stance feet, eq. 10 / 32: J q̈ = target, written for every foot; the swing feet's rows
        are left free (see :meth:`set_swing`)."""
        n, rf, rq, up, lo = self.n, self.r_feet, self.r_fric, self.upper, self.lower
        self.A[rf:rq, :self.nv] = J
        up[n + rf:n + rq] = lo[n + rf:n + rq] = target
        self.sense[n + rf:n + rq] = pat.feet_sense
        if not pat.all_stance:
            up[n + pat.swing_feet_rows] = _INF
            lo[n + pat.swing_feet_rows] = -_INF

    def set_forces(self, pat: StancePattern) -> None:
        """Eqs. 13-14: friction pyramid and normal-force bounds on stance feet; swing forces 0."""
        n, rq, rs, F = self.n, self.r_fric, self.r_single, self.cols_force
        self.upper[n + rq:n + rs], self.lower[n + rq:n + rs] = pat.fric_upper, pat.fric_lower
        self.upper[F], self.lower[F], self.sense[F] = (pat.force_upper, pat.force_lower,
                                                       pat.force_sense)

    def set_cost(self, R_diagonal, H_force, g_force) -> None:
        """Cost ‖u‖²_R plus the force block (trunk wrench task, eqs. 7a and 8, and the force
        regulariser): H = diag(R) + [0, H_F, 0], g = [0, g_F, 0]."""
        F, n = self.cols_force, self.n
        self.H[:] = 0.0
        self.H.flat[::n + 1] = R_diagonal  # (flat-iterator assignment writes in place)
        self.g[:] = 0.0
        self.g[F] = g_force
        self.H[F, F] += H_force

    def set_single_slacks(self, stance: np.ndarray, slack_weight: float) -> None:
        """Single-slack layout: a stance foot's slack is pinned at 0 and its paired rows are free;
        a swing foot's slack is in [0, inf) with cost α ε² (its rows are set in set_swing)."""
        n, e, rs = self.n, self.cols_slack, self.r_single
        self.upper[e] = np.where(stance, 0.0, _INF)
        self.lower[e] = 0.0
        self.sense[e] = np.where(stance, EQ, FREE)
        cols = np.arange(e.start, e.stop)  # H[e, e] = v with a slice would fill the whole block
        self.H[cols, cols] = np.where(stance, 1.0, slack_weight)  # 1: keeps H definite
        self.upper[n + rs:n + self.m], self.lower[n + rs:n + self.m] = _INF, -_INF

    def set_swing(self, J_rows, b, pat: StancePattern, slack: str, slack_weight: float) -> None:
        """Swing feet's eq. 12 rows J q̈ = b: hard (``slack`` "none", eq. 11), a weighted
        least-squares term α‖J q̈ − b‖² (``"per-direction"``, eq. 33 with one slack per row) or
        J q̈ − ε ≤ b ≤ J q̈ + ε (``"single"``, one slack per foot)."""
        nv, n = self.nv, self.n
        rows = n + pat.swing_feet_rows
        if slack == "per-direction":  # rows stay free: α‖J q̈ − b‖² in the cost
            self.H[:nv, :nv] += slack_weight * (J_rows.T @ J_rows)
            self.g[:nv] -= slack_weight * (J_rows.T @ b)
            return
        self.A[pat.swing_feet_rows, :nv] = J_rows
        if slack == "none":
            self.upper[rows] = self.lower[rows] = b
            self.sense[rows] = EQ
        else:
            self.A[pat.swing_single_rows, :nv] = J_rows
            self.upper[rows] = b
            self.lower[n + pat.swing_single_rows] = b

    # ------------------------------------------------------------------ solve
    def solve(self) -> DaqpResult:
        """DAQP on the full layout, warm-started from the last successful solve's multipliers."""
        result = solve_daqp_qp(self.H, self.g, self.A, self.upper, self.lower, self.sense,
                               dual_start=self.dual)
        self.dual = result.dual
        return result


def hand_assembled(wbc, plan, qp: PassiveQP | None = None) -> SimpleNamespace:
    """The QP of ``wbc`` (a PassiveWBC that has just solved ``plan`` at the robot's cached state:
    its stance anchors, W_d and τ bounds are this cycle's) assembled in ``qp`` (a new one if
    None; a kept one warm-starts DAQP) and solved: (ok, x, qdd, lam, tau by eq. 19, swing
    residuals per contact, the single slacks, qp)."""
    robot, nv = wbc.robot, wbc.robot.nv
    contacts = wbc.contacts
    if qp is None:
        qp = PassiveQP(nv, len(contacts), single_slack=wbc.swing_slack == "single")
    J = robot.stacked_contact_jacobian(contacts)
    stance = plan.contact[wbc._leg]
    qp.set_friction(plan.touchdown_normal[wbc._leg], wbc.mu, wbc.f_min, wbc.f_max)
    pat = qp.pattern(stance)
    qp.set_dynamics(robot.M, J, robot.h, *wbc._tau_bounds)
    qp.set_joint_bounds(*wbc.joint_limits.bounds(robot))
    points = robot.contact_points  # (PassiveWBC's contacts are the robot's, in its order)
    target = -robot.stacked_contact_drift(contacts)
    if wbc.K_st or wbc.D_st:  # eq. 32 about the controller's anchors
        target += wbc.K_st * (wbc._anchors - points).ravel()
        target -= wbc.D_st * (J @ robot.v)
    qp.set_feet(J, target, pat)
    if wbc.dependent_stance:  # an independent set of the dependent rows, the others free
        rows = np.flatnonzero(pat.s3)
        A, b, rank = independent_rows(J[rows], target[rows], STANCE_RANK_TOLERANCE)
        at = qp.n + qp.r_feet + rows
        qp.A[qp.r_feet + rows, :nv] = A
        qp.upper[at] = qp.lower[at] = b
        qp.sense[at[rank:]] = FREE
        qp.upper[at[rank:]], qp.lower[at[rank:]] = np.inf, -np.inf
        if qp.dual is not None:
            qp.dual[at] = 0.0
    qp.set_forces(pat)
    # cost: ‖u‖²_R, the trunk wrench (eqs. 7a, 8), the force regulariser (Sect. V-D)
    G = contact_wrench_map(robot, contacts, np.zeros((6, qp.nf)), points)
    W_d = wbc.last_desired_wrench
    GQ = G.T @ heading_weights(wbc.Q, plan.trunk.rotation)
    HF = GQ @ G
    if wbc.regularization == "torque":  # footnote 16: R_F = J_st,j R_τ J_st,jᵀ
        JjT = J[:, 6:].T * np.sqrt(wbc.torque_weights)[:, None]
        HF += JjT.T @ JjT
    elif wbc.regularization == "force-parallel" and wbc.tangential_weight:
        HF += wbc.tangential_weight * qp.leaning_tangential(stance, W_d[:3], wbc.mu)
    elif wbc.tangential_weight:
        HF += wbc.tangential_weight * pat.tangential
    R = np.zeros(qp.n)
    R[:nv], R[nv:nv + qp.nf] = wbc.R_qdd, wbc.R_force
    qp.set_cost(R, HF, -GQ @ W_d)
    if (wbc.posture_K or wbc.posture_D) and wbc.posture_mask.any():
        qp.g[6:nv] -= wbc.R_qdd * wbc.posture_acceleration()
    if wbc.swing_slack == "single":
        qp.set_single_slacks(stance, wbc.slack_weight)
    residual_of = None
    if not pat.all_stance:  # eq. 6 and eq. 12 rows J q̈ = v̇_d − J̇ v of the swing feet
        sw = pat.swing
        legs = wbc._leg[sw]
        Jsw = robot.contact_frame_jacobians[sw, :3]  # frame origins (sphere centres)
        position = robot.contact_points[sw]
        position[:, 2] += wbc._radii[sw]
        a_d = wbc.swing.K * (plan.foot_position[legs] - position)
        a_d += wbc.swing.D * (plan.foot_velocity[legs] - Jsw @ robot.v)
        if wbc.swing.feedforward:
            a_d += plan.foot_acceleration[legs]
        swing_target = a_d - robot.contact_frame_drifts[sw, :3]
        qp.set_swing(Jsw.reshape(-1, nv), swing_target.reshape(-1), pat, wbc.swing_slack,
                     wbc.slack_weight)
        residual_of = (Jsw, swing_target)
    result = qp.solve()
    out = SimpleNamespace(ok=result.ok, x=result.x, qp=qp, swing_errors=np.zeros(len(contacts)),
                          slacks={})
    if result.ok:
        x = result.x
        out.qdd, out.lam = x[:nv], x[nv:nv + qp.nf]
        out.tau = robot.M[6:] @ out.qdd + robot.h[6:] - J[:, 6:].T @ out.lam  # eq. 19
        if residual_of is not None:
            Jsw, swing_target = residual_of
            residual = Jsw @ out.qdd - swing_target
            out.swing_errors[pat.swing] = np.sqrt(np.einsum("ij,ij->i", residual, residual))
        if wbc.swing_slack == "single":
            eps = x[nv + qp.nf:]
            out.slacks = {f"slack {contacts[i]}": eps[i] for i in pat.swing}
    return out
