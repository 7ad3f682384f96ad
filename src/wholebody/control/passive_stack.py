"""PassiveWBC's QP (Fahmi et al. 2019, eq. 7) as a two-level stack of library tasks: hard
constraints (eqs. 9-10/32, 13-18, hard swing rows of eq. 11), then the weighted objective (eqs.
4/7a/8, the regulariser, swing tasks softened by eq. 33) — for ``Formulation.solve`` or a
:class:`~wholebody.cycle.HierarchyCycle` with ``SolverSettings(method="weighted")``, an
independent assembly of the same problem."""

from __future__ import annotations

import numpy as np

from ..formulation import Stack
from ..tasks import (ContactConstraint, ForceRegularizer, FrameTask, FrictionCone, NewtonEuler,
                     NormalForceBounds)
from ..tasks.motion import SlackedFrameTask
from ..tasks.regularization import (AccelerationTarget, AuxiliaryRegularizer,
                                    ContactTorqueRegularizer, TangentialForceRegularizer)
from ..tasks.wrench import TrunkWrenchTask
from ..variables import Variables


class PassiveStack:
    """The tasks of a :class:`~wholebody.control.passive.PassiveWBC`'s QP, built once; each
    :meth:`update` sets their plan's references (stance normals, trunk reference, lean, swing
    references) and puts the swing feet's tasks on their level, after
    :meth:`set_state_references` (stance anchors, posture target), so
    that a compiled cycle keeps one program per stance set. The weights and gains are the
    controller's when built. The per-contact tasks apply to all active contacts: the stance
    feet of :meth:`update`'s variables; where their rows are linearly dependent (legs of two
    joints) the stance task takes an independent set of them (``rank_tolerance``), as the Python
    engine does. The swing feet's tasks: hard (swing slack "none"), weighted ("per-direction") or,
    with one slack per foot ("single"), a :class:`~wholebody.tasks.motion.SlackedFrameTask` on the
    hard level (its slack an auxiliary variable of the stance set's variables) with the slack's
    cost α ε² on the objective level. The controller's ``extra_tasks`` join their levels."""

    def __init__(self, wbc):
        self.wbc = wbc
        robot = wbc.robot
        self.contact = ContactConstraint(kp=wbc.K_st, kd=wbc.D_st,
                                         rank_tolerance=wbc.stance_rank_tolerance)
        self.friction = FrictionCone(wbc.mu)
        self.normal_bounds = NormalForceBounds(wbc.f_min, wbc.f_max)
        self.hard = [NewtonEuler(), self.contact, self.friction, self.normal_bounds,
                     wbc.torque_limits, wbc.joint_limits]
        self.wrench = TrunkWrenchTask(wbc.impedance, weight=np.sqrt(wbc.Q), heading=True)
        self.posture = AccelerationTarget(np.zeros(robot.nv), weight=np.sqrt(wbc.R_qdd))
        self.objective = [self.wrench, self.posture,
                          ForceRegularizer(weight=np.sqrt(wbc.R_force))]
        self.tangential = None
        if wbc.regularization == "torque":
            self.objective.append(ContactTorqueRegularizer(weight=np.sqrt(wbc.torque_weights)))
        elif wbc.tangential_weight:
            self.tangential = TangentialForceRegularizer(
                weight=np.sqrt(wbc.tangential_weight), mu=wbc.mu)
            self.objective.append(self.tangential)
        self.single = wbc.swing_slack == "single"
        if self.single:  # per foot: |J q̈ − b| ≤ ε (hard level), α ε² (objective)
            self.swing = [SlackedFrameTask(robot.contact(n).frame, f"slack {n}", kp=wbc.swing.K,
                                           kd=wbc.swing.D, mask="position", name=f"swing {n}")
                          for n in wbc.contacts]
            self.slack_costs = [AuxiliaryRegularizer([task.slack], name=f"slack cost {n}",
                                                     weight=np.sqrt(wbc.slack_weight))
                                for n, task in zip(wbc.contacts, self.swing)]
        else:
            self.slack_costs = []
            self.swing = [FrameTask(robot.contact(n).frame, kp=wbc.swing.K, kd=wbc.swing.D,
                                    mask="position", name=f"swing {n}",
                                    weight=1.0 if wbc.swing_slack == "none"
                                    else np.sqrt(wbc.slack_weight))
                          for n in wbc.contacts]
        self.swing_level = 0 if wbc.swing_slack in ("none", "single") else 1
        own = {t.name for t in self.hard + self.objective + self.swing
               + self.slack_costs}
        taken = sorted(own & {t.name for tasks in wbc.extra_tasks.values() for t in tasks})
        if taken:
            raise ValueError(f"extra_tasks: the names {taken} are the controller's own tasks'; "
                             "name the tasks differently")
        self.hard += wbc.extra_tasks["hard"]
        self.objective += wbc.extra_tasks["objective"]
        self.stack = Stack([list(self.hard), list(self.objective)])
        # the stance task anchors frame origins, the controller the sphere bottoms: the anchors
        # are rows of one array (all contacts; the task reads its active ones), set every cycle
        #: the stance anchors as the contact frames' origins (rows: contacts)
        self.anchor_frames = np.zeros((len(wbc.contacts), 3))
        self._radius_offset = np.zeros((len(wbc.contacts), 3))
        self._radius_offset[:, 2] = wbc._radii
        self.contact.anchors = dict(zip(wbc.contacts, self.anchor_frames))
        self._stances: dict[tuple, tuple] = {}  # stance flags -> (levels, swing, variables)
        self._normals = None  # (stance, the plan's normals' bytes) last set on the tasks
        #: where the stance feet's forces go among all contacts' (3 per contact), and the swing
        #: feet as (task, leg), of the stance set of the last update
        self.force_index = np.zeros(0, dtype=int)
        self.swinging: list[tuple] = []

    def _stance(self, in_stance: tuple) -> tuple:
        """(levels, swing feet as (task, leg), variables, the stance feet's legs, their names,
        where their forces go among all contacts' 3 per contact) of a stance set (flags per
        contact), made on first use."""
        wbc = self.wbc
        stance = tuple(n for n, s in zip(wbc.contacts, in_stance) if s)
        levels = [list(self.hard), list(self.objective)]
        swing = [(task, wbc._leg[i]) for i, task in enumerate(self.swing) if not in_stance[i]]
        levels[self.swing_level] += [task for task, _ in swing]
        levels[1] += [cost for cost, s in zip(self.slack_costs, in_stance) if not s]
        # (the swing feet's slacks and the extra tasks' auxiliary variables are added by the
        # solver, Formulation.variables_for)
        entry = (levels, swing, Variables(wbc.robot, stance),
                 wbc._leg[np.flatnonzero(in_stance)], stance,
                 np.flatnonzero(np.repeat(in_stance, 3)))
        self._stances[in_stance] = entry
        return entry

    def set_state_references(self, q=None, v=None) -> None:
        """The references that follow the controller's state, computed in Python: the stance
        anchors (the controller's, as the contact frames' origins) and the posture target at
        (q, v), default the robot's cached state. (The native engine's compiled references,
        ``PassiveReferences.update``, write the same arrays.)"""
        wbc = self.wbc
        np.add(wbc._anchors, self._radius_offset, out=self.anchor_frames)
        # in place: the target was checked when set, a posture acceleration of a finite state
        # is finite (a NaN would fail the cycle's row check)
        self.posture.target[6:] = wbc.posture_acceleration(q, v)

    def update(self, plan, lean=None) -> tuple[Stack, Variables]:
        """The stack and variables of ``plan``: the tasks' plan references (stance set and
        normals, trunk reference, swing references; ``lean``: the desired net force of the
        cycle, for "force-parallel"), the state references being set already
        (:meth:`set_state_references` or the compiled ones)."""
        wbc = self.wbc
        in_stance = tuple(plan.contact[wbc._leg].tolist())
        entry = self._stances.get(in_stance)
        levels, swing, variables, legs, stance, self.force_index = (entry
                                                                    or self._stance(in_stance))
        self.swinging = swing
        key = (stance, plan.touchdown_normal.tobytes())
        if key != self._normals:  # checked and set when they change only
            self._normals = key
            normals = plan.touchdown_normal[legs]
            self.friction.normals = self.normal_bounds.normals = dict(zip(stance, normals))
            if self.tangential is not None:
                self.tangential.normals = self.friction.normals
        self.wrench.reference = plan.trunk
        if self.tangential is not None:
            lean = lean if wbc.regularization == "force-parallel" else None
            if lean is not self.tangential.lean:  # (a view the task keeps is checked once)
                self.tangential.lean = lean
        feedforward = wbc.swing.feedforward
        for task, foot in swing:
            task.position = plan.foot_position[foot]
            task.velocity[:3] = plan.foot_velocity[foot]
            task.acceleration[:3] = plan.foot_acceleration[foot] if feedforward else 0.0
        if self.stack.levels is not levels:
            self.stack.levels = levels
        return self.stack, variables


def passive_stack(wbc, plan):
    """The QP of ``wbc.solve(plan)`` (a :class:`~wholebody.control.passive.PassiveWBC`) as
    (stack, variables), new tasks. Needs a prior ``wbc.solve`` on the same plan (stance anchors,
    the desired wrench)."""
    lean = None if wbc.last_desired_wrench is None else wbc.last_desired_wrench[:3]
    stack = PassiveStack(wbc)
    stack.set_state_references()
    return stack.update(plan, lean)
