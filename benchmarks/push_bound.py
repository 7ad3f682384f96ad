"""The strongest push a standing humanoid can recover from without stepping, whatever its controller.

An upper bound for the push thresholds of ``wholebody run push-series``: the largest velocity
change ``dv`` of a 0.1 s half-sine push for which some ground reaction keeps the CoP inside the
soles, within friction, and brings the robot to rest (CoG at rest over the soles, no angular
momentum) within the scenario's time, on the planar centroidal model along the push (the robot
lumped into its CoM and its locked centroidal inertia I_G about the horizontal axis across the
push, Herzog et al. 2016 eq. 21 with a constant CoM height)::

    m u''   = f + F(t)
    L'      = -z0 f - (p - u) m g + d F(t)      (about the CoM; f, p the ground force and CoP)
    phi'    = L / I_G                            (the body's mean rotation, the "hip strategy")

``F`` is the push, ``d`` the push point's height above the CoM, ``z0`` the CoM height above the
soles. A feasibility LP per dv (force and CoP held over 10 ms steps, the model discretised exactly;
HiGHS's interior point, which stays quick near the boundary where its simplex can stall),
bisected, for several bounds on |phi|: a small bound keeps the body from turning (the CoP must
take out at once the angular momentum the push brings), larger ones allow a hip strategy. It
ignores joint ranges, torque limits and the feet's compliance (the scenarios count a foot tilted
by 2 degrees as a failure, the LP lets the CoP sit on the edge), so the real thresholds lie below.

Run: ``.venv/bin/python benchmarks/push_bound.py [--robot talos14] [--phi 1,10,20,30,90]
[--sole-fraction 0.8]``
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp

import wholebody as wb
from wholebody.robots.roles import biped_soles
from wholebody.scenarios.pushes import LOCATIONS, push_point


def push_geometry(robot, location: str, sole_fraction: float = 1.0) -> dict:
    """Support interval along the push direction (the soles shrunk about their centres to
    ``sole_fraction`` of their size), CoM height, push point height above the CoM and the inertia
    about the axis across the push, at the reference posture."""
    robot.update(robot.q_ref, np.zeros(robot.nv))
    part, direction, offset = LOCATIONS[location]
    u = np.asarray(direction, float)
    frame, point = push_point(robot, part, offset)
    pos, R = robot.frame_placement(frame)
    height = float((pos + R @ point)[2] - robot.com[2])
    corners = []
    for name in biped_soles(robot):
        c = robot.contact(name)
        origin = robot.contact_point(name)
        _, Rc = robot.frame_placement(c.frame)
        hx, hy = sole_fraction * np.asarray(c.spec.half_size)
        corners += [origin + Rc @ np.array([sx * hx, sy * hy, 0.0]) for sx in (-1, 1) for sy in (-1, 1)]
    along = np.array([u @ (k - robot.com) for k in corners])
    ground = float(np.mean([k[2] for k in corners]))
    axis = np.cross([0.0, 0.0, 1.0], u)
    return {"support": (float(along.min()), float(along.max())), "z0": float(robot.com[2] - ground),
            "push_height": height, "inertia": float(axis @ robot.centroidal_inertia() @ axis),
            "mass": robot.mass, "gravity": float(np.linalg.norm(robot.model.gravity.linear))}


def discrete_model(geom: dict, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation of the planar model, state ``[u, u', L, phi]``, inputs
    ``[f, p, F]`` held over each step: ``x+ = Ad x + Bd w``."""
    m, g, z0, d, inertia = (geom[k] for k in ("mass", "gravity", "z0", "push_height", "inertia"))
    A = np.zeros((4, 4))
    A[0, 1], A[2, 0], A[3, 2] = 1.0, m * g, 1.0 / inertia
    B = np.zeros((4, 3))
    B[1] = [1.0 / m, 0.0, 1.0 / m]
    B[2] = [-z0, -m * g, d]
    E = scipy.linalg.expm(np.block([[A, B], [np.zeros((3, 7))]]) * dt)
    return E[:4, :4], E[:4, 4:]


