"""The package's layout rules (docs/architecture.md, "Layout"), checked on the source: scenarios build a robot,
a controller and a world, run and measure — no controller or planner is defined in them and no
scenario imports another; every QP goes through ``solvers/`` (no ``daqp`` import elsewhere)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import wholebody

PACKAGE = Path(wholebody.__file__).resolve().parent
SCENARIOS = PACKAGE / "scenarios"


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), filename=str(path))


def _defines_scenario(tree: ast.Module) -> bool:
    return any(isinstance(node, (ast.Assign, ast.AnnAssign)) and any(
        isinstance(t, ast.Name) and t.id in ("SCENARIO", "SCENARIOS")
        for t in (node.targets if isinstance(node, ast.Assign) else [node.target]))
        for node in tree.body)


def _imported_modules(tree: ast.Module, package: str) -> set[str]:
    """Dotted names of the modules ``tree`` imports, relative imports resolved in ``package``."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            names.add(module)
            names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


SCENARIO_MODULES = sorted(p.stem for p in SCENARIOS.glob("*.py") if _defines_scenario(_tree(p)))


def test_the_scenario_modules_are_found():
    assert {"push", "crawl", "stand", "single_support"} <= set(SCENARIO_MODULES)


@pytest.mark.parametrize("name", SCENARIO_MODULES)
def test_no_scenario_imports_another(name):
    imported = _imported_modules(_tree(SCENARIOS / f"{name}.py"), "wholebody.scenarios")
    others = {f"wholebody.scenarios.{m}" for m in SCENARIO_MODULES if m != name}
    assert not imported & others, f"scenarios/{name}.py imports {sorted(imported & others)}"


# A controller turns a state into torques (``compute``); a planner gives it references.
_CONTROLLER_METHODS = {"compute", "plan"}
_CONTROLLER_BASES = {"PlannedController", "GaitPlanner", "Controller"}


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.py")), ids=lambda p: p.name)
def test_no_controller_class_is_defined_in_scenarios(path):
    for node in ast.walk(_tree(path)):
        if not isinstance(node, ast.ClassDef):
            continue
        methods = {f.name for f in node.body if isinstance(f, ast.FunctionDef)}
        bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
        assert not methods & _CONTROLLER_METHODS and not bases & _CONTROLLER_BASES, (
            f"{path.name}: class {node.name} is a controller or planner (methods "
            f"{sorted(methods & _CONTROLLER_METHODS)}, bases {sorted(bases & _CONTROLLER_BASES)}); "
            "it belongs in control/ or planning/")


def test_daqp_is_imported_only_by_the_solvers():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        if "solvers" in path.relative_to(PACKAGE).parts:
            continue
        if any(m == "daqp" or m.startswith("daqp.")
               for m in _imported_modules(_tree(path), "wholebody")):
            offenders.append(str(path.relative_to(PACKAGE)))
    assert not offenders, f"daqp imported outside solvers/: {offenders}"


def test_the_rules_see_a_violation():
    """The checks above can fail: a module importing a scenario and defining a controller."""
    bad = _tree_from("from .push import LOCATIONS\nimport daqp\nclass C:\n    def compute(self): ...\n")
    assert "wholebody.scenarios.push" in _imported_modules(bad, "wholebody.scenarios")
    assert "daqp" in _imported_modules(bad, "wholebody.scenarios")
    assert any(isinstance(n, ast.ClassDef) and "compute" in {f.name for f in n.body}
               for n in ast.walk(bad))


def _tree_from(source: str) -> ast.Module:
    return ast.parse(source)
