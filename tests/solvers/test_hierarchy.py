"""Robot-free hierarchical QP solver (Herzog et al. 2016, §2.2) against an independent oracle.

The oracle is written differently from the library: every level is solved over the FULL vector
x (no nullspace), the optimality of the higher levels is imposed as explicit constraints — their
weighted residual vector fixed (it is unique over a least-squares optimal set, so fixing it is
exact) and their inequalities relaxed by their own optimal slacks — and the QPs are handed to
quadprog/DAQP directly, with a backend different from the one under test.

Two comparisons, because the ε‖x‖² of eq. 5 is part of the method:
* same ε (1e-4, the paper's value): the oracle solves the same regularised sequence, so the
  per-level costs must agree to solver precision: |Δ| ≤ 1e-6 (1 + cost) (quadprog, DAQP;
  ProxQP to its measured envelope);
* small ε (1e-10) against the oracle at ε = 1e-11: the cascade reproduces the exact
  lexicographic optimum — all within 1e-5 (1 + cost), ≥ 98 % within 1e-6 — on well-scaled
  instances (‖x‖ ≤ 1e3; beyond that ε‖x‖² × multipliers is no longer small; skipped, counted).
Every tolerance here was measured on 4 × 240 hierarchies (seeds 1000, 5000, 9000, 20000).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import quadprog
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.linalg import null_space, qr

from wholebody.solvers import (Level, SolverSettings, evaluate_levels, row_normalised, solve_hierarchy,
                               solve_qp)
from wholebody.solvers import backends as backends_mod
from wholebody.solvers.settings import HIERARCHY_DEFAULT

N_PROBLEMS = 240


def cfg(**changes) -> SolverSettings:
    """solve_hierarchy's default settings (quadprog, no fallback, ε = 1e-4) with ``changes``."""
    return dataclasses.replace(HIERARCHY_DEFAULT, **changes)

BACKENDS = ("quadprog", "daqp", "proxsuite")


