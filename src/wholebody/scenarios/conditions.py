"""Real-robot conditions for any scenario (``--set realism=exact|sensors|robot``).

* ``exact``: the controller reads the twin's exact state; the twin is the controller's model.
* ``sensors``: the controller reads the state estimate of
  :class:`~wholebody.estimation.KinematicInertialEKF` (Bloesch et al. 2013) fed by the twin's
  sensors (:class:`~wholebody.sim.sensors.SensorSpec`'s defaults: a noisy, biased IMU with a
  drifting attitude filter, quantised encoders, differenced joint velocities, contact flags from
  a force threshold), updated at every simulator step.
* ``robot``: ``sensors`` plus a twin that differs from the controller's model
  (:class:`~wholebody.sim.mismatch.Mismatch`): link masses within ±5 %, link centres of mass moved
  by 0.5 % of the standing base height, torques applied one step late, through a 50 Hz
  first-order torque lag, with noise of 1 % of the median torque limit.

A :class:`RobotConditions` is a simulator observer: the simulator takes its mismatch, the closed
loop (:func:`~wholebody.scenarios.loop.run_closed_loop`) gives the controller
:meth:`RobotConditions.controller_state` instead of the exact state. The measures of a scenario
still read the twin's true state.
"""

from __future__ import annotations

import weakref

import numpy as np

from ..estimation.twin import TwinEstimation
from ..sim.mismatch import Mismatch

LEVELS = ("exact", "sensors", "robot")
#: the ``robot`` level's model and actuator errors (see the module docstring)
MASS_NOISE, COM_OFFSET_SHARE, TORQUE_DELAY_STEPS = 0.05, 0.005, 1
TORQUE_BANDWIDTH_HZ, TORQUE_NOISE_SHARE = 50.0, 0.01


def robot_mismatch(robot, seed: int = 0) -> Mismatch:
    """The ``robot`` level's twin: the errors of the module docstring, sized by ``robot``."""
    limits = np.abs(robot.torque_bounds(robot.q_ref)[1])
    return Mismatch(mass_noise=MASS_NOISE, com_offset=COM_OFFSET_SHARE * float(robot.q_ref[2]),
                    torque_delay=TORQUE_DELAY_STEPS, torque_bandwidth=TORQUE_BANDWIDTH_HZ,
                    torque_noise=TORQUE_NOISE_SHARE * float(np.median(limits)), seed=seed)


class RobotConditions:
    """The sensors and estimator between the twin and the controller, and the twin's mismatch,
    of one realism level (:data:`LEVELS` but ``exact``) for ``robot``; seeded.

    Every simulation it watches gets its own sensors and estimator, made anew at each reset with
    the same seed: a scenario's simulations (run one after the other or side by side) each start
    as a single run would, none inheriting another's biases, filters or noise draws. The
    mismatch is the same robot for all of them."""

    def __init__(self, robot, level: str, seed: int = 0, ground_map: bool = True):
        if level not in LEVELS[1:]:
            raise ValueError(f"realism: expected one of {LEVELS[1:]}, got {level!r}")
        self.robot, self.level, self.seed = robot, level, seed
        self.ground_map = bool(ground_map)
        self.mismatch = robot_mismatch(robot, seed) if level == "robot" else None
        self._runs: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

    def estimation(self, sim) -> TwinEstimation:
        """The sensors and estimator of the simulation ``sim`` (since its last reset)."""
        return self._runs[sim]

    def controller_state(self, sim) -> tuple[np.ndarray, np.ndarray]:
        """What the controller reads at the simulator's present time: the estimate (q̂, v̂)."""
        estimate = self._runs[sim].current()
        return estimate.q, estimate.v

    # the simulator observer's protocol (SimObserver)
    def start(self, sim) -> None:
        estimation = TwinEstimation.for_robot(self.robot, seed=self.seed,
                                              ground_map=self.ground_map)
        estimation.record = False
        self._runs[sim] = estimation
        estimation.start(sim)

    def step(self, sim) -> None:
        self._runs[sim].step(sim)

    def controller_result(self, sim, result) -> None:
        pass


def conditions_for(robot, level: str, seed: int = 0,
                   ground_map: bool = True) -> RobotConditions | None:
    """The observer of ``level`` for ``robot`` (None for ``exact``: nothing between);
    ``ground_map``: its estimator measures the stance feet on the twin's ground."""
    return None if level == "exact" else RobotConditions(robot, level, seed, ground_map)


def job_observers(robot, params: dict, observers=None) -> tuple:
    """The observers of one simulation of a scenario that farms its runs out (a ``workers``
    pool): ``observers`` as given in the scenario's own process; None in a pool's worker, where
    the parent's observers cannot follow, so the realism level's conditions are made there
    (``params["realism"]``; none for ``exact``)."""
    if observers is not None:
        return tuple(observers)
    conditions = conditions_for(robot, params.get("realism", "exact"),
                                ground_map=params.get("ground_map", True))
    return () if conditions is None else (conditions,)
