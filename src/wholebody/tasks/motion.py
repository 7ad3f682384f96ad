"""Motion tasks: desired closed-loop accelerations J qdd + Jdot v = a_ref (Herzog et al. 2016 Sect. 2.1,
"Motion and force control tasks"; Fahmi et al. 2019 eqs. 6, 11-12 for the swing foot)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ..robot import FREE_FLYER_NQ, FREE_FLYER_NV
from . import schema
from .base import (Task, TaskRows, check_gain, checked_attribute, choice_rule, gain_rule,
                   pd_acceleration)

AXES = {"x": 0, "y": 1, "z": 2}


_GAINS_DOC = ("PD gain: finite >= 0, a number, one per row, or a matrix (positive semi-definite "
              "symmetric part).")


class CoMTask(Task):
    """CoM PD: J_com qdd + Jdot_com v = a_d + Kp (x_d - x) + Kd (v_d - v). ``axes`` selects rows
    (a non-empty selection of "x", "y", "z"). ``kp``, ``kd``: a number, 3 numbers or a 3x3 matrix,
    finite and >= 0, checked on every assignment."""

    kp = checked_attribute(gain_rule(size=3), _GAINS_DOC)
    kd = checked_attribute(gain_rule(size=3), _GAINS_DOC)

    kernel = "com"
    params = (schema.vector("position", 3, get=lambda t, layout, state: t.held_position(state)),
              schema.vector("velocity", 3), schema.vector("acceleration", 3),
              schema.diagonal("kp", 3), schema.diagonal("kd", 3))

    def selection(self, robot):
        return {"rows": list(self.rows_idx)}

    def layout_key(self):
        return tuple(self.rows_idx)

    def row_count(self, layout):
        return len(self.rows_idx)

    def held_position(self, state) -> np.ndarray:
        """``position``, set to ``state.com`` if not set yet (hold the CoM first seen)."""
        if self.position is None:
            self.position = np.array(state.com, dtype=float)
        return self.position

    def __init__(self, kp=100.0, kd=20.0, name=None, weight=1.0, axes: str = "xyz"):
        super().__init__(name, weight)
        self.kp, self.kd = kp, kd
        if (not isinstance(axes, str) or not axes or any(a not in AXES for a in axes)
                or len(set(axes)) != len(axes)):
            raise ValueError(f"axes: expected a selection of 'x', 'y', 'z' (e.g. 'xyz'), got "
                             f"{axes!r}")
        self.rows_idx = [AXES[a] for a in axes]
        self.position: np.ndarray | None = None  # None: hold the CoM where it was first seen
        self.velocity = np.zeros(3)
        self.acceleration = np.zeros(3)

    def rows(self, robot, variables):
        self.held_position(robot)
        a = pd_acceleration(self.kp, self.kd, self.position - robot.com,
                            self.velocity - robot.vcom, self.acceleration)
        i = self.rows_idx
        return TaskRows(qdd=robot.J_com[i], lam=None, tau=None, target=(a - robot.com_drift)[i])


class FrameTask(Task):
    """PD on a frame's position and/or orientation (world axes), e.g. a swing foot.

    Orientation error: log3(R_d R^T) (world axes). ``mask`` is "6d", "position" or "orientation".
    ``kp``, ``kd``: a number, 6 numbers ([linear; angular]) or a 6x6 matrix, finite and >= 0;
    they and ``mask`` are checked on every assignment.
    """

    MASKS = {"6d": slice(0, 6), "position": slice(0, 3), "orientation": slice(3, 6)}
    kp = checked_attribute(gain_rule(size=6), _GAINS_DOC)
    kd = checked_attribute(gain_rule(size=6), _GAINS_DOC)
    mask = checked_attribute(choice_rule(tuple(MASKS)), "'6d', 'position' or 'orientation'.")

    kernel = "frame"
    params = (schema.vector("position", 3, get=lambda t, layout, state: t.held_pose(state)[0]),
              schema.matrix("rotation", 9, get=lambda t, layout, state: t.held_pose(state)[1]),
              schema.vector("velocity", 6), schema.vector("acceleration", 6),
              schema.diagonal("kp", 6), schema.diagonal("kd", 6))

    def selection(self, robot):
        return {"rows": list(range(6)[self.MASKS[self.mask]]),
                "frame": [robot.frame_id(self.frame, f"task '{self.name}'.frame")]}

    def layout_key(self):
        return (self.frame, self.mask)

    def row_count(self, layout):
        return len(range(6)[self.MASKS[self.mask]])

    def held_pose(self, state) -> tuple[np.ndarray, np.ndarray]:
        """(position, rotation), each set where ``state`` sees the frame if not set yet."""
        if self.position is None or self.rotation is None:
            pos, rot = state.frame_placement(self.frame)
            if self.position is None:
                self.position = pos
            if self.rotation is None:
                self.rotation = rot
        return self.position, self.rotation

    def __init__(self, frame: str, kp=100.0, kd=20.0, name=None, weight=1.0, mask: str = "6d"):
        super().__init__(name or f"frame {frame}", weight)
        self.frame, self.kp, self.kd, self.mask = frame, kp, kd, mask
        self.position: np.ndarray | None = None  # None: hold the pose first seen
        self.rotation: np.ndarray | None = None
        self.velocity = np.zeros(6)  # [linear; angular], world axes
        self.acceleration = np.zeros(6)

    def rows(self, robot, variables):
        pos, rot = robot.frame_placement(self.frame)
        self.held_pose(robot)
        error = np.concatenate([self.position - pos, pin.log3(self.rotation @ rot.T)])
        vel = robot.frame_velocity(self.frame)
        a = pd_acceleration(self.kp, self.kd, error, self.velocity - vel, self.acceleration)
        s = self.MASKS[self.mask]
        return TaskRows(qdd=robot.frame_jacobian(self.frame)[s], lam=None, tau=None,
                        target=(a - robot.frame_drift(self.frame))[s])


class SlackedFrameTask(FrameTask):
    """A :class:`FrameTask` whose rows hold within one shared slack: |J_i q̈ − a_i| ≤ ε on every
    selected row i (2 inequality rows each), ε ≥ 0 the auxiliary variable named ``slack`` (size
    1) — Fahmi et al. 2019's swing task with one slack per foot (eq. 33 with a single ε: an
    ∞-norm relaxation). Put a cost on ε on a lower level (:class:`~wholebody.tasks.regularization.
    AuxiliaryRegularizer`), or it relaxes the rows for free."""

    kind = "ineq"
    kernel = "slacked_frame"

    def __init__(self, frame: str, slack: str, kp=100.0, kd=20.0, name=None, weight=1.0,
                 mask: str = "6d"):
        if not isinstance(slack, str) or not slack:
            raise ValueError(f"slack: expected the auxiliary variable's name, got {slack!r}")
        super().__init__(frame, kp=kp, kd=kd, name=name, weight=weight, mask=mask)
        self._slack = slack

    @property
    def slack(self) -> str:
        """The slack's name (fixed: the stack's variables are made from it)."""
        return self._slack

    def auxiliary(self):
        return {self.slack: 1}

    def layout_key(self):
        return (self.frame, self.mask, self.slack)

    def row_count(self, layout):
        return 2 * super().row_count(layout)

    def rows(self, robot, variables):
        frame = super().rows(robot, variables)
        k, a = frame.m, frame.target
        aux = np.zeros((2 * k, variables.n_aux))
        column = variables.auxiliary_columns((self.slack,), f"task '{self.name}'")[0]
        aux[:k, column], aux[k:, column] = -1.0, 1.0
        return TaskRows(qdd=np.vstack([frame.qdd, frame.qdd]), lam=None, tau=None, aux=aux,
                        lower=np.concatenate([np.full(k, -np.inf), a]),
                        upper=np.concatenate([a, np.full(k, np.inf)]))


class PostureTask(Task):
    """Joint-space PD toward a reference posture; with ``base_kp`` > 0 also the floating base
    (position and orientation, LOCAL base frame as Pinocchio's v) — Table 2's "14 + 6 eq".

    ``kp``, ``kd``: a number, one per joint or an na x na matrix, finite and >= 0 (the robot,
    hence na, is not known on assignment: a wrong size fails in :meth:`rows`); ``base_kp``,
    ``base_kd``: numbers >= 0. All are checked on every assignment."""

    kp = checked_attribute(gain_rule(), _GAINS_DOC)
    kd = checked_attribute(gain_rule(), _GAINS_DOC)
    base_kp = checked_attribute(gain_rule(scalar_only=True), "Base stiffness (1/s^2), >= 0.")
    base_kd = checked_attribute(gain_rule(scalar_only=True), "Base damping (1/s), >= 0.")

    kernel = "posture"
    params = (schema.vector("q_ref", 1, "nq", get=lambda t, layout, state: t.reference(layout.robot)),
              schema.diagonal("kp", 1, "na"), schema.diagonal("kd", 1, "na"),
              schema.diagonal("base_kp", 6), schema.diagonal("base_kd", 6))

    def selection(self, robot):
        return {"with_base": [int(self.has_base())]}

    def layout_key(self):
        return (self.has_base(),)

    def row_count(self, layout):
        return layout.robot.nv if self.has_base() else layout.robot.na

    def has_base(self) -> bool:
        """True when the floating base has rows too (``base_kp`` or ``base_kd`` > 0)."""
        return bool(self.base_kp or self.base_kd)

    def reference(self, robot) -> np.ndarray:
        return robot.q_ref if self.q_ref is None else self.q_ref

    def __init__(self, kp=50.0, kd=10.0, name=None, weight=1.0, q_ref=None,
                 base_kp: float = 0.0, base_kd: float = 0.0):
        super().__init__(name, weight)
        self.kp, self.kd, self.base_kp, self.base_kd = kp, kd, base_kp, base_kd
        self.q_ref = None if q_ref is None else np.asarray(q_ref, dtype=float)

    def rows(self, robot, variables):
        q_ref = self.reference(robot)
        n = FREE_FLYER_NV
        joint_acc = pd_acceleration(self.kp, self.kd, robot.joint_error(robot.q, q_ref), -robot.v[n:])
        if not (self.base_kp or self.base_kd):
            return TaskRows(qdd=robot.joint_selection, lam=None, tau=None, target=joint_acc)
        # base error in the local frame: log6 of the relative placement
        base = pin.XYZQUATToSE3(robot.q[:FREE_FLYER_NQ])
        base_ref = pin.XYZQUATToSE3(q_ref[:FREE_FLYER_NQ])
        err = pin.log6(base.actInv(base_ref)).vector
        base_acc = self.base_kp * err - self.base_kd * robot.v[:n]
        if getattr(self, "_identity", None) is None or self._identity.shape[0] != robot.nv:
            self._identity = np.eye(robot.nv)
        return TaskRows(qdd=self._identity, lam=None, tau=None,
                        target=np.concatenate([base_acc, joint_acc]))


def _joint_gain(value, field, obj):
    return check_gain(value, field, size=len(obj.joints))


class JointTrajectoryTask(Task):
    """Named joints track q_d(t), qdot_d(t), qddot_d(t) with a PD (Herzog et al. 2016 Sect. 5.4).

    ``kp``, ``kd``: a number, one per joint or a k x k matrix, finite and >= 0, checked on every
    assignment."""

    kp = checked_attribute(_joint_gain, _GAINS_DOC)
    kd = checked_attribute(_joint_gain, _GAINS_DOC)

    kernel = "joint_trajectory"
    params = (schema.vector("position", 1, "rows", get=lambda t, layout, state: t.held_position(state)),
              schema.vector("velocity", 1, "rows"), schema.vector("acceleration", 1, "rows"),
              schema.diagonal("kp", 1, "rows"), schema.diagonal("kd", 1, "rows"))

    def selection(self, robot):
        missing = [j for j in self.joints if j not in robot.joint_names]
        if missing:
            raise ValueError(f"joints: unknown joints {missing}")
        return {"rows": [robot.joint_names.index(j) for j in self.joints]}

    def layout_key(self):
        return self.joints

    def row_count(self, layout):
        return len(self.joints)

    def held_position(self, state) -> np.ndarray:
        """``position``, set where ``state`` sees the joints if not set yet."""
        if self.position is None:
            self.position = state.joint_positions(self.joints)
        return self.position

    def __init__(self, joints, kp=100.0, kd=20.0, name=None, weight=1.0):
        if isinstance(joints, str) or not all(isinstance(j, str) for j in joints) or not joints:
            raise ValueError(f"joints: expected a non-empty list of joint names, got {joints!r}")
        super().__init__(name or f"joints {','.join(joints)}", weight)
        self.joints, self.kp, self.kd = tuple(joints), kp, kd
        self.position: np.ndarray | None = None
        self.velocity = np.zeros(len(self.joints))
        self.acceleration = np.zeros(len(self.joints))
        self._idx: np.ndarray | None = None

    def rows(self, robot, variables):
        if self._idx is None:
            missing = [j for j in self.joints if j not in robot.joint_names]
            if missing:
                raise ValueError(f"joints: unknown joints {missing}")
            self._idx = np.array([robot.joint_names.index(j) for j in self.joints])
        q = robot.joint_angles(robot.q)[self._idx]
        qd = robot.v[FREE_FLYER_NV + self._idx]
        if self.position is None:
            self.position = q.copy()
        a = pd_acceleration(self.kp, self.kd, self.position - q, self.velocity - qd,
                            self.acceleration)
        sel = np.zeros((len(self._idx), robot.nv))
        sel[np.arange(len(self._idx)), FREE_FLYER_NV + self._idx] = 1.0
        return TaskRows(qdd=sel, lam=None, tau=None, target=a)
