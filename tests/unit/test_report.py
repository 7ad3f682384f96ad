"""``wholebody report`` without simulating: the claims' run specs are valid, the verdict
functions map metrics to verdicts, the runner turns runs into rows (an erroring run into an
``error`` row), ``--only``, the exit codes, and ``--update-docs`` on a copy of the docs."""

from __future__ import annotations

import functools
import json
import shutil
from pathlib import Path

import pytest


from wholebody.cli import main
from wholebody.report import claims as C
from wholebody.report import runner
from wholebody.report.claims import CLAIMS, Claim, RunSpec, claims_for, run, select
from wholebody.scenarios import SCENARIOS, get_scenario
from wholebody.scenarios.base import Scenario, ScenarioResult
from wholebody.sweep import SerialExecutor

ROOT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------- the registry
def test_claim_ids_unique_and_papers_known():
    ids = [c.id for c in CLAIMS]
    assert len(ids) == len(set(ids))
    assert {c.paper for c in CLAIMS} == set(C.PAPERS)
    assert claims_for("all") == C.HERZOG + C.FAHMI  # the papers; the agility table apart
    assert claims_for("agility") == C.AGILITY
    assert all(c.paper == "fahmi2019" for c in claims_for("fahmi2019"))


@functools.lru_cache(maxsize=None)
def _load(name: str):
    """A preset the session's ``robots`` fixture does not load, once per test process."""
    import wholebody as wb
    return wb.load_robot(name)


@pytest.mark.parametrize("claim", CLAIMS, ids=lambda c: c.id)
def test_every_run_spec_is_valid(claim, robots):
    """Its scenario exists, its controller is one of the scenario's, and the scenario resolves
    and validates its --set pairs on its robot (nothing simulated)."""
    scenario = get_scenario(claim.run.scenario)
    controller = claim.run.controller or scenario.controllers[0]
    assert controller in scenario.controllers
    scenario.resolve(claim.run.overrides)
    robot_name = claim.run.robot or scenario.default_robot
    robot = robots[robot_name] if robot_name in robots else _load(robot_name)
    scenario.validate(robot, claim.run.overrides)


def test_command_text_is_the_run_spec():
    spec = RunSpec("crawl", "hyq", "passive", (("gait", "trot"), ("speed_end", "0.3")))
    assert spec.command() == ("wholebody run crawl --robot hyq --controller passive "
                              "--set gait=trot --set speed_end=0.3")
    assert spec.id == "crawl-hyq-passive-gait=trot-speed_end=0.3"
    assert run("squat", "pd", variant="cop-active").command() == \
        "wholebody run squat --controller pd --set variant=cop-active"
    assert run("ramp").command() == "wholebody run ramp"


def test_select_only_and_errors():
    assert [c.id for c in select("fahmi2019", ["ramp", "crawl"])] == ["crawl", "ramp"]
    with pytest.raises(ValueError, match="unknown claim id 'fig6'"):
        select("fahmi2019", ["fig6"])  # a Herzog claim
    with pytest.raises(ValueError, match="unknown paper"):
        select("nobody2020")


# ---------------------------------------------------------------- verdict functions
def test_crawl_verdicts_follow_the_scenario_claim():
    def summary(lin, ang, holds):
        m = {name: {"linear_rms_m": l, "angular_rms_rad": a, "fell": False}
             for name, l, a in (("passive", 1e-3 * (1 - lin), 1e-3 * (1 - ang)),
                                ("quasi-static", 1e-3, 1e-3))}
        m["claim"] = {"linear_rms_reduction": lin, "angular_rms_reduction": ang, "holds": holds}
        return {"success": True, "metrics": m}
    crawl = next(c for c in CLAIMS if c.id == "crawl")
    assert crawl.evaluate(summary(0.45, 0.42, True))[1] == "reproduced"
    assert crawl.evaluate(summary(0.3, 0.2, False))[1] == "partly"
    ours, verdict = crawl.evaluate(summary(-0.03, -0.04, False))
    assert verdict == "not reproduced" and "3 % higher" in ours


