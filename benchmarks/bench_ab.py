"""Interleaved A/B timing of two checkouts of wholebody (not a test).

Two source trees are imported under different names (symlinks ``wb_main``/``wb_speed`` in
PKGS_DIR pointing at ``.../src/wholebody``) and solve the same moving states alternately in one
process, so both see the same load on a shared machine; prints each one's percentiles and the
median of the paired per-cycle ratios.

    PKGS_DIR=/tmp/pkgs python benchmarks/bench_ab.py t2|t1 daqp|quadprog r|f [fallback|none] [cycles]
"""
import os, sys, time, importlib
os.environ["OPENBLAS_NUM_THREADS"] = "1"
sys.path.insert(0, os.environ.get("PKGS_DIR", "/tmp/pkgs"))
import numpy as np
case, backend, red = sys.argv[1], sys.argv[2], sys.argv[3] == "r"
fallback = sys.argv[4] if len(sys.argv) > 4 and sys.argv[4] != "none" else None
cycles = int(sys.argv[5]) if len(sys.argv) > 5 else 2000
vers = {}
for tag in ("wb_main", "wb_speed"):
    wb = importlib.import_module(tag)
    stacks = importlib.import_module(tag + ".control.stacks")
    F = importlib.import_module(tag + ".formulation"); V = importlib.import_module(tag + ".variables")
    r = wb.load_robot("talos14" if case == "t2" else "talos")
    st = stacks.table2_stack(r, full=not red) if case == "t2" else stacks.table1_stack(r, r.contact_names, full=not red)
    vers[tag] = (r, st, F.Formulation(r, reduced=red), V.Variables(r))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_wbc import moving_states
states = list(moving_states(vers["wb_main"][0], cycles))
T = {k: np.zeros((cycles, 4)) for k in vers}; fails = {k: 0 for k in vers}
order = list(vers)
for i, (q, v) in enumerate(states):
    for tag in (order if i % 2 == 0 else order[::-1]):
        r, st, f, var = vers[tag]
        t0 = time.perf_counter(); r.update(q, v); t1 = time.perf_counter()
        s = f.solve(st, var, backend=backend, fallback_backend=fallback, diagnostics=False)
        t2 = time.perf_counter()
        T[tag][i] = (t1 - t0, s.timings["rows"], s.timings["solve"], t2 - t0); fails[tag] += not s.ok
lab = f"{case} cascade/{backend}{'+' + fallback if fallback else ''} {'reduced' if red else 'full'}"
for tag in vers:
    t = T[tag] * 1e6; tot = t[:, 3]
    print(f"{lab:34} {tag[3:]:5} median {np.median(tot):6.0f} p95 {np.percentile(tot,95):6.0f} p99 {np.percentile(tot,99):6.0f} max {tot.max():7.0f} | upd {np.median(t[:,0]):4.0f} rows {np.median(t[:,1]):4.0f} solve {np.median(t[:,2]):5.0f} | failed {fails[tag]}")
ratio = T["wb_speed"][:, 3] / T["wb_main"][:, 3]
print(f"{lab:34} speed/main: median of paired ratios {np.median(ratio):.2f}, ratio of medians {np.median(T['wb_speed'][:,3])/np.median(T['wb_main'][:,3]):.2f}   load {os.getloadavg()[0]:.1f}")
