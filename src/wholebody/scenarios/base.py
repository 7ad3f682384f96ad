"""The scenario contract: a named experiment with typed parameters that returns a summary and a log."""

from __future__ import annotations

import contextlib
import json
import logging
import math
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Sequence

import numpy as np

from ..control.lqr import DEFAULT_INTEGRAL_LIMIT, DEFAULT_Q_INTEGRAL
from ..control.stacks import COM_PD, COP_MARGIN as COP_MARGIN_DEFAULT, POSTURE_PD, SWING_FOOT_PD
from ..cycle import ENGINES
from .conditions import LEVELS, conditions_for
from ..sim.incidents import IncidentLog
from ..sim.plant import plant_label
from ..sim.simulator import SimulationDiverged
from ..tasks.momentum import MOMENTUM_D_ANGULAR, MOMENTUM_D_LINEAR, MOMENTUM_P

log = logging.getLogger(__name__)


class RobotRelative:
    """A parameter default that depends on the robot (a length in proportion to its height, a
    speed scaled by it): resolved with :meth:`value` once the robot is known
    (:meth:`Scenario.validate`), listed by ``str`` and as :meth:`as_data`."""

    def value(self, robot) -> float:
        raise NotImplementedError

    def as_data(self) -> dict[str, float]:
        raise NotImplementedError


@dataclass(frozen=True)
class BaseHeight(RobotRelative):
    """A robot-relative bound of a size parameter: ``factor`` x the robot's standing base height
    ``h`` (its base above the ground in the reference posture, ``robot.q_ref[2]``). Declared as
    ``0.5 * Parameter.H``, shown as ``0.5 h``, checked when the robot is known
    (:meth:`Scenario.validate`)."""

    factor: float = 1.0

    def __rmul__(self, factor: float) -> BaseHeight:
        return BaseHeight(float(factor) * self.factor)

    __mul__ = __rmul__

    def __neg__(self) -> BaseHeight:
        return BaseHeight(-self.factor)

    def value(self, robot) -> float:
        return self.factor * float(robot.q_ref[2])

    def __str__(self) -> str:
        return {1.0: "h", -1.0: "-h"}.get(self.factor, f"{self.factor:g} h")

    def as_data(self) -> dict[str, float]:
        return {"base_height": self.factor}


#: what ``h`` stands for in the ranges listed by ``wholebody scenarios``
BASE_HEIGHT_LEGEND = ("h: the robot's standing base height (its base above the ground in the "
                      "reference posture), in m; bounds and defaults in h are resolved once the "
                      "robot is known (a default 'v sqrt(h / h0)' is a speed v set on a robot "
                      "h0 high, scaled to keep the gait's Froude number)")

_NOUNS = {bool: ("a boolean (true/false)", "booleans"), int: ("a whole number", "whole numbers"),
          float: ("a number", "numbers"), str: ("a text", "texts")}


