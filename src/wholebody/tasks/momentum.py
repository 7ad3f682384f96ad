"""Centroidal momentum tasks (Herzog et al. 2016 Sect. 3)."""

from __future__ import annotations

import numpy as np

from . import schema
from .base import Task, TaskRows, check_gain, checked_attribute, contact_list, contact_subset


def skew(x: np.ndarray) -> np.ndarray:
    """[x]x: the matrix with skew(x) @ y = x × y."""
    return np.array([[0.0, -x[2], x[1]], [x[2], 0.0, -x[0]], [-x[1], x[0], 0.0]])


def centroidal_map(contact_positions, com: np.ndarray, dims) -> np.ndarray:
    """The matrix of eq. 21 mapping stacked contact forces/wrenches to the momentum rate about the
    CoM: block [I 0; [x_i - x_cog]x I] per 6D contact, [I; [x_i - x_cog]x] per point contact."""
    blocks = []
    for x_i, d in zip(contact_positions, dims):
        r = np.asarray(x_i, dtype=float) - com
        block = np.zeros((6, d))
        block[:3, :3] = np.eye(3)
        block[3, 1], block[3, 2] = -r[2], r[1]
        block[4, 0], block[4, 2] = r[2], -r[0]
        block[5, 0], block[5, 1] = -r[1], r[0]
        if d == 6:
            block[3:, 3:] = np.eye(3)
        blocks.append(block)
    return np.hstack(blocks) if blocks else np.zeros((6, 0))


def momentum_map(robot, contacts) -> np.ndarray:
    """:func:`centroidal_map` at the robot's cached contact positions and CoM."""
    positions = [robot.contact_point(n) for n in contacts]  # where the forces act
    return centroidal_map(positions, robot.com, [robot.contact(n).dim for n in contacts])


def momentum_gain(value, field, obj=None) -> np.ndarray:
    """A 6x6 gain of eq. 22 (or its diagonal, 6 numbers >= 0): finite, with a positive
    semi-definite symmetric part (a scalar would be ambiguous: use a diagonal)."""
    if np.ndim(value) == 0:
        raise ValueError(f"{field}: expected a 6x6 matrix or its diagonal (6 numbers >= 0), got "
                         f"{value!r}")
    out = check_gain(value, field, size=6)
    return np.diag(out) if out.ndim == 1 else out


#: eq. 22's default gains: P on m (x_ref - x_cog) (1/s^2, omega^2 of the CoG), D on the linear and
#: on the angular momentum error (1/s)
MOMENTUM_P, MOMENTUM_D_LINEAR, MOMENTUM_D_ANGULAR = 50.0, 15.0, 5.0


class MomentumPD(Task):
    """Eq. 22: A_G qdd + Adot_G v = P [m (x_ref - x_cog); 0] + D (h_ref - h) + hdot_ref.

    ``P``, ``D``: 6x6 gains (a 6-vector is taken as the diagonal), finite with a positive
    semi-definite symmetric part, checked on every assignment."""

    P = checked_attribute(momentum_gain, "6x6 gain on [m (x_ref - x_cog); 0].")
    D = checked_attribute(momentum_gain, "6x6 gain on h_ref - h.")

    kernel = "momentum_pd"
    params = (schema.matrix("P", 36), schema.matrix("D", 36),
              schema.vector("com_ref", 3, get=lambda t, layout, state: t.held_com_ref(state)),
              schema.vector("h_ref", 6), schema.vector("hdot_ref", 6))

    def row_count(self, layout):
        return 6

    def held_com_ref(self, state) -> np.ndarray:
        """``com_ref``, set to ``state.com`` if not set yet (hold the CoM first seen)."""
        if self.com_ref is None:
            self.com_ref = np.array(state.com, dtype=float)
        return self.com_ref

    def __init__(self, P=None, D=None, name=None, weight=1.0):
        super().__init__(name, weight)
        self.P = np.diag([MOMENTUM_P] * 3 + [0.0] * 3) if P is None else P
        self.D = (np.diag([MOMENTUM_D_LINEAR] * 3 + [MOMENTUM_D_ANGULAR] * 3) if D is None
                  else D)
        self.com_ref: np.ndarray | None = None  # None: hold the CoM first seen
        self.h_ref = np.zeros(6)
        self.hdot_ref = np.zeros(6)

    def desired_rate(self, robot) -> np.ndarray:
        self.held_com_ref(robot)
        e = np.concatenate([robot.mass * (self.com_ref - robot.com), np.zeros(3)])
        return self.P @ e + self.D @ (self.h_ref - robot.h_G) + self.hdot_ref

    def rows(self, robot, variables):
        return TaskRows(qdd=robot.A_G, lam=None, tau=None,
                        target=self.desired_rate(robot) - robot.A_G_dot_v)


class MomentumForce(Task):
    """Eq. 24: G (lambda + K [x_cog; h] - k) = 0 — the LQR force law of eq. 23 projected into
    momentum space, leaving the internal forces free. ``K`` (n_lambda x 9) and ``k`` (n_lambda)
    come from :mod:`wholebody.control.lqr`; they must match the active contacts' order (checked
    in :meth:`rows`; a NaN ends at the formulation's boundary check). ``contacts``: None = all
    active contacts, an empty list = none."""

    contacts = checked_attribute(contact_list, "None (all active contacts) or contact names.")
    per_contact = True
    kernel = "momentum_force"
    params = (schema.matrix("K", 9, "contact_dim", get=lambda t, layout, state: t.gains(layout)[0]),
              schema.vector("k", 1, "contact_dim", get=lambda t, layout, state: t.gains(layout)[1]))

    def row_count(self, layout):
        return 6

    def gains(self, layout) -> tuple[np.ndarray, np.ndarray]:
        """(K, k), checked against the layout's contacts."""
        n = layout.count("contact_dim")
        if self.K is None or self.k is None:
            raise ValueError(f"{self.name}: gains K and k are not set")
        if self.K.shape != (n, 9) or self.k.shape != (n,):
            raise ValueError(f"{self.name}: K must be ({n}, 9) and k ({n},) for contacts "
                             f"{list(layout.contacts)}; got {self.K.shape} and {self.k.shape}")
        return self.K, self.k

    def __init__(self, K=None, k=None, name=None, weight=1.0, contacts=None):
        super().__init__(name, weight)
        self.K = None if K is None else np.asarray(K, dtype=float)
        self.k = None if k is None else np.asarray(k, dtype=float)
        self.contacts = contacts

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        if self.K is None or self.k is None:
            raise ValueError(f"{self.name}: gains K and k are not set")
        G = momentum_map(robot, names)
        if self.K.shape != (G.shape[1], 9) or self.k.shape != (G.shape[1],):
            raise ValueError(f"{self.name}: K must be ({G.shape[1]}, 9) and k ({G.shape[1]},) for "
                             f"contacts {list(names)}; got {self.K.shape} and {self.k.shape}")
        state = np.concatenate([robot.com, robot.h_G])
        lam_cols = np.zeros((6, variables.n_lambda))
        for n, start in zip(names, np.cumsum([0] + [robot.contact(n).dim for n in names])):
            sl = variables.lambda_slices[n]
            lam_cols[:, sl] = G[:, start:start + robot.contact(n).dim]
        return TaskRows(qdd=None, lam=lam_cols, tau=None, target=G @ (self.k - self.K @ state))
