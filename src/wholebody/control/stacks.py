"""The task hierarchies of Herzog et al. 2016 (Tables 1, 2 and 4) as stack builders.

Each returns a :class:`Stack`; tasks are reachable by name (``stack.find("momentum")``) so that a
controller can update references and gains every cycle. Weights are chosen among the paper's
{1e4, 1, 1e-1, 1e-4} (Sect. 5.2.1).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ..formulation import Stack
from ..robot import Robot
from ..robots.roles import leg_missing_directions
from ..tasks import (CenterOfPressure, CoMTask, ContactConstraint, ForceRegularizer, FrameTask,
                     FrictionCone, FullDynamics, JointAccelerationLimits, MomentumForce, MomentumPD,
                     NewtonEuler, PostureTask, TorqueLimits)
from ..tasks.base import contact_list
from ..validation import nonnegative, number


def _dynamics(full: bool):
    return [FullDynamics(name="dynamics") if full else NewtonEuler(name="newton-euler"),
            TorqueLimits(name="torque limits")]


def _contacts(robot: Robot, contacts, name: str, default_all: bool) -> tuple[str, ...]:
    """The builders' contact list: a list of the robot's contact names (None: all of them if
    ``default_all``); an empty list means no contact."""
    if contacts is None and default_all:
        return tuple(robot.contact_names)
    if contacts is None:
        raise ValueError(f"{name}: expected a list of contact names, got None")
    names = contact_list(contacts, name)
    for c in names:
        robot.contact(c)  # ValueError naming an unknown contact
    return names


def _mu(robot: Robot, mu: float | None) -> float:
    """The friction coefficient: ``mu`` (finite, > 0) or, if None, the robot's."""
    return robot.friction if mu is None else number(mu, "mu", low=0.0, low_open=True)


def _contact_conditions(robot: Robot, contacts: Sequence[str], mu: float | None, torsion: bool,
                        cop_margin: float):
    """CoP (weight 1e4, as the paper favours CoPs; ``cop_margin`` of each sole's half-lengths
    inside its edges), friction pyramid (with the wrench cone's yaw-moment rows on rectangle
    contacts if ``torsion``), joint acceleration limits."""
    if not isinstance(torsion, (bool, np.bool_)):
        raise TypeError(f"torsion: expected a bool, got {torsion!r}")
    cop_margin = number(cop_margin, "cop_margin", low=0.0, high=1.0, high_open=True)
    rows = []
    if any(robot.contact(c).spec.type == "rectangle" for c in contacts):
        rows.append(CenterOfPressure(name="center of pressure", weight=1e4, contacts=contacts,
                                     margin=cop_margin))
    rows.append(FrictionCone(_mu(robot, mu), name="friction", contacts=contacts,
                             torsion=bool(torsion)))
    rows.append(JointAccelerationLimits(name="joint acceleration limits"))
    return rows


#: Whether the stacks bound the soles' yaw moments (:class:`~wholebody.tasks.FrictionCone`'s
#: ``torsion``: the yaw-moment rows of each sole's contact wrench cone, Caron et al. 2015, 8 rows
#: per rectangle contact; with the pyramid and the CoP rows the wrenches that friction at the
#: sole's corners can carry). Not in the paper's tables, on by default here: without them nothing
#: in Tables 1/2/4 limits the yaw moments, and when the CoP rows bind (they are written in the
#: measured sole axes, so a fraction of a degree of tilt couples them to yaw) the cascade puts
#: large opposite yaw moments on the two soles (~100 Nm, up to 2500 Nm on talos14) and the robot
#: falls (docs/results.md, Fig. 10 rows); a bound on the yaw moment alone still lets a level
#: squeeze the feet sideways at their friction limit with the CoPs in the corners, which no sole
#: carries (docs/results.md, other robots). ``torsion=False`` gives the papers' 4 rows per contact.
TORSION = True