def test_table3_verdict_compares_with_the_paper_per_point():
    def largest(forces):
        return {"metrics": {"largest_survived": {
            f"{g}/{loc}": {"peak_force_N": f, "delta_v_mps": f / 1000}
            for g in ("pd", "lqr") for loc, f in zip(("front", "right", "back", "left"), forces)}}}
    pd = next(c for c in CLAIMS if c.id == "table3-pd")
    assert pd.evaluate(largest([240, 110, 110, 90]))[1] == "reproduced"
    ours, verdict = pd.evaluate(largest([200, 110, 110, 90]))
    assert verdict == "partly" and ours.startswith("200 / 110 / 110 / 90 N")
    assert pd.evaluate(largest([10, 10, 10, 10]))[1] == "not reproduced"


def test_fig6_and_robust_push_thresholds():
    fig6 = next(c for c in CLAIMS if c.id == "fig6")
    base = {"trials": 56, "survived": {"pd": 28, "lqr": 28}, "pairs_survived_by_both": 28}
    for fraction, verdict in ((0.9, "reproduced"), (0.6, "partly"), (0.43, "not reproduced"),
                              (None, "not reproduced")):
        s = {"metrics": {**base, "lqr_cog_error_le_pd_fraction": fraction}}
        assert fig6.evaluate(s)[1] == verdict
    robust = {c.id: c for c in CLAIMS if c.id.startswith("robust-push")}
    s = {"metrics": {"success_rate": 0.95, "survived": 19, "runs": 20, "max_cog_error_m": 0.006}}
    assert robust["robust-push-pd"].evaluate(s)[1] == "partly"
    assert robust["robust-push-lqi"].evaluate(s)[1] == "ours"
    s["metrics"].update(success_rate=1.0, survived=20)
    assert robust["robust-push-pd"].evaluate(s)[1] == "reproduced"


def test_passivity_verdicts():
    passivity = next(c for c in CLAIMS if c.id == "passivity-crawl")

    def summary(within_1w, count, near, success=True):
        return {"success": success, "parameters": {"gait": "crawl"}, "metrics": {
            "assumption2_wrench_error_N": {"median": 0.1},
            "passivity": {"no_switch": {"fraction_holds": 0.97,
                                        "fraction_holds_within_1W": within_1w},
                          "violations_beyond_1W": {"count": count,
                                                   "within_50ms_after_contact_switch": near}}}}
    assert passivity.evaluate(summary(1.0, 0, 0))[1] == "reproduced"
    assert passivity.evaluate(summary(0.99, 5, 5))[1] == "partly"
    assert passivity.evaluate(summary(0.9, 9, 5))[1] == "not reproduced"
    assert passivity.evaluate(summary(1.0, 0, 0, success=False))[1] == "not reproduced"


def test_a_verdict_outside_the_list_is_refused():
    claim = Claim("x", "fahmi2019", "Fig. 1", "c", "p", run("ramp"), lambda s: ("o", "maybe"))
    with pytest.raises(ValueError, match="verdict 'maybe'"):
        claim.evaluate({})


# ---------------------------------------------------------------- the runner on a fake scenario
def _fake_claims():
    """Three claims of the push scenario: two share a run, the third's run raises."""
    def judge(s):
        force = s["metrics"]["peak_force_N"]
        return f"{force:.0f} N", "reproduced" if s["success"] else "not reproduced"
    return (
        Claim("a", "herzog2016", "Table 3", "strong push", "100 N",
              run("push", "pd", peak_force=100), judge),
        Claim("b", "herzog2016", "Table 3", "same run, other claim", "100 N",
              run("push", "pd", peak_force=100), lambda s: ("x", "partly")),
        Claim("c", "herzog2016", "Fig. 6", "broken run", "—",
              run("push", "lqr", peak_force=666), judge),
        Claim("d", "fahmi2019", "Fig. 5", "too strong", "200 N",
              run("push", "pd", peak_force=200), judge),
    )


