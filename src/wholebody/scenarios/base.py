"""The scenario contract: a named experiment with typed parameters that returns a summary and a log."""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..cycle import ENGINES

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Parameter:
    """A scenario parameter settable with ``--set name=value`` (parsed to the default's type)."""

    name: str
    default: Any
    help: str

    def parse(self, text: str) -> Any:
        kind = type(self.default)
        try:
            if kind is bool:
                lowered = text.strip().lower()
                if lowered not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError(text)
                return lowered in ("true", "1", "yes")
            return kind(text)
        except ValueError:
            raise ValueError(f"--set {self.name}: expected a {kind.__name__}, got '{text}'") from None



#: the controller's engine, for the scenarios that take one (momentum balance, stepping)
ENGINE = Parameter("engine", "python", "controller engine: 'python' (Robot.update + Formulation) "
                                       "or 'native' (wholebody.cycle.HierarchyCycle: rigid-body "
                                       "terms and task rows compiled, same torques)")


def check_engine(params: dict) -> None:
    """ValueError naming ``--set engine`` if it is not a HierarchyCycle engine."""
    engine = params.get("engine", ENGINE.default)
    if engine not in ENGINES:
        raise ValueError(f"--set engine: expected one of {ENGINES}, got '{engine}'")


#: eq. 26's angular-momentum weight of the LQR cost, for the momentum-balance scenarios
Q_ANGULAR = Parameter("q_angular", 0.1, "LQR weight on angular momentum (eq. 26 uses 0.1)")


def duration_parameter(default: float, help: str = "simulated time (s)") -> Parameter:
    """The ``duration`` parameter (simulated time) with a scenario's default."""
    return Parameter("duration", default, help)


def check_biped(robot, params: dict) -> None:
    """ValueError unless the engine is known and ``robot`` has exactly two rectangular soles."""
    check_engine(params)
    if len(robot.contact_names) != 2 or any(c.spec.type != "rectangle" for c in robot.contacts):
        raise ValueError(f"robot '{robot.name}': momentum balance on a board needs a biped with "
                         f"two rectangular soles (talos14, talos)")


def format_mm(value) -> str:
    """A length in m as millimetres with one decimal for notes ("n/a" for None)."""
    return "n/a" if value is None else f"{1000 * value:.1f}"

@dataclass
class ScenarioResult:
    """What a scenario run produced: success, metrics, the simulation log and figure paths."""

    scenario: str
    robot: str
    controller: str
    success: bool
    metrics: dict[str, Any]
    parameters: dict[str, Any]
    notes: list[str] = field(default_factory=list)
    log: Any = None
    figures: list[str] = field(default_factory=list)
    wall_time_s: float = 0.0

    def summary(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario,
            "robot": self.robot,
            "controller": self.controller,
            "success": bool(self.success),
            "metrics": _jsonable(self.metrics),
            "parameters": _jsonable(self.parameters),
            "notes": self.notes,
            "figures": self.figures,
            "wall_time_s": round(self.wall_time_s, 3),
        }

    def write(self, out_dir: Path) -> Path:
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / "summary.json"
        path.write_text(json.dumps(self.summary(), indent=2) + "\n")
        return path


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.floating, float)):
        return None if not np.isfinite(value) else float(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def parse_list(text, kind, name: str) -> list:
    """A comma-separated ``--set`` value as a list of ``kind``; ValueError naming ``name``."""
    try:
        values = [kind(x.strip()) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--set {name}: expected a comma-separated list, got '{text}'") from None
    if not values:
        raise ValueError(f"--set {name}: empty list")
    return values


RunFunction = Callable[..., ScenarioResult]


@dataclass(frozen=True)
class Scenario:
    """A registered experiment: ``run(robot, controller, params, out_dir, progress)``."""

    name: str
    summary: str
    parameters: tuple[Parameter, ...]
    controllers: tuple[str, ...]
    default_robot: str
    run_function: RunFunction
    validate_function: Callable[[Any, dict], None] | None = None

    def validate(self, robot, overrides: dict[str, str] | None = None) -> dict[str, Any]:
        """Parameters resolved and checked against ``robot`` (ValueError naming the problem)."""
        params = self.resolve(overrides or {})
        if self.validate_function is not None:
            self.validate_function(robot, params)
        return params

    def resolve(self, overrides: dict[str, str]) -> dict[str, Any]:
        """Defaults updated with ``--set`` strings; unknown names are an error listing the known."""
        known = {p.name: p for p in self.parameters}
        values = {p.name: p.default for p in self.parameters}
        for key, text in overrides.items():
            if key not in known:
                raise ValueError(f"scenario '{self.name}' has no parameter '{key}'; "
                                 f"parameters: {', '.join(known) or 'none'}")
            values[key] = known[key].parse(text)
        return values

    def run(self, robot, controller: str | None = None, overrides: dict[str, str] | None = None,
            out_dir: Path | None = None, progress: bool = False) -> ScenarioResult:
        controller = controller or self.controllers[0]
        if controller not in self.controllers:
            raise ValueError(f"scenario '{self.name}' has no controller '{controller}'; "
                             f"controllers: {', '.join(self.controllers)}")
        params = self.validate(robot, overrides)
        start = time.perf_counter()
        result = self.run_function(robot, controller, params, out_dir, progress)
        result.wall_time_s = time.perf_counter() - start
        if out_dir is not None:
            result.write(Path(out_dir))
        return result
