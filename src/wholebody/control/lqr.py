"""LQR design of the momentum feedback law (Herzog et al. 2016, Sect. 3.2).

The centroidal model (eq. 21, :mod:`wholebody.control.momentum_model`) with state ``s = [x_cog (3); h (6)]`` (``h = [h_lin; h_ang]``, the
linear and angular momentum about the CoM, world axes, as in eq. 19) and input ``u = lambda``
(the stacked contact forces/wrenches, eq. 21's generalized external forces)::

    x_cog' = h_lin / m
    h'     = G(x_cog) lambda + [m g; 0],   G block of contact i = [I 0; [x_i - x_cog]x I]

is linearised at the nominal point ``(x_cog0, lambda0)``, an infinite-horizon LQR problem with the
cost of eq. 26 is solved, and the result is the force law of eq. 23,
``lambda = -K [x_cog; h] + k(x_ref, h_ref)``, which the :class:`~wholebody.tasks.momentum.MomentumForce`
task projects into momentum space (eq. 24). Gains are computed once per contact configuration and
interpolated during contact transitions (Remark at the end of Sect. 3.2).

Integral action (OUR EXTENSION, not in the paper; off in this class by default, on by default in
:class:`~wholebody.control.balance.MomentumBalance` with :data:`DEFAULT_Q_INTEGRAL`). The LQR of Herzog et al. 2016,
eq. 21-26, has no integral term; everything about ``q_integral`` is ours. With ``q_integral`` the
state of eq. 21 is augmented with the integral of the CoG error, ``z' = x_cog - x_ref`` (3), the
same infinite-horizon Riccati equation is solved for the augmented system (LQI) with
``Q_aug = blockdiag(Q, diag(q_integral))``, and the force law becomes
``lambda = -K [x_cog - x_ref; h - h_ref; z] + lambda_ff``. Its purpose: a constant unknown force
bias (e.g. a robot heavier or lighter than the model: ``Delta m g`` on the vertical rows) gives the
paper's law a steady CoG offset ``bias / stiffness``, and with eq. 26's Q/R the vertical CoG
stiffness is only ~100 N/m on talos14; the integral removes the offset of the regulated (model)
CoG. The integral is clamped elementwise to ``+-integral_limit`` (anti-windup).

Orientation (OUR EXTENSION, not in the paper; off by default). Eq. 21's state has no orientation:
with eq. 26's small weight on angular momentum the gains trade CoG error for angular momentum and
nothing brings back the rotation it integrates to. With ``q_orientation`` the state is augmented
with the orientation error ``theta`` (3, world axes, small angles), ``theta' = I_G^-1 h_ang`` with
``I_G`` the centroidal composite inertia at the linearisation pose (the robot turning as one rigid
body), ``Q_aug = blockdiag(Q, diag(q_orientation))``, and the law gains ``K_theta`` columns acting
on the measured orientation error (:class:`~wholebody.control.balance.MomentumBalance` uses the
floating base's). With both extensions the state is ``[x_cog; h; theta; z]``.

Conventions (those of :mod:`wholebody.robot` and :func:`~wholebody.tasks.momentum.momentum_map`):
a point contact has a 3D force ``f`` (world axes); a rectangle contact a 6D wrench ``[f; tau]`` about
the contact frame origin ``x_i`` (world axes). Gravity is ``g = (0, 0, -gravity)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.linalg

from ..validation import contact_dims, positive, vector, weight_matrix
from .momentum_model import (STATE_DIM, MomentumModel, WeightFactor, balancing_forces,
                             balancing_forces_factored, momentum_model)

log = logging.getLogger(__name__)

#: Herzog et al. 2016, Sect. 5.2.2 (eq. 26): state cost on [x_cog; h_lin; h_ang].
DEFAULT_Q_DIAG = np.array([30.0, 30.0, 50.0, 0.5, 0.5, 0.5, 0.1, 0.1, 0.1])
#: Herzog et al. 2016, Sect. 5.2.2 (eq. 26): input cost of one contact wrench [f; tau]; a point
#: contact (3D force) uses the first three entries.
DEFAULT_R_DIAG = np.array([0.1, 0.1, 0.01, 2.0, 2.0, 2.0])
#: Weight of the CoG-error integral that :class:`~wholebody.control.balance.MomentumBalance`'s LQR
#: uses unless told otherwise (``q_integral=0``: the paper's LQR). With eq. 26's Q/R the vertical
#: CoG pole is 0.11 rad/s on talos14: a robot whose mass or CoG differ from its model settles
#: centimetres off its reference, and the integral removes that offset. docs/results.md measures
#: what it gains under model errors, what it costs in the strongest pushes survived, and why this
#: weight: a tenth of it is too slow for the lightest of ``robust-push``'s draws, three times it
#: makes a five-joint leg on narrow soles rock after a push.
DEFAULT_Q_INTEGRAL = 3e5
#: Anti-windup bound (m s) of each component of the CoG-error integral (our extension, see the
#: module docstring); only used when integral action is on. On talos14 with ``q_integral=3e5``
#: (integral gain ~7.7e3 N per m s on the total vertical force) 0.01 m s caps the integral's force
#: at ~77 N (~9 % of m g), 3.4 times the bias of a 2.3 kg mass error; a 3 cm CoG error during a
#: push reaches the cap in 0.3 s.
DEFAULT_INTEGRAL_LIMIT = 0.01


def contact_cost(dims: Sequence[int], R=None) -> np.ndarray:
    """Block-diagonal input cost of eq. 26 for contacts of dimensions ``dims``.

    ``R`` is the cost of ONE contact wrench ``[f; tau]``: a 6-vector (diagonal) or a 6x6 matrix
    (default ``diag(.1, .1, .01, 2, 2, 2)``, Sect. 5.2.2). A 3D point contact uses its top-left 3x3
    block (the force part).
    """
    dims = contact_dims(dims, None)
    R6 = weight_matrix(DEFAULT_R_DIAG if R is None else R, 6, "R", definite=True)
    return scipy.linalg.block_diag(*[R6[:d, :d] for d in dims]) if dims else np.zeros((0, 0))


# ------------------------------------------------------------------------------------ the LQR
def _check_stabilizable(A: np.ndarray, B: np.ndarray) -> None:
    """PBH test on the eigenvalues of A with non-negative real part."""
    n = A.shape[0]
    scale = max(1.0, float(np.abs(A).max()), float(np.abs(B).max()) if B.size else 1.0)
    for ev in np.linalg.eigvals(A):
        if ev.real >= -1e-9:
            M = np.hstack([A - ev * np.eye(n), B])
            if np.linalg.matrix_rank(M, tol=1e-9 * scale) < n:
                raise ValueError(
                    f"model: (A, B) is not stabilizable (mode at eigenvalue {ev:.3g} cannot be "
                    f"controlled); the contact set cannot regulate all of the CoM and momentum "
                    f"(e.g. a single point contact)")


def _extension_weight(value, name: str) -> np.ndarray | None:
    """An extension's weight (None, 0, a number or a 3-vector, all >= 0) as a 3-vector, None if
    off (``name``: the argument, for the error)."""
    if value is None:
        return None
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: expected a number or a 3-vector >= 0, got {value!r}") from exc
    if arr.ndim == 0:
        arr = np.full(3, float(arr))
    if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f"{name}: expected a number or a 3-vector >= 0, got {value!r}")
    return arr if np.any(arr > 0.0) else None


def _integral_weight(q_integral) -> np.ndarray | None:
    return _extension_weight(q_integral, "q_integral")


def _orientation_weight(q_orientation) -> np.ndarray | None:
    return _extension_weight(q_orientation, "q_orientation")


def integral_augmented(A: np.ndarray, B: np.ndarray, Q: np.ndarray, q_integral
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The model of eq. 21 augmented with ``z' = x_cog - x_ref`` (our extension, not the paper's).

    State ``[s; z_a]``: ``A_aug = [[A, 0], [S, 0]]`` with ``S`` the rows of ``[I 0 0]`` (picks
    x_cog) of the axes ``a`` whose weight is > 0 (an integral with zero weight would be an
    undetectable integrator: no stabilising Riccati solution), ``B_aug = [B; 0]``,
    ``Q_aug = blockdiag(Q, diag(q_integral[a]))``. In deviation coordinates about the reference (an
    equilibrium), ``x_ref`` drops out. Returns ``(A_aug, B_aug, Q_aug, axes)``.
    """
    qi = _integral_weight(q_integral)
    if qi is None:
        raise ValueError("q_integral: integral action needs a weight > 0")
    axes = np.flatnonzero(qi > 0.0)
    n, m, na = A.shape[0], B.shape[1], len(axes)
    Aa = np.zeros((n + na, n + na))
    Aa[:n, :n] = A
    Aa[n:, :3] = np.eye(3)[axes]
    Ba = np.vstack([B, np.zeros((na, m))])
    Qa = scipy.linalg.block_diag(Q, np.diag(qi[axes]))
    return Aa, Ba, Qa, axes


