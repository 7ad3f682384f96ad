"""Matched-work speed comparison of wholebody against placo and TSID, from one command.

    OPENBLAS_NUM_THREADS=1 /work/main/.venv/bin/python benchmarks/peers/compare.py
        [--states 2000] [--repeats 3] [--chunk 100] [--cases hyq,talos14,talos] [--remake-states]

Every side runs in its own environment as a subprocess (run_wholebody.py in wholebody's venv,
run_placo.py and run_tsid.py in the peers' venvs made by setup.sh) and solves the same states
(make_states.py: $PEERS_DIR/states/CASE.npz). The sides stay loaded and are driven in chunks,
interleaved (A B C, B C A, C A B, ...), so that the machine's load hits them alike; each chunk is
timed per state inside the side (model update from (q, v) + task rows + QP + torques). Prints per
case and repeat the median and p90 per side, the ratios of medians, and what each side solved with
a sanity check of its output (success rate, median |tau|, median |CoM acceleration|, median
relative distance of its torques to wholebody's weighted solution). A side whose environment is
missing or fails to start is reported as unavailable with the reason.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import cases  # noqa: E402


def env():
    e = dict(os.environ)
    e.update(OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
             PEERS_DIR=cases.PEERS_DIR)
    return e


class Side:
    """A runner subprocess speaking cases.serve's protocol."""

    def __init__(self, label, argv, extra_env=None):
        self.label, self.argv = label, argv
        self.error, self.solved, self.proc = None, "", None
        e = env()
        e.update(extra_env or {})
        try:
            self.stderr = open(os.path.join(cases.PEERS_DIR, "logs",
                                            label.replace(" ", "_") + ".log"), "w")
            self.proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                         stderr=self.stderr, text=True, env=e, bufsize=1)
        except OSError as exc:
            self.error = str(exc)

    def wait_ready(self):
        if self.error:
            return
        line = self.proc.stdout.readline()
        if not line:
            self.proc.wait()
            self.stderr.flush()
            with open(self.stderr.name) as f:
                tail = [x for x in f.read().strip().splitlines() if x.strip()][-1:]
            self.error = f"failed to start (exit {self.proc.returncode}): {' '.join(tail)[-300:]}"
            return
        self.solved = json.loads(line).get("solved", "")

    def ask(self, command):
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"{self.label}: the runner stopped (see {self.stderr.name})")
        return json.loads(line)

    def close(self):
        if self.proc and self.proc.poll() is None:
            try:
                self.proc.stdin.write("quit\n")
                self.proc.stdin.flush()
                self.proc.wait(timeout=30)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()


def peer_python(name):
    return os.path.join(cases.PEERS_DIR, f"{name}-venv", "bin", "python")


def sides_for(case_name, wholebody_python):
    case = cases.CASES[case_name]
    out = []
    for variant in case["wholebody"]:
        out.append(Side(f"wholebody {variant}",
                        [wholebody_python, os.path.join(HERE, "run_wholebody.py"), case_name, variant],
                        {"PYTHONPATH": os.path.join(REPO, "src")}))
    for peer in ("placo", "tsid"):
        py = peer_python(peer)
        if not os.path.exists(py):
            s = Side.__new__(Side)
            s.label, s.proc, s.solved = peer, None, ""
            s.error = f"no environment at {os.path.dirname(os.path.dirname(py))} (bash benchmarks/peers/setup.sh {peer})"
            if peer == "tsid":
                log = os.path.join(cases.PEERS_DIR, "tsid-build.log")
                if os.path.exists(log):
                    s.error += f"; build log {log}"
            out.append(s)
            continue
        out.append(Side(peer, [py, os.path.join(HERE, f"run_{peer}.py"), case_name]))
    return out


def stats_us(t):
    t = np.asarray(t) * 1e6
    return float(np.median(t)), float(np.percentile(t, 90))


def run_case(case_name, args, wholebody_python):
    n = len(np.load(cases.states_path(case_name))["q"])
    sides = sides_for(case_name, wholebody_python)
    for s in sides:
        s.wait_ready()
    live = [s for s in sides if not s.error]
    times = {s.label: np.zeros((args.repeats, n)) for s in live}
    k = 0
    for r in range(args.repeats):
        for a in range(0, n, args.chunk):
            b = min(n, a + args.chunk)
            order = live[k % len(live):] + live[:k % len(live)]  # rotate who goes first
            k += 1
            for s in order:
                times[s.label][r, a:b] = s.ask(f"run {a} {b}")["times"]
    outputs = {}
    for s in live:
        path = os.path.join(cases.PEERS_DIR, "results", f"{case_name}-{s.label.replace(' ', '_')}.npz")
        s.ask(f"save {path}")
        outputs[s.label] = dict(np.load(path))
        s.close()
    return sides, times, outputs


