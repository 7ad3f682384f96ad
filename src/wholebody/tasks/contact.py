"""Contact constraints and contact-force conditions (Herzog et al. 2016 Sect. 2.1; Fahmi et al. 2019
Sect. II-C)."""

from __future__ import annotations

import functools

import numpy as np

from .base import (Task, TaskRows, checked_attribute, contact_list, contact_subset, flag,
                   gain_rule, normal_map, scalar_rule)
from . import schema

WORLD_UP = np.array([0.0, 0.0, 1.0])


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (np.cross is much slower on tiny arrays)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def tangent_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit normal and two unit tangents (t1, t2, n right-handed) for a surface normal (new
    arrays; the bases of the last normals met are kept, a control loop meets the same few)."""
    return tuple(a.copy() for a in _tangent_basis(*_key(normal)))


def _key(normal) -> tuple[bytes, tuple]:
    """A normal as a cache key: its float64 bytes (exact, -0.0 apart from 0.0) and shape."""
    n = np.asarray(normal, dtype=float)
    return n.tobytes(), n.shape


@functools.lru_cache(maxsize=256)
def _tangent_basis(data: bytes, shape: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = np.frombuffer(data).reshape(shape)
    n = n / np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = cross3(helper, n)
    t1 /= np.linalg.norm(t1)
    return t1, cross3(n, t1), n


def lean_rows(tangents: np.ndarray, normals: np.ndarray, lean: np.ndarray, mu: float = np.inf
              ) -> np.ndarray:
    """:func:`tangent_rows` for a stack of bases: ``tangents`` (s, 2, 3) and ``normals`` (s, 3)
    of :func:`tangent_basis` → (s, 2, 3)."""
    pressing = normals @ lean
    presses = pressing > 0.0
    ratio = tangents @ lean / np.where(presses, pressing, 1.0)[:, None]
    ratio[~presses] = 0.0
    size = np.hypot(ratio[:, 0], ratio[:, 1])
    ratio *= np.minimum(1.0, mu / np.maximum(size, 1e-300))[:, None]  # at most mu
    return tangents - ratio[:, :, None] * normals[:, None, :]


def tangent_rows(normal: np.ndarray, lean: np.ndarray | None = None, mu: float = np.inf) -> np.ndarray:
    """The 2 x 3 rows R with R f = 0 <=> f leans like ``lean`` about ``normal``: rows t_k − r_k n,
    r_k = (t_k·lean)/(n·lean) the lean's tangential-to-normal ratios, scaled down to a ratio of
    at most ``mu`` (a lean outside the cone cannot be met). ``lean`` None, or not pressing into
    the surface: r = 0, the rows [t1; t2] (the force's tangential part)."""
    t1, t2, n = tangent_basis(normal)
    rows = np.array([t1, t2])
    if lean is None:
        return rows
    return lean_rows(rows[None], n[None], np.asarray(lean, dtype=float), mu)[0]


def _rotation_map(block_of) -> np.ndarray:
    """K with ``block_of(R).ravel() == K @ R.ravel()`` for rows that are linear in a rotation R
    (a sole's measured axes): built once from the nine unit matrices, so that a control cycle
    fills the rows with one small product instead of rebuilding them."""
    return np.column_stack([block_of(np.eye(9)[j].reshape(3, 3)).ravel() for j in range(9)])


def friction_faces(normal: np.ndarray, mu: float) -> np.ndarray:
    """The 4 x 3 rows F with F f <= 0 <=> f in the friction pyramid about ``normal`` (a new
    array; kept for the last normals and mu met, as :func:`tangent_basis`)."""
    return _friction_faces(*_key(normal), np.float64(mu).tobytes()).copy()


@functools.lru_cache(maxsize=256)
def _friction_faces(data: bytes, shape: tuple, mu: bytes) -> np.ndarray:
    t1, t2, n = _tangent_basis(data, shape)
    mu = np.frombuffer(mu)[0]
    return np.array([t1 - mu * n, -t1 - mu * n, t2 - mu * n, -t2 - mu * n])


@functools.lru_cache(maxsize=None)
def _world_up(count: int) -> np.ndarray:
    """``count`` world-up normals stacked (read-only, shared)."""
    up = np.tile(WORLD_UP, count)
    up.flags.writeable = False
    return up


class _PerContact(Task):
    """A task with one block of rows per selected contact, placed in the lambda columns.

    ``contacts``: None = all active contacts; an empty list = none (the task has no rows).
    ``normals``: contact name -> surface normal (finite, non-zero; default world up)."""

    contacts = checked_attribute(contact_list, "None (all active contacts) or contact names.")
    normals = checked_attribute(normal_map, "contact name -> non-zero surface normal.")
    per_contact = True

    def __init__(self, name=None, weight=1.0, contacts=None, normals=None):
        super().__init__(name, weight)
        self.contacts = contacts
        self.normals = normals

    def normal(self, contact: str) -> np.ndarray:
        return np.asarray(self.normals.get(contact, WORLD_UP), dtype=float)

    def stacked_normals(self, layout, state=None) -> np.ndarray:
        """The normals of the layout's contacts, stacked (the compiled kernels' parameter,
        :attr:`NORMALS`)."""
        normals = self.normals
        if not normals:
            return _world_up(len(layout.contacts))
        # the stored normals are float arrays (normal_map); one read each, no conversion
        return (np.concatenate([normals.get(n, WORLD_UP) for n in layout.contacts])
                if layout.contacts else ())

    #: the kernels' ``normals`` parameter: read from :attr:`normals` by the compiled packer,
    #: :meth:`stacked_normals` its reference
    NORMALS = schema.vector("normals", 3, "contact", get=stacked_normals, mapping="normals",
                            default=tuple(WORLD_UP))

    def _lambda_rows(self, variables, blocks: dict[str, np.ndarray]) -> np.ndarray:
        """Stack per-contact (rows x dim) blocks into (rows x n_lambda)."""
        m = sum(b.shape[0] for b in blocks.values())
        out = np.zeros((m, variables.n_lambda))
        r = 0
        for name, block in blocks.items():
            sl = variables.lambda_slices[name]
            out[r:r + block.shape[0], sl] = block
            r += block.shape[0]
        return out


def independent_rows(J: np.ndarray, target: np.ndarray, tolerance: float
                     ) -> tuple[np.ndarray, np.ndarray, int]:
    """Equality rows J x = target whose rows may be linearly dependent, replaced by an
    independent set: U_rᵀ J x = U_rᵀ target (J = U Σ Vᵀ, U_r the left singular vectors of the
    singular values above ``tolerance`` σ_max, each signed so that its entry of largest magnitude
    is positive), the remaining rows zero. The least-squares part of ``target`` is kept, the part
    no x can meet dropped, so that the rows stay consistent. → (rows, targets, how many rows
    are kept: the rank), new arrays; rows with a NaN or inf entry are returned as they are (all
    kept), for the cycle's row checks to name the task."""
    if not (np.isfinite(J).all() and np.isfinite(target).all()) or not J.size:
        return J.copy(), target.copy(), J.shape[0]
    U, singular, _ = np.linalg.svd(J)
    rank = int((singular > tolerance * singular[0]).sum())
    U = U[:, :rank]
    if rank:
        U = U * np.sign(U[np.abs(U).argmax(axis=0), np.arange(rank)])
    rows, targets = np.zeros_like(J), np.zeros_like(target)
    rows[:rank], targets[:rank] = U.T @ J, U.T @ target
    return rows, targets, rank


class ContactConstraint(_PerContact):
    """Active contacts do not move: J_c qdd + Jdot_c v = 0 (Herzog et al. 2016, eq. 2).

    With ``kp``/``kd`` > 0 it becomes Fahmi et al. 2019's stance task (eq. 32): the contact
    acceleration tracks kp (x_anchor - x) - kd v, holding each foot at its touchdown position
    ``anchors[name]`` (set on first use) so that slipping feet are pulled back. ``kp``, ``kd``:
    finite numbers >= 0 (one gain for all contacts), checked on assignment.

    ``rank_tolerance`` > 0 (default 0: the rows as they are) replaces the rows by an independent
    set every cycle (:func:`independent_rows`, singular values below ``rank_tolerance`` σ_max
    count as zero): for contacts whose rows are linearly dependent, such as the point feet of legs
    of two joints, whose targets are then generally inconsistent as hard equalities; the contacts
    then meet the least-squares part of their targets.
    """

    kp = checked_attribute(gain_rule(scalar_only=True), "Anchor stiffness (1/s^2), >= 0.")
    kd = checked_attribute(gain_rule(scalar_only=True), "Contact-velocity damping (1/s), >= 0.")
    rank_tolerance = checked_attribute(scalar_rule(low=0.0, high=1.0),
                                       "Singular values below this share of the largest count as "
                                       "zero (0: the rows as they are).")

    kernel = "contact_constraint"
    params = (schema.scalar("kp"), schema.scalar("kd"),
              schema.vector("anchors", 3, "contact", mapping="anchors",
                            get=lambda t, layout, state: t.stacked_anchors(layout, state)),
              schema.scalar("rank_tolerance"))

    def __init__(self, name=None, weight=1.0, contacts=None, kp: float = 0.0, kd: float = 0.0,
                 rank_tolerance: float = 0.0):
        super().__init__(name, weight, contacts)
        self.kp, self.kd = kp, kd
        self.rank_tolerance = rank_tolerance
        self.anchors: dict[str, np.ndarray] = {}

    def row_count(self, layout):
        return layout.count("contact_dim")

    def stacked_anchors(self, layout, state) -> np.ndarray | float:
        """The anchors of the layout's contacts, each held where ``state`` first saw its frame
        — only while the anchor gains are on, as :meth:`rows`; with the gains off (the kernel
        reads no anchor) the anchors held already, or zero."""
        anchors = self.anchors
        missing = [n for n in layout.contacts if n not in anchors]
        if missing and not (self.kp or self.kd):
            return 0.0
        for n in missing:
            anchors[n] = state.contact_frame_position(n)
        return np.concatenate([anchors[n] for n in layout.contacts]) if layout.contacts else ()

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        J = robot.stacked_contact_jacobian(names)
        target = -robot.stacked_contact_drift(names)
        if self.kp or self.kd:
            r = 0
            for n in names:
                c = robot.contact(n)
                pos = robot.data.oMf[c.frame_id].translation
                anchor = self.anchors.setdefault(n, pos.copy())
                vel = robot.contact_jacobians[n] @ robot.v
                target[r:r + 3] += self.kp * (anchor - pos) - self.kd * vel[:3]
                if c.dim == 6:
                    target[r + 3:r + 6] -= self.kd * vel[3:]
                r += c.dim
        if self.rank_tolerance:
            J, target, _ = independent_rows(J, target, self.rank_tolerance)
        return TaskRows(qdd=J, lam=None, tau=None, target=target)


class FrictionCone(_PerContact):
    """Linearised friction cone: |f.t1| <= mu f.n and |f.t2| <= mu f.n, 4 rows per contact
    (Herzog et al. 2016 Sect. 2.1; Fahmi et al. 2019 eqs. 13-14), about each contact's normal.

    ``torsion=True`` adds, for rectangle contacts (6D wrenches), the yaw-moment facets of the
    rectangle's contact wrench cone (Caron, Pham, Nakamura 2015, "Stability of surface contacts
    for humanoid robots"): with the wrench in the sole's measured axes (x along the
    half-size X, y along Y, z the sole normal),

        tau_z <=  mu (X + Y) f_z - |Y f_x + mu tau_x| - |X f_y + mu tau_y|
        tau_z >= -mu (X + Y) f_z + |Y f_x - mu tau_x| + |X f_y - mu tau_y|,

    8 rows per sole (:meth:`wrench_cone_block`). Together with the pyramid and the centre of
    pressure rows (:class:`CenterOfPressure`) they are exactly the wrenches that friction
    pyramids at the sole's four corners can produce (tests/unit/tasks/test_contact.py checks
    this against a linear program over the corner forces) when the pyramid's tangents are the
    sole's axes. A bound on the yaw moment alone (the friction moment of the inscribed disc)
    still admits a tangential force at its limit with the CoP in a corner and a yaw moment at its
    limit, which no sole carries: the corner's friction then fixes the yaw moment. Off by default
    on this task (the papers' 4 rows per contact); the builders of Tables 1/2/4
    (:mod:`wholebody.control.stacks`) turn it on unless given ``torsion=False``.

    ``mu`` (finite, > 0) and ``torsion`` (a bool) are checked on every assignment: a negative mu
    would turn the pyramid inside out (only zero forces satisfy it).
    """

    kind = "ineq"
    mu = checked_attribute(scalar_rule(low=0.0, low_open=True), "Friction coefficient, > 0.")
    torsion = checked_attribute(flag, "Add the rectangle contacts' yaw-moment rows (6D contacts).")

    kernel = "friction_cone"
    params = (schema.scalar("mu"),
              _PerContact.NORMALS)

    def selection(self, robot):
        return {"torsion": [int(self.torsion)]}

    def layout_key(self):
        return (self.torsion,)

    def row_count(self, layout):
        rect = sum(layout.robot.contact(n).dim == 6 for n in layout.contacts)
        return 4 * len(layout.contacts) + (8 * rect if self.torsion else 0)

    def __init__(self, mu: float, name=None, weight=1.0, contacts=None, normals=None,
                 torsion: bool = False):
        super().__init__(name, weight, contacts, normals)
        self.mu = mu
        self.torsion = torsion
        self._cache_key = None
        self._cache: TaskRows | None = None
        self._maps: list = []

    @staticmethod
    def wrench_cone_block(R: np.ndarray, hx: float, hy: float, mu: float) -> np.ndarray:
        """The 8 x 6 yaw-moment rows (``rows @ [f; tau] <= 0``) of the contact wrench cone of a
        hx x hy half-size sole with axes R (columns, in world) (Caron et al. 2015)."""
        ex, ey, ez = R[:, 0], R[:, 1], R[:, 2]
        rows = np.zeros((8, 6))
        k = 0
        for sx in (1.0, -1.0):
            for sy in (1.0, -1.0):
                force = -mu * (hx + hy) * ez + sx * hy * ex + sy * hx * ey
                moment = ez + mu * (sx * ex + sy * ey)
                rows[k, :3], rows[k, 3:] = force, moment  # upper bound of tau_z
                rows[k + 1, :3], rows[k + 1, 3:] = force, -moment  # lower bound of tau_z
                k += 2
        return rows

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        key = (names, tuple(variables.lambda_slices[n].start for n in names), variables.n_lambda,
               self.mu, self.torsion, tuple(tuple(self.normal(n)) for n in names))
        if self._cache_key != key:  # the pyramid only changes with mu, normals or the contacts
            blocks, self._maps, r = {}, [], 0
            for n in names:
                c = robot.contact(n)
                twist = self.torsion and c.spec.dim == 6
                block = np.zeros((12 if twist else 4, c.spec.dim))
                block[:4, :3] = friction_faces(self.normal(n), self.mu)
                if twist:  # the cone rows are linear in the sole rotation R
                    hx, hy = c.spec.half_size
                    K = _rotation_map(lambda R: self.wrench_cone_block(R, hx, hy, self.mu))
                    self._maps.append((c.frame_id, r + 4, variables.lambda_slices[n].start, K))
                blocks[n] = block
                r += block.shape[0]
            A = self._lambda_rows(variables, blocks)
            self._cache = TaskRows(qdd=None, lam=A, tau=None, lower=np.full(A.shape[0], -np.inf),
                                   upper=np.zeros(A.shape[0]))
            self._cache_key = key
        if self._maps:  # the sole axes are measured: the cone rows change every cycle
            A = self._cache.lam.copy()
            oMf = robot.data.oMf
            for frame_id, r, f, K in self._maps:
                A[r:r + 8, f:f + 6] = (K @ oMf[frame_id].rotation.ravel()).reshape(8, 6)
            return TaskRows(qdd=None, lam=A, tau=None, lower=self._cache.lower,
                            upper=self._cache.upper)
        return self._cache


def _f_min_rule(value, field, obj):
    f_min = scalar_rule(low=0.0)(value, field)
    f_max = getattr(obj, "f_max", None)
    if f_max is not None and not f_min < f_max:
        raise ValueError(f"{field}: must be < f_max = {f_max!r} (when raising both bounds, set "
                         f"f_max first), got {value!r}")
    return f_min


def _f_max_rule(value, field, obj):
    f_max = scalar_rule(low=0.0, low_open=True, allow_inf=True)(value, field)
    f_min = getattr(obj, "f_min", None)
    if f_min is not None and not f_max > f_min:
        raise ValueError(f"{field}: must be > f_min = {f_min!r} (when lowering both bounds, set "
                         f"f_min first), got {value!r}")
    return f_max


class NormalForceBounds(_PerContact):
    """f_min <= f.n <= f_max per contact (unilaterality and loading limits; Fahmi et al. 2019 eq. 14).

    0 <= f_min < f_max (f_max may be inf), checked on every assignment against the other bound."""

    kind = "ineq"
    f_min = checked_attribute(_f_min_rule, "Least normal force (N), finite, 0 <= f_min < f_max.")
    f_max = checked_attribute(_f_max_rule, "Largest normal force (N), > f_min, may be inf.")

    kernel = "normal_force_bounds"
    params = (schema.scalar("f_min"), schema.scalar("f_max"),
              _PerContact.NORMALS)

    def row_count(self, layout):
        return len(layout.contacts)

    def __init__(self, f_min: float = 0.0, f_max: float = np.inf, name=None, weight=1.0,
                 contacts=None, normals=None):
        super().__init__(name, weight, contacts, normals)
        self.f_max = f_max
        self.f_min = f_min

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        blocks = {}
        for n in names:
            block = np.zeros((1, robot.contact(n).dim))
            block[0, :3] = tangent_basis(self.normal(n))[2]
            blocks[n] = block
        A = self._lambda_rows(variables, blocks)
        return TaskRows(qdd=None, lam=A, tau=None, lower=np.full(len(names), self.f_min),
                        upper=np.full(len(names), self.f_max))


class CenterOfPressure(_PerContact):
    """The centre of pressure of each rectangular contact stays in its sole (Herzog et al. 2016
    Sect. 2.1): with the wrench [f; tau] about the sole frame expressed in sole axes,
    |tau_y| <= hx f_z and |tau_x| <= hy f_z — 4 linear rows per sole. ``margin`` shrinks the sole
    (0.1 = 10 % smaller half-lengths), 0 <= margin < 1, checked on every assignment (a negative
    margin would admit CoPs outside the sole, one >= 1 none or the mirrored sole)."""

    kind = "ineq"
    margin = checked_attribute(scalar_rule(low=0.0, high=1.0, high_open=True),
                               "Relative shrinking of the sole, in [0, 1).")

    kernel = "center_of_pressure"
    params = (schema.scalar("margin"),)

    def row_count(self, layout):
        return 4 * sum(layout.robot.contact(n).dim == 6 for n in layout.contacts)

    def __init__(self, name=None, weight=1.0, contacts=None, margin: float = 0.0):
        super().__init__(name, weight, contacts)
        self.margin = margin
        self._key = None
        self._maps: list = []

    @staticmethod
    def block(R: np.ndarray, hx: float, hy: float) -> np.ndarray:
        """The 4 x 6 rows over one wrench [f; tau] for a sole with axes R (columns, in world)."""
        rows = np.zeros((4, 6))
        rows[0, :3] = rows[1, :3] = -hx * R[:, 2]  # -hx f_z
        rows[2, :3] = rows[3, :3] = -hy * R[:, 2]  # -hy f_z
        rows[0, 3:], rows[1, 3:] = -R[:, 1], R[:, 1]  # -/+ tau_y
        rows[2, 3:], rows[3, 3:] = R[:, 0], -R[:, 0]  # +/- tau_x
        return rows

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        key = (names, variables.n_lambda, self.margin)
        if self._key != key:
            # the rows are linear in the sole rotation R: block = K vec(R) (_rotation_map)
            self._maps = []
            for n in names:
                c = robot.contact(n)
                if c.spec.type != "rectangle":
                    continue
                hx, hy = (1.0 - self.margin) * np.asarray(c.spec.half_size)
                K = _rotation_map(lambda R: self.block(R, hx, hy))
                self._maps.append((c.frame_id, variables.lambda_slices[n].start, K))
            self._key = key
        A = np.zeros((4 * len(self._maps), variables.n_lambda))
        oMf = robot.data.oMf
        for i, (frame_id, f, K) in enumerate(self._maps):
            A[4 * i:4 * i + 4, f:f + 6] = (K @ oMf[frame_id].rotation.ravel()).reshape(4, 6)
        return TaskRows(qdd=None, lam=A, tau=None, lower=np.full(A.shape[0], -np.inf),
                        upper=np.zeros(A.shape[0]))


class ForceRegularizer(_PerContact):
    """lambda_i ≈ target_i (default zero): regularises contact forces, or unloads a contact before
    it is removed (Herzog et al. 2016 Sect. 5.4)."""

    kernel = "force_regularizer"
    params = (schema.vector("targets", 1, "contact_dim",
                            get=lambda t, layout, state: t.stacked_targets(layout)),)

    def row_count(self, layout):
        return layout.count("contact_dim")

    def stacked_targets(self, layout) -> np.ndarray | float:
        """The targets of the layout's contacts, stacked (zero where none)."""
        if not self.targets:
            return 0.0
        return np.concatenate([np.broadcast_to(self.targets.get(n, 0.0), layout.robot.contact(n).dim)
                               for n in layout.contacts])

    def __init__(self, name=None, weight=1.0, contacts=None, targets=None):
        super().__init__(name, weight, contacts)
        self.targets = dict(targets or {})  # contact name -> target force/wrench
        self._key = None
        self._A: np.ndarray | None = None

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        key = (names, tuple(variables.lambda_slices[n].start for n in names), variables.n_lambda)
        if self._key != key:  # the selection only changes with the contact set
            self._scale = {n: self.row_scale(robot.contact(n).spec) for n in names}
            self._A = self._lambda_rows(variables, {n: np.diag(self._scale[n]) for n in names})
            self._key = key
        dims = [robot.contact(n).dim for n in names]
        target = np.zeros(sum(dims))
        start = 0
        for n, d in zip(names, dims):
            if n in self.targets:
                target[start:start + d] = self._scale[n] * self.targets[n]
            start += d
        return TaskRows(qdd=None, lam=self._A, tau=None, target=target)

    @staticmethod
    def row_scale(spec) -> np.ndarray:
        """Per-component row scale: 1 for forces, 1 / (largest sole half-size) for sole moments,
        so that a moment putting the CoP at the sole's edge costs as much as the normal force
        (in N and Nm alike the regulariser finds moments ~10x cheaper than shifting force
        between the feet, and its exact minimiser pushes the CoPs to the sole edges)."""
        if spec.type != "rectangle":
            return np.ones(3)
        return np.r_[np.ones(3), np.full(3, 1.0 / max(spec.half_size))]
