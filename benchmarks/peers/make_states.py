"""Write the states and the shared references of every case to $PEERS_DIR/states/<case>.npz.

Runs in wholebody's environment (its robot presets define the models and postures):

    PYTHONPATH=src python benchmarks/peers/make_states.py [--states 2000]

Per case: ``q`` (N, nq), ``v`` (N, nv) — Pinocchio's conventions (free flyer [x y z qx qy qz qw],
base velocity in the base frame), which all three sides use — from ``Robot.smooth_motion`` (a
smooth motion around the posture); the model (URDF path, joints locked at which angles, armature),
the reference posture, the CoM and frame references, the torque limits at the reference posture,
the mass matrix at the reference posture (each peer checks its own model against it).
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np
import pinocchio as pin

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cases  # noqa: E402
import wholebody as wb  # noqa: E402
from wholebody.robots.locate import resolve_model_path  # noqa: E402


def erd_path(spec: str) -> str:
    """A preset's "erd:..." path, resolved as wholebody resolves it."""
    return str(resolve_model_path(spec))


def preset(name: str) -> dict:
    import tomllib
    path = os.path.join(os.path.dirname(wb.__file__), "robots", "presets", f"{name}.toml")
    with open(path, "rb") as f:
        return tomllib.load(f)


def case_states(name: str, case: dict, n: int) -> dict:
    robot = wb.load_robot(case["preset"])
    p = preset(case["preset"])
    urdf, srdf = erd_path(p["urdf"]), erd_path(p["srdf"])
    locked_names = list(p.get("locked_joints", []))
    locked_angles = []
    if locked_names:  # the locked joints' angles in the full model's posture
        full = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
        pin.loadReferenceConfigurations(full, srdf, False)
        q_full = full.referenceConfigurations[p["posture"]]
        for j in locked_names:
            locked_angles.append(float(q_full[full.joints[full.getJointId(j)].idx_q]))
    model, data = robot.model, robot.model.createData()
    q_ref = robot.q_ref.copy()
    pin.forwardKinematics(model, data, q_ref)
    pin.updateFramePlacements(model, data)
    com_ref = pin.centerOfMass(model, data, q_ref).copy()
    frames = {t["frame"] for t in case["tasks"] if t["kind"] == "orientation"}
    frames |= {c["frame"] for c in case["contacts"]}
    frames.add(robot.base_frame)
    placements = {f: data.oMf[model.getFrameId(f)].homogeneous.copy() for f in frames}
    M_ref = pin.crba(model, data, q_ref)
    M_ref = np.triu(M_ref) + np.triu(M_ref, 1).T
    _, tau_max = robot.torque_bounds(q_ref)
    motion = robot.smooth_motion(n)
    out = {
        "q": np.array([q for q, _ in motion]), "v": np.array([v for _, v in motion]),
        "q_ref": q_ref, "com_ref": com_ref, "mass": robot.mass, "M_ref": M_ref,
        "tau_max": np.asarray(tau_max, float), "joint_names": np.array(robot.joint_names),
        "armature": model.armature[6:].copy(), "urdf": urdf, "srdf": srdf,
        "locked_names": np.array(locked_names, dtype=str), "locked_angles": np.array(locked_angles),
        "base_frame": robot.base_frame, "placement_frames": np.array(sorted(placements)),
        "placements": np.array([placements[f] for f in sorted(placements)]),
        "q_min": robot.q_min, "q_max": robot.q_max,
    }
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--cases", default=",".join(cases.CASES))
    args = parser.parse_args()
    os.makedirs(os.path.dirname(cases.states_path("x")), exist_ok=True)
    for name in args.cases.split(","):
        data = case_states(name, cases.CASES[name], args.states)
        np.savez(cases.states_path(name), **data)
        print(f"{name}: {len(data['q'])} states, nq {data['q'].shape[1]}, "
              f"{len(data['joint_names'])} joints -> {cases.states_path(name)}")


if __name__ == "__main__":
    main()