def sanity(outputs, reference):
    rows = {}
    ref = outputs.get(reference)
    for label, o in outputs.items():
        tau, acc = o["tau"], o["a_com"]
        row = {"ok": float(np.mean(o["ok"])), "tau_median_abs": float(np.median(np.abs(tau))),
               "acom_median": float(np.median(np.linalg.norm(acc, axis=1)))}
        if ref is not None:
            num = np.linalg.norm(tau - ref["tau"], axis=1)
            den = np.maximum(np.linalg.norm(ref["tau"], axis=1), 1e-9)
            row["tau_rel_to_ref"] = float(np.median(num / den))
        rows[label] = row
    return rows


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--chunk", type=int, default=100)
    parser.add_argument("--cases", default=",".join(cases.CASES))
    parser.add_argument("--remake-states", action="store_true")
    parser.add_argument("--wholebody-python", default=os.environ.get("WHOLEBODY_PYTHON", sys.executable))
    args = parser.parse_args()
    for d in ("states", "results", "logs"):
        os.makedirs(os.path.join(cases.PEERS_DIR, d), exist_ok=True)
    names = args.cases.split(",")
    missing = [c for c in names if args.remake_states or not os.path.exists(cases.states_path(c))
               or len(np.load(cases.states_path(c))["q"]) != args.states]
    if missing:
        subprocess.run([args.wholebody_python, os.path.join(HERE, "make_states.py"), "--states",
                        str(args.states), "--cases", ",".join(missing)], check=True,
                       env=env() | {"PYTHONPATH": os.path.join(REPO, "src")})
    print(f"{args.states} states per case, {args.repeats} repeats, interleaved in chunks of "
          f"{args.chunk}; OPENBLAS_NUM_THREADS=1; load average at start "
          f"{os.getloadavg()[0]:.1f}; {os.cpu_count()} cores", flush=True)
    report = {"states": args.states, "repeats": args.repeats, "chunk": args.chunk, "cases": {}}
    t_start = time.time()
    for name in names:
        case = cases.CASES[name]
        sides, times, outputs = run_case(name, args, args.wholebody_python)
        reference = "wholebody weighted"
        checks = sanity(outputs, reference)
        print(f"\n== {name}: {case['title']}")
        print(f"   tasks (weights are row scales; placo/TSID weigh squared residuals with their "
              f"squares): {cases.describe(case)}")
        for s in sides:
            print(f"   {s.label:20} " + (f"UNAVAILABLE: {s.error}" if s.error else s.solved))
        head = f"   {'side':20} " + " ".join(f"{'run ' + str(r + 1) + ' med/p90 µs':>20}"
                                             for r in range(args.repeats))
        print(head + "   ok    med|tau| Nm  med|a_com|  |Δtau|/|tau| vs wb weighted")
        entry = {"title": case["title"], "tasks": cases.describe(case), "sides": {}}
        for s in sides:
            if s.error:
                entry["sides"][s.label] = {"unavailable": s.error}
                continue
            per = [stats_us(times[s.label][r]) for r in range(args.repeats)]
            c = checks[s.label]
            cells = " ".join(f"{m:10.0f} /{p:7.0f}" for m, p in per)
            rel = c.get("tau_rel_to_ref", float("nan"))
            print(f"   {s.label:20} {cells}   {c['ok']:.2f}  {c['tau_median_abs']:9.2f}  "
                  f"{c['acom_median']:9.3f}  {rel:9.3f}")
            entry["sides"][s.label] = {"solved": s.solved, "median_us": [m for m, _ in per],
                                       "p90_us": [p for _, p in per], **c}
        for wb_label in [s.label for s in sides if s.label.startswith("wholebody") and not s.error]:
            for peer in ("placo", "tsid"):
                if peer in entry["sides"] and "median_us" in entry["sides"][peer]:
                    a = entry["sides"][wb_label]["median_us"]
                    b = entry["sides"][peer]["median_us"]
                    ratios = [x / y for x, y in zip(a, b)]
                    entry.setdefault("ratios", {})[f"{wb_label} / {peer}"] = ratios
                    print(f"   ratio of medians {wb_label} / {peer}: "
                          + ", ".join(f"{x:.2f}" for x in ratios))
        report["cases"][name] = entry
    path = os.path.join(cases.PEERS_DIR, "results", "compare.json")
    with open(path, "w") as f:
        json.dump(report, f, indent=1)
    print(f"\n{time.time() - t_start:.0f} s; results in {path}")


if __name__ == "__main__":
    main()
