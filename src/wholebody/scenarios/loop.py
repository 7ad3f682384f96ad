"""Run a controller against the simulator in closed loop."""

from __future__ import annotations

from typing import Callable

import numpy as np
from tqdm import tqdm

from ..sim.simulator import Simulator


def run_closed_loop(sim: Simulator, controller, duration: float, control_period: float | None = None,
                    progress: bool = False, on_result: Callable | None = None,
                    until: Callable[[], bool] | None = None) -> int:
    """Step ``sim`` for ``duration`` s; the controller runs every ``control_period`` (default: every
    simulation step) and its last torque is held in between. Returns the number of failed cycles
    (results with ``ok`` False); ``on_result(t, result)`` sees every controller result;
    ``until()``, asked after each of them, ends the run early when it returns True. Under
    real-robot conditions (an observer of the simulator with ``controller_state``,
    :class:`~wholebody.scenarios.conditions.RobotConditions`) the controller reads its state
    from there (the estimate) instead of the twin's exact state.
    """
    conditions = next((o for o in sim.observers if hasattr(o, "controller_state")), None)
    read = sim.state if conditions is None else (lambda: conditions.controller_state(sim))
    steps = int(round(duration / sim.dt))
    every = 1 if control_period is None else max(1, int(round(control_period / sim.dt)))
    failures = 0
    tau = np.zeros(sim.robot.na)
    with tqdm(total=steps, disable=not progress, unit="step", leave=False,
              desc=f"{sim.robot.name}") as bar:
        for k in range(steps):
            if k % every == 0:
                q, v = read()
                result = controller.compute(q, v, sim.t)
                tau = result.tau
                failures += not result.ok
                for observer in sim.observers:
                    observer.controller_result(sim, result)
                if on_result is not None:
                    on_result(sim.t, result)
                if until is not None and until():
                    break
            sim.step(tau)
            if k % 100 == 99:
                bar.update(100)
    return failures