@pytest.fixture
def fake_runs(monkeypatch):
    """Scenario.run returns at once (success below 150 N) and writes its summary like the real
    one; ``peak_force=666`` raises; every call is counted."""
    calls = []

    def fake(self, robot, controller=None, overrides=None, out_dir=None, progress=False):
        params = self.validate(robot, overrides)
        calls.append((self.name, controller, params["peak_force"]))
        if params["peak_force"] == 666:
            raise RuntimeError("solver exploded")
        result = ScenarioResult(self.name, robot.name, controller, params["peak_force"] < 150,
                                {"peak_force_N": params["peak_force"]}, params)
        if out_dir is not None:
            result.write(Path(out_dir))
        return result
    monkeypatch.setattr(Scenario, "run", fake)
    return calls


def test_runner_rows_shared_runs_and_error_rows(tmp_path, fake_runs):
    claims = _fake_claims()
    report = runner.run_report(claims, SerialExecutor(), tmp_path)
    assert len(fake_runs) == 3  # a and b share one run
    rows = {r.claim.id: r for r in report.rows}
    assert (rows["a"].ours, rows["a"].verdict) == ("100 N", "reproduced")
    assert rows["b"].verdict == "partly"
    assert rows["c"].verdict == "error" and "RuntimeError: solver exploded" in rows["c"].ours
    assert (rows["d"].ours, rows["d"].verdict) == ("200 N", "not reproduced")
    assert report.errors == 1
    run_dir = tmp_path / "runs" / claims[0].run.id
    assert json.loads((run_dir / "summary.json").read_text())["metrics"]["peak_force_N"] == 100
    assert (tmp_path / "runs" / claims[2].run.id / "error.txt").exists()
    paths = runner.write_outputs(report, tmp_path)
    assert [p.name for p in paths] == ["results-herzog2016.md", "results-fahmi2019.md",
                                       "report.json"]
    md = (tmp_path / "results-herzog2016.md").read_text()
    assert "| claim | paper | ours | verdict | command |" in md
    assert ("| `a` strong push (Table 3) | 100 N | 100 N | reproduced | "
            "`wholebody run push --controller pd --set peak_force=100` |") in md
    assert "`d`" not in md
    data = json.loads((tmp_path / "report.json").read_text())
    assert [r["id"] for r in data["rows"]] == ["a", "b", "c", "d"]
    assert data["runs"][1]["error"] == "RuntimeError: solver exploded"


def test_a_verdict_function_that_raises_is_an_error_row(tmp_path, fake_runs):
    claim = Claim("k", "fahmi2019", "Fig. 1", "c", "p", run("push", "pd"),
                  lambda s: (s["metrics"]["missing"], "reproduced"))
    report = runner.run_report((claim,), SerialExecutor(), tmp_path)
    assert report.rows[0].verdict == "error" and "KeyError" in report.rows[0].ours
    assert report.errors == 1


# ---------------------------------------------------------------- the command
@pytest.fixture
def fake_registry(monkeypatch, fake_runs):
    monkeypatch.setattr(C, "CLAIMS", _fake_claims())
    return fake_runs


def test_cli_exit_codes_and_only(tmp_path, capsys, fake_registry):
    out = tmp_path / "out"
    assert main(["report", "--paper", "herzog2016", "--only", "a,b", "--serial",
                 "--out", str(out)]) == 0
    assert len(fake_registry) == 1
    assert "a: reproduced — 100 N" in capsys.readouterr().out
    assert main(["report", "--paper", "herzog2016", "--serial", "--out", str(out)]) == 1
    assert "c: error" in capsys.readouterr().out
    assert main(["report", "--paper", "all", "--only", "d", "--serial", "--out", str(out)]) == 0
    assert (out / "results-fahmi2019.md").exists()


@pytest.mark.parametrize(("argv", "needle"), [
    (["--paper", "nobody"], "unknown paper 'nobody'"),
    (["--paper", "herzog2016", "--only", "zz"], "unknown claim id 'zz'"),
    (["--paper", "fahmi2019", "--only", "a"], "unknown claim id 'a'"),
    (["--paper", "herzog2016", "--only", ","], "no claim id"),
    (["--paper", "herzog2016", "--workers", "0"], "--workers"),
])
def test_usage_errors_exit_2_before_running(argv, needle, tmp_path, capsys, fake_registry):
    assert main(["report", *argv, "--out", str(tmp_path / "o")]) == 2
    assert needle in capsys.readouterr().err
    assert fake_registry == []