# ----------------------------------------------------------------------------- random hierarchies
def random_hierarchy(rng: np.random.Generator, n: int | None = None, n_levels: int | None = None) -> list:
    """2-5 levels over 4-20 variables: conflicting equality tasks, rank-deficient B, duplicated
    rows, two- and one-sided inequalities, unreachable bounds, random row weights."""
    n = n or int(rng.integers(4, 21))
    n_levels = n_levels or int(rng.integers(2, 6))
    levels = []
    for r in range(n_levels):
        k = int(rng.integers(0, max(2, n // 2)))
        m = int(rng.integers(0, n))
        eq = ineq = w = vw = None
        if k:
            if k >= 2 and rng.random() < 0.3:  # rank deficient, inconsistent targets
                rk = int(rng.integers(1, k))
                B = rng.standard_normal((k, rk)) @ rng.standard_normal((rk, n))
            else:
                B = rng.standard_normal((k, n))
            if rng.random() < 0.3:  # duplicated row
                B = np.vstack([B, B[:1]])
                k += 1
            eq = (B, 2.0 * rng.standard_normal(k))
            if rng.random() < 0.5:
                w = rng.uniform(0.2, 3.0, k)
        if m:
            C = rng.standard_normal((m, n))
            c = rng.standard_normal(m)
            lo, up = c - rng.uniform(0, 1, m), c + rng.uniform(0, 1, m)
            kind = rng.integers(0, 4, m)
            lo[kind == 1] = -np.inf  # one-sided
            up[kind == 2] = np.inf
            if rng.random() < 0.3:  # bounds far from anything reachable together with the rest
                lo[kind == 3] += 5.0
                up[kind == 3] = lo[kind == 3] + 0.5
            ineq = (C, lo, up)
            if rng.random() < 0.5:
                vw = rng.uniform(0.2, 3.0, m)
        if eq is None and ineq is None:
            eq = (rng.standard_normal((1, n)), rng.standard_normal(1))
        levels.append(Level(eq=eq, ineq=ineq, weights=w, ineq_weights=vw, name=f"L{r}"))
    return levels


# ----------------------------------------------------------------------------- the oracle
def _independent_rows(E, e, tol=1e-9):
    """A maximal independent subset of the rows of E (pivoted QR of Eᵀ; a row selection)."""
    if E.shape[0] == 0:
        return E, e
    _, R, P = qr(E.T, pivoting=True, mode="economic")
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > tol * d[0])) if d.size and d[0] > 0 else 0
    return E[P[:rank]], e[P[:rank]]


def _oracle_qp(solver, H, g, G, h, meq):
    """min ½yᵀHy + gᵀy s.t. G y ≥ h, the first meq rows with equality."""
    if solver == "quadprog":
        try:
            if G.shape[0]:
                return quadprog.solve_qp(H, -g, G.T.copy(), h, meq)[0]
            return quadprog.solve_qp(H, -g)[0]
        except ValueError:
            return None
    import daqp

    A = G if G.shape[0] else np.zeros((1, H.shape[0]))
    bl = h.copy() if G.shape[0] else np.full(1, -1e30)
    bu = np.full(A.shape[0], 1e30)
    bu[:meq] = bl[:meq]
    sense = np.zeros(A.shape[0], dtype=np.intc)
    sense[:meq] = 5
    for extra in ({}, {"eps_prox": 1e-6}):
        x, _, flag, _ = daqp.solve(H, g, np.ascontiguousarray(A), bu, bl, sense, primal_tol=1e-10, **extra)
        if flag in (1, 2):
            return np.array(x)
    return None


def oracle(levels, eps, solver="quadprog", margin=1e-11):
    """Lexicographic cascade over the full x with explicit optimality constraints.

    Returns (costs at the final x, x) or None if the QP solver gave up. ``margin`` loosens rows
    that are tight at the current x (relative to 1 + |C x|), for the same reason as the library.
    """
    n = next(L.n for L in levels if L.n is not None)
    E, e = np.zeros((0, n)), np.zeros(0)  # fixed weighted residuals  E x = e
    IC, ilo, iup = np.zeros((0, n)), np.zeros(0), np.zeros(0)  # relaxed inequalities
    x = np.zeros(n)
    for L in levels:
        B = L.B if L.n_eq else np.zeros((0, n))
        C = L.C if L.n_ineq else np.zeros((0, n))
        wB, wb, m = L.w[:, None] * B, L.w * L.b, C.shape[0]
        if IC.shape[0]:
            h0 = IC @ x
            d = margin * (1 + np.abs(h0))
            t = np.abs(h0 - ilo) <= d
            ilo = ilo.copy()
            ilo[t] = np.minimum(ilo[t], h0[t]) - d[t]
            t = np.abs(h0 - iup) <= d
            iup = iup.copy()
            iup[t] = np.maximum(iup[t], h0[t]) + d[t]
        Es, es = _independent_rows(E, e)
        nv = n + m
        H = np.zeros((nv, nv))
        H[:n, :n] = wB.T @ wB + eps * np.eye(n)
        H[n:, n:] = np.eye(m)
        g = np.zeros(nv)
        g[:n] = -wB.T @ wb
        I, VC = np.eye(m), L.v[:, None] * C
        fl, fu = np.isfinite(L.lower), np.isfinite(L.upper)
        hl, hu = np.isfinite(ilo), np.isfinite(iup)
        G = np.vstack([
            np.hstack([Es, np.zeros((Es.shape[0], m))]),
            np.hstack([IC[hl], np.zeros((hl.sum(), m))]),
            np.hstack([-IC[hu], np.zeros((hu.sum(), m))]),
            np.hstack([VC[fl], I[fl]]),  # V C x + s ≥ V lower
            np.hstack([-VC[fu], I[fu]]),  # V C x − s ≤ V upper
        ])
        h = np.concatenate([es, ilo[hl], -iup[hu], (L.v * L.lower)[fl], -(L.v * L.upper)[fu]])
        y = _oracle_qp(solver, H, g, G, h, Es.shape[0])
        if y is None or not np.all(np.isfinite(y)):
            return None
        x = y[:n]
        cx = C @ x
        viol = np.maximum(np.maximum(L.lower - cx, cx - L.upper), 0.0)
        keep = L.w > 0
        E, e = np.vstack([E, wB[keep]]), np.concatenate([e, wB[keep] @ x])
        IC = np.vstack([IC, C])
        ilo, iup = np.concatenate([ilo, L.lower - viol]), np.concatenate([iup, L.upper + viol])
    return evaluate_levels(levels, x)[0], x


def oracle_ladder(levels, eps, solvers=("quadprog", "daqp")):
    """The oracle with the smallest margin (then the next solver) that succeeds."""
    for solver in solvers:
        for margin in (1e-11, 1e-10, 1e-9):
            out = oracle(levels, eps, solver, margin)
            if out is not None:
                return out
    return None


def rel_err(got, ref):
    return np.abs(np.asarray(got) - np.asarray(ref)) / (1.0 + np.abs(ref))


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def problems():
    return [random_hierarchy(np.random.default_rng(1000 + i)) for i in range(N_PROBLEMS)]


@pytest.fixture(scope="module")
def oracle_same_eps(problems):
    """Oracle at ε = 1e-4 with quadprog and with DAQP (each test uses the other backend)."""
    return {s: [oracle_ladder(lv, 1e-4, (s,)) for lv in problems] for s in ("quadprog", "daqp")}


# ----------------------------------------------------------------------------- oracle comparisons
@pytest.mark.parametrize("backend", [b if b != "proxsuite" else pytest.param(b, marks=pytest.mark.slow)
                                     for b in BACKENDS])  # proxsuite takes tens of seconds here
def test_cascade_matches_oracle_same_eps(problems, oracle_same_eps, backend):
    """Cascade(ε=1e-4) == full-space oracle(ε=1e-4): per-level costs within 1e-6 (1 + cost).

    ProxQP is an augmented-Lagrangian method whose accuracy is its tolerance, not machine
    precision: even at eps_abs = 1e-11 a few instances end 1e-5 off (measured over 960: 3 above
    1e-5, max 9e-5) and about 1 in 1000 hits the iteration limit (flagged, finite x). For it
    the test asserts the measured envelope instead.
    """
    first, second = ("daqp", "quadprog") if backend == "quadprog" else ("quadprog", "daqp")
    prox = backend == "proxsuite"
    opts = {"eps_abs": 1e-11, "max_iter": 100_000} if prox else None
    errs, skipped, failed = [], 0, 0
    for i, lv in enumerate(problems):
        ref = oracle_same_eps[first][i] or oracle_same_eps[second][i]
        if ref is None:
            skipped += 1
            continue
        sol = solve_hierarchy(lv, cfg(backend=backend, regularization=1e-4, backend_options=opts))
        assert np.all(np.isfinite(sol.x)) and np.all(np.isfinite(sol.costs))
        if not sol.ok and prox:
            failed += 1
            assert "proxsuite" in sol.status
            continue
        assert sol.ok, f"problem {i}: {sol.status}"
        errs.append((rel_err(sol.costs, ref[0]).max(), i))
    assert len(errs) >= 200 and skipped <= 0.05 * len(problems)
    worst, i = max(errs)
    if prox:
        e = np.array([err for err, _ in errs])
        assert failed <= 3 and worst <= 1e-3 and np.mean(e <= 1e-6) >= 0.97, (failed, worst, i)
    else:
        assert worst <= 1e-6, f"{backend}: worst relative cost error {worst:.2e} (problem {i})"


def test_cascade_is_lexicographic_for_small_eps(problems):
    """With ε = 1e-10 the cascade reproduces the (practically) unregularised lexicographic optimum.

    The oracle runs with ε = 1e-11, i.e. cond(H) ~ 1e11-1e12 in quadprog, and is itself only
    good to a few 1e-6 on ill-conditioned instances (its variants disagree among themselves
    there while the cascade is stable in ε). Measured over 934 instances: 5 above 1e-6, none
    above 1e-5. Hence: all within 1e-5, at least 98 % within 1e-6.
    """
    errs, ill_scaled, skipped = [], 0, 0
    for i, lv in enumerate(problems):
        ref = oracle_ladder(lv, 1e-11)
        if ref is None:
            skipped += 1
            continue
        if np.linalg.norm(ref[1]) > 1e3:  # ε‖x‖² × multipliers no longer small
            ill_scaled += 1
            continue
        sol = solve_hierarchy(lv, settings=cfg(regularization=1e-10))
        assert sol.ok, f"problem {i}: {sol.status}"
        errs.append((rel_err(sol.costs, ref[0]).max(), i))
    assert ill_scaled + skipped <= 0.08 * len(problems), (ill_scaled, skipped)
    worst, i = max(errs)
    assert worst <= 1e-5, f"worst relative cost error {worst:.2e} (problem {i})"
    assert np.mean([err <= 1e-6 for err, _ in errs]) >= 0.98


def test_default_eps_is_close_to_lexicographic(problems, oracle_same_eps):
    """Measured, not assumed: how far the paper's ε = 1e-4 moves the costs from the exact optimum.

    The gap is O(ε‖x‖ × multipliers); on these instances it stays below 1e-2 relative in 95 %
    of the cases, but single ill-scaled instances move more. This pins the documented size.
    """
    gaps = []
    for i, lv in enumerate(problems[:120]):
        exact = oracle_ladder(lv, 1e-11)
        if exact is None or np.linalg.norm(exact[1]) > 1e3:
            continue
        sol = solve_hierarchy(lv, settings=cfg(regularization=1e-4))
        gaps.append(rel_err(sol.costs, exact[0]).max())
    gaps = np.array(gaps)
    assert np.quantile(gaps, 0.95) < 1e-2
    assert gaps.max() > 1e-7  # the bias is real: ε = 1e-4 is not the exact optimum


# ----------------------------------------------------------------------------- DAQP hierarchical mode
def _well_posed(rng, n=12):
    """3 levels, independent dense rows, lower-bounded inequalities (the 'few percent' set)."""
    levels = []
    for r in range(3):
        k, m = int(rng.integers(2, 6)), int(rng.integers(2, 8))
        B, C = rng.standard_normal((k, n)), rng.standard_normal((m, n))
        levels.append(Level(eq=(B, rng.standard_normal(k)),
                            ineq=(C, rng.standard_normal(m) + 1.0, np.full(m, np.inf)), name=f"L{r}"))
    return levels


def test_daqp_native_mode_minimises_row_normalised_residuals():
    """DAQP's own soft penalty acts on unit-normalised rows: rows x = 1 and 2x = 0 give 0.5.

    (A single level also checks the dummy hard first block: DAQP 0.11 does not soften the
    first break-point block, so without it these conflicting rows would make setup fail.)
    """
    L = Level(eq=(np.array([[1.0, 0.0], [2.0, 0.0]]), np.array([1.0, 0.0])))
    native = solve_hierarchy([L], cfg(method="daqp", regularization=1e-8), daqp_native_weights=True)
    fixed = solve_hierarchy([L], settings=cfg(method="daqp", regularization=1e-8))
    cascade = solve_hierarchy([L], settings=cfg(regularization=1e-8))
    assert native.ok and fixed.ok
    assert native.x[0] == pytest.approx(0.5, abs=1e-6)  # min (x-1)² + x²      (normalised)
    assert cascade.x[0] == pytest.approx(0.2, abs=1e-6)  # min (x-1)² + (2x)²   (eq. 5)
    assert fixed.x[0] == pytest.approx(0.2, abs=1e-6)


def test_daqp_native_gap_is_the_normalisation():
    """Native DAQP sits a few percent above the cascade, and matches the cascade on row-normalised levels."""
    rng = np.random.default_rng(7)
    gap, match = [], []
    for _ in range(60):
        lv = _well_posed(rng)
        native = solve_hierarchy(lv, cfg(method="daqp", regularization=1e-8), daqp_native_weights=True)
        assert native.ok
        cascade = solve_hierarchy(lv, settings=cfg(regularization=1e-8))
        normed = row_normalised(lv)
        ref = solve_hierarchy(normed, settings=cfg(regularization=1e-8))
        gap.append(rel_err(native.costs, cascade.costs).max())
        match.append(rel_err(evaluate_levels(normed, native.x)[0], ref.costs).max())
    gap, match = np.array(gap), np.array(match)
    assert np.median(gap) > 1e-3 and np.mean(gap > 1e-3) > 0.5  # the reported "few percent"
    assert np.median(match) < 1e-5 and np.mean(match < 1e-3) > 0.9  # same problem, other solver


def test_daqp_method_matches_cascade():
    """With one per-row soft weight for all rows (original scale) DAQP's hierarchy solves eq. 5.

    Measured over 1000 problems: median difference ~2e-8, ≥ 98 % within 1e-4, ~0.5 % failed
    with exitflag 3. Instances with ‖x‖ > 1e3 are skipped: there the cascade's ε‖x‖² matters
    (DAQP has no such term, its ‖x‖² only breaks ties) and the two legitimately differ.
    """
    rng = np.random.default_rng(11)
    errs, failed = [], 0
    for _ in range(100):
        lv = _well_posed(rng)
        sol = solve_hierarchy(lv, settings=cfg(method="daqp", regularization=1e-8))
        if not sol.ok:  # DAQP exitflag 3: reported, x from an earlier level, finite
            failed += 1
            assert np.all(np.isfinite(sol.x)) and "exitflag" in sol.status
            continue
        ref = solve_hierarchy(lv, settings=cfg(regularization=1e-8))
        if np.linalg.norm(ref.x) > 1e3:
            continue
        errs.append(rel_err(sol.costs, ref.costs).max())
    errs = np.array(errs)
    assert failed <= 5 and len(errs) >= 90
    assert np.median(errs) < 1e-6 and np.mean(errs < 1e-4) > 0.95 and errs.max() < 1e-2


def test_daqp_method_handles_conflicting_dependent_equalities():
    """x0 = 1 and x0 = 2 in one level (dependent, inconsistent): compromise 1.5, as the cascade."""
    B = np.array([[1.0, 0.0], [1.0, 0.0]])
    lv = [Level(eq=(B, np.array([1.0, 2.0])), name="conflict"),
          Level(eq=(np.array([[0.0, 1.0]]), np.array([5.0])), name="next")]
    sol = solve_hierarchy(lv, settings=cfg(method="daqp", regularization=1e-8))
    ref = solve_hierarchy(lv, settings=cfg(regularization=1e-8))
    assert sol.ok, sol.status
    np.testing.assert_allclose(sol.x, [1.5, 5.0], atol=1e-6)
    np.testing.assert_allclose(sol.costs, ref.costs, rtol=1e-6, atol=1e-6)


# ----------------------------------------------------------------------------- properties
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), extra_seed=st.integers(0, 2**32 - 1))
def test_adding_a_lower_level_never_changes_higher_costs(seed, extra_seed):
    """Priorities are strict: an appended level only moves x inside the higher optimal set.

    Exact (to 1e-9) for small ε. With the paper's ε = 1e-4 a higher level's cost may DROP (by
    up to ~1e-5 relative, measured): its slack v* carries an O(ε) excess and the relaxed bound
    of eq. 9 lets a lower level reduce it. It never rises beyond what the 1e-9 margin on tight
    rows allows (measured max 1.8e-8 relative over 4000 pairs; asserted 1e-6).
    """
    n_levels = int(np.random.default_rng(seed).integers(1, 5))
    lv = random_hierarchy(np.random.default_rng(seed), n_levels=n_levels)
    extra = random_hierarchy(np.random.default_rng(extra_seed), n=lv[0].n, n_levels=1)[0]
    for eps in (1e-10, 1e-4):
        base = solve_hierarchy(lv, settings=cfg(regularization=eps))
        more = solve_hierarchy(lv + [extra], settings=cfg(regularization=eps))
        assert base.ok and more.ok and len(more.costs) == len(lv) + 1
        change = (more.costs[:-1] - base.costs) / (1.0 + base.costs)
        assert change.max() <= 1e-6  # never worse
        if eps == 1e-10 and np.linalg.norm(more.x) <= 1e3:
            assert np.abs(change).max() <= 1e-9


