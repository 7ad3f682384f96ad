"""Checks of numbers entering the library: each returns the value in its numpy form or raises a
ValueError that names the field and says what was expected."""

from __future__ import annotations

import numpy as np


def vector(value, size: int, name: str) -> np.ndarray:
    """``value`` as a finite float vector of ``size``; ValueError naming ``name`` otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a numeric vector of size {size}") from exc
    if arr.shape != (size,):
        raise ValueError(f"{name}: expected a vector of size {size}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def contact_dims(dims, n_contacts: int | None, name: str = "dims") -> tuple[int, ...]:
    """Per-contact dimensions (3: point force, 6: wrench), ``n_contacts`` of them if given."""
    try:
        out = tuple(int(d) for d in dims)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a list of per-contact dimensions (3 or 6)") from exc
    if any(d not in (3, 6) for d in out):
        raise ValueError(f"{name}: every contact dimension must be 3 (point force) or 6 (wrench), "
                         f"got {list(out)}")
    if n_contacts is not None and len(out) != n_contacts:
        raise ValueError(f"{name}: {len(out)} entries for {n_contacts} contacts")
    return out


def weight_matrix(value, size: int, name: str, definite: bool) -> np.ndarray:
    """A symmetric (size x size) weight from a matrix or the vector of its diagonal."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a {size}x{size} matrix or its diagonal") from exc
    if arr.shape == (size,):
        arr = np.diag(arr)
    if arr.shape != (size, size):
        raise ValueError(f"{name}: expected a {size}x{size} matrix or a diagonal of size {size}, "
                         f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    if not np.allclose(arr, arr.T, rtol=1e-10, atol=1e-12):
        raise ValueError(f"{name}: must be symmetric")
    arr = 0.5 * (arr + arr.T)
    eig_min = float(np.linalg.eigvalsh(arr).min()) if size else 1.0
    tol = 1e-12 * max(1.0, float(np.abs(arr).max()) if size else 1.0)
    if definite and eig_min <= tol:
        raise ValueError(f"{name}: must be positive definite (smallest eigenvalue {eig_min:.3g})")
    if not definite and eig_min < -tol:
        raise ValueError(f"{name}: must be positive semi-definite (smallest eigenvalue "
                         f"{eig_min:.3g})")
    return arr


def contact_positions(value, name: str = "contact_positions") -> np.ndarray:
    """An (n_contacts >= 1, 3) finite array of contact positions."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected an (n_contacts, 3) array of positions") from exc
    if arr.ndim != 2 or arr.shape[1] != 3 or arr.shape[0] == 0:
        raise ValueError(f"{name}: expected an (n_contacts, 3) array with n_contacts >= 1, "
                         f"got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def positive(value, name: str) -> float:
    """``value`` as a finite float > 0; ValueError naming ``name`` otherwise."""
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a positive number, got {value!r}") from exc
    if not np.isfinite(out) or out <= 0.0:
        raise ValueError(f"{name}: expected a positive number, got {value!r}")
    return out


def number(value, name: str, *, low: float = -np.inf, high: float = np.inf,
           low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a finite float in [low, high] (``low_open``/``high_open``: the bound itself is
    excluded); ValueError naming ``name`` and the value otherwise."""
    def interval() -> str:
        left = "(" if low_open else "["
        right = ")" if high_open else "]"
        return f"{left}{low:g}, {high:g}{right}"
    try:
        out = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a number in {interval()}, got {value!r}") from exc
    inside = (out > low if low_open else out >= low) and (out < high if high_open else out <= high)
    if not np.isfinite(out) or not inside:
        raise ValueError(f"{name}: expected a finite number in {interval()}, got {value!r}")
    return out


def nonnegative(value, name: str) -> float:
    """``value`` as a finite float >= 0; ValueError naming ``name`` otherwise."""
    return number(value, name, low=0.0)


def finite_array(value, name: str, *, shape: tuple | None = None,
                 nonnegative: bool = False) -> np.ndarray:
    """``value`` as a finite float array (of ``shape`` if given; entries >= 0 if
    ``nonnegative``); ValueError naming ``name``, and the first bad entry, otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected numbers, got {value!r}") from exc
    if shape is not None and arr.shape != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {arr.shape}")
    # the common case in few numpy calls (asked every control cycle); the first bad entry is
    # looked for only when there is one
    if np.isfinite(arr).all() and not (nonnegative and arr.size and arr.min() < 0.0):
        return arr
    bad = ~np.isfinite(arr) | ((arr < 0.0) if nonnegative else False)
    if np.any(bad):
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        what = "finite numbers >= 0" if nonnegative else "finite numbers"
        where = f" at index {index[0] if len(index) == 1 else index}" if arr.ndim else ""
        raise ValueError(f"{name}: expected {what}, got {float(arr[index])!r}{where}")
    return arr
