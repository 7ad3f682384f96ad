"""The three cases of the peer comparison, written once for every side.

Pure Python + numpy: imported by run_wholebody.py (wholebody's venv), run_placo.py and run_tsid.py
(the peers' own venvs). Weights are *row scales* s as in wholebody (a row r costs s^2 |r|^2);
placo and TSID weigh the squared residual directly, so they get s^2 (:func:`quadratic_weight`).

Every case is solved by each side as: hard = rigid-body dynamics (the base rows), rigid contacts
(zero contact acceleration) and their friction / contact wrench cones, torque limits (and for the
Talos cases joint limits as acceleration bounds); soft = the motion tasks below, each with the
same PD gains, references and weights, and a small contact-force regulariser.
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
PEERS_DIR = os.environ.get("PEERS_DIR", "/work/peers")

# --- the cases -------------------------------------------------------------------------------
# task kinds: "com" (CoM PD; kp, kd), "orientation" (a frame's orientation PD; frame, kp, kd),
# "posture" (joint PD; kp, kd; base=True adds a 6D PD of the base frame to its reference),
# "angular_momentum" (damping kd towards zero), "force_regularizer" (contact forces -> 0).
CASES = {
    "hyq": {
        "title": "HyQ, TSID-style weighted task set",
        "preset": "hyq",
        "contacts": [{"frame": f, "type": "point"} for f in ("lf_foot", "rf_foot", "lh_foot", "rh_foot")],
        "mu": 0.7,
        "joint_limits": False,
        "tasks": [
            {"kind": "com", "kp": 100.0, "kd": 20.0, "weight": 1.0},
            {"kind": "orientation", "frame": "trunk", "kp": 100.0, "kd": 20.0, "weight": 1.0},
            {"kind": "posture", "kp": 50.0, "kd": 14.0, "weight": 0.1, "base": False},
            {"kind": "force_regularizer", "weight": 1e-2},
        ],
        "wholebody": ["weighted", "2level"],
    },
    "talos14": {
        "title": "talos14 (14 DoF), Table 2 tasks",
        "preset": "talos14",
        "contacts": [{"frame": f, "type": "rectangle", "half_size": [0.105, 0.065]}
                     for f in ("left_sole_link", "right_sole_link")],
        "mu": 0.8,
        "cop_margin": 0.1,
        "joint_limits": True,
        # Table 2's level 3: momentum PD (eq. 22: P = 50, D = 15 linear, 5 angular; linear rows
        # weigh 1e4 in N, i.e. 1e4 m in m/s^2 on the CoM), posture (joints + base, 1e-1),
        # force regulariser 1e-4; the angular-momentum rows weigh 1e-4.
        "tasks": [
            {"kind": "com", "kp": 50.0, "kd": 15.0, "weight": "1e4*mass"},
            {"kind": "angular_momentum", "kd": 5.0, "weight": 1e-4},
            {"kind": "posture", "kp": 50.0, "kd": 14.0, "weight": 0.1, "base": True},
            {"kind": "force_regularizer", "weight": 1e-4},
        ],
        "wholebody": ["cascade", "weighted", "2level"],
    },
    "talos": {
        "title": "Talos (32 DoF), Table 1 tasks (double support)",
        "preset": "talos",
        "contacts": [{"frame": f, "type": "rectangle", "half_size": [0.105, 0.065]}
                     for f in ("left_sole_link", "right_sole_link")],
        "mu": 0.8,
        "cop_margin": 0.1,
        "joint_limits": True,
        # Table 1's levels 3-5 (CoG PD; posture with base; force regulariser) as one weighted
        # objective: 10 > 1 > 1e-2 stands for the strict order of the cascade.
        "tasks": [
            {"kind": "com", "kp": 100.0, "kd": 20.0, "weight": 10.0},
            {"kind": "posture", "kp": 50.0, "kd": 14.0, "weight": 1.0, "base": True},
            {"kind": "force_regularizer", "weight": 1e-2},
        ],
        "wholebody": ["cascade", "weighted", "2level"],
    },
}

#: joint-limit braking horizon (s) for the acceleration bounds of the Talos cases (all sides)
JOINT_LIMIT_DT = 0.01


def weight(task: dict, mass: float) -> float:
    """A task's row scale (the string form "1e4*mass" scales with the robot's mass)."""
    w = task["weight"]
    if isinstance(w, str):
        factor, _ = w.split("*")
        return float(factor) * mass
    return float(w)


def quadratic_weight(task: dict, mass: float) -> float:
    """The weight on the squared residual (placo, TSID): the row scale squared."""
    return weight(task, mass) ** 2


def describe(case: dict) -> str:
    parts = []
    for t in case["tasks"]:
        k = t["kind"]
        w = t["weight"]
        if k == "com":
            parts.append(f"CoM PD {t['kp']:g}/{t['kd']:g} w {w}")
        elif k == "orientation":
            parts.append(f"{t['frame']} orientation {t['kp']:g}/{t['kd']:g} w {w}")
        elif k == "posture":
            parts.append(f"posture{' +base' if t['base'] else ''} {t['kp']:g}/{t['kd']:g} w {w}")
        elif k == "angular_momentum":
            parts.append(f"angular momentum D {t['kd']:g} w {w}")
        elif k == "force_regularizer":
            parts.append(f"force reg w {w}")
    return "; ".join(parts)


def states_path(case: str) -> str:
    return os.path.join(PEERS_DIR, "states", f"{case}.npz")


# --- a reduced URDF (for placo, which loads a URDF, not a Pinocchio model) -------------------

def _rpy_to_matrix(r, p, y):
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _matrix_to_rpy(R):
    p = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(p)) < 1e-9:  # gimbal lock: put everything in yaw
        return 0.0, p, math.atan2(-R[0, 1], R[1, 1])
    return math.atan2(R[2, 1], R[2, 2]), p, math.atan2(R[1, 0], R[0, 0])


def _axis_angle(axis, angle):
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def reduced_urdf(urdf_path: str, locked: dict[str, float], strip_geometry: bool = True) -> str:
    """The URDF text with each joint of ``locked`` (name -> angle) made fixed at that angle (what
    Pinocchio's buildReducedModel does to the model), and without visual/collision elements
    (geometry plays no part in the dynamics)."""
    tree = ET.parse(urdf_path)
    root = tree.getroot()
    for joint in root.findall("joint"):
        name = joint.get("name")
        if name not in locked:
            continue
        kind = joint.get("type")
        origin = joint.find("origin")
        if origin is None:
            origin = ET.SubElement(joint, "origin")
        xyz = [float(x) for x in (origin.get("xyz") or "0 0 0").split()]
        rpy = [float(x) for x in (origin.get("rpy") or "0 0 0").split()]
        axis_el = joint.find("axis")
        axis = [float(x) for x in axis_el.get("xyz").split()] if axis_el is not None else [1, 0, 0]
        R = _rpy_to_matrix(*rpy)
        t = np.array(xyz)
        if kind in ("revolute", "continuous"):
            R = R @ _axis_angle(axis, locked[name])
        elif kind == "prismatic":
            t = t + R @ (np.asarray(axis, float) / np.linalg.norm(axis)) * locked[name]
        else:
            raise ValueError(f"reduced_urdf: cannot lock a {kind} joint ({name})")
        origin.set("xyz", " ".join(repr(float(x)) for x in t))
        origin.set("rpy", " ".join(repr(float(x)) for x in _matrix_to_rpy(R)))
        joint.set("type", "fixed")
        for tag in ("axis", "limit", "dynamics", "mimic", "safety_controller", "calibration"):
            for el in joint.findall(tag):
                joint.remove(el)
    if strip_geometry:
        for link in root.findall("link"):
            for tag in ("visual", "collision"):
                for el in link.findall(tag):
                    link.remove(el)
    text = ET.tostring(root, encoding="unicode")
    return re.sub(r"^<\?xml[^>]*>", "", text)


# --- the worker protocol shared by the three runners ----------------------------------------

def serve(solve_one, acceleration_of_com, n_states: int, solved: str = "", warmup: int = 50):
    """The runners' loop. ``solve_one(i) -> (seconds, tau, qdd, ok)`` solves state i (the time
    covers the whole cycle: model update from (q, v), task rows, QP, torques);
    ``acceleration_of_com(i, qdd)`` is the CoM acceleration that qdd gives at state i (not timed).

    Protocol, one line each on stdin: ``run START STOP`` -> one JSON line {"times": [...]} with
    the seconds of states START..STOP-1 (after warm-up the runner prints {"ready": true,
    "solved": SOLVED}, what it solves); ``save PATH`` -> the last tau, CoM acceleration and
    success flag of every state solved so far, to an .npz; ``quit``. Standalone (no driver):
    ``--all`` runs every state once and prints the JSON times."""
    import json
    import sys

    taus, qdds, oks = {}, {}, {}

    def run(a, b):
        times = []
        for i in range(a, b):
            dt, tau, qdd, ok = solve_one(i)
            times.append(dt)
            taus[i], qdds[i], oks[i] = tau, qdd, ok
        return times

    for i in range(min(warmup, n_states)):
        solve_one(i)
    if "--all" in sys.argv:
        print(json.dumps({"times": run(0, n_states)}))
        return
    print(json.dumps({"ready": True, "solved": solved}), flush=True)
    for line in sys.stdin:
        words = line.split()
        if not words:
            continue
        if words[0] == "quit":
            break
        if words[0] == "run":
            print(json.dumps({"times": run(int(words[1]), int(words[2]))}), flush=True)
        elif words[0] == "save":
            idx = sorted(taus)
            np.savez(words[1], index=np.array(idx), tau=np.array([taus[i] for i in idx]),
                     a_com=np.array([acceleration_of_com(i, qdds[i]) for i in idx]),
                     ok=np.array([oks[i] for i in idx]))
            print(json.dumps({"saved": words[1]}), flush=True)
