"""One priority level of a hierarchical least-squares problem over a plain vector x.

A level holds the two kinds of rows of Herzog et al. 2016, eqs. 3-4 (written here in the
usual "target" form rather than the paper's ``B y + b = 0``):

* equalities   ``B x ≈ b``            residual ``B x - b``, weighted row-wise by ``W`` (eq. 7);
* inequalities ``lower ≤ C x ≤ upper`` violation ``max(0, lower - C x, C x - upper)``, weighted
  row-wise by ``V`` (eq. 6); bounds may be ±inf (one-sided rows), ``lower == upper`` is allowed.

The level objective (eq. 5 without the ε term) is ``‖W (B x - b)‖² + ‖V · violation‖²``.
Everything is validated once, at construction; the solver then trusts the arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Level"]


def _as_matrix(value, label: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1 and arr.size == 0:
        arr = arr.reshape(0, 0)
    if arr.ndim != 2:
        raise ValueError(f"{label} must be a 2-D matrix, got shape {arr.shape}")
    return arr


def _as_vector(value, rows: int, label: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(rows, float(arr))
    arr = arr.reshape(-1) if arr.ndim == 2 and 1 in arr.shape else arr
    if arr.ndim != 1 or arr.shape[0] != rows:
        raise ValueError(f"{label} has shape {arr.shape}, expected ({rows},)")
    return arr


@dataclass(eq=False)
class Level:
    """A priority level: weighted equality task and weighted (soft) inequalities (Herzog et al. 2016, eqs. 3-7).

    Parameters
    ----------
    eq : ``(B, b)`` — the task ``B x ≈ b`` (``B`` is k×n, ``b`` has k entries), or None.
    ineq : ``(C, lower, upper)`` — ``lower ≤ C x ≤ upper`` (``C`` is m×n), or None. A bound of
        ``None`` means unbounded on that side; ±inf entries give one-sided rows.
    weights : per-row weights of the equality rows (the diagonal of W, eq. 7) or a scalar; ≥ 0.
        A zero weight removes the row from the objective (it then locks no direction).
    ineq_weights : per-row weights of the inequality rows (the diagonal of V, eq. 6) or a
        scalar; must be > 0 (a violation must cost something, or the relaxed bound of eq. 9
        would be undefined).
    name : used in error messages and diagnostics.

    After construction the normalised arrays are available as ``B, b, w`` (k rows) and
    ``C, lower, upper, v`` (m rows); missing parts have zero rows. ``n`` is the column count
    (None for an empty level); column consistency across levels is checked by the solver.
    """

    eq: tuple | None = None
    ineq: tuple | None = None
    weights: object = None
    ineq_weights: object = None
    name: str = ""

    B: np.ndarray = field(init=False, repr=False)
    b: np.ndarray = field(init=False, repr=False)
    w: np.ndarray = field(init=False, repr=False)
    C: np.ndarray = field(init=False, repr=False)
    lower: np.ndarray = field(init=False, repr=False)
    upper: np.ndarray = field(init=False, repr=False)
    v: np.ndarray = field(init=False, repr=False)
    n: int | None = field(init=False, repr=False)

    def __post_init__(self) -> None:
        tag = f"Level {self.name!r}"
        n_eq = n_in = None

        if self.eq is not None:
            if not isinstance(self.eq, (tuple, list)) or len(self.eq) != 2:
                raise ValueError(f"{tag}: eq must be a pair (B, b)")
            B = _as_matrix(self.eq[0], f"{tag}: eq B")
            k, n_eq = B.shape
            b = _as_vector(self.eq[1], k, f"{tag}: eq b")
            if not np.all(np.isfinite(B)):
                raise ValueError(f"{tag}: eq B contains NaN or inf")
            if not np.all(np.isfinite(b)):
                raise ValueError(f"{tag}: eq b contains NaN or inf")
        else:
            if self.weights is not None and np.size(self.weights) > 1:
                raise ValueError(f"{tag}: weights given but the level has no eq rows")
            B, b, k = None, np.zeros(0), 0

        if self.ineq is not None:
            if not isinstance(self.ineq, (tuple, list)) or len(self.ineq) != 3:
                raise ValueError(f"{tag}: ineq must be a triple (C, lower, upper)")
            C = _as_matrix(self.ineq[0], f"{tag}: ineq C")
            m, n_in = C.shape
            lo = np.full(m, -np.inf) if self.ineq[1] is None else _as_vector(self.ineq[1], m, f"{tag}: ineq lower")
            up = np.full(m, np.inf) if self.ineq[2] is None else _as_vector(self.ineq[2], m, f"{tag}: ineq upper")
            if not np.all(np.isfinite(C)):
                raise ValueError(f"{tag}: ineq C contains NaN or inf")
            if np.any(np.isnan(lo)):
                raise ValueError(f"{tag}: ineq lower contains NaN")
            if np.any(np.isnan(up)):
                raise ValueError(f"{tag}: ineq upper contains NaN")
            if np.any(lo == np.inf):
                raise ValueError(f"{tag}: ineq lower contains +inf (row can never hold)")
            if np.any(up == -np.inf):
                raise ValueError(f"{tag}: ineq upper contains -inf (row can never hold)")
            bad = np.flatnonzero(lo > up)
            if bad.size:
                raise ValueError(f"{tag}: ineq lower > upper in rows {bad[:10].tolist()}")
        else:
            if self.ineq_weights is not None and np.size(self.ineq_weights) > 1:
                raise ValueError(f"{tag}: ineq_weights given but the level has no ineq rows")
            C, lo, up, m = None, np.zeros(0), np.zeros(0), 0

        if n_eq is not None and n_in is not None and n_eq != n_in:
            raise ValueError(f"{tag}: ineq C has {n_in} columns, expected {n_eq} (as eq B)")
        n = n_eq if n_eq is not None else n_in

        w = np.ones(k) if self.weights is None else _as_vector(self.weights, k, f"{tag}: weights")
        if not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"{tag}: weights must be finite and >= 0")
        v = np.ones(m) if self.ineq_weights is None else _as_vector(self.ineq_weights, m, f"{tag}: ineq_weights")
        if not np.all(np.isfinite(v)) or np.any(v <= 0):
            raise ValueError(f"{tag}: ineq_weights must be finite and > 0")

        ncol = 0 if n is None else n
        self.B = np.ascontiguousarray(B) if B is not None else np.zeros((0, ncol))
        self.b = np.ascontiguousarray(b)
        self.w = w
        self.C = np.ascontiguousarray(C) if C is not None else np.zeros((0, ncol))
        self.lower = np.ascontiguousarray(lo)
        self.upper = np.ascontiguousarray(up)
        self.v = v
        self.n = n

    @classmethod
    def trusted(cls, B: np.ndarray, b: np.ndarray, w: np.ndarray, C: np.ndarray,
                lower: np.ndarray, upper: np.ndarray, v: np.ndarray, name: str = "") -> "Level":
        """A level from arrays the caller has already checked (shapes consistent, finite data,
        lower <= upper, weights > 0); skips the validation of the constructor. For assemblers
        that refill preallocated arrays every control cycle (``wholebody.formulation``)."""
        level = object.__new__(cls)
        level.eq = (B, b) if B.shape[0] else None
        level.ineq = (C, lower, upper) if C.shape[0] else None
        level.weights, level.ineq_weights, level.name = w, v, name
        level.B, level.b, level.w = B, b, w
        level.C, level.lower, level.upper, level.v = C, lower, upper, v
        level.n = B.shape[1]
        return level

    # ------------------------------------------------------------------ evaluation
    @property
    def n_eq(self) -> int:
        return self.B.shape[0]

    @property
    def n_ineq(self) -> int:
        return self.C.shape[0]

    def eq_residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual ``W (B x - b)`` (eq. 7)."""
        return self.w * (self.B @ x - self.b)

    def ineq_violation(self, x: np.ndarray) -> np.ndarray:
        """Weighted slack ``v = V · max(0, lower - C x, C x - upper) ≥ 0`` (eq. 6)."""
        cx = self.C @ x
        return self.v * np.maximum(np.maximum(self.lower - cx, cx - self.upper), 0.0)

    def cost(self, x: np.ndarray) -> float:
        """Level objective ``‖W(Bx-b)‖² + ‖v‖²`` (eq. 5 without the ε term)."""
        r = self.eq_residual(x)
        s = self.ineq_violation(x)
        return float(r @ r + s @ s)
