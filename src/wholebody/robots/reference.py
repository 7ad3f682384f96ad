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


def froude_ratio(robot) -> float:
    """sqrt(h / BASE_HEIGHT) of ``robot`` (its standing base height h = ``robot.q_ref[2]``):
    speeds and times of HyQ's gaits times this, frequencies divided by it; exactly 1 on HyQ."""
    return math.sqrt(float(robot.q_ref[2]) / BASE_HEIGHT)