def test_unwritable_out_and_docs_without_markers_exit_2(tmp_path, capsys, fake_registry):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert main(["report", "--paper", "herzog2016", "--serial", "--out", str(blocker)]) == 2
    assert "cannot write there" in capsys.readouterr().err
    docs = tmp_path / "results.md"
    docs.write_text("# no markers\n")
    assert main(["report", "--paper", "herzog2016", "--serial", "--out", str(tmp_path / "o"),
                 "--update-docs", "--docs", str(docs)]) == 2
    assert "report:herzog2016:begin" in capsys.readouterr().err
    assert fake_registry == []


def test_update_docs_replaces_only_the_marked_region(tmp_path, capsys, fake_registry):
    docs = tmp_path / "results.md"
    shutil.copy(ROOT / "docs" / "results.md", docs)
    original = docs.read_text()
    begin, end = runner.markers("herzog2016")
    assert main(["report", "--paper", "herzog2016", "--only", "a", "--serial", "--out",
                 str(tmp_path / "o"), "--update-docs", "--docs", str(docs)]) == 0
    text = docs.read_text()
    head, rest = text.split(begin)
    region, tail = rest.split(end)
    assert head == original.split(begin)[0] and tail == original.split(end)[1]
    assert "| `a` strong push (Table 3) | 100 N | 100 N | reproduced |" in region
    # --only d of the other paper leaves the Herzog region as it is; a second --only run keeps
    # the rows it did not run
    assert main(["report", "--paper", "herzog2016", "--only", "d,b", "--serial", "--out",
                 str(tmp_path / "o"), "--update-docs", "--docs", str(docs)]) == 2  # d: fahmi
    assert main(["report", "--paper", "herzog2016", "--only", "b", "--serial", "--out",
                 str(tmp_path / "o"), "--update-docs", "--docs", str(docs)]) == 0
    region = docs.read_text().split(begin)[1].split(end)[0]
    lines = [line for line in region.splitlines() if line.startswith("| `")]
    assert [line.split("`")[1] for line in lines] == ["a", "b"]


def test_docs_have_both_report_regions():
    text = (ROOT / "docs" / "results.md").read_text()
    for paper in C.PAPERS:
        runner.check_markers(text, paper)


def test_report_under_real_robot_conditions(tmp_path, capsys, monkeypatch, fake_registry):
    """--realism robot: every run gets --set realism=robot (its command says so), the tables are
    results-PAPER-robot.md, and --update-docs fills the paper's robot region only."""
    seen = []
    real_validate = Scenario.validate

    def validate(self, robot, overrides=None):
        params = real_validate(self, robot, overrides)
        seen.append(params["realism"])
        return params
    monkeypatch.setattr(Scenario, "validate", validate)
    docs = tmp_path / "results.md"
    begin, end = runner.markers("herzog2016-robot")
    docs.write_text(f"intro\n{begin}\nold\n{end}\nafter\n")
    out = tmp_path / "o"
    assert main(["report", "--paper", "herzog2016", "--only", "a", "--serial", "--out", str(out),
                 "--realism", "robot", "--update-docs", "--docs", str(docs)]) == 0
    assert seen and set(seen) == {"robot"}
    md = (out / "results-herzog2016-robot.md").read_text()
    assert "under 'robot' conditions" in md and "--set realism=robot" in md
    text = docs.read_text()
    assert text.startswith("intro\n") and text.endswith("after\n") and "old" not in text
    assert "| `a` strong push (Table 3)" in text
    assert main(["report", "--paper", "herzog2016", "--realism", "perfect", "--out",
                 str(out)]) == 2
    assert "--realism" in capsys.readouterr().err
    assert C.under_conditions(C.CLAIMS, "exact") == tuple(C.CLAIMS)
    kept = C.under_conditions(C.CLAIMS, "sensors")  # only the runs that can take it, all moved
    assert kept and all(("realism", "sensors") in c.run.sets for c in kept)
    assert all(SCENARIOS[c.run.scenario].simulations is not None for c in kept)
