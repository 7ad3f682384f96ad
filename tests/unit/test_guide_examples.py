"""The worked examples of docs/guide.md ("Examples") run as they are and do what they say.

Each example is a fenced block whose info string is ``python example:<name>`` (it still renders
as Python). ``test_docs.py`` runs only the plain ``python`` blocks (its fence allows nothing after
the language), so these blocks run here, once each, and the MuJoCo-loop one can be slow-marked.
Each runs in a fresh namespace from a temporary working directory (MuJoCo may write a log there);
its own ``assert`` statements must pass, and the test then checks the variables it leaves.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guide.md"
#: a ```python fence with more in its info string than the language (test_docs.py takes the rest)
MARKED = re.compile(r"^```python[ \t]+(\S[^\n]*?)[ \t]*\n(.*?)^```[ \t]*$",
                    re.MULTILINE | re.DOTALL)
EXAMPLE = re.compile(r"example:([a-z0-9-]+)")


def marked_blocks(path: Path | None = None) -> list[tuple[str, str]]:
    """(info string after "python", code) of every marked ```python block of ``path`` (default:
    the guide), in order."""
    return MARKED.findall((path or GUIDE).read_text(encoding="utf-8"))


def example_code(name: str) -> str:
    """The code of the block fenced as ```python example:<name>; fails if it is not there once."""
    found = [code for info, code in marked_blocks() if info == f"example:{name}"]
    if len(found) != 1:
        pytest.fail(f"docs/guide.md: expected one ```python example:{name} block, found "
                    f"{len(found)}")
    return found[0]


def run_example(name: str, tmp_path, monkeypatch) -> dict:
    """Execute the example in a fresh namespace (cwd: ``tmp_path``) and return the namespace."""
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "__guide_example__"}
    code = compile(example_code(name), f"docs/guide.md, example {name}", "exec")
    exec(code, namespace)  # noqa: S102 - the documented code
    return namespace


# ------------------------------------------------------------------------- what each one leaves
def check_own_stack(ns: dict) -> None:
    from wholebody.guard import Outcome
    from wholebody.robot import GRAVITY

    robot, sol = ns["robot"], ns["sol"]
    assert sol.outcome is Outcome.SOLVED and not sol.sacrificed()
    assert len(ns["stack"].levels) == 3 and set(sol.forces) == set(robot.contact_names)
    vertical = sum(f[2] for f in sol.forces.values())
    assert vertical == pytest.approx(robot.mass * GRAVITY, rel=1e-6)
    assert all(f[2] > 0.0 for f in sol.forces.values())  # both soles loaded
    lower, upper = robot.torque_bounds()
    assert np.all(sol.tau >= lower) and np.all(sol.tau <= upper)


def check_own_task(ns: dict) -> None:
    from wholebody.cycle import HierarchyCycle
    from wholebody.formulation import Formulation
    from wholebody.solvers import SolverSettings
    from wholebody.tasks import Task

    robot, sol, squat = ns["robot"], ns["sol"], ns["squat"]
    assert issubclass(ns["FrameHeight"], Task) and squat in ns["stack"].levels[2]
    assert ns["asked"] == pytest.approx(-3.0) and ns["z_ddot"] == pytest.approx(-3.0, rel=1e-3)
    report = next(t for t in sol.tasks if t.name == squat.name)
    assert report.level == 3 and report.kind == "eq" and report.rows == 1
    with pytest.raises(ValueError, match=r"FrameHeight\('height .*'\)\.kp"):
        squat.kp = -1.0  # the gains are checked attributes, as the library's
    # the guide's claim: a task of your own runs natively with its rows from Python, and the
    # cycle gives the Python reference's torques, up to 1e-6 Nm plus the reference's own
    # sensitivity (the squat and the saturated torques make this cascade ill-conditioned)
    from wholebody.cycle import native_available, python_tasks
    assert python_tasks(ns["stack"]) == [squat]
    settings = SolverSettings(backend="quadprog", fallback_backend=None)
    cycle = HierarchyCycle(robot, ns["stack"], engine="auto", settings=settings)
    assert cycle.engine_name == ("native" if native_available() else "python")
    q, v = robot.q_ref, np.zeros(robot.nv)
    native = cycle.solve(q, v)

    def reference(q, v):
        robot.update(q, v)
        return Formulation(robot).solve(ns["stack"], settings=settings).tau
    from conftest import torque_tolerance
    np.testing.assert_allclose(native.tau, reference(q, v), rtol=0,
                               atol=torque_tolerance(reference, q, v, robot.nq))


def check_own_loop(ns: dict) -> None:
    data = ns["data"]
    assert data.time == pytest.approx(1.0, abs=2e-3)
    assert ns["outcomes"] and all(o.ok for o in ns["outcomes"])
    assert ns["drift"] < 0.01
    assert np.all(np.isfinite(data.qpos)) and abs(data.qpos[2] - ns["z0"]) < 0.01


def check_walk(ns: dict) -> None:
    walker, q = ns["walker"], ns["q"]
    assert len(walker.steps) >= 4 and walker.phase.kind == "stand"
    assert 0.2 < q[0] < 0.6  # about 2 s at 0.2 m/s
    assert abs(q[2] - ns["robot"].q_ref[2]) < 0.1  # standing, not fallen


def check_estimated_state(ns: dict) -> None:
    log, robot = ns["log"], ns["robot"]
    assert ns["sim"].t == pytest.approx(2.0, abs=2e-3)
    # the filter ran once per step of the twin: 2000 steps read the states at t = 0 .. 1.999 s
    assert len(log["t"]) == 2000 and np.allclose(np.diff(log["t"]), 1e-3)
    assert np.max(np.abs(log["q_true"][:, 0] - log["q_true"][0, 0])) > 1e-3  # the push moved it
    assert np.all(np.isfinite(log["q_hat"])) and ns["q"][2] > 0.9 * robot.q_ref[2]


EXAMPLES = {"own-stack": check_own_stack, "own-task": check_own_task,
            "own-loop": check_own_loop, "walk": check_walk,
            "estimated-state": check_estimated_state}
SLOW = {"own-loop", "walk", "estimated-state"}  # simulate the twin: seconds


def test_guide_has_exactly_the_examples():
    """Every marked ```python block of the guide is one of the examples, each exactly once: a
    misspelt marker would otherwise be run by neither this file nor test_docs.py."""
    infos = [info for info, _ in marked_blocks()]
    names = [m.group(1) if (m := EXAMPLE.fullmatch(info)) else info for info in infos]
    assert sorted(names) == sorted(EXAMPLES), infos


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW else [])
                                  for n in EXAMPLES])
def test_example_runs(name, tmp_path, monkeypatch, capsys):
    namespace = run_example(name, tmp_path, monkeypatch)
    EXAMPLES[name](namespace)
    assert capsys.readouterr().out.strip(), f"example {name} printed nothing"