def test_weighted_equals_two_level_cascade():
    rng = np.random.default_rng(3)
    for _ in range(40):
        n = int(rng.integers(4, 16))
        x_feas = rng.standard_normal(n)
        Bh = rng.standard_normal((int(rng.integers(1, n // 2 + 1)), n))
        Ch = rng.standard_normal((int(rng.integers(1, n)), n))
        cx = Ch @ x_feas
        hard = Level(eq=(Bh, Bh @ x_feas), ineq=(Ch, cx - rng.uniform(0, 1, cx.size), np.full(cx.size, np.inf)),
                     name="hard")
        obj = random_hierarchy(rng, n=n, n_levels=1)[0]
        # ε small: the cascade's soft first level trades O(ε) violation for norm, the hard rows don't
        w = solve_hierarchy([hard, obj], settings=cfg(method="weighted", regularization=1e-10))
        c = solve_hierarchy([hard, obj], settings=cfg(method="cascade", regularization=1e-10))
        assert w.ok and c.ok and w.method == "weighted" and not w.warnings
        np.testing.assert_allclose(w.costs, c.costs, rtol=1e-6, atol=1e-6)
        # (x itself is only pinned by the tiny ε in directions neither level sees: not compared)


def test_weighted_falls_back_to_cascade_when_hard_level_is_infeasible():
    n = 4
    hard = Level(ineq=(np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0]]), np.array([1.0, -np.inf]), np.array([np.inf, 0.0])),
                 name="hard")  # x0 ≥ 1 and x0 ≤ 0
    obj = Level(eq=(np.eye(n), np.arange(n, dtype=float)), name="obj")
    w = solve_hierarchy([hard, obj], settings=cfg(method="weighted"))
    c = solve_hierarchy([hard, obj], settings=cfg(method="cascade"))
    assert w.ok and w.method == "cascade" and w.warnings
    np.testing.assert_allclose(w.x, c.x)
    assert w.costs[0] == pytest.approx(0.5, rel=1e-3)  # the hard level's best compromise x0 = 0.5


def test_first_level_solution_replaces_the_first_qp():
    rng = np.random.default_rng(5)
    for _ in range(20):
        n = 12
        B1 = rng.standard_normal((6, n))
        x_feas = rng.standard_normal(n)
        T = rng.standard_normal((8, n))
        lv = [Level(eq=(B1, B1 @ x_feas), ineq=(T, T @ x_feas - 1.0, T @ x_feas + 1.0), name="newton-euler")]
        lv += random_hierarchy(rng, n=n, n_levels=2)
        x1 = np.linalg.lstsq(B1, B1 @ x_feas, rcond=None)[0]  # −B₁⁺b₁ in the paper's sign convention
        Z1 = null_space(B1)
        fast = solve_hierarchy(lv, first_level_solution=(x1, Z1), settings=cfg(regularization=1e-10))
        ref = solve_hierarchy(lv, settings=cfg(regularization=1e-10))
        assert fast.ok, fast.status
        # v*_1 = 0: the first level's inequalities hold exactly (x1 itself may violate them)
        assert fast.costs[0] <= 1e-12
        np.testing.assert_allclose(fast.costs, ref.costs, rtol=1e-6, atol=1e-6)
        # a non-orthonormal basis of the same space gives the same answer
        other = solve_hierarchy(lv, first_level_solution=(x1, Z1 @ rng.standard_normal((Z1.shape[1],) * 2)),
                                settings=cfg(regularization=1e-10))
        np.testing.assert_allclose(other.costs, fast.costs, rtol=1e-6, atol=1e-6)


def test_first_level_solution_flags_a_violated_frozen_row():
    """§2.4 promises an admissible y exists; if x1 violates a row the nullspace cannot move, say so."""
    L1 = Level(eq=(np.array([[1.0, 0, 0]]), np.array([1.0])),
               ineq=(np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.array([2.0, -1.0]), np.array([3.0, 1.0])), name="ne")
    L2 = Level(eq=(np.eye(3), np.full(3, 5.0)), name="task")
    Z1 = np.array([[0.0, 0], [1, 0], [0, 1]])
    sol = solve_hierarchy([L1, L2], first_level_solution=(np.array([1.0, 0, 0]), Z1),
                          settings=cfg(regularization=1e-10))
    assert sol.ok and any("violate" in w for w in sol.warnings)
    np.testing.assert_allclose(sol.x, [1.0, 1.0, 5.0], atol=1e-6)  # row 2 held at its bound 1


# ----------------------------------------------------------------------------- failures are values
def test_failing_backend_returns_flagged_solution_with_last_good_x(monkeypatch):
    lv = random_hierarchy(np.random.default_rng(42), n=10, n_levels=3)
    # bounds that exclude x = 0, so that every level needs its QP (an unconstrained minimiser that
    # satisfies all rows is accepted without calling the backend)
    lv = [Level(eq=(L.B, L.b), ineq=(np.eye(10), np.ones(10), 2.0 * np.ones(10)), name=L.name) for L in lv]
    calls = {"n": 0}
    real = backends_mod.BACKENDS["quadprog"]

    def flaky(*args, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            return None, "quadprog: constraints are inconsistent, no solution", False
        return real(*args, **kw)

    monkeypatch.setitem(backends_mod.BACKENDS, "quadprog", flaky)
    sol = solve_hierarchy(lv)
    assert not sol.ok
    assert "level 1" in sol.status and "L1" in sol.status and "inconsistent" in sol.status
    assert np.all(np.isfinite(sol.x)) and sol.levels_solved == 1
    monkeypatch.setitem(backends_mod.BACKENDS, "quadprog", real)
    first = solve_hierarchy(lv[:1])
    np.testing.assert_allclose(sol.x, first.x)
    assert np.all(np.isfinite(sol.costs))


def test_fallback_backend_solves_the_failed_level_qp(monkeypatch):
    """A level QP the backend fails on is solved by the fallback: same optimum, noted in warnings."""
    lv = random_hierarchy(np.random.default_rng(42), n=10, n_levels=3)
    lv = [Level(eq=(L.B, L.b), ineq=(np.eye(10), np.ones(10), 2.0 * np.ones(10)), name=L.name) for L in lv]
    reference = solve_hierarchy(lv, settings=cfg(backend="quadprog"))

    def failing(*args, **kw):
        return None, "daqp: cycling (-2)", False

    monkeypatch.setitem(backends_mod.BACKENDS, "daqp", failing)
    assert not solve_hierarchy(lv, settings=cfg(backend="daqp")).ok
    sol = solve_hierarchy(lv, settings=cfg(backend="daqp", fallback_backend="quadprog"))
    assert sol.ok and any("solved with quadprog" in w for w in sol.warnings)
    np.testing.assert_allclose(sol.costs, reference.costs, rtol=1e-9, atol=1e-12)


def test_backend_that_raises_is_caught(monkeypatch):
    def boom(*args, **kw):
        raise np.linalg.LinAlgError("singular")

    monkeypatch.setitem(backends_mod.BACKENDS, "daqp", boom)
    lv = [Level(ineq=(np.eye(3), -np.ones(3), np.ones(3)), eq=(np.ones((1, 3)), np.array([5.0])))]
    sol = solve_hierarchy(lv, settings=cfg(backend="daqp"))
    assert not sol.ok and "singular" in sol.status and np.all(np.isfinite(sol.x))


@pytest.mark.parametrize("backend", BACKENDS)
def test_backend_contract(backend):
    H = np.diag([2.0, 1.0, 1.0])
    g = np.array([-2.0, -1.0, 1.0])
    A = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    lower = np.array([1.0, -np.inf, 0.0])
    upper = np.array([1.0, 0.2, np.inf])  # x0 + x1 = 1, x1 ≤ 0.2, x2 ≥ 0
    x, status, ok = solve_qp(H, g, A, lower, upper, backend=backend)
    assert ok and status == "optimal"
    np.testing.assert_allclose(x, [0.8, 0.2, 0.0], atol=1e-6)
    # infeasible: never raises
    x, status, ok = solve_qp(H, g, np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([1.0, -np.inf]),
                             np.array([np.inf, 0.0]), backend=backend)
    assert not ok and x is None and status.startswith(backend)


# ----------------------------------------------------------------------------- edge cases
def test_levels_without_freedom_are_evaluated_only():
    n = 3
    lv = [Level(eq=(np.eye(n), np.ones(n)), name="all"),
          Level(eq=(np.ones((1, n)), np.array([0.0])), ineq=(np.eye(n), np.full(n, 2.0), None), name="late")]
    sol = solve_hierarchy(lv, settings=cfg(regularization=1e-10))
    assert sol.ok and list(sol.nullspace_dims) == [0, 0]
    assert sol.costs[1] == pytest.approx(9.0 + 3.0, rel=1e-6)  # (3-0)² + 3 · (2-1)²
    np.testing.assert_allclose(sol.ineq_violations[1], np.ones(n), atol=1e-6)


def test_unsatisfiable_equalities_still_lock_their_direction():
    # level 1 asks x0 = 1 and x0 = 3: compromise 2, and level 2 (x0 = 10) cannot move it
    lv = [Level(eq=(np.array([[1.0, 0.0], [1.0, 0.0]]), np.array([1.0, 3.0]))),
          Level(eq=(np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([10.0, 4.0])))]
    sol = solve_hierarchy(lv, settings=cfg(regularization=1e-10))
    np.testing.assert_allclose(sol.x, [2.0, 4.0], atol=1e-6)
    np.testing.assert_allclose(sol.costs, [2.0, 64.0], rtol=1e-6)


def test_violated_inequality_keeps_its_slack_for_lower_levels():
    # level 1: x0 ≥ 2 and x0 ≤ 0 (weight 3 on the second): compromise; level 2 pulls x0 up
    V = np.array([1.0, 3.0])
    lv = [Level(ineq=(np.array([[1.0, 0], [1.0, 0]]), np.array([2.0, -np.inf]), np.array([np.inf, 0.0])),
                ineq_weights=V),
          Level(eq=(np.array([[1.0, 0.0]]), np.array([5.0])))]
    sol = solve_hierarchy(lv, settings=cfg(regularization=1e-10))
    # min (2 - x)² + (3x)²  →  x = 0.2
    assert sol.x[0] == pytest.approx(0.2, abs=1e-6)
    np.testing.assert_allclose(sol.ineq_violations[0], [1.8, 0.6], atol=1e-6)


def test_one_level_and_empty_level():
    L = Level(eq=(np.array([[1.0, 1.0]]), np.array([2.0])))
    sol = solve_hierarchy([Level(name="empty"), L, Level(name="empty2")], cfg(regularization=1e-10))
    assert sol.ok and sol.costs[0] == 0.0 and sol.costs[2] == 0.0
    np.testing.assert_allclose(sol.x, [1.0, 1.0], atol=1e-6)  # minimum norm via ε


def test_timings_and_fields():
    lv = random_hierarchy(np.random.default_rng(9), n=8, n_levels=3)
    sol = solve_hierarchy(lv)
    assert sol.timings["total"] > 0 and sol.timings["levels"].shape == (3,)
    assert len(sol.eq_residuals) == len(sol.ineq_violations) == 3
    for L, r, v in zip(lv, sol.eq_residuals, sol.ineq_violations):
        assert r.shape == (L.n_eq,) and v.shape == (L.n_ineq,) and np.all(v >= 0)


# ----------------------------------------------------------------------------- bad input
@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(eq=(np.full((2, 3), np.nan), np.zeros(2))), "eq B contains NaN"),
        (dict(eq=(np.ones((2, 3)), np.array([1.0, np.inf]))), "eq b contains NaN or inf"),
        (dict(eq=(np.ones((2, 3)), np.zeros(3))), "eq b has shape"),
        (dict(ineq=(np.ones((2, 3)), np.array([0.0, np.nan]), np.ones(2))), "ineq lower contains NaN"),
        (dict(ineq=(np.ones((2, 3)), np.ones(2), np.zeros(2))), "ineq lower > upper"),
        (dict(ineq=(np.array([[1.0, np.inf, 0]]), None, np.ones(1))), "ineq C contains NaN or inf"),
        (dict(eq=(np.ones((2, 3)), np.zeros(2)), ineq=(np.ones((1, 4)), None, np.ones(1))), "ineq C has 4 columns, expected 3"),
        (dict(eq=(np.ones((2, 3)), np.zeros(2)), weights=np.array([1.0, -1.0])), "weights must be finite"),
        (dict(ineq=(np.ones((2, 3)), None, np.ones(2)), ineq_weights=0.0), "ineq_weights must be finite and > 0"),
    ],
)
def test_bad_level_input_names_the_field(kwargs, message):
    with pytest.raises(ValueError, match="Level 'posture'") as info:
        Level(name="posture", **kwargs)
    assert message in str(info.value)


