"""Scenarios and controllers are robot-relative: no string in their code (docstrings aside) is a
link, frame or joint name of any preset, and a robot's name appears only as a scenario's
``default_robot``. Read from the source with ``ast``, checked against the presets' models."""

import ast
from pathlib import Path

import pytest

import wholebody as wb
from wholebody.robots import preset_names

SOURCE = Path(wb.__file__).parent
FOLDERS = ("scenarios", "control", "planning", "tasks")


@pytest.fixture(scope="module")
def model_names():
    names = set()
    for preset in preset_names():
        model = wb.load_robot(preset).model
        names |= {f.name for f in model.frames} | set(model.names)
    return names - {"universe", "root_joint"}


def string_constants(path: Path):
    """(line, text) of every string constant of ``path`` that is not a docstring, and the
    ``default_robot=`` values."""
    tree = ast.parse(path.read_text())
    docstrings, defaults = set(), set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr) \
                and isinstance(body[0].value, ast.Constant):
            docstrings.add(id(body[0].value))
        if isinstance(node, ast.keyword) and node.arg == "default_robot":
            defaults.add(id(node.value))
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and id(node) not in docstrings and id(node) not in defaults:
            yield node.lineno, node.value


@pytest.mark.parametrize("folder", FOLDERS)
def test_no_link_joint_or_robot_names_in_code(folder, model_names):
    robots = set(preset_names())
    found = []
    for path in sorted((SOURCE / folder).glob("*.py")):
        for line, text in string_constants(path):
            if text in model_names or text in robots:
                found.append(f"{path.name}:{line}: {text!r}")
    assert not found, "robot-specific names in code:\n" + "\n".join(found)


def test_figures_and_notes_name_the_robot_in_use():
    """Figure titles and labels (report/) carry no preset name (HyQ, talos14 …) as a word: the
    scenario passes the robot's name; the LQR note of the balance scenarios names the robot run."""
    import re
    from types import SimpleNamespace

    from wholebody.scenarios.base import paper_q_notes

    word = re.compile(r"\b(%s)\b" % "|".join(preset_names()), re.IGNORECASE)
    found = [f"{path.name}:{line}: {text!r}"
             for path in sorted((SOURCE / "report").glob("*.py"))
             for line, text in string_constants(path) if word.search(text)]
    assert not found, "robot names in figure code:\n" + "\n".join(found)
    robot = SimpleNamespace(name="my_biped")
    (note,) = paper_q_notes(robot, "lqr", {"q_angular": 0.1})
    assert "my_biped" in note and not word.search(note)
    assert paper_q_notes(robot, "pd", {"q_angular": 0.1}) == []
    assert paper_q_notes(robot, "lqr", {"q_angular": 10.0}) == []
