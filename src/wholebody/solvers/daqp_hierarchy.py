"""The ``daqp`` method of :func:`~wholebody.solvers.hierarchy.solve_hierarchy`: DAQP's native
hierarchical mode.

All levels stacked in one constraint matrix with ``break_points``, equality rows with
``sense = 5``. Findings (DAQP 0.11; its ``src/hierarchical.c`` and docs, and experiments
reproduced in the tests) on why its lower-level costs differ from the cascade's:

1. Row normalisation — the cause of the difference. DAQP works on the least-distance
   problem with every row of ``A R⁻¹`` (H = RᵀR) scaled to unit norm, and its soft penalty
   ``s²/(2·rho_soft)`` acts on the violation of the NORMALISED row. A level therefore
   minimises ``Σ_i (r_i / ‖a_i‖_{H⁻¹})²`` instead of ``Σ_i r_i²``: another compromise as soon
   as rows of a level conflict and have different norms. Rows ``x = 1`` and ``2x = 0`` give
   0.5 instead of 0.2. Native DAQP agrees with the cascade run on the row-normalised levels
   (:func:`row_normalised`). Row weights cannot undo it (a scaling is normalised away), the
   scale of H does not matter, it is not a tolerance, not the regularisation, and equalities
   need not be given as doubled inequalities (doing so only makes more level LDPs fail).
   Fix used here: one per-row soft weight ``rho_l = rho_u = 1e-8`` for all rows
   (``daqp.Model.soft_weights``), which DAQP applies in the ORIGINAL row scale: conflicts
   inside a level are then resolved by ``Σ s_i²`` as in eq. 5 (x = 0.2 above, for any ρ).
   ρ does not act like the cascade's ε: DAQP satisfies rows that can be satisfied (to about
   its primal tolerance) and ``½‖x‖²`` (H = I) only breaks ties, so it approximates the
   ε → 0 limit and ``regularization`` is not used by this method.
   ``daqp_native_weights=True`` keeps DAQP's own penalty.
2. The FIRST break-point block is hard: the driver softens only the later blocks. A first
   level with conflicting rows makes the setup fail (exitflag -6, "overdetermined") or
   returns exitflag 3 with x = 0. A free dummy row is passed as the first block here.
3. Exitflag 3 is a failure in disguise: the driver returns it when a level's LDP fails,
   with x restored to an EARLIER level's solution and the remaining levels not optimised.
   Reported here as ``ok=False`` with that (finite) x.
Per-level times are not available (one call).
"""

from __future__ import annotations

import numpy as np

from .common import _finish, _row_norms, _rows
from .level import Level

__all__ = ["row_normalised"]

_DAQP_RHO = 1e-8  # per-row soft weight for the daqp method (its own hierarchical default)


def _daqp_stack(levels, n, split_equalities=False):
    """Stack the levels for DAQP's hierarchical mode: weighted rows, one break point per level.

    ``split_equalities`` passes each equality row as two one-sided soft rows instead of
    ``sense = 5`` (kept for the experiments in the module docstring; it fails more often).
    """
    # DAQP 0.11 treats the FIRST break-point block as hard constraints and softens only the
    # later ones: a free dummy row goes first so that every level of ours is soft
    free = np.zeros((1, n))
    free[0, 0] = 1.0
    As, bus, bls, senses, bps = [free], [np.full(1, np.inf)], [np.full(1, -np.inf)], [np.zeros(1, dtype=int)], [1]
    total = 1
    for L in levels:
        B, C = _rows(L, n)
        wB, wb = L.w[:, None] * B, L.w * L.b
        VC, vl, vu = L.v[:, None] * C, L.v * L.lower, L.v * L.upper
        k = wB.shape[0]
        if split_equalities:
            A = np.concatenate((wB, wB, VC))
            bu = np.concatenate((np.full(k, np.inf), wb, vu))
            bl = np.concatenate((wb, np.full(k, -np.inf), vl))
            se = np.zeros(A.shape[0], dtype=int)
        else:
            A = np.concatenate((wB, VC))
            bu = np.concatenate((wb, vu))
            bl = np.concatenate((wb, vl))
            se = np.concatenate((np.full(k, 5), np.zeros(VC.shape[0], dtype=int)))
        # DAQP normalises rows: a zero row cannot be passed; a free row carries nothing
        keep = (_row_norms(A) > 0.0) & (np.isfinite(bl) | np.isfinite(bu))
        A, bu, bl, se = A[keep], bu[keep], bl[keep], se[keep]
        if A.shape[0] == 0:
            continue
        As.append(A), bus.append(bu), bls.append(bl), senses.append(se)
        total += A.shape[0]
        bps.append(total)
    if len(bps) == 1:
        return None
    A = np.ascontiguousarray(np.concatenate(As))
    bu = np.minimum(np.concatenate(bus), 1e30)
    bl = np.maximum(np.concatenate(bls), -1e30)
    return A, bu, bl, np.concatenate(senses).astype(np.intc), np.asarray(bps, dtype=np.intc)