def recoverable(geom: dict, dv: float, phi_max: float, mu: float = 1.0, duration: float = 0.1,
                horizon: float = 3.0, dt: float = 0.01) -> bool:
    """True if the LP finds a ground reaction (force and CoP held over ``dt`` steps) that brings
    the planar model to rest; the push enters as its mean over each step."""
    m, g = geom["mass"], geom["gravity"]
    lo, hi = geom["support"]
    n = int(round(horizon / dt))
    edges = np.minimum(dt * np.arange(n + 1), duration)
    peak = 0.5 * np.pi * m * dv / duration
    push = peak * duration / np.pi * np.diff(-np.cos(np.pi * edges / duration)) / dt
    Ad, Bd = discrete_model(geom, dt)
    # variables: states x_k (4 each, k = 0..n), then inputs (f_k, p_k), k = 0..n-1
    ns = 4 * (n + 1)
    nvar = ns + 2 * n
    rows, cols, vals, rhs = [], [], [], []
    for i in range(4):  # at rest, upright, CoM at the origin
        rows.append(len(rhs))
        cols.append(i)
        vals.append(1.0)
        rhs.append(0.0)
    for k in range(n):  # x_{k+1} - Ad x_k - Bd[:, :2] (f_k, p_k) = Bd[:, 2] F_k
        for i in range(4):
            r = len(rhs)
            entries = [(4 * (k + 1) + i, 1.0)] + [(4 * k + j, -Ad[i, j]) for j in range(4)] \
                + [(ns + 2 * k + j, -Bd[i, j]) for j in range(2)]
            for c, v in entries:
                if v != 0.0:
                    rows.append(r)
                    cols.append(c)
                    vals.append(v)
            rhs.append(Bd[i, 2] * push[k])
    for i in (1, 2):  # at rest at the end: no velocity, no angular momentum
        rows.append(len(rhs))
        cols.append(4 * n + i)
        vals.append(1.0)
        rhs.append(0.0)
    A = sp.csr_matrix((vals, (rows, cols)), shape=(len(rhs), nvar))
    bounds = [(None, None)] * nvar
    for k in range(n + 1):
        bounds[4 * k] = (lo, hi)
        bounds[4 * k + 3] = (-phi_max, phi_max)
    for k in range(n):
        bounds[ns + 2 * k] = (-mu * m * g, mu * m * g)
        bounds[ns + 2 * k + 1] = (lo, hi)
    res = scipy.optimize.linprog(np.zeros(nvar), A_eq=A, b_eq=np.array(rhs), bounds=bounds,
                                 method="highs-ipm")
    return res.status == 0


def threshold(geom: dict, phi_max: float, steps: int = 12, high: float = 1.5) -> float:
    """Largest recoverable dv by bisection on [0, high]."""
    lo, hi = 0.0, high
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if recoverable(geom, mid, phi_max) else (lo, mid)
    return lo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="talos14")
    parser.add_argument("--phi", default="1,10,20,30,90",
                        help="bounds on the body's mean rotation |phi| (deg), comma-separated")
    parser.add_argument("--sole-fraction", type=float, default=1.0,
                        help="the part of each sole (about its centre) the CoP may use")
    args = parser.parse_args()
    robot = wb.load_robot(args.robot)
    phis = [float(x) for x in args.phi.split(",")]
    print(f"{args.robot}: largest recoverable dv (m/s) of a 0.1 s half-sine push, feet in place, "
          f"CoP on {args.sole_fraction:g} of each sole, planar centroidal LP (an upper bound)")
    print("| point | support behind / ahead (m) | push height over CoM (m) | "
          + " | ".join(f"|phi| <= {p:g} deg" for p in phis) + " |")
    print("|---|---|---|" + "---|" * len(phis))
    for location in LOCATIONS:
        geom = push_geometry(robot, location, args.sole_fraction)
        lo, hi = geom["support"]
        values = [threshold(geom, np.radians(p)) for p in phis]
        print(f"| {location} | {-lo:.3f} / {hi:.3f} | {geom['push_height']:.3f} | "
              + " | ".join(f"{v:.3f}" for v in values) + " |", flush=True)


if __name__ == "__main__":
    main()
