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
