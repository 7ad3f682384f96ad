"""The cascade, the reference method of :func:`~wholebody.solvers.hierarchy.solve_hierarchy`
(Herzog et al. 2016, §2.2, eqs. 8-11).

One QP per level over the nullspace coordinates u, plus one slack per inequality row of the
level that still has freedom (eqs. 10-11). ``Z`` is updated recursively, ``Z_{r+1} = Z_r N_r``
with ``N_r`` an orthonormal kernel basis of ``W_r B_r Z_r``: Z keeps orthonormal columns and
the variable count shrinks level by level. Equality rows lock their directions even when
they cannot be satisfied (their residual is what is kept). Inequality rows with
``‖C_i Z‖ ≤ drop_tol ‖C_i‖`` have no freedom left: they are dropped from the QP (their value
can no longer change) and checked to still hold within ``feas_tol``; a level with
``Z`` empty is only evaluated.

Closed form first. Every level's QP is first solved without its rows: the minimiser of
``½‖M u + e‖² + ε/2‖x* + Z u‖²`` by Householder QR of the stacked ``[M; √ε I]`` (a
regularised least-squares problem; not the normal equations ``MᵀM + εI``, whose condition
number is squared). The level QP reuses that factor R: it is posed in w = R u, so the
backend sees an identity Hessian (see :func:`_level_qp`). If it satisfies the level's own inequality rows and the relaxed higher rows, it
is the QP's solution (the minimiser of a relaxation that is feasible, with zero slacks) and
the backend is not called; otherwise the QP of eqs. 10-11 is solved. A level of equalities
only, below no inequality, is thus exactly the least-squares problem its QP is. Seed 000
solves a QP per level; the optimum is the same. The implicit equalities below are looked for
only when a QP is needed.

Two numerical devices keep the QPs well posed without changing the optimal set by more
than round-off:

* implicit equalities. When a level pushes against higher-priority inequalities (or leaves
  own rows violated), those rows are, once its equalities are locked, pinned: their
  projected normals are positively dependent, the feasible cone of the next QP has an
  empty interior, and the backends report "inconsistent"/"infeasible" on rounding noise
  (plain eqs. 8-11 make quadprog and DAQP fail on random conflicting hierarchies).
  Such rows are detected geometrically — tight rows whose normalised
  normals admit a nonnegative null combination (NNLS, after two cheap certificates of
  independence) — and locked like equality rows. This is exact: the set is the same.
  Deciding it from multipliers or from the size of a violation was tried and rejected:
  rows active or violated only because of the ε term (O(ε‖x‖)) are then locked too, which
  is wrong by O(1) for the lower levels.
* margin. Rows still tight at x* (or violated within ``feas_tol``, what a backend's
  tolerance leaves) are loosened to include x* with a margin ``relax_tol (1 + |C x*|)``
  (1e-9), so the next QP has an interior; costs move by O(relax_tol × multiplier). The
  margin alone does not suffice for every backend (ProxQP still fails on some
  hierarchies); with both devices all three backends solve all test hierarchies.

Nullspace by QR with column pivoting, not SVD: the kernel basis comes from LAPACK
``dgeqp3``/``dorgqr`` on ``(W_r B_r Z_r)ᵀ``; a direction is locked when ``|R_ii|`` exceeds
``rank_tol · max_i ‖W_i B_i‖`` (relative to the UNPROJECTED rows, so a row that is
numerically a combination of already locked rows locks nothing). At these sizes QRCP is
cheaper than a full SVD, which matters at 1 kHz. Its rank decision is reliable except on
adversarial (Kahan-like) matrices; as a guard, whenever some ``|R_ii|`` falls within three
decades of the threshold the QR's kernel is either certified from the factor itself
(``1/‖R11⁻¹‖_F`` above and ``‖R22‖_F`` below the threshold bound the singular values on either
side of it, and their gap bounds the angle to the SVD's kernel: a level whose row weights span
many decades, as Table 2's, has pivots there every cycle) or recomputed with an SVD (the
paper's choice), whose singular values are the exact measure.

ε (``regularization``). The ε‖x‖² of eq. 5 makes every QP strictly convex (Goldfarb–Idnani
needs a positive definite Hessian); reported costs exclude it, but x is the solution of the
regularised cascade. Relative to the exact lexicographic optimum each level's cost is off
by about ε‖x‖² plus what the ε-perturbed residuals/slacks of the higher levels cost it —
O(ε ‖x‖ × multipliers), which can be large: with the paper's ε = 1e-4 and ‖x‖ ~ 10-100 a
higher level's cost can even DROP below the value it had when that level was solved,
because lower levels can move within its relaxed bound. For control this is harmless.
The tests therefore check two different things: (1) the cascade reproduces an
independently formulated regularised cascade at the same ε (1e-4) to 1e-6; (2) with a
small ε (1e-10) it reproduces the unregularised lexicographic optimum (oracle at ε = 1e-11,
itself good to a few 1e-6): all within 1e-5, ≥ 98 % within 1e-6.

:mod:`.compiled_cascade` runs this algorithm compiled, line for line.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.linalg import lapack, solve_triangular
from scipy.optimize import nnls

from .common import _backend_solve, _finish, _row_norms, _rows, log

_TIGHT_TOL = 1e-8  # a higher row is tight at x when |C x - bound| <= _TIGHT_TOL (1 + |C x|)


def _sq_norms(A: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", A, A)


def _solve_cascade(levels, n, settings, fls, tols, t0):
    """The cascade (module docstring) with ``settings`` (a :class:`.SolverSettings`); the reference
    for its compiled mirror (compiled_cascade._solve_compiled)."""
    eps = settings.regularization
    rank_tol, drop_tol, relax_tol, feas_tol = tols
    drop2 = drop_tol * drop_tol  # freedom tests on squared norms: ‖C_i Z‖² > drop_tol² ‖C_i‖²
    nl = len(levels)
    times = np.zeros(nl)
    zdims = np.zeros(nl, dtype=int)
    warns: list[str] = []
    x = np.zeros(n)
    Z = None  # None stands for the identity: nothing locked yet
    z = n
    # higher-priority inequality rows that still have freedom: (C, relaxed lower, relaxed upper
    # (eq. 9), drop_tol² ‖C_i‖²), or None while there are none
    high = None
    HZ = hx = hb = None

    for r, L in enumerate(levels):
        tl = time.perf_counter()
        B, C = _rows(L, n)
        m = C.shape[0]

        if r == 0 and fls is not None:  # analytic first priority (§2.4, eq. 17), v*_1 = 0
            x, Z = fls[0].copy(), fls[1]
            z = Z.shape[1]
            if m:
                CZ1 = C @ Z if z else np.zeros((m, 0))
                high, _ = _drop_frozen((C, L.lower, L.upper, drop2 * _sq_norms(C)), CZ1, x,
                                       feas_tol, L, warns)
            zdims[0], times[0] = z, time.perf_counter() - tl
            continue
        if z == 0:  # no freedom left: the level is only evaluated
            zdims[r], times[r] = 0, time.perf_counter() - tl
            continue

        # ---- higher rows: drop those without freedom; rows tight at x* get a margin (loosened)
        tight = False
        if high is not None:
            high, HZ = _drop_frozen(high, high[0] if Z is None else high[0] @ Z, x, feas_tol, L,
                                    warns)
        if high is not None:
            hx = high[0] @ x
            gap = np.minimum(hx - high[1], high[2] - hx)  # < 0: violated (within tolerance)
            tight = not (gap > max(_TIGHT_TOL, relax_tol) * (1.0 + np.abs(hx))).all()
            hb = _loosen_tight(hx, high[1], high[2], relax_tol, feas_tol) if tight else high[1:3]

        # ---- project the level onto the remaining freedom x = x* + Z u (eq. 8); its
        # unconstrained minimiser (QR least squares) is tried first: if it satisfies the level's own rows
        # and the relaxed higher rows, it is the QP's solution (the minimiser of a relaxation,
        # feasible with zero slacks) and no QP is solved. A level of equalities below no
        # inequality is always solved so: its QP (eq. 10) is exactly a regularised least-squares
        # problem.
        wB, M, own, ls = _project_level(L, B, C, Z, z, x, eps, drop2)
        u, ok, status, Rc = _unconstrained(*ls, eps)
        rows = _qp_rows(own, high, HZ, hx, hb, x, z) if (own is not None or high is not None) else None
        solved = ok and (rows is None or not _violated(rows, u))
        if not solved and tight:
            # implicit equalities (module docstring) keep the QP well posed: looked for only when
            # a QP is solved — the optimal set is the same with or without locking them
            imp = _implicit_equalities(HZ, hx, high[1], high[2])
            if imp is not None:
                Z, z = _lock(Z, high[0][imp], None, rank_tol)
                keep = ~imp
                high = tuple(a[keep] for a in high) if keep.any() else None
                if z == 0:
                    zdims[r], times[r] = 0, time.perf_counter() - tl
                    continue
                if high is not None:
                    high, HZ = _drop_frozen(high, high[0] @ Z, x, feas_tol, L, warns)
                    if high is not None:
                        hx = high[0] @ x
                        hb = _loosen_tight(hx, high[1], high[2], relax_tol, feas_tol)
                wB, M, own, ls = _project_level(L, B, C, Z, z, x, eps, drop2)
                u, ok, status, Rc = _unconstrained(*ls, eps)
                rows = (_qp_rows(own, high, HZ, hx, hb, x, z)
                        if (own is not None or high is not None) else None)
                solved = ok and (rows is None or not _violated(rows, u))
        if not solved and rows is not None:
            u, ok, status = _level_qp(Rc, *rows, lambda *qp: _backend_solve(
                lambda: qp, settings, r, levels, warns))
        if high is not None:  # the margins stay for the lower levels
            high = (high[0], hb[0], hb[1], high[3])
        if not ok:
            times[r] = time.perf_counter() - tl
            status = f"level {r} ({L.name!r}): {status}"
            log.debug("cascade failed: %s", status)
            return _finish(levels, x, status, False, t0, times, "cascade", r, zdims[:r], warns)
        x = x + (u if Z is None else Z @ u)

        # ---- this level's free inequality rows join the higher ones, relaxed by v* (eq. 9)
        if own is not None:
            Co, lo, up, nCo = own[0], own[2], own[3], own[5]
            cx = Co @ x
            viol = np.maximum(np.maximum(lo - cx, cx - up), 0.0)
            if high is None:
                high = (Co, lo - viol, up + viol, nCo)
            else:
                high = (np.concatenate((high[0], Co)), np.concatenate((high[1], lo - viol)),
                        np.concatenate((high[2], up + viol)), np.concatenate((high[3], nCo)))
        # ---- lock the directions of the weighted equality rows: Z_{r+1} = Z_r N_r (eq. 8);
        # after the last level nobody needs the null space (saves a QR/SVD per cycle)
        if wB.shape[0] and r < nl - 1:
            Z, z = _lock(Z, wB, M, rank_tol)
        zdims[r], times[r] = z, time.perf_counter() - tl

    return _finish(levels, x, "optimal", True, t0, times, "cascade", nl, zdims, warns)


def _project_level(L, B, C, Z, z, x, eps, drop2):
    """The level over x = x* + Z u (eq. 8): weighted rows W B, M = W B Z, its own inequality rows
    that still have freedom: (C, C Z, lower, upper, V, drop_tol² ‖C_i‖²) or None, and the data
    (M, r0 = W(B x* − b), Zᵀx*) of ½‖M u + r0‖² + ε/2 ‖x* + Z u‖² for :func:`_unconstrained`."""
    wB = L.w[:, None] * B
    if Z is None:
        M, zx = wB, x
    else:
        M, zx = wB @ Z, Z.T @ x
    r0 = wB @ x - L.w * L.b
    own = None
    if C.shape[0]:  # own rows without freedom keep their (fixed) violation: no slack
        CZ = C if Z is None else C @ Z
        nC = drop2 * _sq_norms(C)
        free = _sq_norms(CZ) > nC
        if free.all():
            own = (C, CZ, L.lower, L.upper, L.v, nC)
        elif free.any():
            own = (C[free], CZ[free], L.lower[free], L.upper[free], L.v[free], nC[free])
    return wB, M, own, (M, r0, zx)


def _qp_rows(own, high, HZ, hx, hb, x, z):
    """The rows of the level QP in u: own (C Z, C x*, lower, upper, V), higher (H Z, H x*,
    relaxed lower, relaxed upper) — the argument list of :func:`_level_qp` after (R, c)."""
    empty = np.zeros(0)
    own_qp = ((np.zeros((0, z)), empty, empty, empty, empty) if own is None
              else (own[1], own[0] @ x, own[2], own[3], own[4]))
    high_qp = ((np.zeros((0, z)), empty, empty, empty) if high is None else (HZ, hx, hb[0], hb[1]))
    return own_qp + high_qp


def _violated(rows, u) -> bool:
    """Some own or higher row of the level QP is violated at u (exactly, no tolerance)."""
    CZ, c0, lo, up, _, HZ, h0, hlo, hup = rows
    return bool(_outside(CZ, c0, lo, up, u).any() or _outside(HZ, h0, hlo, hup, u).any())


def _outside(A, a0, lower, upper, u):
    """Mask of the rows with A u + a0 outside [lower, upper] (exactly, no tolerance)."""
    v = A @ u
    v += a0
    return (v < lower) | (v > upper)


#: the kernel of a certified QR (``_rank_certified``) is within this angle (sin) of the SVD's
_SUBSPACE_TOL = 1e-6


def _rank_certified(qr: np.ndarray, rank: int, tol: float) -> bool:
    """Whether the QR with column pivoting (``qr``: the packed factor, R on and above the
    diagonal) gives the SVD's kernel: its rank ``rank`` (the |R_ii| > ``tol``) is the SVD's count
    of singular values above ``tol`` — σ_rank ≥ σ_min(R11) ≥ s = 1 / ‖R11⁻¹‖_F > tol (R11 a
    leading block of R: interlacing) and σ_rank+1 ≤ ‖R22‖_2 ≤ t = ‖R22‖_F ≤ tol (R without its
    trailing block has rank ``rank``: Weyl) — and its kernel is the SVD's within
    ``_SUBSPACE_TOL``: sin θ ≤ t / (s − t) (Wedin), the accuracy the QR has outside the
    ambiguous window (pivots three decades either side of ``tol``). Cheap next to an SVD: one
    triangular inverse of the kept block."""
    p = min(qr.shape)
    trailing = float(np.linalg.norm(np.triu(qr[rank:p, rank:])))
    if not trailing <= tol:
        return False
    if not rank:
        return True
    inverse = solve_triangular(np.triu(qr[:rank, :rank]), np.eye(rank), lower=False,
                               check_finite=False)
    lower = 1.0 / float(np.linalg.norm(inverse))  # (0 for an inf or NaN inverse)
    return lower > tol and trailing <= _SUBSPACE_TOL * (lower - trailing)


def _kernel(RZ: np.ndarray, tol: float) -> np.ndarray:
    """Orthonormal basis of ker(RZ) (k×z): QR with column pivoting of RZᵀ; an SVD decides when
    some |R_ii| is within three decades of ``tol`` and the QR's kernel is not certified
    (:func:`_rank_certified`)."""
    k, z = RZ.shape
    qr, _, tau, _, info = lapack.dgeqp3(np.array(RZ.T, order="F"))
    p = min(k, z)
    d = np.abs(qr.diagonal()[:p])
    rank = int(np.count_nonzero(d > tol))
    if info != 0 or (((d > 1e-3 * tol) & (d < 1e3 * tol)).any()
                     and not _rank_certified(qr, rank, tol)):
        # the kernel is in doubt: let the singular values decide (exact rank measure)
        U, s, _ = np.linalg.svd(RZ.T, full_matrices=True)
        return U[:, int(np.count_nonzero(s > tol)):]
    if rank == 0:
        return np.eye(z)
    if rank >= z:
        return np.zeros((z, 0))
    a = np.zeros((z, z), order="F")
    a[:, :p] = qr[:, :p]
    t = np.zeros(z)
    t[:p] = tau[:p]
    q, _, info = lapack.dorgqr(a, t, overwrite_a=True)
    if info != 0:
        U, s, _ = np.linalg.svd(RZ.T, full_matrices=True)
        return U[:, int(np.count_nonzero(s > tol)):]
    return q[:, rank:]


def _lock(Z, rows, projected, rank_tol):
    """Restrict Z to the kernel of ``rows``: Z ← Z N (eq. 8). ``projected`` is ``rows Z`` if
    already computed (None: computed here). Returns (Z, z)."""
    z = rows.shape[1] if Z is None else Z.shape[1]
    if rows.shape[0] == 0 or z == 0:
        return Z, z
    scale = math.sqrt(float(_sq_norms(rows).max()))
    if scale == 0.0:
        return Z, z
    if projected is None:
        projected = rows if Z is None else rows @ Z
    N = _kernel(projected, rank_tol * scale)
    if N.shape[1] == z:
        return Z, z
    Z = N if Z is None else Z @ N
    return Z, Z.shape[1]


def _implicit_equalities(HZ, hx, hlo, hup, tight_tol=_TIGHT_TOL, dep_tol=1e-7):
    """Rows tight at x whose signed, projected, normalised normals are positively dependent.

    With g_i = ±C_i Z oriented so that staying feasible near x means g_i d ≥ 0, a tight row i is
    an implicit equality of {d : g_j d ≥ 0} iff some y ≥ 0 with y_i > 0 has Σ y_j g_j = 0.
    Found by NNLS (min ‖Gᵀy‖ with Σy = 1 enforced by a heavy row); each dependency found is
    projected out and the search repeated. Purely geometric: a row that is tight only because
    of the ε term is locked only if the geometry really pins it. Returns a mask, or None when
    no row is an implicit equality.
    """
    m = HZ.shape[0]
    if m < 2:
        return None
    tol = tight_tol * (1.0 + np.abs(hx))
    tl = np.abs(hx - hlo) <= tol  # (a row violated at x — possible after §2.4 — is not tight)
    tu = np.abs(hup - hx) <= tol
    nt = int(np.count_nonzero(tl)) + int(np.count_nonzero(tu))
    if nt < 2:
        return None
    idx = np.concatenate((np.flatnonzero(tl), np.flatnonzero(tu)))
    G = np.concatenate((HZ[tl], -HZ[tu]))
    nrm = _row_norms(G)
    good = nrm > 0.0
    idx, G = idx[good], G[good] / nrm[good, None]
    # cheap certificate of NO dependency: a direction d with G d > 0 (Σ y_j g_j·d > 0 for y ≥ 0)
    d = G.sum(axis=0)
    if np.all(G @ d > dep_tol):
        return None
    GGt = G @ G.T
    GGt.flat[:: GGt.shape[0] + 1] += 1e-10 * GGt.shape[0]
    # d = Gᵀ (G Gᵀ)⁻¹ 1, i.e. G d ≈ 1 when the rows are independent (G Gᵀ SPD then: Cholesky)
    _, y, info = lapack.dposv(GGt, np.ones(G.shape[0]))
    if info == 0:
        d = G.T @ y
        if (G @ d > dep_tol).all():
            return None
    found = np.zeros(idx.shape[0], dtype=bool)
    P = None  # orthonormal basis of the span of the rows found so far
    while idx.shape[0] - np.count_nonzero(found) >= 2:
        rest = np.flatnonzero(~found)
        Gr = G[rest] if P is None else G[rest] - (G[rest] @ P) @ P.T
        k, z = Gr.shape
        A = np.empty((z + 1, k))
        A[:z] = Gr.T
        A[z] = 1e3
        b = np.zeros(z + 1)
        b[z] = 1e3
        try:
            y, _ = nnls(A, b)
        except (RuntimeError, ValueError):
            break
        ys = y.sum()
        if ys <= 0.0 or np.linalg.norm(Gr.T @ y) > dep_tol * ys:
            break
        found[rest[y > 1e-9 * y.max()]] = True
        P = _range_basis(G[found].T)
        # a tight row in the span of implicit equalities is one too (g·d = 0 on every feasible
        # d): taken at once rather than one NNLS each (its projected row is ~0, a dependency
        # of one row)
        rest = np.flatnonzero(~found)
        spanned = _row_norms(G[rest] - (G[rest] @ P) @ P.T) <= dep_tol
        found[rest[spanned]] = True
    if not found.any():
        return None
    out = np.zeros(m, dtype=bool)
    out[idx[found]] = True
    return out


def _range_basis(A):
    """Orthonormal columns spanning range(A) (A is z × k): Q of a QR of A (LAPACK dgeqrf/dorgqr)
    without the columns whose |R_ii| ≤ 1e-12."""
    z, k = A.shape
    p = min(z, k)
    qr, tau, _, info = lapack.dgeqrf(A)
    if info == 0:
        keep = np.abs(qr.diagonal()[:p]) > 1e-12
        Q, _, info = lapack.dorgqr(qr[:, :p], tau[:p], overwrite_a=True)
    if info != 0:
        Q, R = np.linalg.qr(A)
        keep = np.abs(R.diagonal()) > 1e-12
    return Q[:, keep]


def _loosen_tight(hx, hlo, hup, relax_tol, feas_tol):
    """Widen the bounds of rows tight at x so that they include C x with a margin δ = relax_tol
    (1 + |C x|): the next QP then has an interior and x* is feasible for it. Tight: within δ of
    a bound, or beyond it by at most the backends' feasibility tolerance feas_tol (1 + |C x|) —
    the violation a higher level's QP left within its tolerance is kept, as eq. 9 keeps a
    level's optimal violation. (Without the second part, a row DAQP left violated within its
    tolerance makes the next level's QP infeasible for DAQP and quadprog alike.)
    Rows violated by more (e.g. torque limits at the analytic first level's x1) stay hard."""
    a = 1.0 + np.abs(hx)
    dlt, out = relax_tol * a, feas_tol * a
    tl = (hx - hlo <= dlt) & (hlo - hx <= out)
    tu = (hup - hx <= dlt) & (hx - hup <= out)
    if tl.any():
        hlo = hlo.copy()
        hlo[tl] = np.minimum(hlo[tl], hx[tl]) - dlt[tl]
    if tu.any():
        hup = hup.copy()
        hup[tu] = np.maximum(hup[tu], hx[tu]) + dlt[tu]
    return hlo, hup


def _drop_frozen(high, HZ, x, feas_tol, L, warns):
    """Drop higher rows with ‖C_i Z‖ ≤ drop_tol ‖C_i‖ (no freedom left), checking they still hold.

    ``high = (C, lower, upper, drop_tol² ‖C_i‖²)``; returns ``(high, HZ)`` restricted to the rows
    with freedom (``high`` None if there is none left).
    """
    free = _sq_norms(HZ) > high[3]
    if free.all():
        return high, HZ
    hC, hlo, hup, hn = high
    gone = ~free
    cx = hC[gone] @ x
    over = np.maximum(hlo[gone] - cx, cx - hup[gone])
    bad = over > feas_tol * (1.0 + np.abs(cx))
    if bad.any():
        msg = (f"before level {L.name!r}: {int(bad.sum())} higher-priority inequality row(s) without "
               f"freedom violate their relaxed bounds by up to {float(over[bad].max()):.3g}")
        log.debug(msg)
        warns.append(msg)
    if not free.any():
        return None, None
    return (hC[free], hlo[free], hup[free], hn[free]), HZ[free]


def _unconstrained(M, r0, zx, eps):
    """The minimiser of ‖M u + r0‖² + ε ‖zx + u‖² (the level over x = x* + Z u, Z orthonormal so
    that ‖x* + Z u‖² = ‖Zᵀx* + u‖² + const) as the least-squares solution of the stacked system
    [M; √ε I] u ≈ [−r0; −√ε zx] by Householder QR (LAPACK dgeqrf, dormqr, dtrtrs — what dgels
    does). Returns ``(u, ok, status, (R, c))`` with R the triangular factor and c the first z
    entries of Qᵀ·rhs, so that the level's cost is ‖R u − c‖² + const: :func:`_level_qp` uses
    them to give the backend the well-conditioned problem in w = R u.

    Not by Cholesky of the normal equations MᵀM + ε I: that squares the condition number, and a
    level whose row weights span 1e4 … 1e-4 (Table 2's level 3: momentum 1e4, GRF regulariser
    1e-4) has cond(M)² ~ 1e16 — the low-weight rows then sit at rounding level, and a change of
    the state by rounding moves the torques by far more than rounding.
    """
    k, z = M.shape
    A = np.empty((k + z, z), order="F")
    A[:k] = M
    A[k:] = 0.0
    root = math.sqrt(eps)
    A[k:].flat[:: z + 1] = root
    rhs = np.empty((k + z, 1), order="F")
    np.negative(r0, out=rhs[:k, 0])
    np.multiply(zx, -root, out=rhs[k:, 0])
    qr, tau, _, info = lapack.dgeqrf(A, overwrite_a=True)
    if info == 0:
        qtb, _, info = lapack.dormqr("L", "T", qr, tau, rhs, max(1, (k + z) * 64), overwrite_c=True)
    if info != 0:
        return None, False, f"least squares: QR failed (info {info})", None
    R = np.triu(qr[:z, :z])
    c = qtb[:z, 0].copy()
    u, info = lapack.dtrtrs(R, c, lower=0)
    if info != 0 or not np.isfinite(u).all():
        return None, False, f"least squares: triangular solve failed (info {info})", None
    return u, True, "optimal", (R, c)


def _level_qp(Rc, CZ, c0, lo, up, vw, HZ, h0, hlo, hup, solve):
    """QP of eqs. 10-11 over [u, s]: own rows lower − s/V ≤ C x ≤ upper + s/V, higher rows relaxed;
    every row in the caller's units (the slack carries the weight V, not the row: a row weighted
    1e4 would otherwise have its violation, and the backends' feasibility tolerances, counted in
    units 1e4 times smaller — DAQP solutions exact to rounding on such rows were refused);
    ``solve(H, g, A, lower, upper) → (y, ok, status)`` solves it (:func:`.common._backend_solve`).

    The level's cost ½‖M u + r0‖² + ε/2 ‖Zᵀx* + u‖² is ½‖R u − c‖² + const with R, c from the QR
    of the stacked system (:func:`_unconstrained`, ``Rc = (R, c)``). The backend is given the
    problem in w = R u: Hessian I (with the slacks' I), gradient −c, rows C Z R⁻¹ (triangular
    solves); u = R⁻¹ w afterwards. Handing it Hu = MᵀM + εI instead (the normal equations) squares
    cond(R): with Table 2's level-3 weights (1e4 … 1e-4, ε = 1e-4) cond(Hu) ~ 1e16, and every
    backend's factorisation of Hu turned the weakly weighted directions (the internal wrench
    between the feet) into rounding noise. The row values A u are the same in both
    parametrisations, so the backends'
    feasibility tolerances keep their meaning.

    On the normal equations a weakly weighted direction can put a row of a higher level into
    the backend's active set at many times the true optimum's cost (a torque step between two
    cycles whose states differ by rounding); the problem in w does not.
    Nearly dependent active rows after normalisation give LDLᵀ pivots far below DAQP's stock
    ``sing_tol``, which it then takes for dependent ("infeasible"): hence ``sing_tol`` 1e-14 and
    ``primal_tol`` 1e-9 in ``backends.DAQP_DEFAULTS``
    (``test_daqp_settings_leave_no_table1_level_qp_to_the_fallback``).

    ``s ≥ 0`` is not imposed: it holds at the optimum (a negative slack only tightens its row
    and costs s², so it is never better than s = 0).
    """
    R, c = Rc
    z = R.shape[0]
    m = CZ.shape[0]
    nv = z + m
    H = np.eye(nv)
    g = np.zeros(nv)
    np.negative(c, out=g[:z])
    fl, fu = np.isfinite(lo), np.isfinite(up)
    il, iu = np.flatnonzero(fl), np.flatnonzero(fu)
    nl_, nu_, nh = il.size, iu.size, HZ.shape[0]
    nr = nl_ + nu_ + nh
    A = np.zeros((nr, nv))
    lower = np.empty(nr)
    upper = np.empty(nr)
    Au = np.empty((nr, z))  # the rows in u, then mapped to w: Au R⁻¹ = (R⁻ᵀ Auᵀ)ᵀ
    if m:
        # C Z u + s / V ≥ lower − C x* (the slack's cost is s², V its weight: s = V · violation)
        Au[:nl_] = CZ[il]
        A[np.arange(nl_), z + il] = 1.0 / vw[il]
        lower[:nl_] = lo[il] - c0[il]
        upper[:nl_] = np.inf
        # C Z u − s / V ≤ upper − C x*
        Au[nl_ : nl_ + nu_] = CZ[iu]
        A[nl_ + np.arange(nu_), z + iu] = -1.0 / vw[iu]
        lower[nl_ : nl_ + nu_] = -np.inf
        upper[nl_ : nl_ + nu_] = up[iu] - c0[iu]
    if nh:
        Au[nl_ + nu_ :] = HZ
        lower[nl_ + nu_ :] = hlo - h0
        upper[nl_ + nu_ :] = hup - h0
    if nr:
        A[:, :z] = solve_triangular(R, Au.T, trans="T", lower=False, check_finite=False).T
    y, ok, status = solve(H, g, A, lower, upper)
    if not ok:
        return None, False, status
    u = solve_triangular(R, y[:z], lower=False, check_finite=False)
    if not np.isfinite(u).all():
        return None, False, f"{status}: non-finite solution after the change of variables"
    return u, True, status
