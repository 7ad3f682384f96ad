"""``wholebody sweep`` on real simulations: the same rows serially, on the local pool and on a
local Ray instance, and equal to the scenario called directly; push-series and robust-push give
the same metrics with ``workers=2`` as in one process."""

from __future__ import annotations

import json
import math
import os

import pytest

from wholebody import load_robot
from wholebody.cli import main
from wholebody.scenarios import get_scenario
from wholebody.scenarios.base import _jsonable

pytestmark = pytest.mark.slow

# a cheap scenario: 0.2-0.3 s of standing on hyq, 4 runs
GRID = {"duration": ["0.2", "0.3"], "friction": ["0.5", "1.0"]}
ARGS = ["sweep", "stand", "--robot", "hyq", "--no-progress",
        *[a for k, v in GRID.items() for a in ("--grid", f"{k}={','.join(v)}")]]


def _direct_rows() -> list[tuple]:
    """The runs computed here, without the sweep code: (grid values, success, metrics)."""
    def flat(d, prefix=""):
        out = {}
        for k, v in d.items():
            if isinstance(v, dict):
                out.update(flat(v, f"{prefix}{k}/"))
            elif isinstance(v, (bool, int, float)) or v is None:
                out[f"{prefix}{k}"] = None if isinstance(v, float) and not math.isfinite(v) else v
        return out

    scenario, rows = get_scenario("stand"), []
    for duration in GRID["duration"]:
        for friction in GRID["friction"]:
            result = scenario.run(load_robot("hyq"), "standing",
                                  {"duration": duration, "friction": friction})
            rows.append(({"duration": float(duration), "friction": float(friction)},
                         result.success, flat(_jsonable(result.metrics))))
    return rows


def _sweep_rows(out) -> list[tuple]:
    table = json.loads((out / "sweep.json").read_text())
    assert table["completed"] == table["runs"] == 4 and table["raised"] == 0
    return [(r["grid"], r["success"], r["metrics"]) for r in table["rows"]]


def _csv_without_wall_time(out) -> list[str]:
    lines = (out / "sweep.csv").read_text().splitlines()
    assert lines[0].endswith(",wall_time_s")
    return [line.rsplit(",", 1)[0] for line in lines]


@pytest.fixture(scope="module")
def direct():
    return _direct_rows()


@pytest.fixture
def local_ray():
    """A local Ray instance of 2 CPUs, shut down after the test."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False,
             runtime_env={"env_vars": {"OPENBLAS_NUM_THREADS": "1"}})
    yield ray
    ray.shutdown()


def test_serial_and_pool_rows_equal_the_direct_runs(tmp_path, direct):
    assert main([*ARGS, "--serial", "--out", str(tmp_path / "serial")]) == 0
    assert main([*ARGS, "--workers", "2", "--out", str(tmp_path / "pool")]) == 0
    assert _sweep_rows(tmp_path / "serial") == direct
    assert _sweep_rows(tmp_path / "pool") == direct
    assert _csv_without_wall_time(tmp_path / "serial") == _csv_without_wall_time(tmp_path / "pool")
    assert (tmp_path / "pool" / "sweep.png").stat().st_size > 10_000


def test_ray_rows_equal_the_direct_runs(tmp_path, direct, local_ray):
    """``--ray`` with Ray already initialised here: the sweep uses that instance and leaves it
    running."""
    assert main([*ARGS, "--ray", "local", "--out", str(tmp_path / "ray")]) == 0
    assert local_ray.is_initialized()
    assert _sweep_rows(tmp_path / "ray") == direct
    assert main([*ARGS, "--serial", "--out", str(tmp_path / "serial")]) == 0
    assert _csv_without_wall_time(tmp_path / "ray") == _csv_without_wall_time(tmp_path / "serial")


def test_ray_executor_started_here_is_shut_down():
    ray = pytest.importorskip("ray")
    from wholebody.sweep.executors import RayExecutor, ordered

    assert not ray.is_initialized()
    with RayExecutor("local", num_cpus=2) as executor:
        assert ordered(executor, abs, [-1, 2, -3]) == [1, 2, 3]
        assert ordered(executor, os.getenv, ["OPENBLAS_NUM_THREADS"]) == ["1"]
    assert not ray.is_initialized()


@pytest.mark.parametrize("name,controller,sets", [
    ("push-series", "pd+lqr", {"locations": "front", "forces": "100", "duration": "1.0",
                               "bisection": "true", "bisection_steps": "1"}),
    ("robust-push", "lqr", {"locations": "front", "seeds": "2", "start": "0.5",
                            "duration": "1.0"}),
])
def test_scenario_workers_give_the_same_metrics(name, controller, sets):
    scenario, robot = get_scenario(name), load_robot("talos14")
    serial = scenario.run(robot, controller, {**sets, "workers": "1"})
    pooled = scenario.run(robot, controller, {**sets, "workers": "2"})
    assert json.dumps(_jsonable(pooled.metrics), sort_keys=True) == \
        json.dumps(_jsonable(serial.metrics), sort_keys=True)
    assert pooled.success == serial.success and pooled.notes == serial.notes
