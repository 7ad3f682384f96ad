"""Independent evidence for the task tests: kinematics re-evaluated from scratch with Pinocchio's
forward kinematics at states moved with ``pinocchio.integrate``, and finite differences of it.

``q(t) = integrate(q, t v)`` is the motion with constant v (zero q̈ in Pinocchio's convention), so
first differences along it give J(q) v and second differences give the drift J̇ v."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

EPS = 1e-6  # central difference step of first derivatives
EPS2 = 1e-4  # step of second derivatives along q(t)


def state_near_reference(robot, seed: int, scale: float = 0.05, velocity: float = 0.5):
    """A seeded (q, v): the reference posture moved by a small random displacement, random v."""
    rng = np.random.default_rng(seed)
    q = pin.integrate(robot.model, robot.q_ref, scale * rng.normal(size=robot.nv))
    return q, velocity * rng.normal(size=robot.nv)


def moved(robot, q, direction, t):
    return pin.integrate(robot.model, q, t * np.asarray(direction))


class BodyPoint:
    """The pose (position, rotation) of a point fixed in a frame's body, at any q."""

    def __init__(self, robot, frame_id: int, local_offset=np.zeros(3)):
        self.model, self.frame_id = robot.model, frame_id
        self.data = robot.model.createData()
        self.offset = np.asarray(local_offset, dtype=float)

    @classmethod
    def contact(cls, robot, name: str, q):
        """The body point of contact ``name`` currently at its contact point: the sole origin, or
        the point a radius below a foot sphere's centre (world z)."""
        c = robot.contact(name)
        point = cls(robot, c.frame_id)
        _, R = point.pose(q)
        radius = c.spec.radius if c.dim == 3 else 0.0
        return cls(robot, c.frame_id, R.T @ np.array([0.0, 0.0, -radius]))

    def pose(self, q):
        pin.framesForwardKinematics(self.model, self.data, q)
        oMf = self.data.oMf[self.frame_id]
        return oMf.translation + oMf.rotation @ self.offset, oMf.rotation.copy()


def twist_fd(robot, pose, q, direction, eps=EPS) -> np.ndarray:
    """[linear; angular] (world axes) velocity of ``pose`` along q(t) = integrate(q, t direction)."""
    p1, R1 = pose(moved(robot, q, direction, eps))
    p0, R0 = pose(moved(robot, q, direction, -eps))
    return np.concatenate([(p1 - p0) / (2 * eps), pin.log3(R1 @ R0.T) / (2 * eps)])


def jacobian_fd(robot, pose, q) -> np.ndarray:
    """6 x nv Jacobian [linear; angular] (world axes) of ``pose``, one column per v direction."""
    return np.column_stack([twist_fd(robot, pose, q, e) for e in np.eye(robot.nv)])


def drift_fd(robot, pose, q, v, h=EPS2) -> np.ndarray:
    """[linear; angular] acceleration of ``pose`` along q(t) = integrate(q, t v) (J̇ v): second
    differences of the position, first differences of the angular velocity."""
    p = [pose(moved(robot, q, v, k * h))[0] for k in (-1, 0, 1)]
    linear = (p[2] - 2 * p[1] + p[0]) / h ** 2
    omega = [twist_fd(robot, pose, moved(robot, q, v, s * h), v, h)[3:] for s in (-1, 1)]
    return np.concatenate([linear, (omega[1] - omega[0]) / (2 * h)])


def com_fd(robot):
    """q -> CoM position, from a fresh forward-kinematics pass."""
    data = robot.model.createData()
    return lambda q: pin.centerOfMass(robot.model, data, q).copy()


def centroidal_momentum(robot):
    """(q, v) -> h_G = [linear; angular momentum about the CoM] from the RNEA-style
    computeCentroidalMomentum (not the CCRBA that builds A_G)."""
    data = robot.model.createData()
    return lambda q, v: pin.computeCentroidalMomentum(robot.model, data, q, v).vector.copy()


def contact_jacobians_fd(robot, q, names) -> np.ndarray:
    """Stacked contact Jacobians by finite differences: 6 rows per sole, 3 per point foot."""
    blocks = []
    for n in names:
        J = jacobian_fd(robot, BodyPoint.contact(robot, n, q).pose, q)
        blocks.append(J if robot.contact(n).dim == 6 else J[:3])
    return np.vstack(blocks)


def forward_dynamics(robot, q, v, tau, J, lam) -> np.ndarray:
    """q̈ of M q̈ + h = Sᵀ τ + Jᵀ λ with Pinocchio's ABA (no mass matrix of the robot's cache)."""
    data = robot.model.createData()
    return pin.aba(robot.model, data, q, v, np.concatenate([np.zeros(6), tau]) + J.T @ lam)


def row_residual(rows, qdd=None, lam=None, tau=None) -> np.ndarray:
    """A y - target of equality rows (a None block or value counts as zero)."""
    out = -np.asarray(rows.target, dtype=float)
    for block, value in ((rows.qdd, qdd), (rows.lam, lam), (rows.tau, tau)):
        if block is not None and value is not None:
            out = out + block @ value
    return out


def row_values(rows, qdd=None, lam=None, tau=None) -> np.ndarray:
    """A y of inequality rows."""
    out = np.zeros(rows.m)
    for block, value in ((rows.qdd, qdd), (rows.lam, lam), (rows.tau, tau)):
        if block is not None and value is not None:
            out = out + block @ value
    return out


def satisfies(rows, tol=1e-9, **y) -> bool:
    """l <= A y <= u within ``tol``."""
    value = row_values(rows, **y)
    return bool(np.all(value >= rows.lower - tol) and np.all(value <= rows.upper + tol))