def orientation_augmented(A: np.ndarray, B: np.ndarray, Q: np.ndarray, inertia,
                          q_orientation) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The model of eq. 21 augmented with the orientation ``theta' = I_G^-1 h_ang`` (ours).

    State ``[s; theta]`` with ``s = [x_cog; h_lin; h_ang]``: ``A_aug = [[A, 0], [E, 0]]`` with
    ``E = [0 0 I_G^-1]``, ``B_aug = [B; 0]``, ``Q_aug = blockdiag(Q, diag(q_orientation))``.
    ``inertia``: the 3x3 centroidal composite inertia ``I_G`` (symmetric positive definite).
    Returns ``(A_aug, B_aug, Q_aug)``.
    """
    qo = _orientation_weight(q_orientation)
    if qo is None:
        raise ValueError("q_orientation: orientation feedback needs a weight > 0")
    I_G = weight_matrix(inertia, 3, "inertia", definite=True)
    n, m = A.shape[0], B.shape[1]
    Aa = np.zeros((n + 3, n + 3))
    Aa[:n, :n] = A
    Aa[n:, 6:9] = np.linalg.inv(I_G)
    Ba = np.vstack([B, np.zeros((3, m))])
    Qa = scipy.linalg.block_diag(Q, np.diag(qo))
    return Aa, Ba, Qa


def augmented_model(A: np.ndarray, B: np.ndarray, Q: np.ndarray, q_orientation=None,
                    inertia=None, q_integral=None):
    """``(A, B, Q, axes)`` of the design: eq. 21's model, augmented with the orientation
    (:func:`orientation_augmented`) and then the CoG-error integral (:func:`integral_augmented`)
    when their weights are on; ``axes`` are the integral's axes (None without integral)."""
    if _orientation_weight(q_orientation) is not None:
        if A.shape[0] != STATE_DIM:
            raise ValueError(f"q_orientation: the state must be eq. 21's [x_cog; h] ({STATE_DIM}), "
                             f"got {A.shape[0]}")
        if inertia is None:
            raise ValueError("inertia: the orientation state needs the centroidal inertia I_G")
        A, B, Q = orientation_augmented(A, B, Q, inertia, q_orientation)
    axes = None
    if _integral_weight(q_integral) is not None:
        if A.shape[0] < 3:
            raise ValueError("q_integral: the state must start with x_cog (3)")
        A, B, Q, axes = integral_augmented(A, B, Q, q_integral)
    return A, B, Q, axes