def test_mismatched_columns_across_levels_name_the_level():
    a = Level(eq=(np.ones((1, 3)), np.zeros(1)), name="com")
    b = Level(eq=(np.ones((1, 4)), np.zeros(1)), name="posture")
    with pytest.raises(ValueError, match=r"Level 'posture' \(index 1\): eq B has 4 columns, expected 3"):
        solve_hierarchy([a, b])


def test_bad_solver_arguments():
    L = Level(eq=(np.ones((1, 3)), np.zeros(1)))
    with pytest.raises(ValueError, match="settings: expected a SolverSettings or None, got 'weighted'"):
        solve_hierarchy([L], "weighted")
    with pytest.raises(ValueError, match="first_level_solution: x1 contains NaN"):
        solve_hierarchy([L], first_level_solution=(np.array([np.nan, 0, 0]), np.eye(3)))
    with pytest.raises(ValueError, match="'weighted' takes"):
        solve_hierarchy([L, L, L], settings=cfg(method="weighted"))


# ---------------------------------------------------------------------------- compiled cascade
def _python_only(monkeypatch):
    """Run solve_hierarchy's cascade in Python only (the reference), whatever ``compiled`` says."""
    import wholebody.solvers.compiled_cascade as cc
    monkeypatch.setattr(cc, "_CompiledCascade", None)


def _count_requests(monkeypatch):
    """Count the level QPs the compiled cascade solves (from Python, or DAQP's in the run itself:
    ``timings["qps"]``) and the NNLS solves of its implicit-equality searches."""
    import wholebody.solvers.cascade as cascade
    import wholebody.solvers.compiled_cascade as cc
    seen = {"qp": 0, "implicit": 0}
    run_compiled, nnls = cc._run_compiled, cascade.nnls

    def counting_run(*args, **kwargs):
        sol = run_compiled(*args, **kwargs)
        seen["qp"] += sol.timings["qps"]
        return sol

    def counting_nnls(*args):
        seen["implicit"] += 1
        return nnls(*args)

    monkeypatch.setattr(cc, "_run_compiled", counting_run)
    monkeypatch.setattr(cascade, "nnls", counting_nnls)
    return seen


def _daqp_from_python(monkeypatch):
    """The compiled cascade's DAQP QPs solved from Python (``_daqp_on_run``), not in the run."""
    import wholebody.solvers.compiled_cascade as cc
    monkeypatch.setattr(cc, "_daqp_in_cascade", lambda backend, opts: None)


def _daqp_in_run_or_skip():
    """Skip unless DAQP's C interface as declared in cascade.cpp is usable here; fail if the
    installed daqp is the declared version and the layout check still refuses it."""
    import importlib.metadata
    from conftest import native_cycle_or_skip
    import wholebody.solvers.compiled_cascade as cc
    native_cycle_or_skip("_cascade")
    version = importlib.metadata.version("daqp")
    if version != cc._DAQP_C_VERSION:
        pytest.skip(f"daqp {version} installed, cascade.cpp declares {cc._DAQP_C_VERSION}'s C API")
    assert cc._daqp_c_module() is not None, "layout check failed for the declared daqp version"