@dataclass(frozen=True)
class Parameter:
    """A scenario parameter settable with ``--set name=value`` (parsed to the default's type).

    Its declared range is checked by :meth:`parse` (the ``--set`` text) and :meth:`check` (a
    value, with the robot for robot-relative bounds); each error names the parameter, the value
    and the range:

    - numbers (float, int): ``low <= value <= high``, ``low_open``/``high_open`` exclude the
      bound itself; a bound is a number or robot-relative (``0.5 * Parameter.H``, see
      :class:`BaseHeight`). NaN is refused, and +-inf unless ``finite`` is False;
    - strings: ``choices``, if given, are the accepted values;
    - ``special``: numbers accepted outside the range, with a meaning given in the help (the 0 of
      "0: automatic" where the range starts above 0);
    - ``items`` (float, int or str): the value is a comma-separated list of such items, kept as
      the text; each item is checked against the range or ``choices`` (whether the list may be
      empty is the scenario's own check).
    """

    name: str
    default: Any
    help: str
    low: float | BaseHeight = -math.inf
    high: float | BaseHeight = math.inf
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | None = None
    items: type | None = None
    finite: bool = True
    special: tuple[float, ...] = ()

    #: the largest simulated time a time parameter may ask for (s)
    MAX_TIME: ClassVar[float] = 600.0
    #: the robot's standing base height, for robot-relative bounds: ``high=0.5 * Parameter.H``
    H: ClassVar[BaseHeight] = BaseHeight()

    def __post_init__(self):
        if self.choices is not None:
            object.__setattr__(self, "choices", tuple(self.choices))

    @property
    def kind(self) -> type:
        """The type of one value: ``items`` for list parameters, float for a robot-relative
        default, else the default's type."""
        if isinstance(self.default, RobotRelative):
            return float
        return self.items or type(self.default)

    def default_text(self) -> str:
        """The default as listed: ``0.15``, ``'crawl'``, or ``0.367 h`` for a robot-relative one."""
        return str(self.default) if isinstance(self.default, RobotRelative) else repr(self.default)

    @property
    def numeric(self) -> bool:
        return self.kind in (int, float)

    @property
    def robot_relative(self) -> bool:
        return isinstance(self.low, BaseHeight) or isinstance(self.high, BaseHeight)

    # ------------------------------------------------------------------ description
    def range_text(self) -> str | None:
        """The declared range, e.g. ``(0, 600]``, ``[0, 0.5 h]``, ``one of: a, b``; None for
        booleans and free text."""
        if self.kind is str:
            return f"one of: {', '.join(self.choices)}" if self.choices else None
        if not self.numeric:
            return None

        def text(bound) -> str:
            if isinstance(bound, BaseHeight):
                return str(bound)
            if math.isinf(bound):
                return "inf" if bound > 0 else "-inf"
            return str(int(bound)) if self.kind is int else f"{bound:g}"
        return self._special() + self._interval(text(self.low), text(self.high))

    def _interval(self, low: str, high: str) -> str:
        """``[low, high]`` with the brackets of the declared range (open at an infinite bound)."""
        closed_low = not self.low_open and (not self.finite or not self._infinite(self.low))
        closed_high = not self.high_open and (not self.finite or not self._infinite(self.high))
        return f"{'[' if closed_low else '('}{low}, {high}{']' if closed_high else ')'}"

    def _special(self) -> str:
        """The ``special`` values as the start of the range text: ``"0 or "``."""
        return "".join(f"{v:g} or " for v in self.special)

    @staticmethod
    def _infinite(bound) -> bool:
        return not isinstance(bound, BaseHeight) and math.isinf(bound)

    def describe(self) -> str:
        """The range for the listing: ``in (0, 600]``, ``one of: a, b``, ``items in [0, inf)``,
        ``0 or in [0.01, 5]``."""
        text = self.range_text()
        if text is None:
            return ""
        if self.kind is str:
            return f"items {text}" if self.items is not None else text
        extra = self._special()
        return f"{'items ' if self.items is not None else ''}{extra}in {text[len(extra):]}"

    def bounds(self) -> dict[str, Any] | None:
        """The numeric range as data (``wholebody scenarios --json``): ``low``/``high`` a number,
        None (unbounded) or ``{"base_height": factor}``, ``low_open``/``high_open``, ``finite``;
        None for strings and booleans."""
        if not self.numeric:
            return None

        def data(bound):
            if isinstance(bound, BaseHeight):
                return {"base_height": bound.factor}
            return None if math.isinf(bound) else bound
        out = {"low": data(self.low), "high": data(self.high), "low_open": self.low_open,
               "high_open": self.high_open, "finite": self.finite}
        if self.special:
            out["special"] = list(self.special)
        return out

    # ------------------------------------------------------------------ checks
    def parse(self, text: Any) -> Any:
        """The ``--set`` text as a value of the parameter's type, checked against the range
        (robot-relative bounds wait for :meth:`check` with the robot); ValueError naming the
        parameter, the text and what was expected otherwise."""
        text = _as_text(text).strip()
        if self.items is not None:
            for item in (x.strip() for x in text.split(",")):
                if item:
                    self._check(self._convert(item, listed=True), item, None)
            return text
        value = self._convert(text)
        self._check(value, text, None)
        return value

    def check(self, value: Any, robot=None) -> Any:
        """``value`` (of the parameter's type, e.g. from :meth:`parse` or the default) checked
        against the whole range, robot-relative bounds against ``robot`` (skipped if None).
        Returns the value, a robot-relative default (:class:`RobotRelative`) resolved for
        ``robot`` (unchanged without one)."""
        if isinstance(value, RobotRelative):
            if robot is None:
                return value
            value = value.value(robot)
        if self.items is not None:
            for item in (x.strip() for x in str(value).split(",")):
                if item:
                    self._check(self._convert(item, listed=True), item, robot)
            return value
        self._check(value, value, robot)
        return value

    def _convert(self, text: str, listed: bool = False) -> Any:
        kind = self.kind
        try:
            if kind is bool:
                lowered = text.lower()
                if lowered not in ("true", "false", "1", "0", "yes", "no"):
                    raise ValueError(text)
                return lowered in ("true", "1", "yes")
            return kind(text)
        except ValueError:
            one, many = _NOUNS.get(kind, (f"a {kind.__name__}", f"{kind.__name__}s"))
            expected = f"comma-separated {many}" if listed else one
            raise ValueError(f"--set {self.name}: expected {expected}, got '{text}'") from None

    def _check(self, value: Any, shown: Any, robot) -> None:
        shown = f"'{shown}'" if isinstance(shown, str) else repr(shown)
        item = "item " if self.items is not None else ""
        if self.kind is str:
            if self.choices and value not in self.choices:
                raise ValueError(f"--set {self.name}: expected one of {', '.join(self.choices)}, "
                                 f"got {item}{shown}")
            return
        if not self.numeric:
            return
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"--set {self.name}: expected a number in {self.range_text()}, got "
                             f"{shown}") from None
        low, high, note = self.low, self.high, ""
        if self.robot_relative and robot is not None:
            low = low.value(robot) if isinstance(low, BaseHeight) else low
            high = high.value(robot) if isinstance(high, BaseHeight) else high
            numbers = self._interval(f"{low:.3g}", f"{high:.3g}")
            note = f" = {numbers} for robot '{robot.name}' (h = {robot.q_ref[2]:.3g} m)"
        else:  # robot-relative bounds wait for the robot
            low = -math.inf if isinstance(low, BaseHeight) else low
            high = math.inf if isinstance(high, BaseHeight) else high
        inside = ((x > low if self.low_open else x >= low) and
                  (x < high if self.high_open else x <= high)) or x in self.special
        if math.isnan(x) or (self.finite and math.isinf(x)) or not inside:
            what = "whole number" if self.kind is int else \
                "finite number" if self.finite else "number"
            extra = self._special()
            raise ValueError(f"--set {self.name}: expected {extra}a {what} in "
                             f"{self.range_text()[len(extra):]}{note}, got {item}{shown}")


