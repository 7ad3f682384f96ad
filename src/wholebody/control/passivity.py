"""Passivity analysis of the passive WBC: the controller-side pieces and the storage-function
bookkeeping (Fahmi et al. 2019, Sect. III, eqs. 20-31).

* :class:`SwingFeedForwardOff` — a planner wrapper that drops the swing feed-forward acceleration
  (Assumption 2: no feed-forward terms in eqs. 4a and 5; with ``TrunkImpedance(feedforward=False)``
  for the trunk);
* :func:`desired_generalized_velocity` — ν_d realising the desired CoM, trunk and feet velocities,
  whose joint part is q̇_j,d of the supply Δq̇_jᵀ τ (eq. 27a);
* :class:`StorageMeter` — per WBC cycle, the storage function V = V_com + V_sw (eq. 23), its analytic
  rate and the dissipation of eq. 31, into a :class:`StorageLog`.

V_com = ½ Δxᵀ K_x Δx + ½ Δθᵀ K_θ Δθ + m g Δz (eq. 4, footnote 6; Δθ = log3(R_d Rᵀ)). The swing task
is at the acceleration level (eq. 6), the force-level impedance F = Λ(K_sw Δx + D_sw Δv) with
Λ = (J M⁻¹ Jᵀ)⁻¹ (footnote 10), so V_sw = ½ Δx_swᵀ Λ K_sw Δx_sw and D_sw,eff = Λ D_sw.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from ..planning.planner import GaitPlanner
from ..tasks.wrench import GRAVITY, TrunkImpedance


class SwingFeedForwardOff:
    """A planner wrapper whose plans carry no swing feed-forward acceleration: the controller's
    eq. 6 becomes v̇_sw,d = K_sw Δx_sw + D_sw Δv_sw (Assumption 2, "we do not consider the
    feed-forward terms in (4a) and (5)"). Everything else is the wrapped planner's."""

    def __init__(self, planner: GaitPlanner):
        self.planner = planner

    def __getattr__(self, name):
        return getattr(self.planner, name)

    def update(self, t, feet=None, com_velocity=None):
        state = self.planner.update(t, feet, com_velocity)
        state.foot_acceleration[:] = 0.0
        return state


def desired_generalized_velocity(robot, plan, legs) -> tuple[np.ndarray, float]:
    """ν_d solving [J_com; S_ω; J_feet] ν_d = [ẋ_com,d; ω_d; v_feet,d] at the robot's cached state
    (stance feet: contact-point Jacobian, v = 0; swing feet: foot-frame Jacobian, the planner's
    velocity). Returns (ν_d, relative residual of the solve)."""
    nv = robot.nv
    rows = [robot.J_com]
    rhs = [np.asarray(plan.trunk.velocity, dtype=float)]
    R = pin.Quaternion(robot.q[3:7]).normalized().toRotationMatrix()
    S = np.zeros((3, nv))
    S[:, 3:6] = R  # world angular velocity of the base = R v[3:6]
    rows.append(S)
    rhs.append(np.asarray(plan.trunk.angular_velocity, dtype=float))
    for i, name in enumerate(legs):
        if plan.contact[i]:
            rows.append(robot.contact_jacobians[name])
            rhs.append(np.zeros(3))
        else:
            rows.append(robot.frame_jacobian(robot.contact(name).frame)[:3])
            rhs.append(np.asarray(plan.foot_velocity[i], dtype=float))
    A, b = np.vstack(rows), np.concatenate(rhs)
    nu, *_ = np.linalg.lstsq(A, b, rcond=None)
    scale = max(1e-9, float(np.linalg.norm(b)))
    return nu, float(np.linalg.norm(A @ nu - b) / scale)


@dataclass
class StorageLog:
    """One row per WBC cycle of :class:`StorageMeter` (definitions: module docstring)."""

    t: list = field(default_factory=list)
    V_position: list = field(default_factory=list)  # ½ Δxᵀ K_x Δx
    V_orientation: list = field(default_factory=list)  # ½ Δθᵀ K_θ Δθ
    V_gravity: list = field(default_factory=list)  # m g Δz
    V_swing: list = field(default_factory=list)  # ½ Δxᵀ Λ K_sw Δx, summed over swing feet
    V_swing_raw: list = field(default_factory=list)  # ½ K_sw |Δx|² (m²/s², no Λ)
    rate_analytic: list = field(default_factory=list)  # Δv_comᵀ∇V_com + Δv_swᵀ∇V_sw
    dissipation: list = field(default_factory=list)  # Δvᵀ D Δv (CoM) + Δv_swᵀ Λ D_sw Δv_sw
    qd_des: list = field(default_factory=list)  # q̇_j,d
    solve_residual: list = field(default_factory=list)
    wrench_error: list = field(default_factory=list)  # ‖W_com − W_com,d‖ of the QP solution
    stance: list = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v) for k, v in self.__dict__.items()}