def test_daqp_on_the_compiled_run_solves_its_qp_as_the_adapter(monkeypatch):
    """The compiled cascade's DAQP path (rows scaled and checked by the run) returns, for every
    level QP of the random hierarchies, what the generic adapter ``solve_qp(..., "daqp")`` returns
    on the run's unscaled QP: the same verdict and status, y to 1e-8 (the scaled rows differ by
    rounding: the norms are summed in another order)."""
    from conftest import native_cycle_or_skip
    import wholebody.solvers.compiled_cascade as cc
    native_cycle_or_skip("_cascade")
    _daqp_from_python(monkeypatch)
    on_run, compared = cc._daqp_on_run, []

    def compare(run, opts):
        fast = on_run(run, opts)
        g, A, lower, upper = run.qp()
        slow = solve_qp(np.eye(g.shape[0]), g, A, lower, upper, backend="daqp", **opts)
        if fast is not None:
            assert (fast[1], fast[2]) == (slow[1], slow[2])
            if fast[2]:
                np.testing.assert_allclose(fast[0], slow[0], atol=1e-8 * (1 + np.abs(slow[0]).max()))
            compared.append(fast[2])
        return fast

    monkeypatch.setattr(cc, "_daqp_on_run", compare)
    rng = np.random.default_rng(5)
    for _ in range(150):
        solve_hierarchy(random_hierarchy(rng), settings=cfg(backend="daqp"))
    assert len(compared) > 150 and sum(compared) > 100


@pytest.mark.parametrize("case", ["default", "daqp-fails", "verdict-refuses", "tiny-eps"])
def test_daqp_in_the_run_gives_what_python_gives(monkeypatch, case):
    """DAQP called by the compiled run itself (its C interface, ``CascadeRun.advance_daqp``) and
    DAQP called from Python (``daqp.solve`` via ``_daqp_on_run``) on 200 random hierarchies:
    bitwise the same x, the same status, warnings and QP count, and as many DAQP calls — also
    when DAQP fails (iteration limit 2: the fallback quadprog solves, with the same warning),
    when the verdict on the unscaled rows refuses its solution (raw_tol -1: every solution), and
    with ε = 1e-10, where DAQP's "infeasible" misfires and is retried with proximal iterations."""
    import daqp
    import wholebody.solvers.compiled_cascade as cc
    _daqp_in_run_or_skip()
    options = {"daqp-fails": {"iter_limit": 2}, "verdict-refuses": {"raw_tol": -1.0},
               "tiny-eps": {"sing_tol": 3.7e-11, "primal_tol": 1e-7}}.get(case, {})
    rng = np.random.default_rng(8)
    problems = [random_hierarchy(rng) for _ in range(200)]
    kwargs = dict(settings=cfg(backend="daqp", fallback_backend="quadprog", backend_options=options,
                               regularization=1e-10 if case == "tiny-eps" else 1e-4))
    solvers, make_solver = [], cc._daqp_in_cascade

    def recording(backend, opts):
        solvers.append(make_solver(backend, opts))
        return solvers[-1]

    monkeypatch.setattr(cc, "_daqp_in_cascade", recording)
    in_run = [solve_hierarchy(levels, **kwargs) for levels in problems]
    assert all(s is not None for s in solvers)
    calls_in_run = sum(s.calls for s in solvers)
    _daqp_from_python(monkeypatch)
    calls, daqp_solve = [], daqp.solve
    monkeypatch.setattr(daqp, "solve", lambda *a, **k: calls.append(k) or daqp_solve(*a, **k))
    from_python = [solve_hierarchy(levels, **kwargs) for levels in problems]
    for i, (a, b) in enumerate(zip(in_run, from_python)):
        np.testing.assert_array_equal(a.x, b.x, err_msg=str(i))
        assert (a.ok, a.status, a.warnings, a.timings["qps"]) == \
            (b.ok, b.status, b.warnings, b.timings["qps"]), i
    assert calls_in_run == len(calls)
    assert sum(s.timings["qps"] for s in in_run) > 300
    fallbacks = sum("solved with quadprog" in w for s in in_run for w in s.warnings)
    if case == "default":
        assert fallbacks == 0
    else:  # the failure paths were taken (DAQP refused, quadprog solved)
        reason = {"daqp-fails": "iteration limit (-4)", "verdict-refuses": "outside its rows",
                  "tiny-eps": "infeasible (-1)"}[case]
        assert fallbacks > 20 and any(reason in w for s in in_run for w in s.warnings)
    if case == "tiny-eps":  # retried with proximal iterations
        assert sum("eps_prox" in k for k in calls) > 20


def test_daqp_in_the_run_is_used_only_where_it_is_the_adapter():
    """The run solves DAQP's QPs itself only with the stock adapter and DAQP settings: another
    backend, an option that is no DAQP setting, or a non-number setting go through Python; the
    solver refuses an unknown setting by name and a library that is not loaded."""
    import daqp
    import wholebody.solvers.compiled_cascade as cc
    _daqp_in_run_or_skip()
    assert cc._daqp_in_cascade("daqp", {"primal_tol": 1e-8, "raw_tol": 1e-7}) is not None
    assert cc._daqp_in_cascade("quadprog", {}) is None
    assert cc._daqp_in_cascade("daqp", {"primal_start": np.zeros(3)}) is None
    assert cc._daqp_in_cascade("daqp", {"no_such_setting": 1.0}) is None
    with pytest.raises(ValueError, match="no_such_setting"):
        cc._DaqpSolver(daqp.__file__, {"no_such_setting": 1.0}, {}, 1e-6)
    with pytest.raises(ValueError, match="not a loaded library"):
        cc._DaqpSolver("/nonexistent/daqp.so", {}, {}, 1e-6)
    # the settings read through cascade.cpp's declaration are daqp.solve's, given ones applied
    solver = cc._DaqpSolver(daqp.__file__, {"iter_limit": 7, "eps_prox": 1e-3}, {}, 1e-6)
    assert solver.settings()["iter_limit"] == 7 and solver.settings()["eps_prox"] == 1e-3


def test_compiled_cascade_matches_python_on_equality_levels():
    """Levels of equalities only (no QP ever): the compiled cascade gives the Python cascade's
    x (compiled=False) to 1e-9, its costs and null-space dimensions."""
    from conftest import native_cycle_or_skip
    native_cycle_or_skip("_cascade")
    rng = np.random.default_rng(7)
    for _ in range(100):
        n = int(rng.integers(3, 12))
        levels = []
        for _ in range(int(rng.integers(2, 5))):
            k = int(rng.integers(1, n))
            levels.append(Level(eq=(rng.normal(size=(k, n)), rng.normal(size=k)),
                                weights=10.0 ** rng.uniform(-4, 4, size=k)))
        compiled = solve_hierarchy(levels)
        python = solve_hierarchy(levels, compiled=False)
        np.testing.assert_allclose(compiled.x, python.x, atol=1e-9, rtol=1e-9)
        np.testing.assert_allclose(compiled.costs, python.costs, atol=1e-12, rtol=1e-6)
        np.testing.assert_array_equal(compiled.nullspace_dims, python.nullspace_dims)


def _kahan(n: int, c: float = 0.285) -> np.ndarray:
    """Kahan's upper-triangular matrix, its columns shrunk by (1 − 100 ε)^j so that column
    pivoting keeps their order: a QR whose last |R_nn| overstates σ_min by orders of magnitude."""
    s_ = np.sqrt(1.0 - c * c)
    K = np.diag(s_ ** np.arange(n)) @ (np.eye(n) - c * np.triu(np.ones((n, n)), 1))
    return K * (1.0 - 100 * np.finfo(float).eps) ** np.arange(n)


def _kernel_cases(rng):
    """(kind, RZ, tol): matrices with singular values placed around the lock threshold ``tol`` (well
    above, within three decades either side — never within a factor 2 of it, where the count
    itself is rounding —, far below), rows weighted over eight decades as Table 2's level 3,
    and transposed Kahan matrices whose QR pivots lie just above the threshold."""
    for _ in range(150):
        k, z = int(rng.integers(2, 40)), int(rng.integers(2, 30))
        p = min(k, z)
        tol = 10.0 ** rng.uniform(-10, -6)
        exponents = rng.choice([rng.uniform(3.5, 8), rng.uniform(0.3, 3), rng.uniform(-3, -0.3),
                                rng.uniform(-12, -4)], size=p)
        U, _ = np.linalg.qr(rng.standard_normal((k, k)))
        V, _ = np.linalg.qr(rng.standard_normal((z, z)))
        yield "spectrum", U[:, :p] @ np.diag(tol * 10.0 ** exponents) @ V[:, :p].T, tol
    for _ in range(60):
        k, z = int(rng.integers(10, 40)), int(rng.integers(5, 25))
        A = 10.0 ** rng.uniform(-4, 4, size=(k, 1)) * rng.standard_normal((k, z))
        s = np.linalg.svd(A, compute_uv=False)
        yield "weighted", A, float(s.max() * 10.0 ** rng.uniform(-9, -5))
    for _ in range(60):  # more rows than freedom, all of it taken (Table 2's level 3 as walking has it)
        z = int(rng.integers(5, 25))
        k = z + int(rng.integers(5, 20))
        A = 10.0 ** rng.uniform(-4, 4, size=(k, 1)) * rng.standard_normal((k, z))
        s = np.linalg.svd(A, compute_uv=False)
        yield "taken", A, float(s[-1] * 10.0 ** rng.uniform(-2.5, -0.5) / np.sqrt(z))
    for n in (20, 30, 40):
        K = _kahan(n)
        s = np.linalg.svd(K, compute_uv=False)
        r = np.abs(np.diag(K))
        if s[-1] < r[-1] / 20:  # σ_min hidden by the pivot: tol between them
            yield "kahan", K.T, float(np.sqrt(s[-1] * r[-1]))


