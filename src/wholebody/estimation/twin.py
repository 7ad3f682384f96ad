"""The estimator in the twin's loop: sensors read from the simulator and the EKF updated at every
simulator step, the estimate beside the twin's true state, and a controller run on the estimate."""

from __future__ import annotations

import numpy as np

from ..sim.sensors import Sensors, SensorSpec
from ..sim.series import SeriesLog
from .ekf import EstimatorNoise, KinematicInertialEKF, StateEstimate


class EstimationLog(SeriesLog):
    """One row per simulator step: the time, the twin's true (q, v), the estimate's (q, v), the
    feet's normalised innovations, the contact flags and the covariance's diagonal (numpy chunks,
    :class:`~wholebody.sim.series.SeriesLog`)."""

    FIELDS = ("t", "q_true", "v_true", "q_hat", "v_hat", "foot_test", "contact", "variance")


class TwinEstimation:
    """A simulator observer (:class:`~wholebody.sim.simulator.SimObserver`): at every step it
    reads ``sensors`` from the twin and updates ``estimator``, started at each reset from the
    twin's true base position. :meth:`current` gives the estimate of the present state (a
    controller calls it before the step, the observer's ``step`` then finds it done)."""

    def __init__(self, sensors: Sensors, estimator: KinematicInertialEKF, record: bool = True,
                 ground_map: bool = False):
        self.sensors, self.estimator, self.record = sensors, estimator, record
        self.ground_map = ground_map  # the estimator knows the twin's ground (ground_height)
        self.sim = None
        self.log = EstimationLog()

    @classmethod
    def for_robot(cls, robot, spec: SensorSpec | None = None, seed: int = 0,
                  ground_map: bool = False, **noise_overrides) -> "TwinEstimation":
        """Sensors of ``spec`` (default :class:`SensorSpec`) seeded with ``seed`` and a filter
        whose noise model matches them and the robot's size (:meth:`EstimatorNoise.for_robot`);
        ``ground_map``: the filter measures its stance feet on the twin's ground
        (:meth:`~wholebody.sim.simulator.Simulator.ground_height`)."""
        spec = spec or SensorSpec()
        sensors = Sensors(robot, spec, np.random.default_rng(seed))
        return cls(sensors, KinematicInertialEKF(robot, EstimatorNoise.for_robot(
            robot, spec, **noise_overrides)), ground_map=ground_map)

    def start(self, sim) -> None:
        self.sim = sim
        self.log = EstimationLog()
        if self.ground_map:
            self.estimator.ground = sim.ground_height
        self.estimator.reset(self.sensors.read(sim), sim.state()[0][:3])
        self._record(sim, self.estimator.estimate)

    def step(self, sim) -> None:
        self.current()

    def controller_result(self, sim, result) -> None:
        pass

    def current(self) -> StateEstimate:
        """The estimate at the simulator's present time (read and updated once per step)."""
        sim, estimator = self.sim, self.estimator
        if estimator.estimate is not None and sim.t > estimator.estimate.t:
            self._record(sim, estimator.update(self.sensors.read(sim)))
        return estimator.estimate

    def _record(self, sim, estimate: StateEstimate) -> None:
        if not self.record:
            return
        q, v = sim.state()
        self.log.append(t=sim.t, q_true=q, v_true=v, q_hat=estimate.q, v_hat=estimate.v,
                        foot_test=estimate.foot_test, contact=self.sensors.last_contact,
                        variance=np.diag(estimate.covariance))


class OnEstimatedState:
    """``controller`` fed with the estimate of ``estimation`` (a :class:`TwinEstimation` observing
    the simulator) instead of the state it is given: ``compute(q, v, t)`` ignores q and v."""

    def __init__(self, controller, estimation: TwinEstimation):
        self.controller, self.estimation = controller, estimation

    def compute(self, q, v, t):
        estimate = self.estimation.current()
        return self.controller.compute(estimate.q, estimate.v, t)

    def __getattr__(self, name):  # the wrapped controller's attributes (plans, impedance...)
        return getattr(self.controller, name)
