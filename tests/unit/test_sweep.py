"""``wholebody sweep`` without simulating: the grid and its checks (exit 2 before anything runs),
the executors on trivial functions, the table, and the exit codes of runs that raise or are
interrupted (with ``Scenario.run`` replaced)."""

from __future__ import annotations

import csv
import json
import os
import sys

import pytest

from wholebody.cli import main
from wholebody.scenarios import get_scenario
from wholebody.scenarios.base import Scenario, ScenarioResult, parse_sets
from wholebody.sweep import (LocalPoolExecutor, SerialExecutor, SweepRun, expand, ordered,
                             parse_grid)
from wholebody.sweep.executors import SINGLE_THREAD_ENV
from wholebody.sweep.table import columns, default_metric, write_csv, write_figure, write_json
from wholebody.sweep.worker import flatten_metrics


@pytest.fixture
def fake_runs(monkeypatch):
    """Scenario.run returns at once: metrics from the parameters; ``peak_force=666`` raises,
    ``peak_force=777`` is Ctrl-C."""
    def run(self, robot, controller=None, overrides=None, out_dir=None, progress=False):
        params = self.validate(robot, overrides)
        force = params["peak_force"]
        if force == 666:
            raise RuntimeError("solver exploded")
        if force == 777:
            raise KeyboardInterrupt
        return ScenarioResult(self.name, robot.name, controller, force < 150,
                              {"peak_force_N": force, "nested": {"x": 2 * force, "text": "t"}},
                              params)
    monkeypatch.setattr(Scenario, "run", run)


# ---------------------------------------------------------------- the grid
def test_parse_grid_keeps_order_and_splits_values():
    assert parse_grid(["peak_force=100, 150,200", "location=front,back"]) == {
        "peak_force": ["100", "150", "200"], "location": ["front", "back"]}
    assert parse_grid(["forces=100,200;150,250"]) == {"forces": ["100,200", "150,250"]}
    assert parse_grid([]) == {}


@pytest.mark.parametrize("texts,needle", [
    (["peak_force"], "--grid expects key=v1,v2,..., got 'peak_force'"),
    (["=1,2"], "--grid expects key=v1,v2,..., got '=1,2'"),
    (["peak_force="], "--grid peak_force: empty value in ''"),
    (["peak_force=1,,2"], "--grid peak_force: empty value in '1,,2'"),
    (["a=1", "a=2"], "--grid a: given twice"),
])
def test_parse_grid_errors_name_the_field(texts, needle):
    with pytest.raises(ValueError) as info:
        parse_grid(texts)
    assert needle in str(info.value)


def test_parse_sets():
    assert parse_sets(["a=1", " b = x "]) == {"a": "1", "b": "x"}
    with pytest.raises(ValueError, match="--set expects key=value, got 'a'"):
        parse_sets(["a"])


def test_expand_is_the_product_in_grid_order(robots):
    push = get_scenario("push")
    runs = expand(push, robots["talos14"], "talos14", "lqr",
                  {"peak_force": ["1.0", "1.0"], "location": ["front", "back"]},
                  {"duration": "1.0"}, repeat=2)
    assert [r.index for r in runs] == list(range(8))
    assert [(r.grid["peak_force"], r.grid["location"], r.repeat) for r in runs[:4]] == [
        ("1.0", "front", 0), ("1.0", "front", 1), ("1.0", "back", 0), ("1.0", "back", 1)]
    assert all(r.overrides["duration"] == "1.0" and r.controller == "lqr" for r in runs)
    assert runs[5].overrides == {"duration": "1.0", "peak_force": "1.0", "location": "front"}
    assert expand(push, robots["talos14"], "talos14", "lqr", {}, {}, 3)[2].repeat == 2