def lqr_gains(model, Q=None, R=None, dt: float | None = None, full_output: bool = False,
              q_integral=None, q_orientation=None, inertia=None):
    """Infinite-horizon LQR gain ``K`` for the linearised model: ``u = u0 - K (s - s_ref)``.

    Minimises the cost of eq. 26, ``sum/integral of s^T Q s + lambda^T R lambda`` (in deviation
    coordinates around the nominal point; the affine term ``c`` is carried by the feedforward).

    Continuous time by default (``scipy.linalg.solve_continuous_are``): the gains are applied in a
    1 kHz loop, far faster than the closed-loop momentum dynamics (with eq. 26's weights the
    poles lie between about -0.1 and -10 rad/s for Talos and HyQ), so the continuous-time law is the ``dt -> 0`` limit of the discrete one; the paper's sum over
    control ticks with the same Q and R gives the same gains as the integral with Q dt and R dt
    (scaling both weights leaves K unchanged). Pass ``dt`` for the discrete-time design instead
    (zero-order-hold discretisation, ``solve_discrete_are``).

    Parameters
    ----------
    model : a :class:`MomentumModel` or a tuple ``(A, B[, c])``.
    Q : 9x9 state weight or its diagonal; default ``diag(30, 30, 50, .5, .5, .5, .1, .1, .1)``.
    R : n_lambda x n_lambda input weight or its diagonal; default (a MomentumModel only): per
        contact ``diag(.1, .1, .01, 2, 2, 2)`` (first 3 entries for a point contact).
    dt : None (continuous) or the control period for a discrete-time design.
    full_output : also return the Riccati solution ``P``.
    q_integral : None/0 (default: the paper's LQR) or the weight (number or 3-vector, on x, y, z)
        of the CoG-error integral: the design is then done for the augmented model of
        :func:`integral_augmented` (LQI; our extension, not the paper's) and ``K`` has 3 more
        columns, ``[K_s, K_z]``, acting on ``z = integral of (x_cog - x_ref)`` (a column is zero
        for an axis of weight 0; ``P`` is then that of the augmented system without those axes).
    q_orientation, inertia : None/0 (default: the paper's LQR) or the weight (number or 3-vector)
        of the orientation error, with the 3x3 centroidal inertia ``I_G``: the design is done for
        the model of :func:`orientation_augmented` (ours) and ``K`` has 3 more columns acting on
        ``theta`` (before the integral's: ``[K_s, K_theta, K_z]``).

    Returns ``K`` (n_lambda x 9, + 3 with ``q_orientation``, + 3 with ``q_integral``), or
    ``(K, P)`` with ``full_output``.
    """
    if isinstance(model, MomentumModel):
        A, B = model.A, model.B
    else:
        try:
            A, B = (np.asarray(m, dtype=float) for m in tuple(model)[:2])
        except (TypeError, ValueError) as exc:
            raise ValueError("model: expected a MomentumModel or a tuple (A, B[, c])") from exc
    n = A.shape[0] if A.ndim == 2 else -1
    if A.ndim != 2 or A.shape != (n, n) or B.ndim != 2 or B.shape[0] != n or B.shape[1] == 0:
        raise ValueError(f"model: A must be square and B have as many rows, got A {A.shape} and "
                         f"B {B.shape}")
    if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        raise ValueError("model: A or B contains NaN or inf")
    m = B.shape[1]
    if Q is None:
        if n != STATE_DIM:
            raise ValueError(f"Q: no default for a {n}-dimensional state; pass Q")
        Q = DEFAULT_Q_DIAG
    Q = weight_matrix(Q, n, "Q", definite=False)
    if R is None:
        if not isinstance(model, MomentumModel):
            raise ValueError("R: no default without contact dims; pass R or a MomentumModel")
        R = contact_cost(model.dims)
    R = weight_matrix(R, m, "R", definite=True)
    A, B, Q, axes = augmented_model(A, B, Q, q_orientation, inertia, q_integral)
    n_state = A.shape[0] - (0 if axes is None else len(axes))
    n = A.shape[0]
    _check_stabilizable(A, B)
    try:
        if dt is None:
            P = scipy.linalg.solve_continuous_are(A, B, Q, R)
            K = np.linalg.solve(R, B.T @ P)
        else:
            dt = positive(dt, "dt")
            E = np.zeros((n + m, n + m))
            E[:n, :n], E[:n, n:] = A, B
            Phi = scipy.linalg.expm(E * dt)
            Ad, Bd = Phi[:n, :n], Phi[:n, n:]
            Qd, Rd = Q * dt, R * dt
            P = scipy.linalg.solve_discrete_are(Ad, Bd, Qd, Rd)
            K = np.linalg.solve(Rd + Bd.T @ P @ Bd, Bd.T @ P @ Ad)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise ValueError(f"model: the Riccati equation has no stabilising solution ({exc})") from exc
    P = 0.5 * (P + P.T)
    if axes is not None:  # [K_s, K_z] with a zero column for every axis without integral
        K_full = np.zeros((m, n_state + 3))
        K_full[:, :n_state] = K[:, :n_state]
        K_full[:, n_state + axes] = K[:, n_state:]
        K = K_full
    return (K, P) if full_output else K


