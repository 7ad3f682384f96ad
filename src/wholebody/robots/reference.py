"""The robots the papers' numbers were set on, from which robot-relative defaults scale.

Fahmi et al. 2019 tuned its gains, force bounds, speeds and set-ups on HyQ; these are the hyq
preset's own quantities (``hyq_no_sensors.urdf`` at the SRDF's ``standing`` posture), so that HyQ
gets the paper's numbers exactly and any other robot the same proportions and dynamics:

- forces and stiffnesses scale with the mass ``MASS``, rotational gains with ``INERTIA``;
- lengths scale with the standing base height h (``BASE_HEIGHT``), times and speeds with
  :func:`froude_ratio` = sqrt(h / BASE_HEIGHT), which keeps a gait's Froude number v² / (g h) and
  makes its steps dynamically similar.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .roles import leg_joints

MASS = 86.77400500000003  # kg
INERTIA = 9.3599731892699  # kg m², trace(I_G) / 3 (wholebody.tasks.wrench.trunk_inertia)
BASE_HEIGHT = 0.5992595750374548  # m, the base above the floor standing (robot.q_ref[2])
#: tan ψ of the angle ψ between the heading and a diagonal of the standing feet: the feet's mean
#: lateral over their mean fore-aft distance from their centroid
#: (wholebody.tasks.wrench.stance_aspect)
STANCE_ASPECT = 0.8740296557577911
#: the humanoid our push set-ups (Herzog et al. 2016 Sect. 5.2.2 on talos14) were made for: its
#: standing base height (m), from which push points and lifts scale, and its mass (kg), from which
#: push forces scale
HUMANOID_BASE_HEIGHT = 1.0193830429027237
HUMANOID_MASS = 90.27219199999999
#: talos14's :func:`leg_stretch` (m), from which the squat's vertical amplitude scales
HUMANOID_LEG_STRETCH = 0.06368083348448195


def humanoid_length_ratio(robot) -> float:
    """h / h_talos14: ``robot``'s standing base height (``robot.q_ref[2]``) over talos14's, the
    scale of the humanoid set-ups' lengths; exactly 1 on talos14."""
    return float(robot.q_ref[2]) / HUMANOID_BASE_HEIGHT


def humanoid_mass_ratio(robot) -> float:
    """m / m_talos14, the scale of the humanoid set-ups' forces; exactly 1 on talos14."""
    return float(robot.mass) / HUMANOID_MASS


def length_ratio(robot) -> float:
    """``robot``'s standing base height over that of the reference robot of its kind: talos14's
    for a robot standing on soles (Herzog et al. 2016's set-ups), HyQ's for one on point feet
    (Fahmi et al. 2019's); exactly 1 on talos14 and on HyQ."""
    if any(robot.contact(c).spec.type == "rectangle" for c in robot.contact_names):
        return humanoid_length_ratio(robot)
    return float(robot.q_ref[2]) / BASE_HEIGHT


def froude_ratio(robot) -> float:
    """sqrt(h / BASE_HEIGHT) of ``robot`` (its standing base height h = ``robot.q_ref[2]``):
    speeds and times of HyQ's gaits times this, frequencies divided by it; exactly 1 on HyQ."""
    return math.sqrt(float(robot.q_ref[2]) / BASE_HEIGHT)


def leg_stretch(robot) -> float:
    """How far (m) the legs can stretch from the posture: for each contact's leg (its joints from
    :func:`~wholebody.robots.roles.leg_joints`), the distance between its first and its last
    joint (hip and ankle) with every leg joint at its value nearest zero within its limits (a
    URDF's zero pose stands straight) minus that distance in the posture ``robot.q_ref``; the
    smallest over the legs. A CoG rising by more than this straightens a leg onto its limits."""
    model = robot.model
    data = model.createData()

    def span(q, first, last):
        pin.forwardKinematics(model, data, q)
        return float(np.linalg.norm(data.oMi[first].translation - data.oMi[last].translation))

    stretch = []
    for contact in robot.contact_names:
        joints = [model.getJointId(j) for j in leg_joints(robot, contact)]
        if len(joints) < 2:
            continue
        straight = robot.q_ref.copy()
        for j in joints:
            if model.joints[j].nq != 1:  # a continuous joint (cos, sin) keeps its posture
                continue
            i = model.joints[j].idx_q
            straight[i] = min(max(0.0, model.lowerPositionLimit[i]), model.upperPositionLimit[i])
        stretch.append(span(straight, joints[0], joints[-1])
                       - span(robot.q_ref, joints[0], joints[-1]))
    return min(stretch) if stretch else 0.0
