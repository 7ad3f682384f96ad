"""PassiveWBC's QP (Fahmi et al. 2019, eq. 7) as a two-level stack of library tasks: hard
constraints (eqs. 9-10/32, 13-18, hard swing rows of eq. 11), then the weighted objective (eqs.
4/7a/8, the regulariser, swing tasks softened by eq. 33) — for ``Formulation.solve`` with
``SolverSettings(method="weighted")``, an independent assembly of the same problem."""

from __future__ import annotations

import numpy as np

from ..formulation import Stack
from ..tasks import (ContactConstraint, ForceRegularizer, FrameTask, FrictionCone, NewtonEuler,
                     NormalForceBounds)
from ..tasks.regularization import (AccelerationTarget, ContactTorqueRegularizer,
                                    TangentialForceRegularizer)
from ..tasks.wrench import TrunkWrenchTask
from ..variables import Variables


def passive_stack(wbc, plan):
    """The QP of ``wbc.solve(plan)`` (a :class:`~wholebody.control.passive.PassiveWBC`) as
    (stack, variables). Needs a prior ``wbc.solve`` on the same plan (stance anchors). The
    single-slack mode has no stack form (its cost is an ∞-norm, not a weighted task)."""
    if wbc.swing_slack == "single":
        raise ValueError("swing_slack: 'single' has no two-level stack form")
    robot, contacts, leg = wbc.robot, wbc.contacts, wbc._leg
    stance = [n for i, n in enumerate(contacts) if plan.contact[leg[i]]]
    swing = [(i, n) for i, n in enumerate(contacts) if not plan.contact[leg[i]]]
    normals = {n: plan.touchdown_normal[leg[contacts.index(n)]] for n in stance}
    contact = ContactConstraint(contacts=stance, kp=wbc.K_st, kd=wbc.D_st)
    for n in stance:  # the task anchors frame origins; the controller's are the sphere bottoms
        i = contacts.index(n)
        contact.anchors[n] = wbc._anchors[i] + [0.0, 0.0, robot.contact(n).spec.radius]
    hard = [NewtonEuler(), contact, FrictionCone(wbc.mu, contacts=stance, normals=normals),
            NormalForceBounds(wbc.f_min, wbc.f_max, contacts=stance, normals=normals),
            wbc.torque_limits, wbc.joint_limits]
    wrench = TrunkWrenchTask(wbc.impedance, weight=np.sqrt(wbc.Q), contacts=stance)
    wrench.reference = plan.trunk
    posture = np.concatenate([np.zeros(6), wbc.posture_acceleration()])
    objective = [wrench, AccelerationTarget(posture, weight=np.sqrt(wbc.R_qdd)),
                 ForceRegularizer(weight=np.sqrt(wbc.R_force), contacts=stance)]
    if wbc.regularization == "torque":
        objective.append(ContactTorqueRegularizer(weight=np.sqrt(wbc.torque_weights),
                                                  contacts=stance))
    elif wbc.tangential_weight:
        lean = wbc.last_desired_wrench[:3] if wbc.regularization == "force-parallel" else None
        objective.append(TangentialForceRegularizer(weight=np.sqrt(wbc.tangential_weight),
                                                    contacts=stance, normals=normals, lean=lean,
                                                    mu=wbc.mu))
    for i, n in swing:
        foot = leg[i]
        task = FrameTask(robot.contact(n).frame, kp=wbc.swing.K, kd=wbc.swing.D,
                         mask="position", name=f"swing {n}",
                         weight=1.0 if wbc.swing_slack == "none" else np.sqrt(wbc.slack_weight))
        task.position = np.array(plan.foot_position[foot], dtype=float)
        task.velocity[:3] = plan.foot_velocity[foot]
        task.acceleration[:3] = plan.foot_acceleration[foot]
        (hard if wbc.swing_slack == "none" else objective).append(task)
    return Stack([hard, objective]), Variables(robot, stance)