def parse_sets(pairs: list[str]) -> dict[str, str]:
    """``--set key=value`` texts as a dict; ValueError naming the malformed one."""
    out = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set expects key=value, got '{pair}'")
        if key.strip() in out:
            raise ValueError(f"--set {key.strip()}: given twice ('{out[key.strip()]}' and "
                             f"'{value.strip()}')")
        out[key.strip()] = value.strip()
    return out


def _as_text(value: Any) -> str:
    """A programmatic override (a number, a bool, a list) as the text ``--set`` would give."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (list, tuple)):
        return ",".join(str(v) for v in value)
    return str(value)


#: the controller's engine, for the scenarios that take one (momentum balance, stepping)
ENGINE = Parameter("engine", "auto", "controller engine: 'native' (wholebody.cycle.HierarchyCycle: "
                                     "rigid-body terms and task rows compiled, same torques), "
                                     "'python' (Robot.update + Formulation, the reference) or "
                                     "'auto' (native when built)",
                   choices=ENGINES)


#: real-robot conditions (wholebody.scenarios.conditions), on every scenario that declares its
#: simulations
REALISM = Parameter("realism", "exact", "what the controller reads and drives: 'exact' (the twin's "
                                        "state, the twin its model), 'sensors' (the state estimate "
                                        "from the IMU, encoders and contact flags) or 'robot' "
                                        "(sensors, plus model, delay, lag and noise errors)",
                    choices=LEVELS)
#: with realism 'sensors' or 'robot': the estimator also measures each stance foot on the known
#: ground (the twin's surfaces: the terrain map of the robot's planner)
GROUND_MAP = Parameter("ground_map", True, "with realism sensors/robot: the state estimator "
                                           "knows the ground under the feet (the terrain map) "
                                           "and measures each stance foot's height on it")
REAL_ROBOT_PARAMETERS = (REALISM, GROUND_MAP)


def check_engine(params: dict) -> None:
    """ValueError naming ``--set engine`` if it is not a HierarchyCycle engine."""
    engine = params.get("engine", ENGINE.default)
    if engine not in ENGINES:
        raise ValueError(f"--set engine: expected one of {ENGINES}, got '{engine}'")


#: eq. 26's angular-momentum weight of the LQR cost, for the momentum-balance scenarios
Q_ANGULAR = Parameter("q_angular", 0.1, "LQR weight on angular momentum (eq. 26 uses 0.1)",
                      low=0.0, low_open=True)
#: the LQR's integral action on the CoG error (ours, not the paper's; on by default, 0 = the paper's
#: LQR), for the momentum-balance scenarios
Q_INTEGRAL = Parameter("q_integral", DEFAULT_Q_INTEGRAL,
                       "LQR only: weight of the CoG-error integral (integral action, LQI; ours, not "
                       "the paper's); 0 = off, the paper's LQR", low=0.0)
INTEGRAL_LIMIT = Parameter("integral_limit", DEFAULT_INTEGRAL_LIMIT,
                           "LQR integral action: anti-windup clamp of each integral component "
                           "(m s)", low=0.0, low_open=True)
#: the LQR's parameters of the momentum-balance scenarios
LQR_PARAMETERS = (Q_ANGULAR, Q_INTEGRAL, INTEGRAL_LIMIT)


#: eq. 22's momentum PD gains (Table 2's defaults: P = 50, D = 15 on the linear rows, 5 on the
#: angular rows): mass-normalised, so the same CoG stiffness omega^2 on any robot
PD_STIFFNESS = Parameter("pd_stiffness", MOMENTUM_P, "PD only: eq. 22's P on m (x_ref - x_cog), "
                                                     "the CoG stiffness omega^2 (1/s^2)",
                         low=0.0, low_open=True)
PD_DAMPING = Parameter("pd_damping", MOMENTUM_D_LINEAR, "PD only: eq. 22's D on the linear "
                                                        "momentum error (1/s)", low=0.0)
PD_ANGULAR_DAMPING = Parameter("pd_angular_damping", MOMENTUM_D_ANGULAR,
                               "PD only: eq. 22's D on the angular momentum error (1/s)", low=0.0)
PD_PARAMETERS = (PD_STIFFNESS, PD_DAMPING, PD_ANGULAR_DAMPING)


def _task_gain_parameters(task: str, gains: tuple[float, float], where: str) -> tuple:
    """The (kp, kd) of a hierarchy task as the parameters ``<task>_stiffness`` and
    ``<task>_damping`` (accelerations, the same on every robot)."""
    return (Parameter(f"{task}_stiffness", gains[0], f"{where}: stiffness (1/s^2)", low=0.0,
                      high=1e6),
            Parameter(f"{task}_damping", gains[1], f"{where}: damping (1/s)", low=0.0, high=1e4))


#: the CoP constraint's margin of the humanoid scenarios (the CoP task of Tables 1, 2 and 4)
COP_MARGIN = Parameter("cop_margin", COP_MARGIN_DEFAULT, "keep each sole's CoP this share of its "
                       "half-lengths inside its edges (0: the whole sole, the paper's)", low=0.0,
                       high=1.0, high_open=True)


#: the posture task's PD (joints and base) of the humanoid hierarchies (Tables 1, 2 and 4)
POSTURE_PARAMETERS = _task_gain_parameters("posture", POSTURE_PD,
                                           "posture task (joints and base)")
#: the swing-foot task's PD (Tables 1 and 4)
SWING_FOOT_PARAMETERS = _task_gain_parameters("swing", SWING_FOOT_PD, "swing-foot task")
#: the CoG task's PD (Table 1)
COM_PARAMETERS = _task_gain_parameters("com", COM_PD, "CoG task")


def task_gains(params: dict) -> dict:
    """The (kp, kd) pairs of the hierarchy tasks the scenario declares (:data:`POSTURE_PARAMETERS`,
    :data:`SWING_FOOT_PARAMETERS`, :data:`COM_PARAMETERS`) as keyword arguments:
    ``posture_gains``, ``swing_gains``, ``com_gains`` (only those in ``params``)."""
    return {f"{task}_gains": (float(params[f"{task}_stiffness"]),
                              float(params[f"{task}_damping"]))
            for task in ("posture", "swing", "com") if f"{task}_stiffness" in params}


def momentum_gains(controller: str, params: dict) -> dict:
    """:class:`~wholebody.control.balance.MomentumBalance`'s gains from the parameters (missing
    ones at their defaults): for LQR eq. 26's Q with ``q_angular`` and the integral action
    (:data:`LQR_PARAMETERS`), for PD eq. 22's P and D from :data:`PD_PARAMETERS`."""
    from ..control.balance import lqr_q

    get = {p.name: params.get(p.name, p.default) for p in (*LQR_PARAMETERS, *PD_PARAMETERS)}
    if controller == "lqr":
        return {"Q": lqr_q(get["q_angular"]), "q_integral": get["q_integral"],
                "integral_limit": get["integral_limit"]}
    return {"P": np.r_[np.full(3, get["pd_stiffness"]), np.zeros(3)],
            "D": np.r_[np.full(3, get["pd_damping"]), np.full(3, get["pd_angular_damping"])]}


