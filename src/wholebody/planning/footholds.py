"""Footholds: where a swinging foot should land (Raibert-style heuristic) and the nominal footprint.

Fahmi et al. 2019 (Fig. 1 and Sect. II) take the swing-foot targets from a planner
("Given high-level user velocity commands, the planner generates a reference motion online [20]").
The heuristic planner of their ref. [20] places each foot, like Raibert's hoppers, relative to the
hip: at touchdown the foot is put ahead of the hip by half the distance the hip will travel during
the stance, so that the hip passes over the foot at mid-stance,

    p_td = hip(t_td) + v_cmd * T_stance / 2 + k (v - v_cmd),

with an optional feedback on the velocity error. The point is then dropped onto the terrain, whose
normal there is returned too (the friction cones of eq. 13 need it, footnote 17).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from .terrain import Terrain

FREE_FLYER_NQ = 7


@dataclass(frozen=True)
class Foothold:
    """A touchdown target.

    ``point``: the contact point on the terrain; ``normal``: the unit terrain normal there;
    ``position``: where the foot *frame* should be, ``point + foot_radius * normal`` (a point foot's
    frame sits at the centre of its sphere, one radius off the ground).
    """

    point: np.ndarray
    normal: np.ndarray
    position: np.ndarray


def raibert_foothold(hip, v_cmd, stance_duration: float, terrain: Terrain | None = None,
                     velocity=None, gain: float = 0.0, foot_radius: float = 0.0,
                     max_offset: float | None = None) -> Foothold:
    """Raibert-style touchdown target.

    ``hip``: horizontal position (x, y [, z ignored]) of the nominal foot position under the hip at
    the touchdown time; ``v_cmd``: commanded horizontal velocity of that hip (world axes);
    ``stance_duration``: T_stance of the leg; ``velocity``: measured horizontal velocity for the
    feedback term ``gain * (velocity - v_cmd)`` (omitted: no feedback); ``max_offset``: clamp on the
    horizontal distance from the hip (None: no clamp). The target is projected vertically onto
    ``terrain`` (default flat z = 0).
    """
    terrain = Terrain.flat() if terrain is None else terrain
    hip = np.asarray(hip, dtype=float)
    v_cmd = np.asarray(v_cmd, dtype=float)
    if not (np.isfinite(stance_duration) and stance_duration >= 0.0):
        raise ValueError(f"stance_duration: must be a finite time >= 0, got {stance_duration}")
    offset = v_cmd[:2] * (0.5 * stance_duration)
    if velocity is not None and gain != 0.0:
        offset = offset + gain * (np.asarray(velocity, dtype=float)[:2] - v_cmd[:2])
    if max_offset is not None:
        norm = float(np.hypot(offset[0], offset[1]))
        if norm > max_offset:
            offset = offset * (max_offset / norm)
    x, y = hip[0] + offset[0], hip[1] + offset[1]
    point = np.array([x, y, terrain.height(x, y)])
    normal = terrain.normal(x, y)
    return Foothold(point, normal, point + foot_radius * normal)


@dataclass(frozen=True)
class Footprint:
    """The nominal stance of a quadruped, from a standing posture.

    ``feet``: (n, 3) foot-frame positions in the base frame; ``com``: (3,) CoM in the base frame;
    ``base_height``: base height above the ground; ``foot_radius``: per-foot sphere radius (n,).
    The "hip positions" of the foothold heuristic are ``feet[:, :2]``: the nominal foot positions
    under the hips, relative to the base.
    """

    legs: tuple[str, ...]
    feet: np.ndarray
    com: np.ndarray
    base_height: float
    foot_radius: np.ndarray

    @classmethod
    def from_robot(cls, robot, q=None, legs=None) -> "Footprint":
        """Footprint of ``robot`` at ``q`` (default: its standing posture ``robot.q_ref``, feet on
        z = 0). Uses its own Pinocchio data: the robot's per-cycle cache is not touched."""
        q = robot.q_ref if q is None else np.asarray(q, dtype=float)
        legs = tuple(robot.contact_names) if legs is None else tuple(legs)
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, q)
        com_world = pin.centerOfMass(robot.model, data, q)
        base = q[:3]
        R = pin.Quaternion(q[3:7]).normalized().toRotationMatrix()
        feet, radius, lowest = [], [], []
        for leg in legs:
            c = robot.contact(leg)
            p = data.oMf[c.frame_id].translation
            feet.append(R.T @ (p - base))
            radius.append(float(c.spec.radius) if c.spec.type == "point" else 0.0)
            lowest.append(p[2] - radius[-1])
        return cls(legs, np.array(feet), R.T @ (com_world - base),
                   float(base[2] - min(lowest)), np.array(radius))

    @property
    def n_legs(self) -> int:
        return len(self.legs)

    def centered_on_com(self) -> "Footprint":
        """The same stance shifted horizontally so that the feet's centroid lies under the CoM.

        A trot stands on one diagonal at a time; no force on two point feet makes a moment about
        the line between them, so a CoM off that line tips the trunk. HyQ's CoM is 3.9 cm ahead of
        and 1.5 cm beside its feet's centroid in the standing posture: centring the footprint on the
        CoM removes that tipping moment and so reduces the trot's trunk-orientation error."""
        feet = self.feet.copy()
        feet[:, :2] += self.com[:2] - feet[:, :2].mean(axis=0)
        return replace(self, feet=feet)

    def feet_from_com(self) -> np.ndarray:
        """(n, 2) horizontal nominal foot positions relative to the CoM, in the heading frame."""
        return self.feet[:, :2] - self.com[:2]

    def index(self, leg: str | int) -> int:
        if isinstance(leg, (int, np.integer)):
            return int(leg)
        return self.legs.index(leg)