def _solve_daqp(levels, n, opts, t0, uniform_soft_weights=True, split_equalities=False):
    import daqp

    nl = len(levels)
    times = np.full(nl, np.nan)
    stack = _daqp_stack(levels, n, split_equalities)
    if stack is None:
        return _finish(levels, np.zeros(n), "optimal", True, t0, times, "daqp", nl, np.zeros(0), [])
    A, bu, bl, sense, bps = stack
    try:
        model = daqp.Model()
        if opts:
            model.settings = opts
        flag, _ = model.setup(np.eye(n), np.zeros(n), A, bu, bl, sense, bps)
        if flag < 0:
            status = f"daqp hierarchical: setup failed, exitflag {flag}"
            if flag == -6:
                status += " (dependent equality rows with inconsistent targets)"
            return _finish(levels, np.zeros(n), status, False, t0, times, "daqp", 0, np.zeros(0), [])
        if uniform_soft_weights:
            # one ρ for every row, in the ORIGINAL row scale: conflicts are resolved by Σ s²
            rho = np.full(A.shape[0], _DAQP_RHO)
            model.soft_weights(rho_l=rho, rho_u=rho)
        x, _, flag, _ = model.solve()
    except (ValueError, RuntimeError) as exc:
        return _finish(levels, np.zeros(n), f"daqp hierarchical: {exc}", False, t0, times, "daqp", 0,
                       np.zeros(0), [])
    x = np.array(x)
    if flag == 3 and np.all(np.isfinite(x)):
        status = "daqp hierarchical: a level's LDP failed (exitflag 3); x is an earlier level's solution"
        return _finish(levels, x, status, False, t0, times, "daqp", 0, np.zeros(0), [])
    if flag not in (1, 2) or not np.all(np.isfinite(x)):
        return _finish(levels, np.zeros(n), f"daqp hierarchical: exitflag {flag}", False, t0, times, "daqp", 0,
                       np.zeros(0), [])
    return _finish(levels, x, "optimal", True, t0, times, "daqp", nl, np.zeros(0), [])


def row_normalised(levels):
    """The levels with every weighted row scaled to unit norm — what DAQP's native soft penalty sees.

    Running the cascade on these reproduces the daqp method with ``daqp_native_weights=True``.
    """
    out = []
    for L in levels:
        if L.n is None:
            out.append(L)
            continue
        eq = ineq = None
        if L.n_eq:
            wB = L.w[:, None] * L.B
            nb = _row_norms(wB)
            nb = np.where(nb > 0, nb, 1.0)
            eq = (wB / nb[:, None], L.w * L.b / nb)
        if L.n_ineq:
            VC = L.v[:, None] * L.C
            nc = _row_norms(VC)
            ineq = (VC / nc[:, None], L.v * L.lower / nc, L.v * L.upper / nc)
        out.append(Level(eq=eq, ineq=ineq, name=L.name))
    return out