def paper_q_notes(robot, controller: str, params: dict) -> list[str]:
    """The note a momentum-balance run with eq. 26's literal Q gets: the LQR model (eq. 21) has no
    trunk orientation, so 0.1 on angular momentum lets the gains trade CoG error for trunk
    rotation. Empty for PD gains or another ``q_angular``."""
    if controller != "lqr" or params.get("q_angular") != Q_ANGULAR.default:
        return []
    return [f"eq. 26's Q weighs angular momentum by {Q_ANGULAR.default} and eq. 21's state has no "
            f"trunk orientation: on {robot.name} the LQR gains trade CoG error for trunk rotation "
            f"— compare --set q_angular=10"]


#: the range of a phase duration or a time span: ``Parameter(name, 1.0, help, **TIME_SPAN)``
TIME_SPAN = {"low": 0.0, "low_open": True, "high": Parameter.MAX_TIME}
#: the shortest simulated time a run takes (s; a ``duration`` of 0, where a scenario allows it,
#: means until the end of its phases)
MIN_DURATION = 0.1


def duration_parameter(default: float, help: str = "simulated time (s)",
                       low_open: bool = True) -> Parameter:
    """The ``duration`` parameter (simulated time) with a scenario's default: in
    (0, ``Parameter.MAX_TIME``], or [0, ...] with ``low_open=False`` (where 0 means "until the end
    of the scenario's phases")."""
    return Parameter("duration", default, help, low=0.0, high=Parameter.MAX_TIME,
                     low_open=low_open)