def test_lock_kernel_has_the_svds_rank_near_the_threshold(monkeypatch):
    """The null-space basis of a lock (cascade._kernel and its compiled mirror) keeps the
    directions whose singular values are at most the threshold — the count and the kernel of an
    SVD (numpy's, the oracle; within 1e-5 of its angle) — also where QR pivots lie within three
    decades of it; its columns are orthonormal and RZ N ≤ the threshold. The SVD is skipped
    there when the QR's kernel is certified (Table 2-like weights every time), never on a Kahan
    matrix, whose last pivot overstates σ_min."""
    from wholebody.solvers.cascade import _kernel
    svd_calls = []
    real_svd = np.linalg.svd
    monkeypatch.setattr(np.linalg, "svd", lambda *a, **k: svd_calls.append(1) or real_svd(*a, **k))
    try:
        from wholebody._cascade import kernel_basis
    except ImportError:
        kernel_basis = None
    rng = np.random.default_rng(11)
    near = kahan = taken = 0
    certified = {"python": 0, "compiled": 0}
    for kind, RZ, tol in _kernel_cases(rng):
        s = real_svd(RZ, compute_uv=False)
        expected = RZ.shape[1] - int(np.count_nonzero(s > tol))
        d = np.abs(np.diag(qr(RZ.T, pivoting=True, mode="r")[0]))
        in_window = bool(((d > 1e-3 * tol) & (d < 1e3 * tol)).any())
        calls = len(svd_calls)
        bases = [("python", _kernel(RZ, tol), len(svd_calls) > calls)]
        if kernel_basis is not None:
            N, by_svd = kernel_basis(RZ, tol)
            bases.append(("compiled", N, by_svd))
        U = real_svd(RZ.T, full_matrices=True)[0][:, RZ.shape[1] - expected:]
        for who, N, by_svd in bases:
            assert N.shape == (RZ.shape[1], expected), (who, N.shape, expected)
            np.testing.assert_allclose(N.T @ N, np.eye(expected), atol=1e-10, err_msg=who)
            assert np.linalg.norm(RZ @ N, 2) <= tol + 1e-13 * s.max(), who
            # the SVD's kernel (sin of the largest angle between the two)
            assert np.linalg.norm(N @ N.T - U @ U.T, 2) <= 1e-5, (who, kind, by_svd)
            if kind == "kahan":
                assert in_window and by_svd, who
            elif kind == "taken" and in_window:  # full rank by a margin: proven every time
                certified[who] += not by_svd
        near += in_window
        kahan += kind == "kahan"
        taken += kind == "taken" and in_window
    assert near > 100 and kahan >= 2
    if kernel_basis is not None:  # no rows or no freedom: nothing locked
        for shape in ((0, 5), (3, 0), (0, 0)):
            N, by_svd = kernel_basis(np.zeros(shape), 1e-9)
            assert N.shape == (shape[1], shape[1]) and not by_svd
    assert taken >= 30 and certified["python"] == taken
    assert kernel_basis is None or certified["compiled"] == taken


@pytest.mark.parametrize("backend", ["quadprog", "daqp"])
def test_compiled_cascade_matches_python_on_random_hierarchies(monkeypatch, backend):
    """The random hierarchies of the oracle tests (inequalities at every level, conflicts,
    redundant rows, infeasible rows): the compiled cascade, asking Python for each level QP and
    implicit-equality search's NNLS, gives the Python cascade's result — same ok/status kind, x and
    costs to 1e-7 (measured ≤ 2e-9), the same null-space dimensions and warnings."""
    from conftest import native_cycle_or_skip
    native_cycle_or_skip("_cascade")
    seen = _count_requests(monkeypatch)
    rng = np.random.default_rng(2024)
    for i in range(200):
        levels = random_hierarchy(rng)
        compiled = solve_hierarchy(levels, settings=cfg(backend=backend))
        python = solve_hierarchy(levels, settings=cfg(backend=backend), compiled=False)
        assert compiled.ok == python.ok, (i, compiled.status, python.status)
        assert compiled.status == python.status
        assert compiled.levels_solved == python.levels_solved
        scale = 1.0 + np.abs(python.x).max()
        np.testing.assert_allclose(compiled.x, python.x, atol=1e-7 * scale, rtol=0, err_msg=str(i))
        np.testing.assert_allclose(compiled.costs, python.costs, atol=1e-7 * (1 + python.costs.max()),
                                   rtol=0, err_msg=str(i))
        np.testing.assert_array_equal(compiled.nullspace_dims, python.nullspace_dims)
        assert sorted(compiled.warnings) == sorted(python.warnings)
    assert seen["qp"] > 200 and seen["implicit"] > 0  # both requests were exercised


def test_daqp_c_interface_is_refused_for_another_version_or_layout(monkeypatch, caplog, request):
    """DAQP's C structures are declared for one daqp version: with another version installed, or
    with daqp.solve's defaults differing from those read through the declaration (a layout that
    moved), the compiled run is not given a DaqpSolver and the level QPs go through Python, with
    a log line saying why; the results stay the stock path's."""
    import importlib.metadata
    import inspect
    import daqp
    import wholebody.solvers.compiled_cascade as cc
    _daqp_in_run_or_skip()
    request.addfinalizer(cc._daqp_c_module.cache_clear)  # nothing stale left for other tests
    levels = random_hierarchy(np.random.default_rng(3))
    reference = solve_hierarchy(levels, settings=cfg(backend="daqp"))
    version = importlib.metadata.version
    monkeypatch.setattr(importlib.metadata, "version",
                        lambda name: "0.10.3" if name == "daqp" else version(name))
    cc._daqp_c_module.cache_clear()
    with caplog.at_level("INFO", logger=cc.log.name):
        assert cc._daqp_c_module() is None and cc._daqp_in_cascade("daqp", {}) is None
    assert "declared for 0.11.0" in caplog.text
    np.testing.assert_array_equal(solve_hierarchy(levels, cfg(backend="daqp")).x, reference.x)
    monkeypatch.setattr(importlib.metadata, "version", version)
    solve = daqp.solve

    def moved(*args, **kwargs):  # daqp.solve, one of whose defaults the C side does not read
        return solve(*args, **kwargs)

    signature = inspect.signature(solve)
    moved.__signature__ = signature.replace(parameters=[
        p.replace(default=7) if p.name == "iter_limit" else p
        for p in signature.parameters.values()])
    monkeypatch.setattr(daqp, "solve", moved)
    cc._daqp_c_module.cache_clear()
    assert cc._daqp_c_module() is None
    assert "differ from daqp.solve's defaults" in caplog.text
    monkeypatch.setattr(daqp, "solve", solve)
    cc._daqp_c_module.cache_clear()
    assert cc._daqp_c_module() is not None


