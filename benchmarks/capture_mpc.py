"""A prototype push-recovery MPC on the model of push_bound.py — an experiment, not in the library.

Per horizontal axis, the planar centroidal model of ``push_bound.py`` (CoM, its velocity, the
angular momentum about it, the body's rotation; force and CoP held over 20 ms steps) is
predicted 1 s ahead and a QP (DAQP) picks the ground force and CoP: min sum of
``w_u u² + w_v u'² + w_L L² + w_phi phi² + w_f f² + w_p p²`` with the CoP in the soles shrunk to
``sole`` of their size (sideways also times ``lateral``), |phi| <= 10°, friction 0.7. Replanned
every 10 ms from the measured state (CoM, centroidal momentum, the base's rotation), its first
step gives ``hdot`` to :class:`~wholebody.control.balance.MomentumBalance`'s momentum PD with zero
horizontal gains (the vertical keeps eq. 22's P = 50, D = 15; yaw damping 5), angular rows at
weight 1. The push itself is unknown to it. Herzog et al. 2016 has no such planner; it is here to
test whether planning within the CoP bounds closes the gap docs/results.md reports.

Run: ``.venv/bin/python benchmarks/capture_mpc.py --dv 0.3 [--locations front,...]
[--lateral 0.7] [--bisect 0.2,0.4,5]``
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin

import wholebody as wb
from wholebody.control.balance import BalanceReference, MomentumBalance
from wholebody.scenarios.push import PARAMETERS, with_peak_force
from wholebody.scenarios.pushes import LOCATIONS, push_trial
from wholebody.solvers.backends import solve_daqp_qp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import push_bound  # noqa: E402

WEIGHTS = {"u": 1e4, "v": 1e2, "L": 1.0, "phi": 1e3, "f": 1e-5, "p": 1.0}


class AxisMPC:
    """The condensed QP of one axis: states ``Phi x0 + Gamma w``, inputs ``w = (f_k, p_k)``."""

    def __init__(self, geom: dict, dt: float = 0.02, steps: int = 50, phi_max: float = 10.0,
                 mu: float = 0.7):
        self.geom = geom
        Ad, Bd = push_bound.discrete_model(geom, dt)
        B = Bd[:, :2]
        n = 4
        self.Phi = np.zeros((steps * n, n))
        self.Gamma = np.zeros((steps * n, 2 * steps))
        powers = [np.eye(n)]
        for _ in range(steps):
            powers.append(Ad @ powers[-1])
        for k in range(steps):
            self.Phi[k * n:(k + 1) * n] = powers[k + 1]
            for j in range(k + 1):
                self.Gamma[k * n:(k + 1) * n, 2 * j:2 * j + 2] = powers[k - j] @ B
        self.Q = np.kron(np.eye(steps), np.diag([WEIGHTS[k] for k in ("u", "v", "L", "phi")]))
        R = np.kron(np.eye(steps), np.diag([WEIGHTS["f"], WEIGHTS["p"]]))
        H = self.Gamma.T @ self.Q @ self.Gamma + R
        self.H = 0.5 * (H + H.T)
        lo, hi = geom["support"]
        f_max = mu * geom["mass"] * geom["gravity"]
        self.lower = np.tile([-f_max, lo], steps)
        self.upper = np.tile([f_max, hi], steps)
        self.phi_rows = self.Gamma[3::4]
        self.phi_max = np.radians(phi_max)
        self.linear = self.Gamma.T @ self.Q @ self.Phi  # the cost's linear term is linear @ x0
        self.phi_free = self.Phi[3::4]  # phi without inputs

    def first_step(self, x0: np.ndarray) -> tuple[float, float] | None:
        """(force, CoP) of the plan's first step from the state ``x0 = (u, u', L, phi)``; without
        the bound on phi when the state is already beyond what it allows."""
        g = self.linear @ x0
        free = self.phi_free @ x0
        upper = np.r_[self.upper, self.phi_max - free]
        lower = np.r_[self.lower, -self.phi_max - free]
        result = solve_daqp_qp(self.H, g, self.phi_rows, upper, lower,
                               np.zeros(len(upper), dtype=np.int32))
        if not result.ok:
            result = solve_daqp_qp(self.H, g, np.zeros((0, len(g))), self.upper, self.lower,
                                   np.zeros(len(g), dtype=np.int32))
        return None if not result.ok else (float(result.x[0]), float(result.x[1]))


class CaptureReference:
    """``reference(t, robot)`` for MomentumBalance: the MPC's momentum rate, replanned every
    ``every`` calls (10 ms at 1 kHz)."""

    def __init__(self, robot, sole: float = 0.9, lateral: float = 1.0, every: int = 10):
        robot.update(robot.q_ref, np.zeros(robot.nv))
        self.com0, self.mass = robot.com.copy(), robot.mass
        self.R0 = pin.Quaternion(robot.q_ref[3:7]).toRotationMatrix()
        self.axes = []
        for location, scale in (("back", 1.0), ("right", lateral)):  # pushes along +x and +y
            geom = push_bound.push_geometry(robot, location, sole)
            lo, hi = geom["support"]
            self.axes.append(AxisMPC(dict(geom, support=(scale * lo, scale * hi))))
        self.every, self.calls, self.hdot = every, 0, np.zeros(6)

    def __call__(self, t, robot) -> BalanceReference:
        if self.calls % self.every == 0:
            theta = pin.log3(pin.Quaternion(robot.q[3:7]).toRotationMatrix() @ self.R0.T)
            hdot = np.zeros(6)
            # axis x: L about +y turns the top towards +x; axis y: L about -x turns it towards +y
            for axis, (mpc, L, phi, sign) in enumerate((
                    (self.axes[0], robot.h_G[4], theta[1], 1.0),
                    (self.axes[1], -robot.h_G[3], -theta[0], -1.0))):
                u = robot.com[axis] - self.com0[axis]
                step = mpc.first_step(np.array([u, robot.vcom[axis], L, phi]))
                if step is None:
                    continue
                f, p = step
                hdot[axis] = f
                hdot[4 - axis] = sign * (-mpc.geom["z0"] * f - (p - u) * self.mass
                                         * mpc.geom["gravity"])
            self.hdot = hdot
        self.calls += 1
        return BalanceReference(self.com0.copy(), None, self.hdot.copy(), None)


def trial(robot, location: str, dv: float, sole: float, lateral: float):
    """One push of the scenario's protocol under the prototype → the push trial."""
    params = {p.name: p.default for p in PARAMETERS}
    params.update(location=location, dv=dv)
    balance = MomentumBalance(
        robot, gains="pd", P=np.diag([0.0, 0.0, 50.0, 0.0, 0.0, 0.0]),
        D=np.diag([0.0, 0.0, 15.0, 0.0, 0.0, 5.0]), angular_weight=1.0, cop_margin=0.0,
        reference=CaptureReference(robot, sole, lateral))  # the plan holds its own CoP bound
    return push_trial(robot, "pd", with_peak_force(robot, params), balance=balance)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robot", default="talos14")
    parser.add_argument("--dv", type=float, default=0.3)
    parser.add_argument("--locations", default=",".join(LOCATIONS))
    parser.add_argument("--sole", type=float, default=0.9)
    parser.add_argument("--lateral", type=float, default=1.0)
    parser.add_argument("--bisect", default="",
                        help="LOW,HIGH,STEPS: the largest survived dv per point by bisection")
    args = parser.parse_args()
    robot = wb.load_robot(args.robot)
    for location in args.locations.split(","):
        if args.bisect:
            low, high, steps = (float(x) for x in args.bisect.split(","))
            for _ in range(int(steps)):
                mid = 0.5 * (low + high)
                survived = trial(robot, location, mid, args.sole, args.lateral).success
                low, high = (mid, high) if survived else (low, mid)
            print(f"{location:9s} largest survived dv {low:.3f} m/s (bisection on "
                  f"{args.bisect})", flush=True)
            continue
        result = trial(robot, location, args.dv, args.sole, args.lateral)
        m = result.metrics
        print(f"{location:9s} dv {args.dv:.3f}: {'survived' if result.success else 'failed':8s} "
              f"CoG {1e3 * m['max_cog_error_m']:.1f} mm, back in {m['cog_recovery_time_s']:.2f} s, "
              f"feet tilt {m['max_foot_tilt_deg']:.1f}°, slip {1e3 * m['max_foot_slip_m']:.1f} mm, "
              f"trunk {m['max_trunk_rotation_deg']:.1f}° (end {m['final_trunk_rotation_deg']:.1f}°)",
              flush=True)


if __name__ == "__main__":
    main()
