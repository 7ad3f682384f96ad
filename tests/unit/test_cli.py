"""The command line behaves like a good CLI: listings, a run writing summary.json and plots, clear
one-line errors with exit code 2 for bad input."""

import fcntl
import json
import subprocess
import sys

import pytest

from wholebody.cli import main


def test_robots_lists_presets(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    for name, dof in (("talos14", "14"), ("talos", "32"), ("hyq", "12"), ("go1", "12"),
                      ("go2", "12"), ("a1", "12"), ("solo12", "12"), ("anymal_c", "12"),
                      ("romeo", "13")):
        assert any(line.split()[:2] == [name, dof] for line in out.splitlines()), out
    assert main(["robots", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["name"] for r in rows} == {"talos14", "talos", "hyq", "go1", "go2", "a1", "solo12",
                                        "anymal_c", "romeo"}


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
    (["run", "stand", "--robot", "atlas"],
     "unknown robot 'atlas'; presets: a1, anymal_c, go1, go2, hyq, romeo, solo12, talos, talos14"),
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


def test_robot_without_feet_is_refused(tmp_path, capsys):
    """A robot with no contacts (an upper body such as example-robot-data's Alex) is refused at
    load, by check-robot and by run, with what a contact is for."""
    robot_file = tmp_path / "upper_body.toml"
    robot_file.write_text('name = "alex"\nurdf = "erd:alex_description/urdf/alex_nub_hands.urdf"\n'
                          'srdf = "erd:alex_description/srdf/alex_nub_hands.srdf"\n'
                          'posture = "default"\ncontacts = []\n')
    for argv in (["check-robot", str(robot_file)], ["run", "stand", "--robot", str(robot_file)]):
        assert main(argv) == 2
        err = capsys.readouterr()
        assert "field 'contacts' is empty" in err.err + err.out


def test_console_script_entry_point():
    """`python -m wholebody` / the installed script reach the same main()."""
    proc = subprocess.run([sys.executable, "-m", "wholebody", "run", "nothing"],
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "unknown scenario" in proc.stderr


def test_output_cut_short_by_its_reader_is_not_an_error():
    """`wholebody scenarios | head -1`: the pipe closes after one line; no traceback, exit 0."""
    proc = subprocess.Popen([sys.executable, "-m", "wholebody", "scenarios"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    if hasattr(fcntl, "F_SETPIPE_SZ"):  # a pipe smaller than the listing: the writer must wait
        fcntl.fcntl(proc.stdout.fileno(), fcntl.F_SETPIPE_SZ, 4096)
    first = proc.stdout.readline()
    proc.stdout.close()  # the reader goes away with most of the listing unread
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 0, stderr
    assert first and "Traceback" not in stderr and "BrokenPipe" not in stderr


# ---------------------------------------------------------------- checked before simulating
@pytest.mark.parametrize("argv,needle", [
    (["run", "stand", "--set", "duration=0"],
     "--set duration: expected a finite number in (0, 600], got '0'"),
    (["run", "stand", "--set", "duration=nan"], "--set duration: expected a finite number in "
                                                "(0, 600], got 'nan'"),
    (["run", "stand", "--set", "duration=inf"], "got 'inf'"),
    (["run", "stand", "--set", "duration=-inf"], "got '-inf'"),
    (["run", "stand", "--set", "duration=1e9"], "--set duration: expected a finite number in "
                                                "(0, 600], got '1e9'"),
    (["run", "crawl", "--set", "ramp_time=0"], "--set ramp_time: expected a finite number in "
                                               "(0, 600], got '0'"),
    (["run", "stand", "--set", "friction=-1"],
     "--set friction: expected a finite number in (0, 10], got '-1'"),
    (["run", "push", "--set", "start=-1"], "--set start: expected a finite number in [0, 600], "
                                           "got '-1'"),
    (["run", "push", "--set", "peak_force=-150"], "--set peak_force: expected a finite number in "
                                                  "[0, inf), got '-150'"),
    (["run", "push", "--set", "location=nose"], "--set location: expected one of front, right"),
    (["run", "stand", "--set", "duration=abc"], "--set duration: expected a number, got 'abc'"),
    (["run", "stepping", "--set", "steps=1.5"], "--set steps: expected a whole number, got '1.5'"),
    (["run", "stepping", "--set", "steps=0"], "--set steps: expected a whole number in [1, 100], "
                                              "got '0'"),
    (["run", "push-series", "--set", "forces=60,nan"], "--set forces: expected a finite number in "
                                                       "(0, inf), got item 'nan'"),
    (["run", "push-series", "--set", "locations=front,nose"], "--set locations: expected one of "),
    (["run", "robust-push", "--set", "torque_delay=1,-2"], "--set torque_delay: expected a whole "
                                                           "number in [0, 1000], got item '-2'"),
    (["run", "robust-push", "--set", "locations=hip-right"],
     "no measured nominal force for pd at 'hip-right' (known: front, back, left, right); pass "
     "--set nominal_force=N"),
    (["run", "squat", "--set", "variant=deep"], "--set variant: expected one of tracking, "
                                                "cop-active, got 'deep'"),
    (["run", "ramp", "--set", "speed=0.001"], "--set speed: expected 0 or a finite number in "
                                              "[0.01, 5], got '0.001'"),  # 0: the course's speed
    # robot-relative: a size against the robot's standing base height h
    (["run", "stepping", "--set", "lift=0.6"],
     "--set lift: expected a finite number in (0, 0.5 h] = (0, 0.51] for robot 'talos' "
     "(h = 1.02 m), got 0.6"),
    (["run", "ramp", "--set", "step=0.3"],
     "--set step: expected a finite number in (-0.25 h, 0.25 h) = (-0.15, 0.15) for robot 'hyq'"),
    # in range, but beyond what the robot's legs reach (HyQ lifts a foot 0.145 m, r 0.022 m)
    (["run", "ramp", "--set", "course=stairs", "--set", "step_height=0.28"],
     "--set step_height: 0.28 m is more than hyq's legs reach"),
    # in range, but not together: each crashed after simulating or reported a push that never came
    (["run", "crawl", "--controller", "passive", "--set", "duration=1.0"],
     "--set duration: 1 s ends before the gait starts (at 1 s)"),
    (["run", "stand", "--set", "duration=0.0001"], "--set duration: 0.0001 s is shorter than"),
    (["run", "push", "--set", "duration=0.0001"], "--set duration: 0.0001 s is shorter than"),
    (["run", "crawl", "--controller", "passive", "--set", "period=1e-300", "--set",
      "duration=1.5"], "--set period: 1e-300 s is shorter than 0.1 s"),
    (["run", "push", "--set", "start=600", "--set", "duration=0.3"],
     "--set start: the push ends at 600.1 s, less than 0.2 s before the run does"),
    (["run", "stand", "--set", "duration=1", "--set", "duration=2"],
     "--set duration: given twice ('1' and '2')"),
])
def test_out_of_range_exit_2_before_simulating(argv, needle, capsys, no_simulation, tmp_path):
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wholebody: error: ") and needle in err, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # nothing made before the checks passed


def test_bad_input_via_the_console_script(tmp_path):
    """The installed entry point: exit 2, one line on stderr, no traceback (no simulation: the
    values are refused while parsing)."""
    for sets in (["duration=0"], ["duration=nan"], ["kp=x"], ["speed=1"]):
        proc = subprocess.run([sys.executable, "-m", "wholebody", "run", "stand",
                               *[a for s in sets for a in ("--set", s)], "--out",
                               str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, (sets, proc.stderr)
        assert proc.stderr.startswith("wholebody: error: ") and "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("contents,needle", [
    (b"\xff\xfe", "not UTF-8 text"),
    (b"name = = \n", "invalid TOML"),
    (b'name = "x"\n', "missing required field"),
])
def test_bad_robot_file_exit_2(tmp_path, capsys, contents, needle, no_simulation):
    robot_file = tmp_path / "bad.toml"
    robot_file.write_bytes(contents)
    assert main(["run", "stand", "--robot", str(robot_file), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("wholebody: error: ") and needle in err and len(err.splitlines()) == 1


def test_declared_ranges_cover_every_parameter():
    """Every numeric parameter of every scenario has a declared range, every fixed-set string its
    choices, and every default lies in its range (robot-relative bounds on the default robot)."""
    import math

    from wholebody.robots import load_robot
    from wholebody.scenarios import SCENARIOS
    from wholebody.scenarios.base import RobotRelative

    free_text = {("joint-limit", "joint"), ("weak-joint", "joint"),
                 ("single-support", "sine_joints")}  # robot-dependent names, checked by validate
    robots = {}
    for s in SCENARIOS.values():
        for p in s.parameters:
            if p.numeric:
                assert p.low != -math.inf or p.high != math.inf, (s.name, p.name)
            elif p.kind is str:
                assert p.choices or (s.name, p.name) in free_text, (s.name, p.name)
            if not isinstance(p.default, RobotRelative):  # those are checked with the robot
                p.parse(str(p.default).lower() if isinstance(p.default, bool) else str(p.default))
        robot = robots.setdefault(s.default_robot, load_robot(s.default_robot))
        for p in s.parameters:
            value = p.check(p.default, robot)
            assert isinstance(value, str if p.items else p.kind), (s.name, p.name, value)
        # durations and times are bounded: nothing asks for more than MAX_TIME of simulated time
        for p in s.parameters:
            if p.name == "duration" or p.help.rstrip(")").endswith("(s"):
                assert p.high == p.MAX_TIME, (s.name, p.name)


def test_parameter_ranges_unit():
    from types import SimpleNamespace

    from wholebody.scenarios.base import Parameter

    robot = SimpleNamespace(name="toy", q_ref=[0.0, 0.0, 0.8])
    lift = Parameter("lift", 0.1, "lift (m)", low=0.0, low_open=True, high=0.5 * Parameter.H)
    assert lift.range_text() == "(0, 0.5 h]" and lift.describe() == "in (0, 0.5 h]"
    assert lift.parse("0.7") == 0.7  # robot-relative bounds wait for the robot ...
    with pytest.raises(ValueError, match=r"--set lift: .*\(0, 0\.4\] for robot 'toy'.*got 0\.7"):
        lift.check(0.7, robot)  # ... and are checked with it
    assert lift.check(0.4, robot) == 0.4
    for bad in ("0", "-0.1", "nan", "inf"):
        with pytest.raises(ValueError, match="--set lift: expected a finite number"):
            lift.parse(bad)
    count = Parameter("n", 2, "count", low=1, high=5)
    assert count.parse("5") == 5 and count.range_text() == "[1, 5]"
    with pytest.raises(ValueError, match=r"--set n: expected a whole number in \[1, 5\], got '6'"):
        count.parse("6")
    mode = Parameter("mode", "a", "mode", choices=("a", "b"))
    assert mode.parse("b") == "b" and mode.describe() == "one of: a, b"
    with pytest.raises(ValueError, match="--set mode: expected one of a, b, got 'c'"):
        mode.parse("c")
    forces = Parameter("forces", "1,2", "forces", low=0.0, low_open=True, items=float)
    assert forces.parse(" 3, 4 ") == "3, 4" and forces.describe() == "items in (0, inf)"
    with pytest.raises(ValueError, match="got item '-4'"):
        forces.parse("3,-4")
    unbounded = Parameter("x", 1.0, "x", low=0.0, finite=False)
    assert unbounded.parse("inf") == float("inf") and unbounded.range_text() == "[0, inf]"
    with pytest.raises(ValueError, match="got 'nan'"):
        unbounded.parse("nan")
    auto = Parameter("speed", 0.0, "speed (0: automatic)", low=0.01, high=5.0, special=(0.0,))
    assert auto.parse("0") == 0.0 and auto.parse("0.5") == 0.5
    assert auto.describe() == "0 or in [0.01, 5]"
    with pytest.raises(ValueError, match=r"expected 0 or a finite number in \[0\.01, 5\]"):
        auto.parse("0.001")
    flag = Parameter("flag", False, "flag")
    assert flag.parse("yes") is True and flag.parse(True) is True and flag.range_text() is None


def test_scenarios_name_shows_that_scenario(capsys):
    assert main(["scenarios", "crawl"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("crawl  (robot ") and "--set speed_start=" in out
    assert "\nstand  (robot" not in out and "\npush  (robot" not in out
    assert main(["scenarios", "crawl", "--json"]) == 0
    assert list(json.loads(capsys.readouterr().out)) == ["crawl"]
    assert main(["scenarios", "fly"]) == 2
    captured = capsys.readouterr()
    assert "unknown scenario 'fly'; scenarios: " in captured.err and captured.out == ""


def test_a_papers_claim_is_a_verdict_of_its_own():
    """crawl can succeed while the paper's claim does not hold: the claim is not printed as one
    more metric under SUCCESS but as its own verdict."""
    from wholebody.cli import _claim_verdict

    line = _claim_verdict({"paper": "errors ~50 % lower", "linear_rms_reduction": 0.44,
                           "holds": False})
    assert "DOES NOT HOLD: errors ~50 % lower (linear_rms_reduction=0.44)" in line
    assert "not the run's success" in line and "holds=" not in line


def test_scenarios_lists_ranges(capsys):
    from wholebody.scenarios import SCENARIOS

    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    names = [line.split()[0] for line in out.splitlines() if line and not line.startswith(" ")
             and not line.startswith("h:")]
    assert names == list(SCENARIOS)
    assert "simulated time (s); in (0, 600]" in out
    assert "one of: auto, native, python" in out and "in (0, 0.5 h]" in out
    assert out.rstrip().splitlines()[-1].startswith("h: the robot's standing base height")
    assert main(["scenarios", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == set(SCENARIOS)
    duration = data["stand"]["parameters"]["duration"]
    assert duration["range"] == "(0, 600]" and duration["bounds"] == {
        "low": 0.0, "high": 600.0, "low_open": True, "high_open": False, "finite": True}
    assert data["push"]["parameters"]["engine"]["choices"] == ["auto", "native", "python"]
    assert data["stepping"]["parameters"]["lift"]["bounds"]["high"] == {"base_height": 0.5}
    assert data["push-series"]["parameters"]["forces"]["list"] is True


# ---------------------------------------------------------------- output directory, Ctrl-C
@pytest.mark.parametrize("make_out", [
    lambda tmp: tmp / "a_file",  # an existing file
    lambda tmp: tmp / "a_file" / "sub",  # under a file
])
def test_unwritable_out_exit_2_before_simulating(tmp_path, capsys, no_simulation, make_out):
    (tmp_path / "a_file").write_text("not a directory\n")
    out = make_out(tmp_path)
    assert main(["run", "stand", "--set", "duration=0.2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"wholebody: error: --out {out}: cannot write there")
    assert len(err.strip().splitlines()) == 1


def test_unwritable_out_read_only_directory(tmp_path, capsys, no_simulation):
    import os

    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o500)
    try:
        if os.access(out, os.W_OK):
            pytest.skip("running as a user that may write into read-only directories (root)")
        assert main(["run", "stand", "--set", "duration=0.2", "--out", str(out)]) == 2
        assert f"--out {out}: cannot write there" in capsys.readouterr().err
    finally:
        out.chmod(0o700)


def test_interrupted_run_writes_marked_summary(tmp_path, capsys, monkeypatch):
    """Ctrl-C during the run: the stale summary.json of an earlier run is gone before the run
    starts, and an interrupted one (scenario, robot, parameters, "interrupted": true) replaces it;
    exit 130."""
    from wholebody.scenarios.base import Scenario

    out = tmp_path / "run"
    out.mkdir()
    (out / "summary.json").write_text(json.dumps({"scenario": "stand", "success": True}))
    seen = {}

    def run(self, robot, controller=None, overrides=None, out_dir=None, progress=False):
        seen["stale summary"] = (out / "summary.json").exists()
        raise KeyboardInterrupt
    monkeypatch.setattr(Scenario, "run", run)
    assert main(["run", "stand", "--robot", "hyq", "--set", "duration=0.7", "--out", str(out)]) \
        == 130
    assert seen == {"stale summary": False}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] is True and summary["success"] is False
    assert summary["scenario"] == "stand" and summary["robot"] == "hyq"
    assert summary["controller"] == "standing" and summary["parameters"]["duration"] == 0.7
    assert summary["metrics"] == {} and summary["figures"] == []
    err = capsys.readouterr().err
    assert "stand on hyq (standing): INTERRUPTED" in err and str(out / "summary.json") in err


def test_summary_says_not_interrupted():
    from wholebody.scenarios.base import ScenarioResult

    summary = ScenarioResult("stand", "hyq", "standing", True, {}, {}).summary()
    assert summary["interrupted"] is False


def test_diverging_simulation_is_reported_with_its_time(tmp_path, capsys, monkeypatch):
    """Solo12 (example-robot-data, its URDF's 1000 Nm limits) standing on absolute joint gains
    made for a 90 kg Talos (kp = 1000, kd = 30; the defaults before they were derived from the
    robot), far too stiff for a 2.5 kg robot: MuJoCo diverges within the first hundredth of a
    second. The run ends with exit 1 and a summary that says when, not with an error from
    downstream, and what went wrong before (the incidents, printed too)."""
    robot = tmp_path / "solo12.toml"
    robot.write_text('name = "solo12"\nurdf = "erd:solo_description/robots/solo12.urdf"\n'
                     'srdf = "erd:solo_description/srdf/solo.srdf"\nposture = "standing"\n'
                     'contacts = [\n' + "".join(
                         f'  {{ name = "{leg.lower()}", frame = "{leg}_FOOT", type = "point", radius = 0.0 }},\n'
                         for leg in ("FL", "FR", "HL", "HR")) + "]\n")
    out = tmp_path / "run"
    monkeypatch.chdir(tmp_path)  # MuJoCo writes MUJOCO_LOG.TXT into the working directory
    assert main(["run", "stand", "--robot", str(robot), "--set", "kp=1000", "--set", "kd=30",
                 "--out", str(out), "--no-progress"]) == 1
    summary = json.loads((out / "summary.json").read_text())
    assert summary["success"] is False and 0.0 < summary["metrics"]["diverged_at_s"] < 0.1
    printed = capsys.readouterr()
    assert "the simulation diverged at t = " in printed.err
    incidents = summary["incidents"]
    assert incidents and all(x["t"] <= summary["metrics"]["diverged_at_s"] for x in incidents)
    assert "first incidents in the twin:" in printed.out and incidents[0]["what"] in printed.out


def test_a_robot_path_that_is_no_file_is_named(tmp_path, capsys):
    folder = tmp_path / "robot.toml"
    folder.mkdir()
    for path, needle in ((folder, "is a folder, not a .toml file"),
                         ("/dev/null", "is not a regular file"),
                         (tmp_path / "missing.toml", "robot file not found")):
        assert main(["run", "stand", "--robot", str(path), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert needle in err and len(err.strip().splitlines()) == 1, err
