"""Timing harness for the robot-free hierarchical solver (not a test).

Random problems of realistic whole-body size: n = 50 variables, 4 levels, ~60 inequality rows
(a Newton–Euler-like equality block with torque-limit and friction-like inequalities first,
then motion tasks with acceleration bounds, a posture task, a force regulariser). Every
method/backend solves the same problems; we print median, p95, p99 and max wall time in µs.

    python benchmarks/bench_hierarchy.py [--solves 1000]     (from the project root, wholebody installed)
"""

import os

os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from wholebody.solvers import Level, solve_hierarchy  # noqa: E402
from wholebody.solvers.settings import HIERARCHY_DEFAULT  # noqa: E402


def realistic_problem(rng: np.random.Generator, n: int = 50) -> list:
    """A 4-level stack shaped like a humanoid inverse-dynamics problem over y = [q̈, λ].

    Level 1 is feasible by construction (as the paper's physics level, §2.4): 6 Newton–Euler
    rows, 24 torque-limit-like two-sided rows, 16 friction-like and 8 CoP-like one-sided rows
    on the contact wrenches. Level 2: 12 task rows (momentum, swing foot) and 10 joint
    acceleration bounds. Level 3: posture. Level 4: contact-force regulariser. 58 inequality rows.
    """
    nq = n - 12  # accelerations; 12 = two 6-D contact wrenches
    y0 = rng.standard_normal(n)
    B1 = rng.standard_normal((6, n))
    T = 0.5 * rng.standard_normal((24, n))
    F = np.zeros((24, n))
    for c in range(2):
        F[12 * c : 12 * c + 12, nq + 6 * c : nq + 6 * c + 6] = rng.standard_normal((12, 6))
    C1 = np.vstack([T, F])
    c1 = C1 @ y0
    lo1 = np.concatenate([c1[:24] - rng.uniform(0.5, 3.0, 24), np.full(24, -np.inf)])
    up1 = np.concatenate([c1[:24] + rng.uniform(0.5, 3.0, 24), c1[24:] + rng.uniform(0.0, 1.0, 24)])
    B2 = rng.standard_normal((12, n))
    b2 = 2.0 * rng.standard_normal(12)
    C2 = np.eye(n)[rng.choice(nq, 10, replace=False)]
    B3 = np.eye(n)[6:nq]
    b3 = 0.3 * rng.standard_normal(nq - 6)
    B4 = np.eye(n)[nq:]
    return [
        Level(eq=(B1, B1 @ y0), ineq=(C1, lo1, up1), name="dynamics+limits"),
        Level(eq=(B2, b2), ineq=(C2, np.full(10, -2.0), np.full(10, 2.0)), name="momentum+swing"),
        Level(eq=(B3, b3), weights=0.1, name="posture"),
        Level(eq=(B4, np.zeros(12)), weights=0.01, name="forces"),
    ]


def first_level(levels):
    """Analytic first priority (§2.4, eq. 17): x1 = B1⁺ b1 and an orthonormal basis Z1 of ker B1."""
    B1, b1 = levels[0].B, levels[0].b
    U, s, Vt = np.linalg.svd(B1, full_matrices=True)
    x1 = Vt[: len(s)].T @ ((U.T @ b1) / s)
    return x1, Vt[len(s) :].T


def bench(problems, fls=None, **kw):
    """Times of solve_hierarchy with SolverSettings(**kw) (its defaults otherwise)."""
    settings = replace(HIERARCHY_DEFAULT, **kw)
    times, bad = [], 0
    for i, lv in enumerate(problems):
        t0 = time.perf_counter()
        sol = solve_hierarchy(lv, settings, first_level_solution=None if fls is None else fls[i])
        times.append(time.perf_counter() - t0)
        bad += not sol.ok
    t = np.array(times) * 1e6
    return np.median(t), np.quantile(t, 0.95), np.quantile(t, 0.99), t.max(), bad


def report(name, stats):
    med, p95, p99, mx, bad = stats
    print(f"{name:28s} median {med:7.0f} µs   p95 {p95:7.0f}   p99 {p99:7.0f}   max {mx:7.0f}   failed {bad}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--solves", type=int, default=1000)
    ap.add_argument("--n", type=int, default=50)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    problems = [realistic_problem(rng, args.n) for _ in range(args.solves)]
    fls = [first_level(lv) for lv in problems]
    m_in = sum(L.n_ineq for L in problems[0])
    print(f"{args.solves} solves, n = {args.n}, {len(problems[0])} levels, {m_in} inequality rows "
          f"(OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']})")
    runs = [
        ("cascade/quadprog", {"method": "cascade", "backend": "quadprog"}, None),
        ("cascade/daqp", {"method": "cascade", "backend": "daqp"}, None),
        ("cascade/proxsuite", {"method": "cascade", "backend": "proxsuite"}, None),
        ("cascade/quadprog + §2.4 L1", {"method": "cascade", "backend": "quadprog"}, fls),
        ("cascade/daqp + §2.4 L1", {"method": "cascade", "backend": "daqp"}, fls),
        ("daqp hierarchical", {"method": "daqp"}, None),
    ]
    for name, kw, f in runs:
        bench(problems[:20], f, **kw)  # warm-up (imports, caches)
        report(name, bench(problems, f, **kw))
    # the single weighted QP on the first two levels (hard level 1, objective = level 2)
    two = [[lv[0], lv[1]] for lv in problems]
    for backend in ("quadprog", "daqp"):
        bench(two[:20], method="weighted", backend=backend)
        report(f"weighted/{backend} (2 levels)", bench(two, method="weighted", backend=backend))
        report(f"cascade/{backend} (same 2)", bench(two, method="cascade", backend=backend))


if __name__ == "__main__":
    main()
