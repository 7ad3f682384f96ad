"""Momentum-based balance with hierarchical inverse dynamics (Herzog et al. 2016, Sects. 3 and 5.2).

The hierarchy of Table 2 (double support): (1) Newton-Euler + torque limits, (2) contact
constraints, CoP, friction, joint acceleration limits, (3) momentum control + posture + GRF
regulariser. The momentum task is either the LQR force law projected into momentum space (eq. 24,
gains from :class:`~wholebody.control.lqr.MomentumLQR` with the cost of eq. 26) or the PD law on
the momentum rate (eq. 22). The hierarchy's torques are the only command: no joint PD.

References. By default the CoG reference is constant (the CoM of the reference posture) and the
momentum reference is zero, as in the push experiments (Sect. 5.2.2). A ``reference`` callable
``(t, robot) -> BalanceReference`` makes them time-varying: it gives ``x_ref`` and optionally
``h_ref`` and the feed-forward ``hdot_ref`` of eq. 22 (the LQR law of eq. 23 re-balances its
feed-forward forces for the same ``hdot_ref``), and optionally a floating-base reference for the
posture task. Two are provided: :class:`CoMSineReference` (the squat of Sect. 5.3) and
:class:`SoleFrameReference` (CoG and base fixed in the frame of the soles, for the moving platform
and tilting board of Sect. 5.2.3).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from ..cycle import ENGINES, HierarchyCycle
from ..formulation import Formulation, Solution
from ..guard import Outcome
from ..robot import Robot
from ..solvers import SolverSettings
from ..solvers.settings import settings_or_default
from ..variables import Variables
from ..planning.blend import quintic_blend
from ..tasks.base import checked_attribute, contact_list, vector_rule
from ..tasks.momentum import momentum_gain
from ..validation import finite_array, nonnegative, number, positive
from .base import FailureStreak
from .lqr import DEFAULT_INTEGRAL_LIMIT, DEFAULT_Q_DIAG, DEFAULT_Q_INTEGRAL, MomentumLQR
from .stacks import ANGULAR_MOMENTUM_WEIGHT, COP_MARGIN, POSTURE_PD, TORSION, table2_stack

GAINS = ("lqr", "pd")


@dataclass
class BalanceReference:
    """References of one control cycle: ``com`` (x_ref), ``h`` (h_ref, [linear; angular] about the
    CoM, world axes), ``hdot`` (the feed-forward of eq. 22), and ``base`` (XYZQUAT of the floating
    base for the posture task; None keeps the preset's reference posture)."""

    com: np.ndarray
    h: np.ndarray | None = None
    hdot: np.ndarray | None = None
    base: np.ndarray | None = None


def lqr_q(q_angular: float) -> np.ndarray:
    """Eq. 26's Q (:data:`~wholebody.control.lqr.DEFAULT_Q_DIAG`) with the angular-momentum weight
    replaced by ``q_angular``."""
    return np.diag(np.r_[DEFAULT_Q_DIAG[:6], [q_angular] * 3])


class CoMSineReference:
    """x_ref(t) = x0 + e(t) a sin(2 pi f t) per axis (Sect. 5.3's squat: 2 cm forward, 3 cm up, 0.3
    or 0.5 Hz), with h_ref = m x_ref' and hdot_ref = [m x_ref''; 0] as feed-forward.

    ``amplitude`` and ``frequency`` are 3-vectors (world x, y, z); the envelope ``e`` rises from 0 to 1
    over ``ramp`` seconds (quintic) so that the reference starts at rest. ``x0`` defaults to the CoM
    of the reference posture. Checked at construction: ``amplitude`` and ``frequency`` (>= 0, Hz)
    finite 3-vectors, ``ramp`` finite >= 0 (0: no ramp), ``start`` finite, ``x0`` a finite 3-vector.

    With ``move_base`` (default) the floating-base reference of the posture task is translated with
    the CoG reference, so that the posture task does not pull the base back to its standing
    position. With Table 2's weights this changes little: the momentum task (weight 1e4) leaves the
    posture task (1e-1) two directions of q'' and the base translation is not among them.
    """

    def __init__(self, robot: Robot, amplitude, frequency, ramp: float = 1.0, x0=None,
                 start: float = 0.0, move_base: bool = True):
        self.amplitude = finite_array(amplitude, "amplitude", shape=(3,))
        self.frequency = finite_array(frequency, "frequency", shape=(3,), nonnegative=True)
        self.ramp, self.start = nonnegative(ramp, "ramp"), number(start, "start")
        if x0 is None:
            robot.update(robot.q_ref, np.zeros(robot.nv))
            x0 = robot.com.copy()
        self.x0 = finite_array(x0, "x0", shape=(3,))
        self.mass = robot.mass
        self.base0 = robot.q_ref[:7].copy() if move_base else None

    def terms(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x_ref, x_ref', x_ref'') at time t."""
        tau = t - self.start
        if tau <= 0.0:
            return self.x0.copy(), np.zeros(3), np.zeros(3)
        e, de, dde = quintic_blend(tau / self.ramp, self.ramp) if self.ramp > 0 else (1.0, 0.0, 0.0)
        w = 2 * np.pi * self.frequency
        s, c = np.sin(w * tau), np.cos(w * tau)
        a = self.amplitude
        x = self.x0 + e * a * s
        xd = a * (de * s + e * w * c)
        xdd = a * (dde * s + 2 * de * w * c - e * w ** 2 * s)
        return x, xd, xdd

    def __call__(self, t: float, robot: Robot) -> BalanceReference:
        x, xd, xdd = self.terms(t)
        base = None
        if self.base0 is not None:
            base = self.base0.copy()
            base[:3] += x - self.x0
        return BalanceReference(x, np.concatenate([self.mass * xd, np.zeros(3)]),
                                np.concatenate([self.mass * xdd, np.zeros(3)]), base)


class SoleFrameReference:
    """CoG and floating-base references fixed in the frame of the soles (Sect. 5.2.3).

    The robot stands on a support that moves (rolling platform, tilting board); the controller knows
    only its own state. The sole frame is measured every cycle from that state: origin at the mean
    of the sole frames' positions, heading the mean yaw of the soles (roll and pitch ignored, so that
    on a tilted board the CoG stays above the soles rather than leaning with the board). The CoG
    reference keeps its offset from the reference posture in that frame, x_ref = p + R_z(psi) r0;
    h_ref = [m x_ref'; I_G (0, 0, psi')] with x_ref' = p' + psi' e_z x R_z(psi) r0 from the soles'
    measured velocities. The base reference (posture task) is carried along the same way.

    ``support_acceleration`` (optional, ``t -> (3,)`` world): the measured acceleration of the
    support under the soles (an IMU on the platform, as in Sect. 4.5), used as the feed-forward
    hdot_ref = [m a; 0]. The paper's controller has no such term (hdot_ref = 0, contacts assumed
    stationary); it is an option to measure what the missing feed-forward costs.

    ``contacts``: the soles defining the frame (None: all the robot's contacts; an empty list is
    an error — there is no frame without a sole).
    """

    def __init__(self, robot: Robot, contacts: Sequence[str] | None = None,
                 support_acceleration: Callable[[float], np.ndarray] | None = None):
        self.contacts = _balance_contacts(robot, contacts, "SoleFrameReference")
        if support_acceleration is not None and not callable(support_acceleration):
            raise ValueError(f"support_acceleration: expected None or a callable t -> (3,), got "
                             f"{support_acceleration!r}")
        self.frames = [robot.contact(n).frame for n in self.contacts]
        robot.update(robot.q_ref, np.zeros(robot.nv))
        p0, yaw0 = self._frame(robot)
        Rz0 = pin.rpy.rpyToMatrix(0.0, 0.0, yaw0)
        self.com_offset = Rz0.T @ (robot.com - p0)
        base0 = pin.XYZQUATToSE3(robot.q_ref[:7])
        self.base_offset = pin.SE3(Rz0, p0).actInv(base0)
        self.mass = robot.mass
        self.support_acceleration = support_acceleration

    def _frame(self, robot: Robot) -> tuple[np.ndarray, float]:
        poses = [robot.frame_placement(f) for f in self.frames]
        p = np.mean([pos for pos, _ in poses], axis=0)
        heading = np.sum([R[:2, 0] for _, R in poses], axis=0)
        return p, float(np.arctan2(heading[1], heading[0]))

    def __call__(self, t: float, robot: Robot) -> BalanceReference:
        p, yaw = self._frame(robot)
        Rz = pin.rpy.rpyToMatrix(0.0, 0.0, yaw)
        vel = np.mean([robot.frame_velocity(f) for f in self.frames], axis=0)  # world [lin; ang]
        r = Rz @ self.com_offset
        yaw_rate = float(vel[5])
        com_vel = vel[:3] + yaw_rate * np.array([-r[1], r[0], 0.0])
        Izz = float(robot.data.Ig.inertia[2, 2])
        h = np.concatenate([self.mass * com_vel, [0.0, 0.0, Izz * yaw_rate]])
        base = pin.SE3ToXYZQUAT(pin.SE3(Rz, p) * self.base_offset)
        hdot = None
        if self.support_acceleration is not None:
            a = np.asarray(self.support_acceleration(t), dtype=float).reshape(3)
            hdot = np.concatenate([self.mass * a, np.zeros(3)])
        return BalanceReference(p + r, h, hdot, base)


def _balance_contacts(robot: Robot, contacts, who: str) -> tuple[str, ...]:
    """None: all the robot's contacts; otherwise a non-empty list of its contact names."""
    if contacts is None:
        return tuple(robot.contact_names)
    names = contact_list(contacts, "contacts")
    if not names:
        raise ValueError(f"contacts: {who} needs at least one contact, got an empty list "
                         f"(None means all the robot's contacts)")
    for name in names:
        robot.contact(name)  # ValueError naming an unknown contact
    return names


class MomentumBalance:
    """Balance controller: ``compute(q, v, t) -> Solution`` (tau, contact forces, diagnostics).

    ``gains`` "lqr" (eq. 24, default) or "pd" (eq. 22 with diagonal ``P``/``D``). ``com_ref``
    defaults to the CoM of the reference posture. ``settings`` (a
    :class:`~wholebody.solvers.SolverSettings`; None: its defaults) pick the cascade's QP solver.
    ``reference`` (optional) is called every cycle as ``reference(t, robot)`` after the robot
    update and returns a :class:`BalanceReference`; it sets ``com_ref``, ``h_ref``, ``hdot_ref`` and
    the posture task's base reference. ``cop_margin`` shrinks the admissible CoP region of every
    sole (:class:`~wholebody.tasks.CenterOfPressure`'s margin; None: on soles
    :data:`~wholebody.control.stacks.COP_MARGIN`; 0 = the whole sole, the paper's).
    ``angular_weight``: weight of the momentum task's angular rows (see
    :func:`~wholebody.control.stacks.table2_stack`; 1e4 = the paper's single weight).
    ``torsion`` (default True): the soles' yaw-moment rows in the friction task (False: the
    paper's pyramid only; :data:`~wholebody.control.stacks.TORSION`). ``posture_gains``: the
    posture task's (kp, kd) (:data:`~wholebody.control.stacks.POSTURE_PD`).
    ``q_integral`` (LQR only): weight of the integral of the CoG error ``robot.com - com_ref`` in
    the augmented LQR cost — integral action, our extension, not Herzog et al. 2016 (see
    :mod:`wholebody.control.lqr`); None (default) = :data:`~wholebody.control.lqr.DEFAULT_Q_INTEGRAL`
    with ``gains="lqr"``, 0 = off, the paper's controller. The integral is
    accumulated here, one step per :meth:`compute` call with ``dt`` the time since the previous
    call, clamped to ``+-integral_limit`` (m s, anti-windup), not on a cycle that is ``HELD``;
    :meth:`reset_integral` zeroes it. A ``HELD`` cycle's status ends with "(N failed cycle(s) in
    a row)" (:class:`~wholebody.control.base.FailureStreak`); the next sane state is solved as
    if nothing had failed.
    ``q_orientation`` (LQR only; None/0 = off, the default and the paper's controller): weight of
    the orientation error in the augmented LQR state (ours; see :mod:`wholebody.control.lqr`); the
    error fed back is the floating base's, ``theta = log3(R_base R_ref^T)`` (world axes) against
    the posture task's base reference. Eq. 21 turns the CoG error into angular momentum that
    nothing returns; with this state the gains return the rotation it integrates to. It does not
    make the paper's single momentum weight (``angular_weight=1e4``) usable: the moments the gains
    ask exceed what the soles' CoP allows (docs/results.md measures both).
    ``engine``: ``"auto"`` (default: native when built), ``"native"`` — the stack solved by a
    :class:`~wholebody.cycle.HierarchyCycle` (compiled rigid-body terms and rows, the same
    solution; ``robot.update`` runs only where something reads the robot's cache: a
    ``reference``, the Python engine — the LQR reads the compiled cycle's own terms, so after a
    cycle without a reference the robot's cache is not the state the controller read;
    :attr:`com` is) — or ``"python"``
    (``Formulation.solve``, the reference).

    ``contacts``: None (default) = all the robot's contacts; an empty list is a ValueError
    (balance needs a support; the LQR model has no input without contacts). Checked at
    construction, each error naming the argument: ``com_ref`` a finite 3-vector; ``P``/``D``
    (PD only) 6x6 or their diagonals, finite with a positive semi-definite symmetric part;
    ``Q``/``R`` (LQR only, checked by :class:`~wholebody.control.lqr.MomentumLQR`); ``cop_margin``
    None or in [0, 1), not > 0 without a sole; ``angular_weight`` finite >= 0; ``integral_limit``
    finite > 0; ``reference`` None or callable; ``settings`` None or a SolverSettings whose
    ``analytic_first_level`` the stack allows; ``engine`` one of
    :data:`~wholebody.cycle.ENGINES`. Gains given for the other law (``P``/``D`` with "lqr",
    ``Q``/``R``/``q_integral`` with "pd") are errors, not ignored.
    """

    #: the references of the momentum law (a ``reference`` sets them every cycle), checked on
    #: every assignment: finite vectors of 3, 6 and 6
    com_ref = checked_attribute(vector_rule(3), "CoM reference x_ref (m), finite.")
    h_ref = checked_attribute(vector_rule(6), "Momentum reference h_ref, finite.")
    hdot_ref = checked_attribute(vector_rule(6), "Momentum rate feed-forward, finite.")

    def __init__(self, robot: Robot, gains: str = "lqr", contacts=None, com_ref=None,
                 P=None, D=None, Q=None, R=None, settings: SolverSettings | None = None,
                 reference: Callable[[float, Robot], BalanceReference] | None = None,
                 cop_margin: float | None = None, angular_weight: float = ANGULAR_MOMENTUM_WEIGHT,
                 q_integral=None, integral_limit: float = DEFAULT_INTEGRAL_LIMIT,
                 engine: str = "auto", torsion: bool = TORSION, q_orientation=None,
                 posture_gains=POSTURE_PD):
        if gains not in GAINS:
            raise ValueError(f"gains: expected one of {GAINS}, got '{gains}'")
        for arg, value in (("q_integral", q_integral), ("q_orientation", q_orientation)):
            if gains != "lqr" and value is not None and np.any(np.asarray(value) != 0):
                raise ValueError(f"{arg}: an LQR extension, only available with gains='lqr'")
        for arg, value, law in (("P", P, "pd"), ("D", D, "pd"), ("Q", Q, "lqr"), ("R", R, "lqr")):
            if value is not None and gains != law:
                raise ValueError(f"{arg}: only used with gains='{law}', got gains='{gains}'")
        P = None if P is None else momentum_gain(P, "P")
        D = None if D is None else momentum_gain(D, "D")
        if engine not in ENGINES:
            raise ValueError(f"engine: expected one of {ENGINES}, got {engine!r}")
        if reference is not None and not callable(reference):
            raise ValueError(f"reference: expected None or a callable (t, robot) -> "
                             f"BalanceReference, got {reference!r}")
        if cop_margin is not None:
            cop_margin = number(cop_margin, "cop_margin", low=0.0, high=1.0, high_open=True)
        angular_weight = nonnegative(angular_weight, "angular_weight")
        integral_limit = positive(integral_limit, "integral_limit")
        self.robot = robot
        self.gains = gains
        self.contacts = _balance_contacts(robot, contacts, "MomentumBalance")
        self.variables = Variables(robot, self.contacts)
        if cop_margin and not any(robot.contact(c).spec.type == "rectangle"
                                  for c in self.contacts):
            raise ValueError(f"cop_margin: {cop_margin!r} given, but none of the contacts "
                             f"{list(self.contacts)} is a sole (rectangle)")
        self.stack = table2_stack(robot, self.contacts, lqr=(gains == "lqr"),
                                  angular_weight=angular_weight, torsion=torsion,
                                  posture_gains=posture_gains,
                                  cop_margin=COP_MARGIN if cop_margin is None else cop_margin)
        self.momentum = self.stack.find("momentum")
        if P is not None:
            self.momentum.P = P
        if D is not None:
            self.momentum.D = D
        self.formulation = Formulation(robot)
        self.settings = settings_or_default(settings)
        Formulation.uses_analytic_first_level(self.stack, self.settings)  # (a ValueError now)
        self.cycle = (None if engine == "python" else
                      HierarchyCycle(robot, self.stack, engine=engine, settings=self.settings))
        if com_ref is None:
            robot.update(robot.q_ref, np.zeros(robot.nv))
            com_ref = robot.com.copy()
        self.com_ref = finite_array(com_ref, "com_ref", shape=(3,))  # (the argument named)
        self.h_ref = np.zeros(6)
        self.hdot_ref = np.zeros(6)
        self.reference = reference
        self.posture = self.stack.find("posture")
        if gains == "lqr" and q_integral is None:
            q_integral = DEFAULT_Q_INTEGRAL
        self.lqr = (MomentumLQR(robot, self.contacts, Q=Q, R=R, q_integral=q_integral,
                                integral_limit=integral_limit, q_orientation=q_orientation)
                    if gains == "lqr" else None)
        self.cog_integral = np.zeros(3)
        self._t_last: float | None = None
        self._cycle_view = None  # (the compiled cycle's terms, the contacts' points in them)
        self.failures = FailureStreak("MomentumBalance")
        if self.lqr is not None:
            robot.update(robot.q_ref, np.zeros(robot.nv))
            self.lqr.gains(robot, self.contacts)  # gains at the reference pose (Sect. 3.2 remark)

    @property
    def cop_margin(self) -> float:
        """The CoP rows' margin: the share of each sole's half-lengths kept inside its edges (0
        without a sole)."""
        return next((t.margin for t in self.stack.tasks() if t.name == "center of pressure"),
                    0.0)

    def reset_integral(self) -> None:
        """Zero the CoG-error integral (integral action only) and forget the last call's time."""
        self.cog_integral = np.zeros(3)
        self._t_last = None

    def base_orientation_error(self, q=None) -> np.ndarray:
        """``log3(R_base R_ref^T)``: the floating base's rotation at ``q`` (default: the robot's
        cached state) from the posture task's base reference, world axes (the orientation state
        of the LQR extension)."""
        q_ref = self.robot.q_ref if self.posture.q_ref is None else self.posture.q_ref
        R = pin.Quaternion((self.robot.q if q is None else q)[3:7]).toRotationMatrix()
        R_ref = pin.Quaternion(q_ref[3:7]).toRotationMatrix()
        return pin.log3(R @ R_ref.T)

    @property
    def com(self) -> np.ndarray:
        """The CoM of the state the last :meth:`compute` read, through the controller's model."""
        return self.robot.com.copy() if self.cycle is None else self.cycle.com

    def compute(self, q, v, t: float = 0.0) -> Solution:
        """Torques for the state (q, v) in Pinocchio convention."""
        robot, cycle = self.robot, self.cycle
        # the robot's cache is updated only where something reads it (a reference, the Python
        # engine); on the compiled cycle the LQR reads the cycle's own terms (one rigid-body pass)
        on_cycle = cycle is not None and self.reference is None
        if not on_cycle:
            robot.update(q, v)
        elif self.lqr is not None:
            cycle.update(q, v)
        if self.reference is not None:
            ref = self.reference(t, robot)
            self.com_ref = ref.com
            self.h_ref = np.zeros(6) if ref.h is None else ref.h
            self.hdot_ref = np.zeros(6) if ref.hdot is None else ref.hdot
            if ref.base is not None:
                q_ref = robot.q_ref.copy()
                q_ref[:7] = ref.base
                self.posture.q_ref = q_ref
        integral = None
        if self.lqr is not None:
            if on_cycle:
                terms, positions = self._cycle_terms()
                com, q_read = terms.com, terms.q
            else:
                com, q_read, positions = robot.com, robot.q, None
            if self.lqr.integral:
                integral = self._integral_step(t, com)
            self._t_last = float(t)
            theta = self.base_orientation_error(q_read) if self.lqr.orientation else None
            # the references were checked when set (checked attributes)
            K, k = self.lqr.force_law(robot, self.lqr.gains(robot, self.contacts), self.com_ref,
                                      self.h_ref, self.hdot_ref, integral=integral,
                                      orientation=theta,
                                      positions=positions)
            self.momentum.K, self.momentum.k = K, k
        else:
            self.momentum.com_ref = self.com_ref
            self.momentum.h_ref = self.h_ref
            self.momentum.hdot_ref = self.hdot_ref
        if on_cycle and self.lqr is not None:
            sol = cycle.solve_updated(self.variables)
        elif cycle is not None:
            sol = cycle.solve(q, v, self.variables)
        else:
            sol = self.formulation.solve(self.stack, self.variables, self.settings,
                                         diagnostics=False)
        if integral is not None and sol.outcome is not Outcome.HELD:
            self.cog_integral = integral  # a held cycle's error is not integrated (anti-windup)
        return self.failures.note(sol)

    def _cycle_terms(self):
        """The compiled cycle's terms (:meth:`HierarchyCycle.terms_view
        <wholebody.cycle.HierarchyCycle.terms_view>`) and the LQR's contacts' points in them
        (name -> a row the cycle's update rewrites), bound on first use."""
        if self._cycle_view is None:
            terms = self.cycle.terms_view()
            index = {n: i for i, n in enumerate(self.robot.contact_names)}
            self._cycle_view = terms, {n: terms.points[index[n]] for n in self.contacts}
        return self._cycle_view

    def _integral_step(self, t: float, com: np.ndarray) -> np.ndarray:
        """The CoG-error integral advanced by ``dt`` (the time since the previous call) for this
        cycle's feedback at the CoM ``com``, clamped to ``+-integral_limit``; :meth:`compute`
        keeps it only when the cycle is not ``HELD``. A non-finite step (an absurd ``t``: dt = inf
        times a zero error) leaves it as it was."""
        dt = 0.0 if self._t_last is None else max(float(t) - self._t_last, 0.0)
        step = dt * (com - self.com_ref)
        if not np.isfinite(step).all():
            return self.cog_integral.copy()
        return self.lqr.clip_integral(self.cog_integral + step)
