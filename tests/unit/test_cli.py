"""The command line behaves like a good CLI: listings, a run writing summary.json and plots, clear
one-line errors with exit code 2 for bad input."""

import json
import subprocess
import sys

import pytest

from wholebody.cli import main


def test_robots_lists_presets(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    for name, dof in (("talos14", "14"), ("talos", "32"), ("hyq", "12")):
        assert any(line.split()[:2] == [name, dof] for line in out.splitlines()), out
    assert main(["robots", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["name"] for r in rows} == {"talos14", "talos", "hyq"}


def test_scenarios_lists_parameters(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert "stand" in out and "--set duration=5.0" in out


def test_run_writes_summary_and_plots(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "stand", "--robot", "hyq", "--set", "duration=1.0", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert {"scenario", "robot", "controller", "success", "metrics"} <= set(summary)
    assert summary["scenario"] == "stand" and summary["robot"] == "hyq"
    assert summary["success"] is True and summary["parameters"]["duration"] == 1.0
    pngs = list(out.glob("*.png"))
    assert pngs and all(p.stat().st_size > 10_000 for p in pngs)
    assert "SUCCESS" in capsys.readouterr().out


def test_crawl_with_the_native_engine(tmp_path):
    """`--set engine=native` runs the passive WBC's compiled cycle in the crawl scenario."""
    from conftest import native_cycle_or_skip
    native_cycle_or_skip()
    out = tmp_path / "crawl"
    assert main(["run", "crawl", "--robot", "hyq", "--controller", "passive", "--set",
                 "engine=native", "--set", "duration=3.0", "--set", "ramp_time=2.0",
                 "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is True and summary["parameters"]["engine"] == "native"
    assert summary["metrics"]["passive"]["distance_m"] > 0.1


def test_run_with_robot_file(tmp_path):
    robot_file = tmp_path / "quad.toml"
    robot_file.write_text(
        'name = "quad"\nurdf = "erd:hyq_description/robots/hyq_no_sensors.urdf"\n'
        'srdf = "erd:hyq_description/srdf/hyq.srdf"\nposture = "standing"\ncontacts = [\n' +
        "".join(f'  {{ name = "{l}", frame = "{l}_foot", type = "point", radius = 0.02175 }},\n'
                for l in ("lf", "rf", "lh", "rh")) + "]\n")
    out = tmp_path / "o"
    assert main(["run", "stand", "--robot", str(robot_file), "--set", "duration=0.3",
                 "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["robot"] == "quad"


@pytest.mark.parametrize("argv,needle", [
    (["run", "fly"], "unknown scenario 'fly'; scenarios: "),
    (["run", "stand", "--robot", "atlas"], "unknown robot 'atlas'; presets: hyq, talos, talos14"),
    (["run", "stand", "--set", "speed=3"], "no parameter 'speed'"),
    (["run", "stand", "--set", "duration"], "--set expects key=value"),
    (["run", "stand", "--controller", "mpc"], "no controller 'mpc'"),
    (["run", "stand", "--robot", "missing.toml"], "robot file not found"),
    (["run", "crawl", "--robot", "hyq", "--set", "engine=gpu"], "--set engine: expected one of"),
    *[(["run", name, "--set", "engine=gpu"], "--set engine: expected one of")
      for name in ("push", "platform", "tilt-board", "squat", "stepping")],
])
def test_bad_input_exit_2(argv, needle, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert needle in err and len(err.strip().splitlines()) == 1


def test_robot_file_missing_field_named(tmp_path, capsys):
    robot_file = tmp_path / "bad.toml"
    robot_file.write_text('name = "bad"\nurdf = "erd:hyq_description/robots/hyq_no_sensors.urdf"\n'
                          'posture = {lf_kfe_joint = -1.5}\n')
    assert main(["run", "stand", "--robot", str(robot_file)]) == 2
    assert "missing required field 'contacts'" in capsys.readouterr().err


def test_console_script_entry_point():
    """`python -m wholebody` / the installed script reach the same main()."""
    proc = subprocess.run([sys.executable, "-m", "wholebody", "run", "nothing"],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "unknown scenario" in proc.stderr
