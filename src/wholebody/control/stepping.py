"""Stepping in place under the Table 1 hierarchy (Herzog et al. 2016 Sect. 5.1, Fig. 5).

Per step (stance sole s, swing sole w; from the second step on, the CoG first returns over the
middle of the feet), the contact-switch pattern of :mod:`~wholebody.control.contact_switch` with
the Table 1 stack (:func:`~wholebody.control.stacks.table1_stack`):

1. shift: the CoG reference moves (quintic, velocity and acceleration as feedforward) over s;
2. unload: a force regulariser on level 3 drives w's wrench from its value at the start of the phase
   to zero (a ramp of the target);
3. single support (c = 1): w is dropped from the contacts, the swing-foot task lifts it by ``lift``
   and puts it back (``touchdown_depth`` below its lift-off height, so that it surely touches);
4. touch-down: double support again; over ``reload_time`` the regulariser ramps w's normal force
   target from zero to ``preload`` of the weight (with eq. 2 alone a sole that stopped a fraction
   of a millimetre above the floor hovers there, and the next shift then drops the robot), and is
   released; the next shift moves the weight onto w.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..cycle import HierarchyCycle
from ..formulation import Formulation
from ..planning.blend import quintic_blend, smoothstep
from ..tasks import ForceRegularizer
from ..variables import Variables
from .base import FailureStreak
from .stacks import COM_PD, COP_MARGIN, POSTURE_PD, SWING_FOOT_PD, TORSION, table1_stack


@dataclass(frozen=True)
class SteppingConfig:
    """Settings of :class:`Stepping` (times in s, lengths in m).

    ``stance_order``: (first stance sole, first swing sole), alternating over the ``steps``;
    ``lift_time`` is the duration of the lift and, again, of the lowering; ``preload``: normal force
    ramped onto the touched-down sole during the reload, as a fraction of the weight; ``settle``:
    time after the final shift back to the middle; ``contact_kd``: damping of the contact
    velocities in the contact constraint (1/s; 0: eq. 2 as is); ``posture_gains``,
    ``swing_gains``, ``com_gains``: the posture's, the swing-foot task's and the CoG task's (kp,
    kd) (:mod:`~wholebody.control.stacks`).
    """

    stance_order: tuple[str, str]
    steps: int
    shift_time: float
    unload_time: float
    lift_time: float
    reload_time: float
    preload: float
    lift: float
    touchdown_depth: float
    settle: float
    contact_kd: float
    posture_gains: tuple[float, float] = POSTURE_PD
    swing_gains: tuple[float, float] = SWING_FOOT_PD
    com_gains: tuple[float, float] = COM_PD


@dataclass
class Phase:
    kind: str  # "shift", "unload", "single", "reload", "center", "final"
    start: float
    end: float
    stance: str | None = None  # the sole carrying the robot in unload/single/reload
    swing: str | None = None


def timeline(config: SteppingConfig) -> list[Phase]:
    """The phases of the stepping motion (see the module docstring)."""
    c = config
    first, second = c.stance_order
    phases, t = [], 0.0
    for k in range(int(c.steps)):
        stance, swing = (first, second) if k % 2 == 0 else (second, first)
        if k > 0:  # back over the middle first (one shift over the whole stance width dropped it)
            phases.append(Phase("center", t, t + c.shift_time))
            t += c.shift_time
        for kind, dur in (("shift", c.shift_time), ("unload", c.unload_time),
                          ("single", 2.0 * c.lift_time), ("reload", c.reload_time)):
            phases.append(Phase(kind, t, t + dur, stance, swing))
            t += dur
    phases.append(Phase("final", t, t + c.shift_time + c.settle))
    return phases


class Stepping:
    """Table 1 stepping controller, ``compute(q, v, t)``, on one formulation (reduced or full).

    Wall time of every cycle (update + rows + solve + tau) is appended to ``cycle_times``.
    ``engine="native"`` (or ``"auto"``, the default, when native is built) solves each stack with
    a :class:`~wholebody.cycle.HierarchyCycle` (its own compiled rigid-body pass and rows); the Python ``robot.update`` then runs only when a
    phase begins (the swing foot's lift-off placement), so ``robot``'s cached terms are those
    of that cycle — the scenario's records update it themselves, outside the cycle time.
    ``torsion`` (default True): the soles' yaw-moment rows in the Table 1 stacks, and
    ``cop_margin`` their CoP rows' margin (:func:`~wholebody.control.stacks.table1_stack`).
    """

    def __init__(self, robot, config: SteppingConfig, reduced: bool = True,
                 engine: str = "auto", torsion: bool = TORSION, cop_margin: float = COP_MARGIN):
        self.robot, self.config, self.reduced = robot, config, reduced
        self.failures = FailureStreak("Stepping")  # HELD cycles in a row, in the status
        self.phases = timeline(config)
        self.formulation = Formulation(robot, reduced=reduced)
        full = not reduced
        contacts = tuple(robot.contact_names)
        task_pd = {"posture_gains": config.posture_gains, "swing_gains": config.swing_gains,
                   "com_gains": config.com_gains, "cop_margin": cop_margin}
        self.double = table1_stack(robot, contacts, full=full, torsion=torsion, **task_pd)
        self.double_vars = Variables(robot, contacts)
        # eq. 2 keeps whatever velocity a sole has at touch-down (J qdd + Jdot v = 0): with both
        # soles on the ground a residual landing velocity made the whole robot roll over in closed
        # loop, so the contact accelerations also damp the contact velocities (-kd J v)
        self.double.find("contacts").kd = config.contact_kd
        # one unloading regulariser per sole, with the CoG task on level 3 (fixed contact sets, so
        # the formulation's row plan is reused)
        self.unload = {c: ForceRegularizer(name=f"unload {c}", contacts=[c], weight=0.0)
                       for c in contacts}
        for task in self.unload.values():
            self.double.insert(2, task)
        self.single, self.single_vars, self.swing_task = {}, {}, {}
        for stance in contacts:
            swing = next(c for c in contacts if c != stance)
            frame = robot.contact(swing).frame
            self.single[stance] = table1_stack(robot, [stance], [frame], full=full,
                                               torsion=torsion, **task_pd)
            self.single[stance].find("contacts").kd = config.contact_kd
            self.single_vars[stance] = Variables(robot, [stance])
            self.swing_task[stance] = self.single[stance].find(f"swing {frame}")
        self.cycles = None
        if engine != "python":
            self.cycles = {id(st): HierarchyCycle(robot, st, reduced=reduced, engine=engine)
                           for st in [self.double, *self.single.values()]}
        robot.update(robot.q_ref, np.zeros(robot.nv))
        self.com_middle = robot.com.copy()
        self.sole_xy = {c: robot.frame_placement(robot.contact(c).frame)[0][:2].copy()
                        for c in contacts}
        self.com_task = self.double.find("com")
        self.com_from = self.com_middle.copy()
        self._phase_index = -1
        self.unload_start = None
        self.lift_start = None
        self.last = None
        self.cycle_times: list[float] = []
        self.timings: list[dict] = []
        self.n_contacts: list[int] = []

    def phase(self, t: float) -> Phase:
        for ph in self.phases:
            if t < ph.end:
                return ph
        return self.phases[-1]

    def com_target(self, ph: Phase) -> np.ndarray:
        if ph.kind in ("final", "center"):
            return self.com_middle
        xy = self.sole_xy[ph.stance]
        return np.array([xy[0], xy[1], self.com_middle[2]])

    def com_reference(self, t: float, ph: Phase):
        """Quintic shift from the CoG reference at the start of a shift phase to its target."""
        if ph.kind in ("shift", "center", "final"):
            T = self.config.shift_time
            s, ds, dds = quintic_blend((t - ph.start) / T, T)
            delta = self.com_target(ph) - self.com_from
            return self.com_from + s * delta, ds * delta, dds * delta
        return self.com_target(ph), np.zeros(3), np.zeros(3)

    def compute(self, q, v, t: float):
        t0 = time.perf_counter()
        robot, p = self.robot, self.config
        ph = self.phase(t)
        index = self.phases.index(ph)
        if self.cycles is None or index != self._phase_index:  # (the native cycles need no
            robot.update(q, v)                                  # Python terms but at phase entry)
        if index != self._phase_index:  # entering a phase
            if ph.kind in ("shift", "center", "final"):
                self.com_from = self.com_task.position.copy() if self._phase_index >= 0 \
                    else self.com_middle.copy()
                for task in self.unload.values():
                    task.weight = 0.0
            elif ph.kind == "unload":
                self.unload_start = self.last.forces[ph.swing].copy()
                self.unload[ph.swing].targets[ph.swing] = self.unload_start.copy()
                self.unload[ph.swing].weight = 1.0
            elif ph.kind == "single":
                frame = robot.contact(ph.swing).frame
                self.lift_start, rotation = robot.frame_placement(frame)
                self.swing_task[ph.stance].rotation = rotation
            elif ph.kind == "reload":  # touch-down: the new contact's wrench ramps to a preload
                self.unload[ph.swing].weight = 1.0
            self._phase_index = index
        c, dc, ddc = self.com_reference(t, ph)
        if ph.kind == "single":
            stack, variables = self.single[ph.stance], self.single_vars[ph.stance]
            task = self.swing_task[ph.stance]
            u = (t - ph.start) / p.lift_time  # up over [0, 1], down over [1, 2]
            z = smoothstep(u) if u <= 1.0 else 1.0 - smoothstep(u - 1.0)
            depth = p.touchdown_depth * smoothstep(u - 1.0)  # zero while going up
            task.position = self.lift_start + np.array([0.0, 0.0, p.lift * z - depth])
        else:
            stack, variables = self.double, self.double_vars
            if ph.kind == "unload":
                alpha = smoothstep((t - ph.start) / p.unload_time)
                self.unload[ph.swing].targets[ph.swing] = (1.0 - alpha) * self.unload_start
            elif ph.kind == "reload":
                preload = np.zeros_like(self.unload_start)
                preload[2] = p.preload * robot.mass * 9.81
                alpha = smoothstep((t - ph.start) / p.reload_time)
                self.unload[ph.swing].targets[ph.swing] = alpha * preload
        com = stack.find("com")
        com.position, com.velocity, com.acceleration = c, dc, ddc
        self.com_task = com
        if stack is not self.double:  # keep the double-support CoG task's reference current
            self.double.find("com").position = c
        if self.cycles is None:
            sol = self.formulation.solve(stack, variables, diagnostics=False)
        else:
            sol = self.cycles[id(stack)].solve(q, v, variables)
        sol = self.failures.note(sol)
        self.cycle_times.append(time.perf_counter() - t0)
        self.timings.append(dict(sol.timings))
        self.n_contacts.append(len(variables.contacts))
        self.last = sol
        return sol
