"""State conversion between Pinocchio and MuJoCo for a free-floating robot — the only place it lives.

Pinocchio: q = [p, quat (x, y, z, w), joints], v = [v_lin (LOCAL), omega (LOCAL), joint rates].
MuJoCo:    qpos = [p, quat (w, x, y, z), joints], qvel = [v_lin (WORLD), omega (LOCAL), joint rates].

So ``v_mj = T v_pin`` with ``T = diag(R, I, I)`` (R the base rotation). Generalised forces map with
``T^T``, the mass matrix as ``M_pin = T^T M_mj T``, and because ``T`` depends on the state,
``h_pin = T^T (h_mj + M_mj Tdot v_pin)`` with ``Tdot v_pin = [R (omega x v_lin); 0; 0]``.
"""

from __future__ import annotations

import math

import numpy as np


def quat_xyzw_to_wxyz(quat: np.ndarray) -> np.ndarray:
    return np.array([quat[3], quat[0], quat[1], quat[2]])


def quat_wxyz_to_xyzw(quat: np.ndarray) -> np.ndarray:
    return np.array([quat[1], quat[2], quat[3], quat[0]])


def quat_to_matrix(quat_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion given as (x, y, z, w) (normalised first)."""
    quat = np.asarray(quat_xyzw, dtype=float)
    x, y, z, w = (quat / math.sqrt(quat.dot(quat))).tolist()  # np.linalg.norm's sqrt(q . q)
    return np.array([
        1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
        2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
        2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
    ]).reshape(3, 3)


def pin_to_mj(q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) in Pinocchio convention -> (qpos, qvel) of the robot's MuJoCo joints."""
    qpos = np.array(q, dtype=float)
    qpos[3:7] = quat_xyzw_to_wxyz(q[3:7])
    qvel = np.array(v, dtype=float)
    qvel[:3] = quat_to_matrix(q[3:7]) @ v[:3]
    return qpos, qvel


def mj_to_pin(qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(qpos, qvel) of the robot's MuJoCo joints -> (q, v) in Pinocchio convention: the
    quaternion normalised (``sqrt(q . q)``), the linear velocity turned to the base frame by
    ``R(q)ᵀ`` (:func:`quat_to_matrix` of the normalised quaternion, which normalises it once
    more). In Python numbers, each sum left to right: once per simulator step, where numpy's
    per-call overhead is most of the cost."""
    q = np.array(qpos, dtype=float)
    w, x, y, z = q[3:7].tolist()
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    q[3], q[4], q[5], q[6] = x, y, z, w
    norm = math.sqrt(x * x + y * y + z * z + w * w)  # (quat_to_matrix's own normalisation)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    v = np.array(qvel, dtype=float)
    a, b, c = v[:3].tolist()
    v[0] = (1 - 2 * (y * y + z * z)) * a + 2 * (x * y + z * w) * b + 2 * (x * z - y * w) * c
    v[1] = 2 * (x * y - z * w) * a + (1 - 2 * (x * x + z * z)) * b + 2 * (y * z + x * w) * c
    v[2] = 2 * (x * z + y * w) * a + 2 * (y * z - x * w) * b + (1 - 2 * (x * x + y * y)) * c
    return q, v


def velocity_map(q: np.ndarray) -> np.ndarray:
    """T(q) with v_mj = T v_pin."""
    T = np.eye(len(q) - 1)
    T[:3, :3] = quat_to_matrix(q[3:7])
    return T


def mass_matrix_to_pin(q: np.ndarray, M_mj: np.ndarray) -> np.ndarray:
    """MuJoCo mass matrix -> Pinocchio's (T^T M_mj T)."""
    T = velocity_map(q)
    return T.T @ M_mj @ T


def bias_to_pin(q: np.ndarray, v: np.ndarray, M_mj: np.ndarray, bias_mj: np.ndarray) -> np.ndarray:
    """MuJoCo ``qfrc_bias`` -> Pinocchio nonlinear effects ``h = T^T (bias + M_mj Tdot v)``."""
    T = velocity_map(q)
    tdot_v = np.zeros(len(v))
    tdot_v[:3] = T[:3, :3] @ np.cross(v[3:6], v[:3])
    return T.T @ (bias_mj + M_mj @ tdot_v)