@pytest.mark.parametrize("grid,sets,needle", [
    ({"peak": ["1"]}, {}, "--grid peak: scenario 'push' has no parameter 'peak'"),
    ({"peak_force": ["100", "-5"]}, {},
     "--grid peak_force=-5: --set peak_force: expected a finite number in [0, inf), got '-5'"),
    ({"location": ["front", "top"]}, {}, "--grid location=top: --set location: expected one of"),
    ({"peak_force": ["x"]}, {}, "--grid peak_force=x: --set peak_force: expected a number"),
    ({"peak_force": ["1"]}, {"peak_force": "2"},
     "--grid peak_force: also given with --set peak_force=2"),
    ({"peak_force": ["1"]}, {"duration": "0"}, "--set duration: expected a finite number in "
                                               "(0, 600], got '0'"),
    ({"peak_force": ["1"]}, {"nope": "1"}, "scenario 'push' has no parameter 'nope'"),
])
def test_expand_errors_name_field_and_value(robots, grid, sets, needle):
    with pytest.raises(ValueError) as info:
        expand(get_scenario("push"), robots["talos14"], "talos14", "lqr", grid, sets)
    assert needle in str(info.value)


def test_expand_validates_every_combination(robots):
    """Each value is in range on its own; one combination is not (the push ends after the
    run): the message names that grid point."""
    with pytest.raises(ValueError) as info:
        expand(get_scenario("robust-push"), robots["talos14"], "talos14", "lqr",
               {"start": ["1.0", "4.45"]}, {"duration": "4.5"})
    assert "--grid start=4.45: --set start/duration: the push must end" in str(info.value)


# ---------------------------------------------------------------- the CLI's usage errors
@pytest.mark.parametrize("argv,needle", [
    (["sweep", "nope"], "unknown scenario 'nope'"),
    (["sweep", "push", "--robot", "nobot"], "unknown robot 'nobot'"),
    (["sweep", "push", "--robot", "hyq", "--grid", "peak_force=1"],
     "--grid peak_force=1: robot 'hyq'"),  # the push's own check (no torso, point feet)
    (["sweep", "push", "--controller", "xx"], "scenario 'push' has no controller 'xx'"),
    (["sweep", "push", "--grid", "peak_force"], "--grid expects key=v1,v2,..., got 'peak_force'"),
    (["sweep", "push", "--grid", "peak=1,2"], "--grid peak: scenario 'push' has no parameter"),
    (["sweep", "push", "--grid", "peak_force=100,-1"],
     "--grid peak_force=-1: --set peak_force: expected a finite number in [0, inf), got '-1'"),
    (["sweep", "stand", "--robot", "hyq", "--grid", "drift_tolerance=0.01,0.7"],
     "--grid drift_tolerance=0.7: --set drift_tolerance: expected a finite number in (0, h] = "
     "(0, 0.599] for robot 'hyq'"),
    (["sweep", "push", "--set", "duration"], "--set expects key=value, got 'duration'"),
    (["sweep", "push", "--set", "duration=0"], "--set duration: expected a finite number"),
    (["sweep", "push", "--repeat", "0"], "--repeat: expected a whole number >= 1, got 0"),
    (["sweep", "push", "--workers", "0"], "--workers: expected a whole number >= 1, got 0"),
])
def test_usage_errors_exit_2_before_simulating(argv, needle, capsys, no_simulation, tmp_path):
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wholebody: error: ") and needle in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # nothing made before the checks passed


def test_unwritable_out_exit_2(tmp_path, capsys, no_simulation):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert main(["sweep", "push", "--grid", "peak_force=1", "--out", str(blocker)]) == 2
    assert f"--out {blocker}: cannot write there" in capsys.readouterr().err


