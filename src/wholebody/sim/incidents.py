"""What went wrong first in a simulated run: the twin's joints reaching their position limits and
the controller's failed cycles, each with the time it first happened.

A failed run's metrics say that it fell and when; the first incidents say what came before (a knee
at its limit, then the first failed cycle), which is where a new robot's problem is found.
:class:`IncidentLog` is a :class:`~wholebody.sim.simulator.SimObserver`;
:meth:`~wholebody.scenarios.base.Scenario.run` watches every scenario that declares its
simulations with one, and ``summary.json`` has what it saw (``incidents``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

try:
    from .. import _sim_reads
except ImportError:  # built without the compiled parts (see setup.py): the Python reference
    _sim_reads = None


@dataclass(frozen=True)
class Incident:
    """Something that first happened at simulated time ``t`` (s) in the run labelled ``run``."""

    t: float
    what: str
    run: str = ""

    def as_dict(self) -> dict:
        return {"t": round(self.t, 4), "what": self.what, **({"run": self.run} if self.run else {})}


class IncidentLog:
    """Watches simulations (one run per :meth:`start`, i.e. per simulator reset) and keeps, for each
    run, the first time each of these happened:

    * a joint of the twin arriving at or beyond a limit of its range, once per joint and side (a
      joint that starts on that limit is left out for the run);
    * a controller cycle that failed (``Solution.ok`` false), with its status: the first clipped
      one (a torque beyond the limits by more than the solver's tolerance,
      :data:`wholebody.guard.LIMIT_TOLERANCE`) and the first held one, each once, so that a
      clipped cycle early in the run does not hide the first cycle with no solution at all.

    ``incidents`` lists them run by run (runs by their simulator's ``label``; a reset starts its
    run over), each run's in time order.
    """

    def __init__(self):
        self._runs: dict[str, list[Incident]] = {}
        self._label = ""
        self._failure_seen: set = set()

    def start(self, sim) -> None:
        self._label = sim.label
        self._runs[self._label] = []
        self._failure_seen: set = set()
        model = sim.model
        limited = np.flatnonzero(model.jnt_limited)
        self._names = [model.joint(int(j)).name for j in limited]
        self._qpos = model.jnt_qposadr[limited]
        self._lower, self._upper = model.jnt_range[limited].T.copy()
        q = sim.data.qpos[self._qpos]  # a posture on a limit (e.g. closed grippers, which then
        # touch it on and off) is not something that went wrong: only arrivals count
        self._seen = np.stack((q <= self._lower, q >= self._upper), axis=1)  # [joint, side]
        self._addresses = self._qpos.astype(np.int64)
        self._watch()

    def _watch(self) -> None:
        """The limits still watched: a side already seen becomes -inf / +inf, which no finite
        position reaches, so that the per-step test is true only on a new arrival."""
        self._lower_watched = np.where(self._seen[:, 0], -np.inf, self._lower)
        self._upper_watched = np.where(self._seen[:, 1], np.inf, self._upper)
        # (qpos address, lower, upper) as Python numbers: the per-step test of a few joints
        # costs a fraction of numpy's calls (the same comparisons)
        self._limits = list(zip(self._qpos.tolist(), self._lower_watched.tolist(),
                                self._upper_watched.tolist()))

    def _beyond_limits(self, qpos: np.ndarray) -> bool:
        """True when some joint is at or beyond a limit not yet seen (the reference of the
        compiled ``beyond_limits``, asked every step)."""
        values = qpos.tolist()
        return any(values[address] <= lower or values[address] >= upper
                   for address, lower, upper in self._limits)

    def step(self, sim) -> None:
        qpos = sim.data.qpos
        if not (self._beyond_limits(qpos) if _sim_reads is None else
                _sim_reads.beyond_limits(qpos, self._addresses, self._lower_watched,
                                         self._upper_watched)):
            return  # no joint arrived on a limit
        q = qpos[self._qpos]
        low = (q <= self._lower) & ~self._seen[:, 0]
        high = (q >= self._upper) & ~self._seen[:, 1]
        if not (low.any() or high.any()):
            return
        for joint, side in zip(*np.nonzero(np.stack((low, high), axis=1))):
            self._seen[joint, side] = True
            limit = (self._lower, self._upper)[side][joint]
            self._add(sim.t, f"joint {self._names[joint]} at its {('lower', 'upper')[side]} "
                             f"position limit ({limit:.3f})")
        self._watch()

    def controller_result(self, sim, result) -> None:
        if not result.ok and result.outcome not in self._failure_seen:
            self._failure_seen.add(result.outcome)  # the first clipped and the first held apart
            self._add(sim.t, f"first failed controller cycle ({result.outcome.value}): "
                             f"{result.status}")

    def _add(self, t: float, what: str) -> None:
        self._runs.setdefault(self._label, []).append(Incident(float(t), what, self._label))

    @property
    def incidents(self) -> list[Incident]:
        """Every run's first incidents, run by run (in the order they started), in time order."""
        return [x for run in self._runs.values() for x in run]

    def as_dicts(self) -> list[dict]:
        """:attr:`incidents` as JSON-ready dicts (``t``, ``what``, and ``run`` if labelled)."""
        return [x.as_dict() for x in self.incidents]
