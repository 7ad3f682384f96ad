"""The check of a DAQP solution on the caller's rows (``backends._row_violation``, compiled
``_cascade.row_violation``): a violation that the rounding of a_i x can explain is no
violation; anything beyond it by more than ``raw_tol`` refuses the solution.

The evidence is exact arithmetic (``fractions.Fraction``): rows and points are built so that the
exact product sits on the bound or a known distance beyond it, and the floating-point verdict is
compared with that."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from conftest import native_cycle_or_skip
from wholebody.solvers import backends

EPS = np.finfo(float).eps


def exact_product(a: np.ndarray, x: np.ndarray) -> Fraction:
    return sum((Fraction(float(ai)) * Fraction(float(xi)) for ai, xi in zip(a, x)), Fraction(0))


def row_on_its_bound(rng, n: int, norm: float) -> tuple[np.ndarray, np.ndarray, float]:
    """A row of norm ``norm`` with cancelling entries and a point x whose exact product a x is the
    bound (rounded to the nearest double): a x == upper up to rounding of a x only."""
    a = rng.standard_normal(n) * norm / np.sqrt(n)
    x = rng.standard_normal(n)
    return a, x, float(exact_product(a, x))


VIOLATIONS = [backends._row_violation_numpy]
try:
    from wholebody._cascade import row_violation as compiled_row_violation
    VIOLATIONS.append(compiled_row_violation)
except ImportError:  # the compiled mirror is optional; the parity test below says so
    compiled_row_violation = None


@pytest.mark.parametrize("violation", VIOLATIONS, ids=lambda f: f.__module__)
def test_rounding_of_the_product_is_no_violation(violation):
    """Rows of norm 1e10 whose exact product equals the bound: the float product is off by up to
    ~1e-6, which the check must not call a violation (DAQP and quadprog alike produce such x)."""
    rng = np.random.default_rng(0)
    seen_off = 0.0
    for _ in range(200):
        a, x, bound = row_on_its_bound(rng, int(rng.integers(5, 60)), 1e10)
        A = a[None, :]
        seen_off = max(seen_off, float((A @ x)[0]) - bound)
        assert violation(A, x, np.array([-np.inf]), np.array([bound])) == 0.0
        assert violation(A, x, np.array([bound]), np.array([np.inf])) == 0.0
    assert seen_off > 1e-6  # the plain check (A x - upper > 1e-6) would have refused some


@pytest.mark.parametrize("violation", VIOLATIONS, ids=lambda f: f.__module__)
def test_a_violation_beyond_rounding_is_reported(violation):
    """The same rows with the bound moved by a known amount d inside: the reported violation is
    d less at most the rounding allowance n eps |a| |x|, and refused by the verdict for d well
    above ``raw_tol``."""
    rng = np.random.default_rng(1)
    for norm in (1.0, 1e4, 1e10):
        for _ in range(50):
            n = int(rng.integers(5, 60))
            a, x, bound = row_on_its_bound(rng, n, norm)
            allowance = n * EPS * np.linalg.norm(a) * np.linalg.norm(x)
            d = 10.0 * allowance + 1e-3
            over = violation(a[None, :], x, np.array([-np.inf]), np.array([bound - d]))
            assert d - 1.1 * allowance - 1e-12 * d <= over <= d + 1e-12 * d
            x_out, status, ok = backends.daqp_verdict(x, "optimal", over)
            assert not ok and x_out is None and "outside its rows" in status


def test_infeasible_rows_and_non_finite_points():
    a = np.array([[1.0, 2.0], [0.0, 1.0]])
    x = np.array([1.0, 1.0])
    # row 0: 3 <= 2.5 is violated by 0.5; row 1 holds
    for violation in VIOLATIONS:
        assert violation(a, x, np.array([-np.inf, 0.0]), np.array([2.5, 2.0])) == pytest.approx(
            0.5, abs=1e-14)
        assert violation(a, np.array([np.nan, 1.0]), np.full(2, -np.inf), np.full(2, np.inf)) \
            == np.inf
        assert violation(np.zeros((0, 2)), x, np.zeros(0), np.zeros(0)) == 0.0


def test_compiled_check_is_the_python_check():
    """Parity of the compiled mirror with the Python reference on random rows, points, bounds."""
    native_cycle_or_skip("_cascade")
    rng = np.random.default_rng(2)
    for _ in range(300):
        m, n = int(rng.integers(1, 40)), int(rng.integers(1, 40))
        A = rng.standard_normal((m, n)) * 10.0 ** rng.uniform(-2, 10, size=(m, 1))
        x = rng.standard_normal(n) * 10.0 ** rng.uniform(-2, 6)
        ax = A @ x
        lower = ax - np.abs(rng.standard_normal(m)) * 10.0 ** rng.uniform(-12, 2, size=m) * \
            rng.choice([-1.0, 1.0], size=m)
        upper = lower + np.abs(rng.standard_normal(m))
        lower[rng.random(m) < 0.3] = -np.inf
        expected = backends._row_violation_numpy(A, x, lower, upper)
        got = compiled_row_violation(A, x, lower, upper)
        assert got == pytest.approx(expected, rel=1e-9, abs=1e-12 * (1 + np.abs(ax).max()))