def check_biped(robot, params: dict) -> None:
    """ValueError unless the engine is known and ``robot`` has exactly two rectangular soles."""
    check_engine(params)
    if len(robot.contact_names) != 2 or any(c.spec.type != "rectangle" for c in robot.contacts):
        raise ValueError(f"robot '{robot.name}': momentum balance on a board needs a biped with "
                         f"two rectangular soles (e.g. talos14, romeo)")


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
    #: the run was cut short (Ctrl-C): ``metrics`` and ``figures`` are what was known by then
    interrupted: bool = False
    #: what first went wrong in the twin (:class:`~wholebody.sim.incidents.Incident` dicts), when
    #: the run was watched by an :class:`~wholebody.sim.incidents.IncidentLog`; None otherwise
    incidents: list[dict] | None = None
    #: why the run ended without its result (an error in the scenario), None if it did not
    error: str | None = None
    #: what was simulated: "exact twin" or "vendor MJCF <file>" (the robot's ``plant``)
    plant: str = "exact twin"
    #: what the controller read and drove (``--set realism``; "exact": the twin's state)
    realism: str = "exact"

    def summary(self) -> dict[str, Any]:
        out = {
            "scenario": self.scenario,
            "robot": self.robot,
            "controller": self.controller,
            "plant": self.plant,
            "realism": self.realism,
            "success": bool(self.success),
            "completed": bool(not self.interrupted and self.error is None),
            "interrupted": bool(self.interrupted),
            "metrics": _jsonable(self.metrics),
            "parameters": _jsonable(self.parameters),
            "notes": self.notes,
            "figures": self.figures,
            "wall_time_s": round(self.wall_time_s, 3),
        }
        if self.incidents is not None:
            out["incidents"] = self.incidents
        if self.error is not None:
            out["error"] = self.error
        return out

    def write(self, out_dir: Path) -> Path:
        """``out_dir/summary.json``, written atomically: a reader sees the previous file or this
        one whole, never a part (a temporary file in the same folder, then renamed over it)."""
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        path = out_dir / "summary.json"
        text = json.dumps(self.summary(), indent=2) + "\n"
        handle, temporary = tempfile.mkstemp(prefix=".summary-", suffix=".json", dir=out_dir)
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(temporary, 0o644)  # as a plain write would leave it (mkstemp: 0o600)
            os.replace(temporary, path)
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(temporary)
            raise
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
    """A registered experiment: ``run(robot, controller, params, out_dir, progress)``.

    ``simulations``: how many simulations one run makes, a number or a function
    ``(params, controller) -> number``; None if not declared. A scenario that declares it takes
    ``observers`` (:class:`~wholebody.sim.simulator.SimObserver`, e.g. the replay recorder or the
    live viewer): its run function accepts ``observers=`` and passes them to every
    :class:`~wholebody.sim.simulator.Simulator` it builds.
    """

    name: str
    summary: str
    parameters: tuple[Parameter, ...]
    controllers: tuple[str, ...]
    default_robot: str
    run_function: RunFunction
    validate_function: Callable[[Any, dict], None] | None = None
    simulations: int | Callable[[dict, str], int] | None = None

    def __post_init__(self):
        # a scenario that takes observers runs under any realism level (its loop asks them)
        if self.simulations is not None:
            names = {p.name for p in self.parameters}
            added = tuple(p for p in REAL_ROBOT_PARAMETERS if p.name not in names)
            object.__setattr__(self, "parameters", (*self.parameters, *added))

    def simulation_count(self, params: dict, controller: str | None = None) -> int | None:
        """How many simulations a run with ``params`` and ``controller`` makes (None: not
        declared)."""
        if self.simulations is None or isinstance(self.simulations, int):
            return self.simulations
        return int(self.simulations(params, controller or self.controllers[0]))

    def validate(self, robot, overrides: dict[str, str] | None = None) -> dict[str, Any]:
        """Parameters resolved and checked against ``robot``: every declared range (the
        robot-relative ones with this robot), then the scenario's own checks (ValueError naming
        the problem)."""
        params = self.resolve(overrides or {})
        for p in self.parameters:
            params[p.name] = p.check(params[p.name], robot)
        duration = params.get("duration")
        if isinstance(duration, (int, float)) and 0.0 < duration < MIN_DURATION:
            raise ValueError(f"--set duration: {duration:g} s is shorter than {MIN_DURATION:g} s "
                             f"(fewer than {MIN_DURATION / 1e-3:.0f} cycles of the 1 kHz twin "
                             f"measure nothing)")
        if (overrides or {}).get("ground_map") is not None and params["ground_map"] \
                and params.get("realism") == "exact":
            raise ValueError("--set ground_map: true needs --set realism=sensors or robot (the "
                             "exact state has no estimator to measure the ground)")
        if self.validate_function is not None:
            self.validate_function(robot, params)
        return params

    def resolve(self, overrides: dict[str, str]) -> dict[str, Any]:
        """Defaults updated with ``--set`` strings, each parsed and checked against its declared
        range (:meth:`Parameter.parse`); unknown names are an error listing the known."""
        known = {p.name: p for p in self.parameters}
        values = {p.name: p.default for p in self.parameters}
        for key, text in overrides.items():
            if key not in known:
                raise ValueError(f"scenario '{self.name}' has no parameter '{key}'; "
                                 f"parameters: {', '.join(known) or 'none'}")
            values[key] = known[key].parse(text)
        return values

    def run(self, robot, controller: str | None = None, overrides: dict[str, str] | None = None,
            out_dir: Path | None = None, progress: bool = False,
            observers: Sequence = ()) -> ScenarioResult:
        """Run the scenario; ``observers`` watch its simulations (only for a scenario that
        declares ``simulations``, ValueError otherwise). A scenario that declares them is also
        watched by an :class:`~wholebody.sim.incidents.IncidentLog`, whose first incidents go
        into ``result.incidents`` (or, if the simulation diverged, into the exception's)."""
        controller = controller or self.controllers[0]
        if controller not in self.controllers:
            raise ValueError(f"scenario '{self.name}' has no controller '{controller}'; "
                             f"controllers: {', '.join(self.controllers)}")
        params = self.validate(robot, overrides)
        extra, incidents = {}, None
        if observers and self.simulations is None:
            raise ValueError(f"scenario '{self.name}' does not declare its simulations; it "
                             f"takes no observers")
        if self.simulations is not None:
            incidents = IncidentLog()
            conditions = conditions_for(robot, params["realism"],
                                        ground_map=params["ground_map"])
            extra["observers"] = (*observers, incidents, *([conditions] if conditions else []))
        start = time.perf_counter()
        try:
            result = self.run_function(robot, controller, params, out_dir, progress, **extra)
        except SimulationDiverged as exc:
            exc.incidents = None if incidents is None else incidents.as_dicts()
            raise
        result.wall_time_s = time.perf_counter() - start
        result.plant = plant_label(robot)
        result.realism = params.get("realism", "exact")
        missing = [f for f in result.figures if not Path(f).is_file()]
        if missing:  # save_figure logged why
            result.figures = [f for f in result.figures if f not in missing]
            result.notes.append(f"figure(s) not written: {', '.join(missing)}")
        if incidents is not None:
            result.incidents = incidents.as_dicts()
        if out_dir is not None:
            result.write(Path(out_dir))
        return result
