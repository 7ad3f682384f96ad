"""Baseline standing controller: contact-consistent gravity compensation plus joint PD.

Not a whole-body controller — it proves the closed loop. With all contacts held and q̈ = 0, the
floating-base rows of the dynamics (Herzog et al. 2016, eq. 13) fix the contact forces up to the
internal forces: ``h_b = J_{c,b}^T lambda``. The least-norm lambda is used, and the actuated rows
(eq. 14) give the compensating torques ``tau_g = h_u - J_{c,u}^T lambda``. Compensating only the
joint rows (``tau = h_u``) ignores that the contacts carry the robot and makes Talos fall in the twin.

The PD gains default to the robot's own scale (:func:`relative_joint_gains`): each joint a
second-order loop of natural frequency ``frequency_hz`` and damping ratio ``damping_ratio`` on its
own inertia, so that one default holds for a 90 kg humanoid and a 2.5 kg quadruped alike.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from ..formulation import Solution
from ..guard import Outcome, guard_torque
from ..robot import FREE_FLYER_NV, Robot
from ..tasks.base import check_gain
from ..validation import finite_array, nonnegative, positive

#: natural frequency of every joint's PD loop (Hz) and its damping ratio, the defaults of
#: :class:`StandingController` (see :func:`relative_joint_gains` for why these values)
DEFAULT_FREQUENCY_HZ = 10.0
DEFAULT_DAMPING_RATIO = 0.7


def joint_inertia(robot: Robot, q: np.ndarray | None = None) -> np.ndarray:
    """Inertia of each actuated joint at ``q`` (default the reference posture) with the rest of the
    robot free, base included: ``1 / (M^-1)_ii`` (Pinocchio's ``computeMinverse``; the joint's
    acceleration per unit torque is ``(M^-1)_ii``), with the model's armature, the reflected rotor
    inertia, in M. In kg m² (revolute) or kg (prismatic). It is at most M_ii, the inertia with
    every other coordinate held, and far below it for a joint that carries much more than the
    links it moves (a hip under a heavy trunk on light legs). Computed on a separate
    ``pinocchio.Data``: the robot's per-cycle cache is left untouched."""
    q = robot.q_ref if q is None else finite_array(q, "q", shape=(robot.nq,))
    inverse = pin.computeMinverse(robot.model, robot.model.createData(), np.asarray(q, float))
    return 1.0 / np.diag(inverse)[FREE_FLYER_NV:]


def relative_joint_gains(robot: Robot, frequency_hz: float = DEFAULT_FREQUENCY_HZ,
                         damping_ratio: float = DEFAULT_DAMPING_RATIO,
                         q: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(kp, kd) per actuated joint: kp_i = ω² m_i, kd_i = 2 ζ ω m_i (ω = 2π ``frequency_hz``,
    ζ = ``damping_ratio``, m_i from :func:`joint_inertia` at ``q``: the joint's inertia with the
    rest of the robot free).

    The explicit discrete PD's damping step kd dt / m_i is then 2 ζ ω dt on every joint of every
    robot (0.088 with the defaults at the twin's 1 ms; it must stay well below 2) — the absolute
    kp = 1000, kd = 30 made for Talos give 55 on a Solo12 knee. Gains on M_ii (the inertia with
    the other joints held, the former default) reach 1.6-4.3 on robots whose light distal links
    carry a heavy body without rotor inertia (G1, iCub, Alexander from example-robot-data), and
    those chatter; on the presets the two differ by at most 2.2 × at the worst joint and stand
    alike (base drift within 0.6 mm). With the feet on the ground the distal joints move more
    than either (a Solo12 knee ~13 ×, a Talos ankle up to 150 ×), so their stance frequency is
    lower; gains on that stance inertia were tried and chatter on hyq and talos14. The frequency
    and damping ratio were chosen in the twin under a model mismatch (masses × 1.1 ± 10 %, CoM
    offsets 5 mm, one-step torque delay) with gains on M_ii: 1-5 Hz let the quadrupeds sag by
    5-50 %, 10 Hz holds the six presets within 1.6 cm, 15 Hz or ζ = 1.5 make talos14 chatter."""
    positive(frequency_hz, "frequency_hz")
    nonnegative(damping_ratio, "damping_ratio")
    omega = 2.0 * math.pi * float(frequency_hz)
    inertia = joint_inertia(robot, q)
    return omega ** 2 * inertia, 2.0 * float(damping_ratio) * omega * inertia


def gravity_compensation(robot: Robot, contacts=None) -> tuple[np.ndarray, np.ndarray]:
    """(τ_g, λ) at the robot's cached state (module docstring): the least-norm contact forces λ
    balancing the floating-base rows, J_bᵀ λ = h_b (Herzog et al. 2016, eq. 13), and the joint
    torques τ_g = h_u − J_uᵀ λ (eq. 14); on ``contacts`` (names; default all of them)."""
    J = robot.stacked_contact_jacobian(contacts)
    n = FREE_FLYER_NV
    lam, *_ = np.linalg.lstsq(J[:, :n].T, robot.h[:n], rcond=None)
    return robot.h[n:] - J[:, n:].T @ lam, lam


class StandingController:
    """tau = h_u - J_{c,u}^T lambda + Kp (q_ref - q) - Kd qdot, saturated to the torque limits
    (outcome ``CLIPPED`` when saturated).

    ``kp``, ``kd``: a number or one per joint, finite and >= 0; None (default): the relative
    gains of :func:`relative_joint_gains` for ``frequency_hz`` (> 0, Hz) and ``damping_ratio``
    (>= 0) at ``q_ref`` — an explicit ``kp`` or ``kd`` overrides its own. ``q_ref``: a finite nq
    vector (default the robot's reference posture). Checked at construction (ValueError naming
    the argument and the bad value)."""

    def __init__(self, robot: Robot, kp: float | np.ndarray | None = None,
                 kd: float | np.ndarray | None = None, q_ref: np.ndarray | None = None, *,
                 frequency_hz: float = DEFAULT_FREQUENCY_HZ,
                 damping_ratio: float = DEFAULT_DAMPING_RATIO):
        self.robot = robot
        q_ref = robot.q_ref if q_ref is None else finite_array(q_ref, "q_ref", shape=(robot.nq,))
        self.frequency_hz = positive(frequency_hz, "frequency_hz")
        self.damping_ratio = nonnegative(damping_ratio, "damping_ratio")
        if kp is None or kd is None:
            kp_rel, kd_rel = relative_joint_gains(robot, frequency_hz, damping_ratio, q_ref)
        self.kp = kp_rel if kp is None else np.broadcast_to(
            check_gain(kp, "kp", robot.na, matrix=False), robot.na).copy()
        self.kd = kd_rel if kd is None else np.broadcast_to(
            check_gain(kd, "kd", robot.na, matrix=False), robot.na).copy()
        self.q_ref = np.array(q_ref, dtype=float)

    def compute(self, q, v, t: float = 0.0) -> Solution:
        robot = self.robot
        robot.update(q, v)
        tau, lam = gravity_compensation(robot)
        n = FREE_FLYER_NV
        tau += self.kp * robot.joint_error(robot.q, self.q_ref) - self.kd * robot.v[n:]
        tau, outcome, status = guard_torque(tau, *robot.torque_bounds(), Outcome.SOLVED, "solved")
        forces, start = {}, 0
        for c in robot.contacts:
            forces[c.name] = lam[start:start + c.dim]
            start += c.dim
        return Solution(qdd=np.zeros(robot.nv), lam=lam, tau=tau, forces=forces, outcome=outcome,
                        status=status, level_costs=np.zeros(0), contacts=tuple(forces))