#: The CoP rows' margin (:class:`~wholebody.tasks.CenterOfPressure`): the CoP of every sole is
#: kept this share of its half-lengths inside its edges. Not in the paper's tables, whose CoP
#: constraint admits the whole sole; the paper's CoPs stay "in the interior of the foot soles
#: with a margin" (Sect. 5.2.3) and saturate "close to the heel" (Fig. 11). A CoP on an edge
#: leaves the opposite edge unloaded, and a sole that complies at all (the twin's soft contacts,
#: a real foot) then tips about it: narrow soles tipped in sideways pushes, on a rocking platform
#: and under repeated pushes (docs/results.md). ``cop_margin=0`` gives the paper's whole sole.
COP_MARGIN = 0.1

#: Weight of the angular rows of Table 2's momentum task (see :func:`table2_stack`). The paper's
#: single weight for the whole task is ``1e4`` (``angular_weight=1e4`` restores it).
ANGULAR_MOMENTUM_WEIGHT = 1e-4


def momentum_task(lqr: bool, angular_weight: float = 1e4):
    """The momentum task of level 3: LQR force law (eq. 24) or diagonal PD (eq. 22). Its six rows
    are [linear; angular] (momentum rates, or forces and moments for eq. 24); the linear rows weigh
    1e4, the angular rows ``angular_weight`` (finite, >= 0)."""
    weight = np.array([1e4] * 3 + [nonnegative(angular_weight, "angular_weight")] * 3)
    if lqr:
        return MomentumForce(name="momentum", weight=weight)
    return MomentumPD(name="momentum", weight=weight)


#: Weight of the posture task's rows (Sect. 5.2.1's 1e-1).
POSTURE_WEIGHT = 1e-1

#: (kp, kd) of the posture task, joints and base alike (1/s², 1/s): 7.1 rad/s, damping ratio 0.99
POSTURE_PD = (50.0, 14.0)
#: (kp, kd) of the swing-foot task of Tables 1 and 4 (1/s², 1/s): 20 rad/s, damping ratio 1
SWING_FOOT_PD = (400.0, 40.0)
#: (kp, kd) of the CoG task of Table 1 (1/s², 1/s): 10 rad/s, damping ratio 1
COM_PD = (100.0, 20.0)


def pd_gains(gains, name: str) -> tuple[float, float]:
    """``gains`` = (kp, kd) as two finite floats >= 0 (ValueError naming ``name``)."""
    try:
        kp, kd = gains
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected (kp, kd), got {gains!r}") from None
    return nonnegative(kp, f"{name} kp"), nonnegative(kd, f"{name} kd")


def posture_task(robot: Robot, base_orientation_weight: float | None = None,
                 gains=POSTURE_PD, weight=None) -> PostureTask:
    """The posture task (joints and base) with the PD ``gains``; its rows weigh ``weight``, or
    (None) :func:`posture_weight`."""
    kp, kd = pd_gains(gains, "posture_gains")
    weight = posture_weight(robot, base_orientation_weight) if weight is None else weight
    return PostureTask(name="posture", weight=weight, kp=kp, kd=kd, base_kp=kp, base_kd=kd)


def swing_tasks(swing_frames: Sequence[str], gains=SWING_FOOT_PD) -> list[FrameTask]:
    """One 6D swing-foot PD per frame of ``swing_frames``."""
    kp, kd = pd_gains(gains, "swing_gains")
    return [FrameTask(f, kp=kp, kd=kd, name=f"swing {f}", mask="6d") for f in swing_frames]


def posture_weight(robot: Robot, base_orientation_weight: float | None):
    """The posture task's row weights: :data:`POSTURE_WEIGHT` on every row, or with
    ``base_orientation_weight`` (finite, >= 0) that weight on the three rows of the base
    orientation (its rows are [base linear; base angular; joints], the velocity's layout)."""
    if base_orientation_weight is None:
        return POSTURE_WEIGHT
    w = np.full(robot.nv, POSTURE_WEIGHT)
    w[3:6] = nonnegative(base_orientation_weight, "base_orientation_weight")
    return w


