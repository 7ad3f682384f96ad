"""The trunk task of Fahmi et al. 2019 (Sect. II-B): a desired wrench at the CoM.

``W_com,d = K Δx + D Δv + ∇V_g + W_ff − W_ext`` (eq. 4): a Cartesian impedance on the CoM position
and the trunk orientation, gravity compensation, a feed-forward ``M_com v̇_com,d`` and an optional
external-wrench estimate. The contact forces realise it through ``W_com = J_st,comᵀ F`` (eq. 2):
for point feet ``W_com = Σ_i [f_i; (p_i − c) × f_i]``, the contact wrench about the CoM.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..planning.trunk import TrunkState
from ..robot import GRAVITY
from ..robots import reference
from ..validation import finite_array, nonnegative, positive
from . import schema
from .base import Task, TaskRows, checked_attribute, contact_list, contact_subset, flag

# The trunk gains and normal-force bound of Fahmi et al. 2019, Sect. V (K_x = 2000 N/m,
# D_x = 400 N s/m, K_θ = 1000 Nm/rad, D_θ = 200 Nm s/rad, f_max = 2000 N), tuned on HyQ, whose mass
# and trunk inertia are REFERENCE_MASS and REFERENCE_INERTIA (:mod:`wholebody.robots.reference`).
REFERENCE_MASS, REFERENCE_INERTIA = reference.MASS, reference.INERTIA
REFERENCE_K_X, REFERENCE_D_X = 2000.0, 400.0
REFERENCE_K_THETA, REFERENCE_D_THETA = 1000.0, 200.0
REFERENCE_F_MAX = 2000.0  # N

#: natural frequencies (Hz) and damping ratios of the trunk impedance that the paper's gains have on
#: HyQ, ω = sqrt(K / m), ζ = D / (2 sqrt(K m)) (0.764 Hz, 0.480; 1.645 Hz, 1.034)
FREQUENCY_X_HZ = math.sqrt(REFERENCE_K_X / REFERENCE_MASS) / (2.0 * math.pi)
DAMPING_RATIO_X = REFERENCE_D_X / (2.0 * math.sqrt(REFERENCE_K_X * REFERENCE_MASS))
FREQUENCY_THETA_HZ = math.sqrt(REFERENCE_K_THETA / REFERENCE_INERTIA) / (2.0 * math.pi)
DAMPING_RATIO_THETA = REFERENCE_D_THETA / (2.0 * math.sqrt(REFERENCE_K_THETA * REFERENCE_INERTIA))
#: default normal-force bound f_max as a multiple of the robot's weight: the paper's 2000 N on HyQ
#: (2.350 m g)
F_MAX_WEIGHTS = REFERENCE_F_MAX / (REFERENCE_MASS * GRAVITY)


def trunk_inertia(robot, q=None) -> float:
    """The scalar rotational inertia the trunk impedance acts on (kg m²): trace(I_G) / 3, the mean
    principal moment of the locked (composite rigid body) centroidal inertia I_G at ``q`` (default
    the reference posture; Pinocchio's ``ccrba``, on its own ``Data``). The trunk wrench of eq. 4
    is realised as the rate of the centroidal momentum (eq. 2, ḣ_G = W_com), whose angular part
    is I_G ω̇ with the legs held, so I_G, not the base link's inertia, is what K_θ works against;
    the paper's K_θ is isotropic, hence one number, the mean over the axes."""
    q = robot.q_ref if q is None else finite_array(q, "q", shape=(robot.nq,))
    return float(np.trace(robot.centroidal_inertia(q))) / 3.0


def trunk_gains(robot, frequency_x_hz: float | None = None,
                damping_ratio_x: float = DAMPING_RATIO_X,
                frequency_theta_hz: float | None = None,
                damping_ratio_theta: float = DAMPING_RATIO_THETA) -> dict[str, float]:
    """Trunk impedance gains (eq. 4) from the robot: K_x = m ω_x², D_x = 2 ζ_x m ω_x,
    K_θ = I ω_θ², D_θ = 2 ζ_θ I ω_θ (ω = 2π × frequency, m the robot's mass, I
    :func:`trunk_inertia`) → {"K_x", "D_x", "K_theta", "D_theta"}.

    The defaults are the damping ratios the paper's gains have on HyQ and its frequencies divided
    by :func:`~wholebody.robots.reference.froude_ratio` (a smaller robot's gait is faster in the
    same proportion, :func:`~wholebody.scenarios.locomotion.make_schedule`), so HyQ gets exactly
    the paper's gains and any other robot dynamically similar CoM and trunk loops. The formulas
    are evaluated as the reference gains times m / m_ref and (ω / ω_ref)² (the same numbers), so
    that the reference robot's gains come out exactly, not to rounding."""
    if frequency_x_hz is None:
        frequency_x_hz = FREQUENCY_X_HZ / reference.froude_ratio(robot)
    if frequency_theta_hz is None:
        frequency_theta_hz = FREQUENCY_THETA_HZ / reference.froude_ratio(robot)
    for name, value in (("frequency_x_hz", frequency_x_hz),
                        ("frequency_theta_hz", frequency_theta_hz)):
        positive(value, name)
    for name, value in (("damping_ratio_x", damping_ratio_x),
                        ("damping_ratio_theta", damping_ratio_theta)):
        nonnegative(value, name)
    mass = robot.mass / REFERENCE_MASS
    inertia = trunk_inertia(robot) / REFERENCE_INERTIA
    wx, wt = frequency_x_hz / FREQUENCY_X_HZ, frequency_theta_hz / FREQUENCY_THETA_HZ
    return {"K_x": REFERENCE_K_X * mass * wx ** 2,
            "D_x": REFERENCE_D_X * mass * wx * (damping_ratio_x / DAMPING_RATIO_X),
            "K_theta": REFERENCE_K_THETA * inertia * wt ** 2,
            "D_theta": (REFERENCE_D_THETA * inertia * wt
                        * (damping_ratio_theta / DAMPING_RATIO_THETA))}


def stance_aspect(robot) -> float:
    """tan ψ of the standing stance: the feet's mean lateral over their mean fore-aft distance
    from their centroid, in the base frame at the reference posture (ψ: the angle between the
    heading and a diagonal of a quadruped's feet; HyQ 0.874)."""
    from ..planning.footholds import Footprint  # planning depends on tasks' modules, not back
    feet = Footprint.from_robot(robot).feet[:, :2]
    spread = np.abs(feet - feet.mean(axis=0)).mean(axis=0)
    if not spread[0] > 1e-9 * max(spread[1], 1.0):
        raise ValueError(f"robot '{robot.name}': its contacts have no fore-aft extent about their "
                         "centroid; the trunk weights need a support area")
    return float(spread[1] / spread[0])


def trunk_weights(robot, pitch: float | None = None) -> tuple[float, ...]:
    """Default Q of ‖W_com − W_com,d‖²_Q (eq. 7a; the paper gives no values): force x, y, z and
    moment about the heading, lateral and vertical axes (the trunk reference's heading frame,
    :func:`heading_weights`). All 1 except the pitch weight, tan ψ / tan ψ_HyQ (ours).

    Two diagonal feet (a trot) at angle ψ to the heading make no moment about the line between
    them; the horizontal moment they do make is along n = (−sin ψ, cos ψ) (roll, pitch), so a
    roll moment comes with cot ψ times as much pitch, which the pitch error then asks back. The
    least squares weighs the two asks along n as w_roll sin ψ against w_pitch cos ψ; with
    w_pitch = tan ψ / tan ψ_HyQ every robot trades them as HyQ does with unit weights. With unit
    weights a robot standing narrower than HyQ trotted with a steady roll error that its pitch
    asks cancelled (docs/results.md); HyQ's weights are exactly 1. ``pitch``: that weight instead
    (>= 0)."""
    if pitch is None:
        pitch = stance_aspect(robot) / reference.STANCE_ASPECT
    return (1.0, 1.0, 1.0, 1.0, nonnegative(pitch, "trunk_pitch_weight"), 1.0)


def heading_weights(Q, rotation) -> np.ndarray:
    """(6, 6) weight of the wrench error for weights ``Q`` (6) about the heading frame of the
    trunk reference ``rotation`` (3 x 3): blockdiag(R_h diag(Q_f) R_hᵀ, R_h diag(Q_m) R_hᵀ), R_h
    the rotation about z by the heading (the direction of the rotation's x axis on the ground; a
    vertical x axis: the world axes). Weights equal about x and y are the same in any heading:
    then diag(Q) exactly."""
    Q = np.asarray(Q, dtype=float)
    W = np.diag(Q)
    if Q[0] == Q[1] and Q[3] == Q[4]:
        return W
    Rh = heading_rotation(rotation)
    W[:3, :3] = (Rh * Q[:3]) @ Rh.T
    W[3:, 3:] = (Rh * Q[3:]) @ Rh.T
    return W


def heading_rotation(rotation) -> np.ndarray:
    """R_h (3 x 3): the rotation about z by the heading of ``rotation`` (the direction of its x
    axis on the ground; a vertical x axis: the identity)."""
    R = np.asarray(rotation, dtype=float)
    c, s = R[0, 0], R[1, 0]
    norm = math.hypot(c, s)
    if norm == 0.0:
        return np.eye(3)
    c, s = c / norm, s / norm
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def force_bound(robot, weights: float = F_MAX_WEIGHTS) -> float:
    """A normal-force bound (N) of ``weights`` (> 0) times the robot's weight m g (default: the
    paper's 2000 N on HyQ, evaluated as 2000 N x m / m_ref so that HyQ's is exact)."""
    positive(weights, "f_max_weights")
    return REFERENCE_F_MAX * (robot.mass / REFERENCE_MASS) * (weights / F_MAX_WEIGHTS)


def _diagonal_gain(value, field, obj=None) -> np.ndarray:
    """A diagonal impedance gain: a number or 3 numbers (x, y, z), finite and >= 0, as a new
    3-vector."""
    arr = finite_array(value, field, nonnegative=True)
    if arr.shape not in ((), (1,), (3,)):
        raise ValueError(f"{field}: expected a number or 3 numbers, got shape {arr.shape}")
    return np.broadcast_to(arr, 3).astype(float)


class TrunkImpedance:
    """Eq. 4 of Fahmi et al. 2019 with diagonal gains (defaults: Sect. V, K_x = 2000, D_x = 400,
    K_θ = 1000, D_θ = 200, absolute values tuned on HyQ; :meth:`for_robot` scales them to any
    robot). The orientation error is log3(R_d Rᵀ) in world axes; ``feedforward``
    switches W_ff off (Assumption 2 of the passivity analysis); ``external_wrench`` is W_ext.
    The gains (a number or 3, finite and >= 0) and ``feedforward`` (a bool) are checked on every
    assignment (:class:`~wholebody.tasks.base.checked_attribute`)."""

    K_x = checked_attribute(_diagonal_gain, "CoM stiffness (N/m), 3 values >= 0.")
    D_x = checked_attribute(_diagonal_gain, "CoM damping (N s/m), 3 values >= 0.")
    K_theta = checked_attribute(_diagonal_gain, "Trunk orientation stiffness (Nm/rad), >= 0.")
    D_theta = checked_attribute(_diagonal_gain, "Trunk angular damping (Nm s/rad), >= 0.")
    feedforward = checked_attribute(flag, "Add W_ff = M_com v̇_com,d.")

    def __init__(self, K_x=2000.0, D_x=400.0, K_theta=1000.0, D_theta=200.0,
                 feedforward: bool = True):
        self.K_x, self.D_x, self.K_theta, self.D_theta = K_x, D_x, K_theta, D_theta
        self.feedforward = feedforward
        self.external_wrench = np.zeros(6)
        self.last_errors = np.zeros(12)  # [Δx, Δθ, Δv, Δω] of the last call, world axes

    @classmethod
    def for_robot(cls, robot, frequency_x_hz: float | None = None,
                  damping_ratio_x: float = DAMPING_RATIO_X,
                  frequency_theta_hz: float | None = None,
                  damping_ratio_theta: float = DAMPING_RATIO_THETA,
                  feedforward: bool = True) -> "TrunkImpedance":
        """The impedance with the robot-relative gains of :func:`trunk_gains` (default: exactly
        the paper's gains on HyQ, dynamically similar ones on any other robot)."""
        gains = trunk_gains(robot, frequency_x_hz, damping_ratio_x, frequency_theta_hz,
                            damping_ratio_theta)
        return cls(**gains, feedforward=feedforward)

    @staticmethod
    def trunk_state(robot) -> tuple[np.ndarray, np.ndarray]:
        """(rotation, world angular velocity) of the floating base at the robot's cached state."""
        R = robot.data.oMi[1].rotation  # the free-flyer joint, placed by Robot.update's kinematics
        return R, R @ robot.v[3:6]

    @staticmethod
    def pose_errors(R, com, ref) -> tuple[np.ndarray, np.ndarray]:
        """(e_x, e_θ) of eq. 4 for base rotation ``R`` and CoM ``com`` against the trunk reference
        ``ref``: ``ref.position - com`` and ``log3(ref.rotation R^T)`` (what :meth:`wrench_at`
        writes into ``last_errors[0:6]``), for a measure of the twin's own state."""
        return np.asarray(ref.position) - com, pin.log3(np.asarray(ref.rotation) @ R.T)

    def wrench(self, robot, ref, out: np.ndarray | None = None) -> np.ndarray:
        """W_com,d (6,) = [force; moment about the CoM] for the robot's cached state."""
        R, omega = self.trunk_state(robot)
        return self.wrench_at(R, omega, robot.com, robot.vcom, robot.mass, robot.data.Ig.inertia,
                              ref, out)

    def wrench_at(self, R, omega, com, vcom, mass: float, Ig, ref,
                  out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`wrench` for a given state: base rotation ``R``, world angular velocity
        ``omega``, CoM position and velocity, ``mass`` and locked centroidal inertia ``Ig``."""
        out = np.empty(6) if out is None else out
        e = self.last_errors
        e[0:3] = ref.position - com
        e[3:6] = pin.log3(ref.rotation @ R.T)
        e[6:9] = ref.velocity - vcom
        e[9:12] = ref.angular_velocity - omega
        out[0:3] = self.K_x * e[0:3] + self.D_x * e[6:9]
        out[3:6] = self.K_theta * e[3:6] + self.D_theta * e[9:12]
        out[2] += mass * GRAVITY  # ∇V_g: gravity compensation
        if self.feedforward:  # W_ff = M_com v̇_com,d with the locked centroidal inertia
            out[0:3] += mass * np.asarray(ref.acceleration)
            out[3:6] += Ig @ np.asarray(ref.angular_acceleration)
        out -= self.external_wrench
        return out


def contact_wrench_map(robot, contacts, out: np.ndarray | None = None,
                       points: np.ndarray | None = None) -> np.ndarray:
    """J_st,comᵀ of eq. 2 for point contacts: the 6 x 3k map from stacked forces to the wrench about
    the CoM, blocks [I; [p_i − c]x] (``points``: the contact points, default from the robot)."""
    out = np.zeros((6, 3 * len(contacts))) if out is None else out
    if points is None:
        points = np.array([robot.contact_point(name) for name in contacts])
    r = points - robot.com
    out[0:3] = 0.0
    out[0, 0::3] = out[1, 1::3] = out[2, 2::3] = 1.0
    out[3, 0::3] = out[4, 1::3] = out[5, 2::3] = 0.0
    out[3, 1::3], out[3, 2::3] = -r[:, 2], r[:, 1]
    out[4, 0::3], out[4, 2::3] = r[:, 2], -r[:, 0]
    out[5, 0::3], out[5, 1::3] = -r[:, 1], r[:, 0]
    return out


class TrunkWrenchTask(Task):
    """Σ_i [f_i; (p_i − c) × f_i] ≈ W_com,d (Fahmi et al. 2019, eqs. 2, 4, 7a-8) as equality rows over
    the contact forces (point contacts). ``reference`` is a trunk sample (:class:`~wholebody.planning.trunk.TrunkState`: CoM position/velocity/
    acceleration, rotation, angular velocity/acceleration, world axes);
    ``impedance`` a :class:`TrunkImpedance`; weights are per row (√ of the diagonal of Q).
    ``contacts``: None = all active contacts, an empty list = none. ``heading``: both sides in
    the heading frame of the reference rotation (:func:`heading_rotation`), so that the per-row
    weights are the weights about that frame, as :func:`heading_weights`."""

    contacts = checked_attribute(contact_list, "None (all active contacts) or contact names.")
    heading = checked_attribute(flag, "Rows in the heading frame of the reference rotation.")
    per_contact = True
    kernel = "trunk_wrench"
    params = (schema.diagonal("K_x", 3, attribute="impedance.K_x"),
              schema.diagonal("D_x", 3, attribute="impedance.D_x"),
              schema.diagonal("K_theta", 3, attribute="impedance.K_theta"),
              schema.diagonal("D_theta", 3, attribute="impedance.D_theta"),
              schema.flag("feedforward", attribute="impedance.feedforward"),
              schema.vector("external_wrench", 6, attribute="impedance.external_wrench"),
              schema.vector("position", 3, attribute="reference.position"),
              schema.vector("velocity", 3, attribute="reference.velocity"),
              schema.vector("acceleration", 3, attribute="reference.acceleration"),
              schema.matrix("rotation", 9, attribute="reference.rotation"),
              schema.vector("angular_velocity", 3, attribute="reference.angular_velocity"),
              schema.vector("angular_acceleration", 3, attribute="reference.angular_acceleration"),
              schema.flag("heading"))

    def __init__(self, impedance: TrunkImpedance | None = None, name="trunk wrench", weight=1.0,
                 contacts=None, heading: bool = False):
        super().__init__(name, weight)
        self.impedance = impedance or TrunkImpedance()
        self.reference = TrunkState()
        self.contacts = contacts
        self.heading = heading

    def row_count(self, layout):
        self._point_contacts(layout.robot, layout.contacts)
        return 6

    @staticmethod
    def _point_contacts(robot, names) -> None:
        if any(robot.contact(n).dim != 3 for n in names):
            raise ValueError("TrunkWrenchTask: point contacts (3D forces) only")

    def rows(self, robot, variables):
        names = contact_subset(variables, self.contacts)
        self._point_contacts(robot, names)
        G = contact_wrench_map(robot, names)
        A = np.zeros((6, variables.n_lambda))
        for i, n in enumerate(names):
            A[:, variables.lambda_slices[n]] = G[:, 3 * i:3 * i + 3]
        target = self.impedance.wrench(robot, self.reference)
        if self.heading:
            Rt = heading_rotation(self.reference.rotation).T
            A, target = A.reshape(2, 3, -1), target.reshape(2, 3)
            A, target = (Rt @ A).reshape(6, -1), (target @ Rt.T).reshape(6)
        return TaskRows(qdd=None, lam=A, tau=None, target=target)