def test_ray_missing_exit_2(tmp_path, capsys, no_simulation, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    assert main(["sweep", "push", "--grid", "peak_force=1", "--ray", "local",
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "--ray local: Ray is not installed; pip install 'wholebody[cluster]'" in err
    assert not (tmp_path / "out").exists()


def test_executor_options_are_exclusive(capsys, no_simulation):
    with pytest.raises(SystemExit) as info:
        main(["sweep", "push", "--serial", "--workers", "2"])
    assert info.value.code == 2 and "not allowed with" in capsys.readouterr().err


# ---------------------------------------------------------------- runs, table, exit codes
def test_serial_sweep_table_and_exit_0(tmp_path, capsys, fake_runs):
    """Every run executed: exit 0 even where the criterion failed (success False)."""
    out = tmp_path / "out"
    assert main(["sweep", "push", "--serial", "--grid", "peak_force=100,200",
                 "--grid", "location=front,back", "--repeat", "2", "--out", str(out),
                 "--metric", "nested/x"]) == 0
    assert "8 runs" in capsys.readouterr().out
    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0])[:4] == ["peak_force", "location", "repeat", "success"]
    assert [(r["peak_force"], r["location"], r["repeat"], r["success"]) for r in rows[:3]] == [
        ("100.0", "front", "0", "True"), ("100.0", "front", "1", "True"),
        ("100.0", "back", "0", "True")]
    assert rows[4]["success"] == "False" and rows[4]["nested/x"] == "400.0"
    assert "nested/text" not in rows[0]  # only numeric metrics
    table = json.loads((out / "sweep.json").read_text())
    assert table["runs"] == table["completed"] == 8 and table["interrupted"] is False
    assert table["grid"] == {"peak_force": ["100", "200"], "location": ["front", "back"]}
    assert [r["index"] for r in table["rows"]] == list(range(8))
    assert (out / "sweep.png").stat().st_size > 10_000


def test_a_run_that_raises_gives_exit_1(tmp_path, capsys, fake_runs):
    out = tmp_path / "out"
    assert main(["sweep", "push", "--serial", "--grid", "peak_force=100,666,200",
                 "--out", str(out)]) == 1
    assert "RuntimeError: solver exploded" in capsys.readouterr().out
    rows = json.loads((out / "sweep.json").read_text())["rows"]
    assert [r["error"] for r in rows] == [None, "RuntimeError: solver exploded", None]
    assert rows[2]["metrics"] == {"peak_force_N": 200.0, "nested/x": 400.0}


def test_ctrl_c_gives_130_with_what_is_done(tmp_path, capsys, fake_runs):
    out = tmp_path / "out"
    assert main(["sweep", "push", "--serial", "--grid", "peak_force=100,120,777,200",
                 "--out", str(out)]) == 130
    assert "INTERRUPTED" in capsys.readouterr().err
    table = json.loads((out / "sweep.json").read_text())
    assert table["interrupted"] is True and table["completed"] == 2 and table["runs"] == 4
    with open(out / "sweep.csv", newline="") as f:
        assert [r["peak_force"] for r in csv.DictReader(f)] == ["100.0", "120.0"]


def test_flatten_metrics():
    import numpy as np
    flat = flatten_metrics({"a": 1, "b": {"c": np.float64(2.5), "d": {"e": True}},
                            "f": float("nan"), "g": None, "h": "text", "i": [1, 2],
                            "j": np.int64(3), "k": np.array(4.0)})
    assert flat == {"a": 1, "b/c": 2.5, "b/d/e": True, "f": None, "g": None, "j": 3, "k": 4.0}
    assert type(flat["b/c"]) is float and type(flat["j"]) is int


def test_table_rows_in_grid_order(tmp_path):
    rows = [{"index": i, "repeat": 0, "grid": {"k": k, "m": m}, "success": k < 2, "error": None,
             "metrics": {"v": float(k)} if i else {"v": 0.0, "w": 1.0}, "wall_time_s": 0.1}
            for i, (k, m) in enumerate((k, m) for k in (1, 2, 3) for m in ("a", "b"))]
    shuffled = rows[::-1]
    assert columns(shuffled, ["k", "m"]) == ["k", "m", "repeat", "success", "error", "v", "w",
                                             "wall_time_s"]
    write_csv(tmp_path / "t.csv", shuffled, ["k", "m"])
    with open(tmp_path / "t.csv", newline="") as f:
        assert [int(r["k"]) for r in csv.DictReader(f)] == [1, 1, 2, 2, 3, 3]
    write_json(tmp_path / "t.json", {"scenario": "x"}, shuffled)
    assert [r["index"] for r in json.loads((tmp_path / "t.json").read_text())["rows"]] == \
        list(range(6))
    assert write_figure(tmp_path / "t.png", shuffled, ["k", "m"], "t", metric="v").exists()
    assert write_figure(tmp_path / "u.png", [], [], "empty").exists()


def test_a_flat_success_line_gives_way_to_a_metric_that_varies(tmp_path, monkeypatch):
    """Every run succeeded: sweep.png plots the first metric that changes along the grid (not a
    timing), not a line at 1."""
    rows = [{"index": i, "repeat": 0, "grid": {"dv": dv}, "success": True, "error": None,
             "metrics": {"cycle_time_median_us": 90.0 + i, "fell": False, "drift_m": 0.01 * dv},
             "wall_time_s": 0.1} for i, dv in enumerate((0.1, 0.2, 0.3))]
    assert default_metric(rows, ["dv"]) == "drift_m"
    flat = [{**r, "metrics": {"fell": False, "cycle_time_median_us": 90.0 + r["index"]}}
            for r in rows]
    assert default_metric(flat, ["dv"]) is None
    labels = []
    from matplotlib.axes import Axes
    real = Axes.set_ylabel
    monkeypatch.setattr(Axes, "set_ylabel", lambda ax, text, *a, **k: (labels.append(text),
                                                                        real(ax, text, *a, **k)))
    write_figure(tmp_path / "a.png", rows, ["dv"], "t")
    write_figure(tmp_path / "b.png", flat, ["dv"], "t")
    mixed = [{**r, "success": r["index"] != 1} for r in rows]
    write_figure(tmp_path / "c.png", mixed, ["dv"], "t")
    assert labels == ["drift_m", "success rate", "success rate"]


# ---------------------------------------------------------------- executors
def test_serial_executor_in_order_and_raises():
    assert list(SerialExecutor().map(abs, [-1, 2, -3])) == [(0, 1), (1, 2), (2, 3)]
    with pytest.raises(TypeError), SerialExecutor() as ex:
        list(ex.map(abs, ["x"]))


def test_local_pool_same_results_single_threaded_workers():
    """Results by index equal the serial ones; the workers see OPENBLAS_NUM_THREADS=1 while this
    process's environment is left as it was."""
    before = dict(os.environ)
    with LocalPoolExecutor(2) as pool:
        assert ordered(pool, abs, [-1, 2, -3, 4]) == [1, 2, 3, 4]
        seen = sorted(i for i, _ in pool.map(abs, range(5)))
        assert seen == list(range(5))
        env = ordered(pool, os.getenv, list(SINGLE_THREAD_ENV))
        with pytest.raises(TypeError):
            list(pool.map(abs, ["x"]))
    assert env == ["1"] * len(SINGLE_THREAD_ENV)
    assert dict(os.environ) == before
    with pytest.raises(ValueError, match="--workers: expected a whole number >= 1, got 0"):
        LocalPoolExecutor(0)


def test_sweep_run_is_picklable():
    import pickle
    run = SweepRun(3, "push", "talos14", "lqr", {"peak_force": "100"}, {"peak_force": "100"}, 1)
    assert pickle.loads(pickle.dumps(run)) == run
    assert run.label() == "peak_force=100 repeat=1"


def test_robot_reference_makes_files_absolute(tmp_path, monkeypatch):
    """A robot file is passed to the workers as an absolute path (a Ray worker's directory is
    not this one); a preset name as it is."""
    from wholebody.sweep.grid import robot_reference
    (tmp_path / "quad.toml").write_text("")
    monkeypatch.chdir(tmp_path)
    assert robot_reference("quad.toml") == str(tmp_path / "quad.toml")
    assert robot_reference("talos14") == "talos14"


def test_unreachable_ray_address_exit_2(tmp_path, capsys, no_simulation):
    """A host:port nobody listens on is refused at once (Ray itself would retry for minutes)."""
    pytest.importorskip("ray")
    assert main(["sweep", "push", "--grid", "peak_force=1", "--ray", "127.0.0.1:1",
                 "--out", str(tmp_path / "out")]) == 2
    assert "--ray 127.0.0.1:1: no Ray head node answers there" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_sweep_of_more_runs_than_it_can_list_is_refused(capsys, tmp_path):
    """--repeat 1e9 grew memory without bound before the first run: refused, exit 2."""
    assert main(["sweep", "stand", "--grid", "duration=1,2", "--repeat", "1000000000",
                 "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert "--grid/--repeat: 2000000000 runs, more than 100000" in err


def test_a_sweep_on_a_busy_output_folder_is_refused(capsys, tmp_path):
    from wholebody.outputs import claim_output

    out = tmp_path / "s"
    with claim_output(out):
        assert main(["sweep", "stand", "--grid", "duration=0.2", "--serial", "--out",
                     str(out)]) == 2
    assert "in use by another wholebody command (pid" in capsys.readouterr().err