def test_daqp_settings_leave_no_table1_level_qp_to_the_fallback(robots):
    """With the adapter's DAQP settings (``backends.DAQP_DEFAULTS``: sing_tol 1e-14, primal_tol
    1e-9) DAQP solves the level QPs of Table 1 (talos, double support, the first 600 moving
    states of bench_wbc; on the 604th quadprog alone loops forever, see
    tests/solvers/test_quadprog_adapter.py) on all but a few cycles (measured: none with the Python engine, one with
    the native engine, whose level QP has a sole's wrench at the apex of its contact wrench cone,
    all 16 of its rows active, and DAQP's solution 3e-6 outside a row after its proximal retry),
    and the torques equal those of a cycle solved by quadprog alone to 1e-6 Nm — except on a few
    such vertices, where DAQP's torques are only as exact as DAQP itself makes them: solved again
    at the state with v changed by 1e-15 (relative), they move by as much; there the two backends
    must agree to 4 times that spread (quadprog's own is orders of magnitude smaller). Which
    states these are depends on the build's rounding (e.g. whether the compiler fuses
    multiply-adds).
    With DAQP's own sing_tol and the earlier primal_tol 1e-7 (``backend_options``, both engines)
    the same states leave QPs to quadprog on over a third of the cycles ("infeasible" on nearly
    dependent active rows, or solutions refused on the raw rows): the case the settings are for.
    The stack has the paper's CoP rows (the whole sole, ``cop_margin=0``), those these numbers
    were measured on."""
    from wholebody.control.stacks import table1_stack
    from wholebody.cycle import HierarchyCycle
    from wholebody.variables import Variables
    robot = robots["talos"]
    variables = Variables(robot)
    states = list(robot.smooth_motion(2000, 1e-3))[:600]

    def cycle(backend, engine="auto", **options):
        stack = table1_stack(robot, robot.contact_names, cop_margin=0.0)
        return HierarchyCycle(robot, stack, engine=engine, settings=SolverSettings(
            backend=backend, fallback_backend="quadprog" if backend == "daqp" else None,
            backend_options=options))

    def fell_back(status):
        """A level QP solved with quadprog, or the whole cycle solved again by quadprog alone
        ("quadprog after daqp") when the fallback failed on a lower level."""
        return "solved with quadprog" in status or status.startswith("optimal (quadprog after daqp")

    def daqp_spread(index, tau):
        """How far DAQP's torques ``tau`` at states[index] move when v changes by 1e-15
        (relative), solved again after the same earlier states (the stack's references are those
        of its first cycle: a fresh cycle would take other ones)."""
        q, v = states[index]
        rng = np.random.default_rng(7)
        spread = 0.0
        for _ in range(4):
            again = cycle("daqp")
            for q_seen, v_seen in states[:index]:
                again.solve(q_seen, v_seen, variables)
            v_near = v * (1.0 + 1e-15 * rng.standard_normal(v.shape))
            spread = max(spread, np.abs(again.solve(q, v_near, variables).tau - tau).max())
        return spread

    daqp, quadprog = cycle("daqp"), cycle("quadprog")
    fallbacks, loose = 0, []
    for index, (q, v) in enumerate(states):
        a, b = daqp.solve(q, v, variables), quadprog.solve(q, v, variables)
        assert a.ok and (a.status == "optimal" or fell_back(a.status)), a.status
        fallbacks += a.status != "optimal"
        apart = np.abs(a.tau - b.tau).max()
        if apart > 1e-6:
            loose.append((index, apart, a.tau.copy()))
    assert fallbacks <= 3
    assert len(loose) <= 3, [(i, apart) for i, apart, *_ in loose]
    for index, apart, tau in loose:
        spread = daqp_spread(index, tau)
        assert apart <= 4.0 * spread, (index, apart, spread)
    for engine in ("native", "python"):
        before = cycle("daqp", engine, sing_tol=3.7e-11, primal_tol=1e-7)
        fallbacks = sum(fell_back(before.solve(q, v, variables).status) for q, v in states[:400])
        assert fallbacks >= 50, engine


@pytest.mark.parametrize("name", ["talos14", "talos", "talos14-single"])
def test_compiled_cascade_matches_python_on_robots(robots, monkeypatch, name):
    """Table 2 (talos14), Table 1 (talos) and Table 4 (talos14 on its left sole, right sole a
    6D swing task) over a moving state: the same torques (1e-6 Nm) and level costs (to the
    backend's tolerance) with the compiled cascade as with the Python cascade.

    Table 4 on these synthetic states (stance foot dragged by the moving base, swing task at
    weight 1e4 holding its first pose) has a level-3 residual of ~1e12: a large-residual least
    squares problem, whose solution depends on the rounding order at the cond² level. Eigen's and
    LAPACK's QR then give torques up to 1e-2 Nm apart, with costs equal to 1e-9 (both are
    deterministic: a 1e-13 change of the state moves either by < 1e-11 Nm; merely permuting the
    level-3 rows moves the Python cascade's x by up to 8e-4): asserted to 0.05 Nm there."""
    import sys
    from pathlib import Path
    from conftest import native_cycle_or_skip
    native_cycle_or_skip("_cascade")
    import wholebody.solvers.compiled_cascade as cc
    from wholebody.control.stacks import table1_stack, table2_stack
    from wholebody.formulation import Formulation
    from wholebody.variables import Variables
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from bench_wbc import moving_states
    from wholebody.control.stacks import table4_stack
    robot = robots[name.split("-")[0]]
    variables = Variables(robot)
    if name == "talos14":
        stack = table2_stack(robot)
    elif name == "talos":
        stack = table1_stack(robot, robot.contact_names)
    else:
        stack = table4_stack(robot, ["left_sole"], ["right_sole_link"])
        variables = Variables(robot, ["left_sole"])
    formulation = Formulation(robot)
    seen = _count_requests(monkeypatch)
    compiled = cc._CompiledCascade
    for k, (q, v) in enumerate(moving_states(robot, 1200)):
        if k % 20:
            continue
        robot.update(q, v)
        a = formulation.solve(stack, variables, diagnostics=False)
        monkeypatch.setattr(cc, "_CompiledCascade", None)
        b = formulation.solve(stack, variables, diagnostics=False)
        monkeypatch.setattr(cc, "_CompiledCascade", compiled)
        assert a.ok and b.ok
        np.testing.assert_allclose(a.tau, b.tau, atol=0.05 if name == "talos14-single" else 1e-6,
                                   err_msg=f"state {k}")
        # a row of slack weight V (CoP: 1e4) may stay violated by DAQP's primal tolerance
        # (1e-7), i.e. cost (1e4 · 1e-7)² = 1e-6: costs agree to that, relatively to 1e-6
        np.testing.assert_allclose(a.level_costs, b.level_costs, atol=1e-6, rtol=1e-6)
    if name == "talos":  # Table 1's levels need QPs and implicit-equality searches (NNLS)
        assert seen["qp"] > 60 and seen["implicit"] > 30


@pytest.mark.parametrize("compiled", [True, False])
def test_table1_level_qps_stay_feasible_after_tolerance_violations(robots, compiled):
    """A higher row a backend left violated within its tolerance (DAQP: ~1e-8) is kept at that
    value for the lower levels (_loosen_tight), as eq. 9 keeps a level's optimal violation.
    Without that, 2 of these 100 Table 1 cycles (talos, double support; states 229 and 263)
    failed: the level-5 QP was infeasible for DAQP and quadprog alike (x* itself outside its
    rows by ~1e-8)."""
    import sys
    from pathlib import Path
    from conftest import native_cycle_or_skip
    if compiled:
        native_cycle_or_skip("_cascade")
    from wholebody.control.stacks import table1_stack
    from wholebody.formulation import Formulation
    from wholebody.variables import Variables
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from bench_wbc import moving_states
    robot = robots["talos"]
    stack = table1_stack(robot, robot.contact_names)
    formulation, variables = Formulation(robot), Variables(robot)
    failed = []
    for k, (q, v) in enumerate(moving_states(robot, 300)):
        if k < 200:
            continue
        robot.update(q, v)
        levels, _ = formulation.levels(stack, variables)
        fls = formulation.first_level_solution(levels[0])
        sol = solve_hierarchy(levels, settings=cfg(backend="daqp", fallback_backend="quadprog",
                                                   regularization=1e-6),
                              first_level_solution=fls, compiled=compiled)
        if not sol.ok:
            failed.append((k, sol.status))
    assert not failed


@pytest.mark.parametrize("compiled", [True, False])
def test_analytic_first_level_is_the_least_norm_solution(compiled):
    """first_level_solution='analytic' (eq. 17), in the compiled cascade and in Python: x1 is
    the least-norm solution of level 1 (numpy's pseudo-inverse as the oracle), also for a
    rank-deficient B; with a second level the result equals the one from an explicit (x1, Z1)
    of an independent SVD null-space basis."""
    if compiled:
        from conftest import native_cycle_or_skip
        native_cycle_or_skip("_cascade")
    rng = np.random.default_rng(11)
    for trial in range(40):
        n, k = int(rng.integers(4, 12)), int(rng.integers(1, 4))
        B = rng.normal(size=(k, n))
        if trial % 4 == 0 and k > 1:  # dependent rows (consistent right-hand side)
            B[-1] = B[0]
        x_true = rng.normal(size=n)
        w = 10.0 ** rng.uniform(-1, 1, size=k)
        L1 = Level(eq=(B, B @ x_true), weights=w)
        only = solve_hierarchy([L1], first_level_solution="analytic", compiled=compiled)
        np.testing.assert_allclose(only.x, np.linalg.pinv(B) @ (B @ x_true), atol=1e-9)
        L2 = Level(eq=(rng.normal(size=(2, n)), rng.normal(size=2)),
                   ineq=(rng.normal(size=(3, n)), -np.ones(3), np.ones(3)))
        _, s, Vt = np.linalg.svd(B)
        Z1 = Vt[int(np.count_nonzero(s > 1e-10)):].T
        both = solve_hierarchy([L1, L2], first_level_solution="analytic", compiled=compiled)
        given = solve_hierarchy([L1, L2], first_level_solution=(np.linalg.pinv(B) @ (B @ x_true), Z1),
                                compiled=False)
        if trial % 4 or k == 1:  # (dependent rows: Z1 keeps n - k columns, see the docstring)
            np.testing.assert_allclose(both.x, given.x, atol=1e-7)
    with pytest.raises(ValueError, match="needs equality rows in level 1"):
        solve_hierarchy([Level(ineq=(np.eye(2), -np.ones(2), np.ones(2)))], first_level_solution="analytic")
    with pytest.raises(ValueError, match="expected \\(x1, Z1\\) or 'analytic'"):
        solve_hierarchy([L1], first_level_solution="qr")
    from wholebody.solvers.hierarchy import analytic_first_level
    with pytest.raises(ValueError, match="needs equality rows"):
        analytic_first_level(Level(ineq=(np.eye(2), -np.ones(2), np.ones(2)), name="limits"))