def contact_constraint(robot: Robot, contacts: Sequence[str], posture_gains=POSTURE_PD,
                       weight: float = 1.0) -> ContactConstraint:
    """Eq. 2's contact constraint, J_c qdd + Jdot_c v = 0 on ``contacts``; when a leg cannot move
    its contact every way the contact constrains (a five-joint leg under a sole:
    :func:`~wholebody.robots.roles.leg_missing_directions`), with the contacts' velocity damped
    at the posture's rate (``posture_gains``' kd), J_c qdd + Jdot_c v = -kd J_c v (Fahmi et al.
    2019 eq. 32 without its anchor). Along the missing direction (no ankle roll: the sole's roll)
    the sole moves with the whole robot, held by nothing but the contact's compliance, and eq. 2
    keeps whatever velocity it has: on narrow soles (Unitree H1's 3 cm) the robot rocks on them,
    a 1 Hz oscillation that grows until it falls, at rest, under either momentum law
    (docs/results.md). On six-joint legs the constraint is the paper's (kd = 0)."""
    _, kd = pd_gains(posture_gains, "posture_gains")
    short = any(len(leg_missing_directions(robot, c)) for c in contacts)
    return ContactConstraint(name="contacts", contacts=contacts, weight=weight,
                             kd=kd if short else 0.0)


def table2_stack(robot: Robot, contacts: Sequence[str] | None = None, lqr: bool = False,
                 full: bool = False, mu: float | None = None,
                 angular_weight: float = ANGULAR_MOMENTUM_WEIGHT,
                 base_orientation_weight: float | None = None, torsion: bool = TORSION,
                 posture_gains=POSTURE_PD, cop_margin: float = COP_MARGIN) -> Stack:
    """Table 2, double support: (1) Newton-Euler + torque limits; (2) contact constraints, CoP,
    friction, joint acceleration limits; (3) momentum control, posture (joints + base), GRF
    regulariser.

    Weights of level 3 (rows are scaled by them, so costs go with their squares): linear momentum
    1e4, posture 1e-1, GRF regulariser 1e-4, and the angular-momentum rows ``angular_weight``
    (default 1e-4; the paper gives the whole momentum task one weight, 1e4). Why: with both feet
    locked, 8 of the 20 DoF are free; momentum takes 6 and the posture is meant to trade off against
    it on the same level (Sect. 5.2.1). Eq. 22 has no stiffness on the angular part (P [m e; 0]),
    nor has the LQR state an orientation, so the trunk orientation is held only by the posture's
    base rows. An angular-momentum row costs about I_G (~15 kg m^2 on talos14) per rad/s^2, so at
    1e4 against the posture's 1e-1 the posture has no say in those 3 directions: a bias torque from
    model errors (1 cm link CoM offsets: ~ m g x 1 cm ~ 10 Nm) then drives the pelvis away at a
    constant rate and the robot falls without any push (docs/results.md). The posture
    (base kp 50) holds the trunk only if the angular rows weigh less than the posture's by more
    than I_G, i.e. 1e-4 among the paper's {1e4, 1, 1e-1, 1e-4}; the angular momentum is then damped
    through the posture's base damping instead of eq. 22's D.

    ``contacts``: None = all the robot's contacts; an empty list means no contact: the contact
    tasks (contact constraints, friction, GRF regulariser) then have no rows and there is no CoP
    task — a stack for a robot with no support, to be solved with ``Variables(robot, [])``
    (:class:`~wholebody.control.balance.MomentumBalance` refuses it: balancing needs a contact).
    ``mu``: None = the robot's friction coefficient, else finite and > 0 (0 used to mean None).
    ``base_orientation_weight``: None = the posture's 1e-1 on all its rows, else the weight of its
    three base-orientation rows (:func:`posture_weight`). ``torsion`` (default :data:`TORSION`,
    True): the friction task's torsional rows on the rectangle contacts (the soles' yaw-moment
    bound, not in the paper); False gives the paper's friction pyramid only. ``posture_gains``:
    the posture's (kp, kd), :data:`POSTURE_PD` by default. ``cop_margin``: the share of each
    sole's half-lengths the CoP keeps inside its edges, in [0, 1) (:data:`COP_MARGIN`; 0: the
    paper's whole sole)."""
    contacts = _contacts(robot, contacts, "contacts", default_all=True)
    return Stack([
        _dynamics(full),
        [contact_constraint(robot, contacts, posture_gains)]
        + _contact_conditions(robot, contacts, mu, torsion, cop_margin),
        [momentum_task(lqr, angular_weight),
         posture_task(robot, base_orientation_weight, posture_gains),
         ForceRegularizer(name="force regularizer", weight=1e-4, contacts=contacts)],
    ])