class StorageMeter:
    """``on_cycle(t, result, ctrl, sim)`` callback of a closed-loop run recording the storage
    function, its analytic rate, the dissipation and q̇_j,d at the robot's cached state."""

    def __init__(self, robot, impedance: TrunkImpedance, K_sw: float, D_sw: float):
        self.robot = robot
        self.imp = impedance
        self.K_sw, self.D_sw = float(K_sw), float(D_sw)
        self.log = StorageLog()

    def __call__(self, t, result, ctrl, sim) -> None:
        robot, plan, imp, L = self.robot, ctrl.last_plan, self.imp, self.log
        legs = ctrl.planner.legs
        R = pin.Quaternion(robot.q[3:7]).normalized().toRotationMatrix()
        ref = plan.trunk
        dx = np.asarray(ref.position) - robot.com
        dth = pin.log3(np.asarray(ref.rotation) @ R.T)
        dv = np.asarray(ref.velocity) - robot.vcom
        dw = np.asarray(ref.angular_velocity) - R @ robot.v[3:6]
        mg = robot.mass * GRAVITY
        L.t.append(t)
        L.V_position.append(0.5 * float(dx @ (imp.K_x * dx)))
        L.V_orientation.append(0.5 * float(dth @ (imp.K_theta * dth)))
        L.V_gravity.append(mg * float(dx[2]))
        rate = float(dv @ (imp.K_x * dx)) + mg * float(dv[2]) + float(dw @ (imp.K_theta * dth))
        diss = float(dv @ (imp.D_x * dv)) + float(dw @ (imp.D_theta * dw))
        V_sw = V_raw = 0.0
        Minv = None
        for i, name in enumerate(legs):
            if plan.contact[i]:
                continue
            frame = robot.contact(name).frame
            J = robot.frame_jacobian(frame)[:3]
            if Minv is None:
                Minv = np.linalg.inv(robot.M)
            Lam = np.linalg.inv(J @ Minv @ J.T)
            foot = robot.data.oMf[robot.contact(name).frame_id].translation
            e = np.asarray(plan.foot_position[i]) - foot
            de = np.asarray(plan.foot_velocity[i]) - J @ robot.v
            V_sw += 0.5 * self.K_sw * float(e @ Lam @ e)
            V_raw += 0.5 * self.K_sw * float(e @ e)
            rate += self.K_sw * float(de @ Lam @ e)
            diss += self.D_sw * float(de @ Lam @ de)
        L.V_swing.append(V_sw)
        L.V_swing_raw.append(V_raw)
        L.rate_analytic.append(rate)
        L.dissipation.append(diss)
        nu, res = desired_generalized_velocity(robot, plan, legs)
        L.qd_des.append(nu[6:].copy())
        L.solve_residual.append(res)
        L.wrench_error.append(float(result.tasks[0].error) if result.tasks else np.nan)
        L.stance.append(np.array(plan.contact, dtype=bool))