def test_daqp_alone_solves_most_table1_cycles_and_agrees_with_quadprog(robots):
    """solve_daqp hands DAQP unit-norm rows (same feasible set) and checks its solution on the
    raw rows. The cascade's level QPs on Table 1 have row norms from ~0.1 to ~1e6: on the raw
    rows DAQP failed (infeasible/cycling verdicts on feasible QPs) in 94 of 300 cycles; with
    unit rows 15 of 300, but its tolerance on unit rows let two solutions of these 100 cycles
    violate raw rows by up to 0.06 (level-1 cost 2e-3 at state 232), which the check refuses.
    Asserted: at most 10 % of 100 cycles fail without a fallback, and every accepted solution
    equals quadprog's (an independent active-set method) to 1e-7."""
    import sys
    from pathlib import Path
    from wholebody.control.stacks import table1_stack
    from wholebody.formulation import Formulation
    from wholebody.variables import Variables
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from bench_wbc import moving_states
    robot = robots["talos"]
    stack = table1_stack(robot, robot.contact_names)
    formulation, variables = Formulation(robot), Variables(robot)
    failed = 0
    for k, (q, v) in enumerate(moving_states(robot, 300)):
        if k < 200:
            continue
        robot.update(q, v)
        levels, _ = formulation.levels(stack, variables)
        kw = dict(first_level_solution="analytic")
        daqp_only = solve_hierarchy(levels, settings=cfg(backend="daqp", regularization=1e-6), **kw)
        reference = solve_hierarchy(levels, settings=cfg(backend="quadprog", regularization=1e-6),
                                    **kw)
        assert reference.ok
        if not daqp_only.ok:
            failed += 1
            continue
        np.testing.assert_allclose(daqp_only.x, reference.x, atol=1e-7, err_msg=f"state {k}")
    assert failed <= 10


def test_implicit_equalities_match_a_linear_programming_oracle(monkeypatch):
    """Tight rows g_i d ≥ 0 (d: directions from x) with a positively dependent cycle, rows in its
    span (implicit equalities too: g·d = 0 wherever the cycle's rows are 0) and independent rows:
    the mask equals the LP oracle's — row i is an implicit equality iff max g_i·d subject to
    G d ≥ 0, |d| ≤ 1 is 0 (scipy's HiGHS, not NNLS) — and the rows in the span cost no NNLS
    solve of their own (one per dependency, the span taken at once)."""
    from scipy.optimize import linprog
    import wholebody.solvers.cascade as cascade
    seen = _count_requests(monkeypatch)
    rng = np.random.default_rng(11)
    for trial in range(40):
        z = int(rng.integers(4, 8))
        g1, g2 = rng.standard_normal((2, z))
        cycle = [g1, g2, -(rng.uniform(0.5, 2) * g1 + rng.uniform(0.5, 2) * g2)]
        spanned = [a * g1 + b * g2 for a, b in rng.standard_normal((int(rng.integers(1, 4)), 2))]
        free = list(rng.standard_normal((int(rng.integers(0, z - 2)), z)))
        rows = cycle + spanned + free
        order = rng.permutation(len(rows))
        G = np.array(rows)[order]
        # half the rows tight at their upper bound (normal -g), the rest at their lower one
        upper = rng.random(len(rows)) < 0.5
        HZ = np.where(upper[:, None], -G, G)
        hx = rng.standard_normal(len(rows))
        hlo = np.where(upper, -np.inf, hx)
        hup = np.where(upper, hx, np.inf)
        before = seen["implicit"]
        mask = cascade._implicit_equalities(HZ, hx, hlo, hup)
        oracle = np.array([
            -linprog(-g, A_ub=-G, b_ub=np.zeros(len(G)), bounds=[(-1, 1)] * z,
                     method="highs").fun <= 1e-9 for g in G])
        got = np.zeros(len(G), bool) if mask is None else mask
        np.testing.assert_array_equal(got, oracle, err_msg=f"trial {trial}")
        assert oracle[np.argsort(order)[:3 + len(spanned)]].all()  # the construction holds
        assert seen["implicit"] - before <= 2, f"trial {trial}: {seen['implicit'] - before} NNLS"


def test_bound_cascade_resolves_in_place_changes_as_solve_hierarchy():
    """A BoundCascade solved again and again while its levels' arrays are overwritten in place
    (contents of other random hierarchies of the same shapes) returns exactly what a fresh
    solve_hierarchy returns on those contents: reset() leaves nothing of the previous solve, and
    a returned solution keeps its values when the next solve runs (its x once was a view of the
    run's buffer and changed under its holder). Its quick path (``solve_quick``) gives the same
    x and costs where it gives any, and only for an optimum without warnings."""
    from conftest import native_cycle_or_skip
    from wholebody.solvers.hierarchy import BoundCascade
    native_cycle_or_skip("_cascade")
    rng = np.random.default_rng(17)
    fields = ("B", "b", "w", "C", "lower", "upper", "v")
    quick_hits = 0
    for trial in range(40):
        shape_seed = int(rng.integers(1 << 30))
        make = lambda seed: random_hierarchy(np.random.default_rng(seed))  # noqa: E731
        levels = make(shape_seed)
        kw = dict(settings=cfg(backend="daqp", regularization=1e-6, fallback_backend="quadprog"))
        bound = BoundCascade(levels, **kw)
        previous = None
        for _ in range(4):
            # same shapes, new numbers: the random draws of the same structure, perturbed
            for L, M in zip(levels, make(shape_seed)):
                for f in fields:
                    a, b = getattr(L, f), getattr(M, f)
                    noise = rng.normal(scale=0.3, size=a.shape) if f in ("B", "C", "b") else 0.0
                    a[...] = b + noise
            got, want = bound.solve(), solve_hierarchy(levels, **kw)
            quick = bound.solve_quick()
            if quick is not None:
                quick_hits += 1
                assert got.ok and got.status == "optimal" and not got.warnings
                np.testing.assert_array_equal(quick[0], want.x)
                np.testing.assert_array_equal(quick[1], want.costs)
            assert (got.ok, got.status, got.levels_solved) == (want.ok, want.status, want.levels_solved)
            np.testing.assert_array_equal(got.x, want.x, err_msg=f"trial {trial}")
            np.testing.assert_array_equal(got.costs, want.costs)
            np.testing.assert_array_equal(got.nullspace_dims, want.nullspace_dims)
            assert got.warnings == want.warnings
            if previous is not None:
                np.testing.assert_array_equal(previous[0].x, previous[1])
                np.testing.assert_array_equal(previous[0].costs, previous[2])
            previous = (got, got.x.copy(), got.costs.copy())
    assert quick_hits >= 40  # the quick path is the common case


def test_bound_cascade_refuses_arrays_it_would_have_to_copy():
    from conftest import native_cycle_or_skip
    from wholebody.solvers.hierarchy import BoundCascade
    native_cycle_or_skip("_cascade")
    """Level() stores C-contiguous copies; a trusted level (preallocated buffers) may hold a
    Fortran-ordered view, which pybind11 would silently copy: refused, naming level and field."""
    B = np.asfortranarray(np.random.default_rng(0).normal(size=(3, 5)))
    empty = np.zeros((0, 5))
    level = Level.trusted(B, np.ones(3), np.ones(3), empty, np.zeros(0), np.zeros(0), np.zeros(0),
                          name="L1")
    with pytest.raises(ValueError, match="level 'L1' B: needs a C-contiguous float64"):
        BoundCascade([level])


@pytest.mark.parametrize("method", ["cascade", "daqp", "weighted"])
def test_overflowing_entries_are_not_reported_solved(method):
    """Entries of 1e200: the level's cost overflows to inf at any x; no method may call that
    solved (they used to report ok=True with cost inf)."""
    big = Level(eq=(np.array([[1e200, 1.0]]), np.array([1e200])), name="big")
    rest = Level(eq=(np.eye(2), np.ones(2)), name="rest")
    with np.errstate(over="ignore", invalid="ignore"):
        for compiled in (True, False):
            extra = {"compiled": compiled} if method == "cascade" else {}
            sol = solve_hierarchy([big, rest], settings=cfg(method=method), **extra)
            assert not sol.ok and sol.status, (compiled, sol.status)
            assert np.all(np.isfinite(sol.x))


@pytest.mark.parametrize("method", ["cascade", "daqp", "weighted"])
def test_no_variables_is_an_empty_solution(method):
    sol = solve_hierarchy([Level(eq=(np.zeros((1, 0)), np.zeros(1)), name="empty")], cfg(method=method))
    assert sol.ok and sol.x.shape == (0,)