# ------------------------------------------------------------------------------ gains objects
@dataclass(frozen=True)
class ContactGains:
    """LQR gains of one contact configuration (or a blend of two).

    ``K`` (n_lambda x 9) and ``lambda0`` (n_lambda) are ordered as ``contacts`` with ``dims``
    entries each. ``com0`` is the CoM the model was linearised at; ``P`` and ``poles`` (closed-loop
    eigenvalues of ``A - B K``, of the augmented system with integral action) are None for blended
    gains. ``components`` lists ``(weight, ContactGains)`` of the configurations a blend is made of
    (empty for a plain configuration). ``K_integral`` (n_lambda x 3): the gain on the CoG-error
    integral (our extension; None without integral action). ``K_orientation`` (n_lambda x 3): the
    gain on the orientation error (our extension; None without it).
    """

    contacts: tuple[str, ...]
    dims: tuple[int, ...]
    K: np.ndarray
    lambda0: np.ndarray
    com0: np.ndarray
    weight: np.ndarray | None = None  # input weight R of the configuration (nominal distribution)
    P: np.ndarray | None = None
    poles: np.ndarray | None = None
    components: tuple = field(default=(), repr=False)
    K_integral: np.ndarray | None = None
    K_orientation: np.ndarray | None = None

    @property
    def n_lambda(self) -> int:
        return int(sum(self.dims))

    def slices(self) -> dict[str, slice]:
        out, start = {}, 0
        for name, d in zip(self.contacts, self.dims):
            out[name] = slice(start, start + d)
            start += d
        return out


