"""The centroidal model of Herzog et al. 2016, eqs. 20-21, and its linearisation.

State ``s = [x_cog (3); h (6)]`` (``h = [h_lin; h_ang]``, momentum about the CoM, world axes) and
input ``lambda`` (the stacked contact forces/wrenches)::

    x_cog' = h_lin / m
    h'     = G(x_cog) lambda + [m g; 0],   G block of contact i = [I 0; [x_i - x_cog]x I]

A point contact has a 3D force (world axes), a rectangle contact a 6D wrench ``[f; tau]`` about
its frame origin ``x_i``. Gravity is ``g = (0, 0, -gravity)``. :mod:`wholebody.control.lqr`
designs the momentum feedback on this model.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs

from ..tasks.momentum import centroidal_map, skew
from ..validation import contact_dims, contact_positions as check_positions, positive, vector, weight_matrix

log = logging.getLogger(__name__)

STATE_DIM = 9


class WeightFactor:
    """A positive-definite weight ``W`` factored for :func:`balancing_forces`: its Cholesky factor
    ``L`` (``W = L L^T``) and its inverse ``inverse`` (``L^-T L^-1``). Made once per weight (a
    contact configuration's input cost), used every cycle."""

    __slots__ = ("L", "inverse")

    def __init__(self, W: np.ndarray):
        self.L = np.linalg.cholesky(W)
        L_inv = np.linalg.solve(self.L, np.eye(len(W)))
        self.inverse = L_inv.T @ L_inv


#: a Cholesky pivot of the normal equations below this share of the largest: G is taken as rank
#: deficient or ill-conditioned (G W^-1 G^T worse than about 1e8, where the closed form would
#: lose more than ~1e-8 of its digits) and the least-squares solve is used. A humanoid's soles
#: and a quadruped's three or four feet give shares above 0.05; two point feet (rank 5) 1e-8
RANK_PIVOT_SHARE = 1e-4


_min, _max = np.minimum.reduce, np.maximum.reduce  # (without ndarray.min's Python wrapper)


def _weighted_least_norm(G: np.ndarray, w: np.ndarray, factor: WeightFactor) -> np.ndarray:
    """argmin lambda^T W lambda s.t. G lambda = w (least-squares if w is not reachable).

    With G of full row rank, the closed form lambda = W^-1 G^T (G W^-1 G^T)^-1 w: the 6 x 6
    normal equations of the constraint factored by LAPACK's Cholesky (``dpotrf``, called
    directly: numpy.linalg's per-call checks cost more than the factorisation), checked positive
    definite by its pivots, and solved with that factor; otherwise the least-squares solution of
    minimum weighted norm: lambda = L^-T mu with mu the minimum-norm least-squares solution of
    (G L^-T) mu = w (LAPACK's SVD-based solver)."""
    A = G @ factor.inverse  # G W^-1
    S = A @ G.T
    C, info = dpotrf(S, lower=1)
    if info == 0:
        pivots = np.diagonal(C)
        if _min(pivots) > RANK_PIVOT_SHARE * _max(pivots):
            return A.T @ dpotrs(C, w, lower=1)[0]
    L = factor.L
    GL = np.linalg.solve(L, G.T).T  # G L^-T
    mu, *_ = np.linalg.lstsq(GL, w, rcond=None)
    return np.linalg.solve(L.T, mu)


def _momentum_map(X: np.ndarray, com: np.ndarray, dims: tuple[int, ...]) -> np.ndarray:
    """:func:`~wholebody.tasks.momentum.centroidal_map` (the same numbers), filled as Python
    numbers in one pass: cheaper for the few contacts of a control cycle."""
    n = sum(dims)
    rows = [[0.0] * n for _ in range(6)]
    start = 0
    for (rx, ry, rz), d in zip((X - com).tolist(), dims):
        c = start
        rows[0][c] = rows[1][c + 1] = rows[2][c + 2] = 1.0
        rows[3][c + 1], rows[3][c + 2] = -rz, ry
        rows[4][c], rows[4][c + 2] = rz, -rx
        rows[5][c], rows[5][c + 1] = -ry, rx
        if d == 6:
            rows[3][c + 3] = rows[4][c + 4] = rows[5][c + 5] = 1.0
        start += d
    return np.array(rows).reshape(6, n)


def _gravity_wrench(mass: float, gravity: float) -> np.ndarray:
    """[m g; 0] of eq. 21 with g = (0, 0, -gravity)."""
    return np.array([0.0, 0.0, -mass * gravity, 0.0, 0.0, 0.0])


def _model_arguments(contact_positions, dims, com, mass, gravity):
    """Validated (positions, dims, com, mass, gravity) of the centroidal model (eq. 21)."""
    X = check_positions(contact_positions)
    dims = (6,) * len(X) if dims is None else contact_dims(dims, len(X))
    return X, dims, vector(com, 3, "com"), positive(mass, "mass"), positive(gravity, "gravity")


def balancing_forces(contact_positions, com, mass: float, dims: Sequence[int] | None = None,
                     gravity: float = 9.81, weight=None, hdot=None) -> np.ndarray:
    """Contact forces that make eq. 21 give ``h' = hdot`` (default 0: gravity balanced).

    The minimiser of ``lambda^T W lambda`` subject to ``G(com) lambda + [m g; 0] = hdot``, with
    ``W = weight`` (n_lambda x n_lambda or its diagonal; default identity = the least-norm
    distribution). If the wrench cannot be produced by these contacts (rank-deficient ``G``, e.g. a
    single point foot not below the CoM) the least-squares solution is returned and a warning logged.
    """
    X, dims, com, mass, gravity = _model_arguments(contact_positions, dims, com, mass, gravity)
    n = sum(dims)
    W = np.eye(n) if weight is None else weight_matrix(weight, n, "weight", definite=True)
    hdot = np.zeros(6) if hdot is None else vector(hdot, 6, "hdot")
    return balancing_forces_factored(X, com, mass, dims, gravity, WeightFactor(W), hdot)


def balancing_forces_factored(X: np.ndarray, com: np.ndarray, mass: float, dims: tuple[int, ...],
                              gravity: float, factor: WeightFactor, hdot: np.ndarray) -> np.ndarray:
    """:func:`balancing_forces` on arguments already checked (``X`` (n_c, 3) and ``com`` finite,
    ``dims`` a tuple of 3 and 6, ``hdot`` a 6-vector), with the weight factored
    (:class:`WeightFactor`, kept from one call to the next while the weight does not change): the
    same computation without the checks, for a control loop."""
    G = _momentum_map(X, com, dims)
    w = hdot - _gravity_wrench(mass, gravity)
    lam = _weighted_least_norm(G, w, factor)
    if log.isEnabledFor(logging.DEBUG):  # what the checks find is only logged
        residual = float(np.linalg.norm(G @ lam - w))
        if residual > 1e-6 * max(1.0, float(np.linalg.norm(w))):
            log.debug("balancing_forces: the contacts cannot balance the wrench %s exactly "
                      "(residual %.3g)", np.round(w, 3), residual)
        start, fz = 0, []
        for d in dims:
            fz.append(float(lam[start + 2]))
            start += d
        if min(fz) < 0.0:
            log.debug("balancing_forces: negative normal force %s (CoM outside the support?)",
                      np.round(fz, 3))
    return lam


# ---------------------------------------------------------------------------------- the model
def centroidal_dynamics(s, lam, contact_positions, mass: float, dims: Sequence[int] | None = None,
                        gravity: float = 9.81) -> np.ndarray:
    """The nonlinear centroidal model s' = f(s, lambda) of eqs. 20-21 (contacts fixed in place)."""
    X = check_positions(contact_positions)
    dims = (6,) * len(X) if dims is None else contact_dims(dims, len(X))
    s = vector(s, STATE_DIM, "s")
    lam = vector(lam, sum(dims), "lam")
    mass = positive(mass, "mass")
    gravity = positive(gravity, "gravity")
    G = centroidal_map(X, s[:3], dims)
    return np.concatenate([s[3:6] / mass, G @ lam + _gravity_wrench(mass, gravity)])


@dataclass(frozen=True)
class MomentumModel:
    """Linearised centroidal model ``s' ≈ A s + B lambda + c`` (Herzog et al. 2016, eq. 21).

    Unpacks as ``A, B, c = model``. Also carries the linearisation point (``com0``, ``lambda0``),
    the contact ``dims``, ``mass``, ``gravity`` and ``contact_positions``.
    """

    A: np.ndarray
    B: np.ndarray
    c: np.ndarray
    com0: np.ndarray
    lambda0: np.ndarray
    dims: tuple[int, ...]
    mass: float
    gravity: float
    contact_positions: np.ndarray

    def __iter__(self):
        return iter((self.A, self.B, self.c))

    @property
    def n_lambda(self) -> int:
        return int(sum(self.dims))


def momentum_model(contact_positions, com, mass: float, nominal_forces=None,
                   gravity: float = 9.81, dims: Sequence[int] | None = None) -> MomentumModel:
    """Linearise the centroidal model of eq. 21 at ``(x_cog0 = com, lambda0)``.

    Parameters
    ----------
    contact_positions : (n_c, 3) positions ``x_i`` of the contact frame origins (world).
    com : CoM position ``x_cog0`` at which to linearise.
    mass : total mass ``m``.
    nominal_forces : ``lambda0`` (size ``sum(dims)``); default: the least-norm distribution that
        balances gravity, ``G(x_cog0) lambda0 + [m g; 0] = 0`` (see :func:`balancing_forces`).
    gravity : magnitude of g; the gravity vector is ``(0, 0, -gravity)``.
    dims : per-contact dimensions, 3 (point force) or 6 (wrench ``[f; tau]``); default all 6.

    Returns
    -------
    MomentumModel ``(A, B, c)`` with state ``s = [x_cog; h_lin; h_ang]`` and input ``lambda`` such
    that ``s' = A s + B lambda + c`` is the first-order expansion of eq. 21 at ``(s0, lambda0)``
    (exact at that point; ``c = f(s0, lambda0) - A s0 - B lambda0``).

    Derivation. ``x_cog' = h_lin / m`` is linear. ``h_lin' = sum f_i + m g`` is linear. The
    angular rows ``h_ang' = sum_i (x_i - x_cog) × f_i + sum tau_i`` are bilinear in (x_cog, f_i);
    with ``x_cog = x_cog0 + dx`` and ``f_i = f_i0 + df_i``::

        (x_i - x_cog0 - dx) × (f_i0 + df_i)
          ≈ (x_i - x_cog0) × f_i0 + (x_i - x_cog0) × df_i - dx × f_i0
          = ... + [x_i - x_cog0]x df_i + [f_i0]x dx        (since -dx × f = f × dx)

    so ``d h_ang' / d x_cog = + sum_i [f_i0]x = +[F0]x`` with ``F0`` the total nominal contact force
    (``F0 = -m g = (0, 0, m |g|)`` when gravity is balanced), ``B = [0; G(x_cog0)]`` and::

        A = [[0, I/m, 0],
             [0,  0,  0],
             [[F0]x, 0, 0]]

    Moving the CoM by dx under unchanged contact forces changes the moment of those forces about
    the CoM by ``F0 × dx`` (e.g. dx = +y with F0 = +z m|g| gives ``h_ang_x' = -m|g| dy``).
    """
    X, dims, com, mass, gravity = _model_arguments(contact_positions, dims, com, mass, gravity)
    n = sum(dims)
    if nominal_forces is None:
        lam0 = balancing_forces(X, com, mass, dims, gravity)
    else:
        lam0 = vector(nominal_forces, n, "nominal_forces")
    G = centroidal_map(X, com, dims)
    starts = np.cumsum((0,) + dims[:-1])
    F0 = np.sum([lam0[s:s + 3] for s in starts], axis=0)

    A = np.zeros((STATE_DIM, STATE_DIM))
    A[0:3, 3:6] = np.eye(3) / mass
    A[6:9, 0:3] = skew(F0)
    B = np.zeros((STATE_DIM, n))
    B[3:9] = G
    s0 = np.concatenate([com, np.zeros(6)])
    f0 = np.concatenate([np.zeros(3), G @ lam0 + _gravity_wrench(mass, gravity)])
    c = f0 - A @ s0 - B @ lam0
    return MomentumModel(A, B, c, com.copy(), lam0.copy(), dims, mass, gravity, X.copy())