def table4_stack(robot: Robot, stance: Sequence[str], swing_frames: Sequence[str] = (),
                 lqr: bool = False, full: bool = False, mu: float | None = None,
                 angular_weight: float = ANGULAR_MOMENTUM_WEIGHT,
                 base_orientation_weight: float | None = None, torsion: bool = TORSION,
                 posture_gains=POSTURE_PD, swing_gains=SWING_FOOT_PD,
                 cop_margin: float = COP_MARGIN) -> Stack:
    """Table 4, single support: (1) Newton-Euler + torque limits; (2) CoP, friction, joint
    acceleration limits; (3) momentum, contact constraints, swing-foot PD, posture; (4) GRF
    regulariser. ``stance``: the stance contacts (an empty list: none, the contact tasks have no
    rows).

    The angular-momentum rows weigh ``angular_weight`` (default 1e-4; the paper: 1e4) and the
    posture holds the base, as in :func:`table2_stack`, whose docstring gives the reason:
    neither eq. 22 nor the LQR state has the trunk orientation. ``base_orientation_weight``: as
    in :func:`table2_stack`; ``torsion``, ``cop_margin``: as in :func:`table2_stack`;
    ``posture_gains``, ``swing_gains``: the posture's and the swing-foot tasks' (kp, kd)."""
    stance = _contacts(robot, stance, "stance", default_all=False)
    return Stack([
        _dynamics(full),
        _contact_conditions(robot, stance, mu, torsion, cop_margin),
        [momentum_task(lqr, angular_weight),
         contact_constraint(robot, stance, posture_gains, weight=1e4)]
        + swing_tasks(swing_frames, swing_gains)
        + [posture_task(robot, base_orientation_weight, posture_gains)],
        [ForceRegularizer(name="force regularizer", weight=1e-4, contacts=stance)],
    ])


def table1_stack(robot: Robot, stance: Sequence[str], swing_frames: Sequence[str] = (),
                 full: bool = False, mu: float | None = None, torsion: bool = TORSION,
                 posture_gains=POSTURE_PD, swing_gains=SWING_FOOT_PD,
                 com_gains=COM_PD, cop_margin: float = COP_MARGIN) -> Stack:
    """Table 1, the stepping benchmark: (1) dynamics + torque limits; (2) contact constraints, CoP,
    friction, joint acceleration limits; (3) CoG PD + swing-foot PD; (4) posture (joints + base);
    (5) GRF regulariser. ``stance``: the stance contacts (an empty list: none, the contact tasks
    have no rows). ``torsion``, ``cop_margin``: as in :func:`table2_stack`; ``posture_gains``,
    ``swing_gains``, ``com_gains``: the posture's, the swing-foot tasks' and the CoG task's
    (kp, kd)."""
    stance = _contacts(robot, stance, "stance", default_all=False)
    com_kp, com_kd = pd_gains(com_gains, "com_gains")
    return Stack([
        _dynamics(full),
        [contact_constraint(robot, stance, posture_gains)]
        + _contact_conditions(robot, stance, mu, torsion, cop_margin),
        [CoMTask(name="com", kp=com_kp, kd=com_kd)] + swing_tasks(swing_frames, swing_gains),
        [posture_task(robot, gains=posture_gains, weight=1.0)],  # alone on its level
        [ForceRegularizer(name="force regularizer", contacts=stance)],
    ])