def _embed(g: ContactGains, contacts: tuple[str, ...], dims: tuple[int, ...], vec: np.ndarray
           ) -> np.ndarray:
    """Rows of ``vec`` (ordered as g.contacts) placed in the layout of ``contacts`` (zeros elsewhere)."""
    out = np.zeros((sum(dims),) + vec.shape[1:])
    src = g.slices()
    start = 0
    for name, d in zip(contacts, dims):
        if name in src:
            out[start:start + d] = vec[src[name]]
        start += d
    return out


def blend_gains(gains_a: ContactGains, gains_b: ContactGains, alpha: float,
                contacts: Sequence[str] | None = None) -> ContactGains:
    """Interpolate two configurations' gains for a contact transition (Sect. 3.2, Remark).

    ``K = (1 - alpha) K_a + alpha K_b`` and ``lambda0`` likewise, over the UNION of the two contact
    sets, row block by row block (contact by contact): a contact absent from a configuration
    contributes zero rows there. So the rows of a contact that is being removed (in ``a``, not in
    ``b``) fade from ``K_a``'s rows at ``alpha = 0`` to 0 at ``alpha = 1`` (its force command, and
    its share of the nominal load, go to zero), and those of a contact being added (in ``b`` only)
    grow from 0. The columns (the 9 state components) are the same for every configuration.

    The result is ordered as ``contacts`` (must be the union) or, by default, ``gains_a``'s order
    followed by the contacts new in ``gains_b``. ``alpha = 0`` gives ``gains_a`` and ``alpha = 1``
    ``gains_b`` (embedded in the union). Like the paper notes, the blend is not guaranteed to be
    stabilising; it keeps the commanded forces continuous.
    """
    if not isinstance(gains_a, ContactGains):
        raise ValueError("gains_a: expected a ContactGains (from MomentumLQR.gains)")
    if not isinstance(gains_b, ContactGains):
        raise ValueError("gains_b: expected a ContactGains (from MomentumLQR.gains)")
    try:
        alpha = float(alpha)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"alpha: expected a number in [0, 1], got {alpha!r}") from exc
    if not (0.0 <= alpha <= 1.0):
        raise ValueError(f"alpha: expected a number in [0, 1], got {alpha!r}")
    dim_of = dict(zip(gains_a.contacts, gains_a.dims))
    for name, d in zip(gains_b.contacts, gains_b.dims):
        if dim_of.setdefault(name, d) != d:
            raise ValueError(f"gains_b: contact '{name}' has dimension {d} but {dim_of[name]} in "
                             f"gains_a")
    union = gains_a.contacts + tuple(n for n in gains_b.contacts if n not in gains_a.contacts)
    if contacts is None:
        order = union
    else:
        order = tuple(contacts)
        if sorted(order) != sorted(union):
            raise ValueError(f"contacts: must be an ordering of the union {list(union)}, got "
                             f"{list(order)}")
    dims = tuple(dim_of[n] for n in order)
    K = (1.0 - alpha) * _embed(gains_a, order, dims, gains_a.K) \
        + alpha * _embed(gains_b, order, dims, gains_b.K)
    lam0 = (1.0 - alpha) * _embed(gains_a, order, dims, gains_a.lambda0) \
        + alpha * _embed(gains_b, order, dims, gains_b.lambda0)
    com0 = (1.0 - alpha) * gains_a.com0 + alpha * gains_b.com0
    extensions = {}
    for key in ("K_integral", "K_orientation"):
        parts = [(w, g) for w, g in ((1.0 - alpha, gains_a), (alpha, gains_b))
                 if getattr(g, key) is not None]
        extensions[key] = (sum(w * _embed(g, order, dims, getattr(g, key)) for w, g in parts)
                           if parts else None)
    components = tuple((w * cw, cg) for w, g in ((1.0 - alpha, gains_a), (alpha, gains_b))
                       for cw, cg in (g.components or ((1.0, g),)) if w * cw > 0.0)
    return ContactGains(order, dims, K, lam0, com0, components=components, **extensions)


