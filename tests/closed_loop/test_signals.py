"""SIGTERM ends a run as Ctrl-C does: the summary is written, marked interrupted and not
completed, and the process exits 143."""

import json
import signal
import subprocess
import sys
import time

import pytest

pytestmark = pytest.mark.slow


def test_sigterm_mid_run_leaves_a_marked_summary(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "wholebody", "run", "stand", "--set",
                             "duration=120", "--no-progress", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not out.exists() and time.monotonic() < deadline:  # made before the simulation
        time.sleep(0.2)
    time.sleep(2.0)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "INTERRUPTED (SIGTERM)" in err and "Traceback" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["completed"] is False


def _children(pid: int) -> list[int]:
    out = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout
    return [int(x) for x in out.split()]


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/status") as f:
            return "\nState:\tZ" not in f.read()
    except FileNotFoundError:
        return False


def test_sigterm_mid_sweep_writes_the_rows_done_and_stops_its_workers(tmp_path):
    out = tmp_path / "sweep"
    proc = subprocess.Popen([sys.executable, "-m", "wholebody", "sweep", "stand", "--grid",
                             "duration=0.5,60,60,60", "--workers", "2", "--no-progress", "--out",
                             str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    workers: list[int] = []
    while time.monotonic() < deadline and len(workers) < 2:
        time.sleep(0.5)
        workers = [c for c in _children(proc.pid)
                   if "multiprocessing" in open(f"/proc/{c}/cmdline").read().replace("\0", " ")]
    time.sleep(8.0)  # the 0.5 s run is done by now
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, err
    assert "INTERRUPTED (SIGTERM)" in err and "Traceback" not in err
    table = json.loads((out / "sweep.json").read_text())
    assert table["interrupted"] is True and table["completed"] >= 1
    time.sleep(1.0)
    assert workers and not [w for w in workers if _alive(w)]