# ----------------------------------------------------------------------------- the controller
class MomentumLQR:
    """Per-contact-configuration LQR gains for the momentum force task (eqs. 23-24).

    Parameters
    ----------
    robot : the :class:`~wholebody.robot.Robot` (checks contact names; gives mass and dims).
    contacts : the current contact configuration (list of contact names), used by
        :meth:`feedback` unless told otherwise.
    Q : 9x9 state weight or its diagonal (eq. 26), default ``diag(30,30,50,.5,.5,.5,.1,.1,.1)``.
    R : weight of ONE contact wrench ``[f; tau]`` (6-vector diagonal or 6x6), default
        ``diag(.1,.1,.01,2,2,2)``; point contacts use the force part. The same R weights the
        nominal force distribution ``lambda0`` (least ``lambda^T R lambda`` balancing gravity).
    dt : None for the continuous-time design (default), or the control period (discrete design).
    gravity : magnitude of g (default: from the Pinocchio model).
    q_integral : None or 0 (default, the paper's controller) or the weight (number, or 3-vector on
        x, y, z) of the CoG-error integral in the augmented LQR cost (LQI, see the module
        docstring). This integral action is our extension, not part of Herzog et al. 2016.
    integral_limit : anti-windup bound (m s), each component of the integral passed to
        :meth:`feedback` is clamped to ``+-integral_limit`` (:meth:`clamp_integral`).
    q_orientation : None or 0 (default, the paper's controller) or the weight (number, or 3-vector
        on the world axes) of the orientation error in the augmented LQR cost (see the module
        docstring; ours, not Herzog et al. 2016). ``I_G`` is the robot's centroidal inertia at the
        pose the gains are computed at.
    """

    def __init__(self, robot, contacts: Sequence[str], Q=None, R=None, dt: float | None = None,
                 gravity: float | None = None, q_integral=None,
                 integral_limit: float = DEFAULT_INTEGRAL_LIMIT, q_orientation=None):
        self.contacts = self._check_contacts(robot, contacts)
        self.Q = weight_matrix(DEFAULT_Q_DIAG if Q is None else Q, STATE_DIM, "Q", definite=False)
        self.R = weight_matrix(DEFAULT_R_DIAG if R is None else R, 6, "R", definite=True)
        self.dt = None if dt is None else positive(dt, "dt")
        if gravity is None:
            gravity = float(np.linalg.norm(robot.model.gravity.linear))
        self.gravity = positive(gravity, "gravity")
        self.q_integral = _integral_weight(q_integral)
        self.integral_limit = positive(integral_limit, "integral_limit")
        self.q_orientation = _orientation_weight(q_orientation)
        self._cache: dict[tuple[str, ...], ContactGains] = {}
        self._factors: dict[tuple, WeightFactor] = {}  # weight's (shape, bytes) -> its factors

    @property
    def integral(self) -> bool:
        """True if the gains include integral action on the CoG error (our extension)."""
        return self.q_integral is not None

    @property
    def orientation(self) -> bool:
        """True if the gains include feedback of the orientation error (our extension)."""
        return self.q_orientation is not None

    def clamp_integral(self, z) -> np.ndarray:
        """The CoG-error integral clamped elementwise to ``+-integral_limit`` (anti-windup): what
        np.clip selects, by np.maximum and np.minimum (called every cycle: without np.clip's
        Python wrapper)."""
        return self.clip_integral(vector(z, 3, "integral"))

    def clip_integral(self, z: np.ndarray) -> np.ndarray:
        """:meth:`clamp_integral` of a float 3-vector already checked (a control loop's)."""
        limit = self.integral_limit
        return np.minimum(np.maximum(z, -limit), limit)

    @staticmethod
    def _check_contacts(robot, contacts) -> tuple[str, ...]:
        if isinstance(contacts, str):
            raise ValueError(f"contacts: expected a list of contact names, got the string "
                             f"{contacts!r}")
        try:
            names = tuple(contacts)
        except TypeError as exc:
            raise ValueError(f"contacts: expected a list of contact names, got {contacts!r}") \
                from exc
        if not names:
            raise ValueError("contacts: at least one contact is needed")
        unknown = [n for n in names if n not in robot.contact_names]
        if unknown:
            raise ValueError(f"contacts: unknown contact(s) {unknown}; robot '{robot.name}' has "
                             f"{list(robot.contact_names)}")
        if len(set(names)) != len(names):
            raise ValueError(f"contacts: duplicate names in {list(names)}")
        return names

    blend = staticmethod(blend_gains)

    def clear(self) -> None:
        """Forget every cached configuration (gains are recomputed at the next request)."""
        self._cache.clear()
        self._factors.clear()

    def model(self, robot, contacts: Sequence[str] | None = None) -> MomentumModel:
        """The linearised model (eq. 21) at the robot's current pose for ``contacts``."""
        names = self.contacts if contacts is None else self._check_contacts(robot, contacts)
        dims = tuple(robot.contact(n).dim for n in names)
        X = np.array([robot.contact_point(n) for n in names])
        lam0 = balancing_forces(X, robot.com, robot.mass, dims, self.gravity,
                              weight=contact_cost(dims, self.R))
        return momentum_model(X, robot.com, robot.mass, lam0, self.gravity, dims)

    def gains(self, robot, contacts: Sequence[str] | None = None, recompute: bool = False
              ) -> ContactGains:
        """K and lambda0 for ``contacts`` (default: the current configuration).

        Computed at the robot's CURRENT pose (``robot.update`` must have been called) the first
        time a configuration is requested and cached under ``tuple(contacts)`` (order matters: it
        is the row order of K); ``recompute=True`` refreshes the entry. K only depends on the
        contact positions relative to the CoM, so it stays valid while the robot translates.
        """
        names = self.contacts if contacts is None else self._check_contacts(robot, contacts)
        if not recompute and names in self._cache:
            return self._cache[names]
        model = self.model(robot, names)
        R = contact_cost(model.dims, self.R)
        inertia = robot.centroidal_inertia() if self.orientation else None
        K, P = lqr_gains(model, self.Q, R, dt=self.dt, full_output=True,
                         q_integral=self.q_integral, q_orientation=self.q_orientation,
                         inertia=inertia)
        # continuous-time closed-loop poles (for a discrete design: of the same K in continuous
        # time), of the augmented system with the extensions
        A, B, _, axes = augmented_model(model.A, model.B, self.Q, self.q_orientation, inertia,
                                        self.q_integral)
        n_state = A.shape[0] - (0 if axes is None else len(axes))
        columns = np.r_[0:n_state] if axes is None else np.r_[0:n_state, n_state + axes]
        poles = np.linalg.eigvals(A - B @ K[:, columns])
        K_orientation = K[:, STATE_DIM:STATE_DIM + 3] if self.orientation else None
        K_integral = K[:, n_state:] if self.integral else None
        g = ContactGains(names, model.dims, K[:, :STATE_DIM], model.lambda0, model.com0.copy(),
                         weight=R, P=P, poles=poles, K_integral=K_integral,
                         K_orientation=K_orientation)
        log.debug("MomentumLQR: gains for %s, slowest closed-loop pole %.3f rad/s", list(names),
                  float(np.max(poles.real)))
        self._cache[names] = g
        return g

    def feedforward(self, robot, gains: ContactGains, com_ref, hdot_ref=None,
                    positions=None) -> np.ndarray:
        """The nominal forces of ``gains`` re-balanced at the reference CoM.

        For a plain configuration: ``argmin lambda^T R lambda`` s.t. ``G(com_ref) lambda + [m g; 0]
        = hdot_ref`` with the robot's current contact positions (``positions``: contact name ->
        world point, where the state was read elsewhere, e.g. from a compiled cycle's terms;
        default ``robot.contact_point``); for a blend, the same weighted sum of its components'
        re-balanced forces (a leaving contact keeps its fading share).
        """
        com_ref = vector(com_ref, 3, "com_ref")
        hdot_ref = np.zeros(6) if hdot_ref is None else vector(hdot_ref, 6, "hdot_ref")
        return self._rebalanced(robot, gains, com_ref, hdot_ref, positions)

    def _rebalanced(self, robot, gains: ContactGains, com_ref: np.ndarray, hdot_ref: np.ndarray,
                    positions=None) -> np.ndarray:
        """:meth:`feedforward` on checked arguments."""
        parts = gains.components or ((1.0, gains),)
        lam = np.zeros(gains.n_lambda)
        for w, g in parts:
            X = np.array([robot.contact_point(n) if positions is None else positions[n]
                          for n in g.contacts])
            weight = g.weight if g.weight is not None else contact_cost(g.dims, self.R)
            if np.isfinite(X).all():
                lam_g = balancing_forces_factored(X, com_ref, robot.mass, g.dims, self.gravity,
                                                  self._weight_factor(weight), hdot_ref)
            else:  # the checks say what is wrong
                lam_g = balancing_forces(X, com_ref, robot.mass, g.dims, self.gravity,
                                         weight=weight, hdot=hdot_ref)
            lam += w * (lam_g if g is gains else _embed(g, gains.contacts, gains.dims, lam_g))
        return lam

    def _weight_factor(self, weight) -> WeightFactor:
        """An input weight factored (checked as :func:`balancing_forces` checks it), kept by the
        weight's numbers: a configuration's weight does not change from one cycle to the next."""
        arr = np.asarray(weight, dtype=float)
        key = (arr.shape, arr.tobytes())
        factor = self._factors.get(key)
        if factor is None:
            n = arr.shape[0] if arr.ndim else 0
            factor = WeightFactor(weight_matrix(arr, n, "weight", definite=True))
            self._factors[key] = factor
        return factor

    def feedback(self, robot, com_ref, h_ref=None, *, contacts: Sequence[str] | None = None,
                 gains: ContactGains | None = None, hdot_ref=None, rebalance: bool = True,
                 integral=None, orientation=None, positions=None) -> tuple[np.ndarray, np.ndarray]:
        """``(K, k)`` of the force law eq. 23, ``lambda = -K [x_cog; h] + k``, for eq. 24.

        ``k = lambda_ff + K [com_ref; h_ref]``, i.e. ``lambda = lambda_ff - K (s - s_ref)``.
        With ``rebalance=False``, ``lambda_ff`` is the cached ``lambda0`` (gravity balanced about
        the CoM at which the gains were computed), literally ``k = lambda0 + K s_ref``. By default
        (``rebalance=True``) ``lambda_ff`` balances gravity (plus ``hdot_ref``) about ``com_ref``
        with the current contact positions (:meth:`feedforward`, ``positions`` as there), so that
        ``s_ref`` is an equilibrium of the nonlinear model (eq. 21) even when ``com_ref`` is away
        from the linearisation CoM; both coincide when ``com_ref`` is that CoM and the feet have
        not moved.

        ``gains`` (e.g. from :meth:`blend`) overrides ``contacts`` (default: the current
        configuration). Shapes ``(n_lambda, 9)`` and ``(n_lambda,)`` in the order of the gains'
        contacts, ready for ``MomentumForce(K, k, contacts=gains.contacts)``.

        The extensions' states enter ``k``: ``integral`` (the CoG-error integral, clamped) with
        ``K_integral``, ``orientation`` (the measured orientation error theta, world axes) with
        ``K_orientation``; each is an error if the gains lack its columns.
        """
        com_ref = vector(com_ref, 3, "com_ref")
        h_ref = np.zeros(6) if h_ref is None else vector(h_ref, 6, "h_ref")
        if gains is None:
            gains = self.gains(robot, contacts)
        elif not isinstance(gains, ContactGains):
            raise ValueError("gains: expected a ContactGains (from MomentumLQR.gains or blend)")
        if not rebalance and hdot_ref is not None:
            raise ValueError("hdot_ref: only used with rebalance=True")
        if hdot_ref is not None:
            hdot_ref = vector(hdot_ref, 6, "hdot_ref")
        if integral is not None:
            if gains.K_integral is None:
                raise ValueError("integral: these gains have no integral action (q_integral)")
            integral = vector(integral, 3, "integral")
        if orientation is not None:
            if gains.K_orientation is None:
                raise ValueError("orientation: these gains have no orientation feedback "
                                 "(q_orientation)")
            orientation = vector(orientation, 3, "orientation")
        return self.force_law(robot, gains, com_ref, h_ref, hdot_ref, rebalance=rebalance,
                              integral=integral, orientation=orientation, positions=positions)

    def force_law(self, robot, gains: ContactGains, com_ref: np.ndarray, h_ref: np.ndarray,
                  hdot_ref: np.ndarray | None = None, *, rebalance: bool = True,
                  integral: np.ndarray | None = None, orientation: np.ndarray | None = None,
                  positions=None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`feedback` on arguments already checked — float vectors of their sizes, finite;
        gains with the columns of the extensions given —: the same numbers without the checks,
        for a control loop whose references were checked when set."""
        if rebalance:
            lam_ff = self._rebalanced(robot, gains, com_ref,
                                      np.zeros(6) if hdot_ref is None else hdot_ref, positions)
        else:
            lam_ff = gains.lambda0
        s_ref = np.concatenate([com_ref, h_ref])
        K = gains.K.copy()
        k = lam_ff + K @ s_ref
        if integral is not None:
            k = k - gains.K_integral @ self.clip_integral(integral)
        if orientation is not None:
            k = k - gains.K_orientation @ orientation
        return K, k
