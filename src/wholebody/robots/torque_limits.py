"""Actuation limits tau_min(q) <= tau <= tau_max(q) of the actuated joints.

Fahmi et al. 2019, eq. 15: on HyQ the hip and knee flexion joints are driven by hydraulic cylinders
through linkages, so their torque bound is a non-linear function of the joint angle and must be
recomputed every control cycle. A joint with a ``linkage`` entry uses

    tau_max(q) = force * a * b * sin(t) / sqrt(a^2 + b^2 - 2 a b cos(t)),   t = pi/2 + (q - q_peak)

(cylinder force times the lever arm of a triangle with sides a, b); other joints use the URDF effort
limit. ``scale`` multiplies every bound, ``overrides`` replaces the constant of named joints (used e.g.
to weaken one joint, Fahmi et al. 2019 §V-C). Bounds are symmetric: tau_min = -tau_max.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from .description import DescriptionError, check_torque_limits


#: the largest joint torque bound taken as plausible for a legged robot (N m)
MAX_JOINT_TORQUE = 1e5


class TorqueProfile:
    """Joint-dependent symmetric torque bounds for the actuated joints, in model joint order."""

    def __init__(self, joint_names: Sequence[str], urdf_max: np.ndarray,
                 config: Mapping[str, Any] | None = None, where: str = "robot description"):
        """``config`` is the ``torque_limits`` table (checked by
        :func:`~wholebody.robots.description.check_torque_limits`); every joint without a
        ``linkage`` must end with a finite bound > 0, from ``urdf_max`` or ``overrides``
        (DescriptionError naming the joint and the URDF value otherwise)."""
        config = check_torque_limits(config, where)
        self.joint_names = tuple(joint_names)
        index = {n: i for i, n in enumerate(self.joint_names)}
        self.scale = float(config.get("scale", 1.0))
        constant = np.asarray(urdf_max, dtype=float).copy()
        if constant.shape != (len(self.joint_names),):
            raise ValueError(f"urdf_max: expected {len(self.joint_names)} effort limits, got "
                             f"shape {constant.shape}")
        for kind in ("overrides", "linkage"):
            unknown = [j for j in config.get(kind, {}) if j not in index]
            if unknown:
                raise DescriptionError(f"{where}: field 'torque_limits.{kind}' names unknown "
                                       f"joint(s) {unknown}; actuated joints: "
                                       f"{list(self.joint_names)}")
        for joint, value in config.get("overrides", {}).items():
            constant[index[joint]] = value
        linkage = config.get("linkage", {})
        bad = [(j, float(constant[i])) for j, i in index.items()
               if j not in linkage and not (np.isfinite(constant[i]) and constant[i] > 0)]
        if bad:
            listed = ", ".join(f"'{j}' ({v!r} Nm)" for j, v in bad)
            example = ", ".join(f"{j} = <Nm>" for j, _ in bad[:2])
            raise DescriptionError(
                f"{where}: the URDF effort limit of joint(s) {listed} is not a finite torque > 0; "
                f"give a bound with torque_limits.overrides = {{ {example} }} (or a "
                f"torque_limits.linkage profile)")
        self.constant = constant
        rows, params = [], []
        for joint, p in linkage.items():
            params.append([p["a"], p["b"], p["force"], p["q_peak"]])
            rows.append(index[joint])
        self._linkage_rows = np.asarray(rows, dtype=int)
        self._linkage = np.asarray(params, dtype=float).reshape(-1, 4)
        a, b, force, q_peak = self._linkage.T  # constants of the profile, evaluated every cycle
        with np.errstate(all="ignore"):
            self._ab, self._a2b2, self._force_ab = a * b, a * a + b * b, force * a * b
        self._angle_offset = np.pi / 2 - q_peak
        # the same constants as Python numbers, per profiled joint, for upper()
        self._linkage_index = self._linkage_rows.tolist()
        self._linkage_terms = list(zip(self._force_ab.tolist(), self._a2b2.tolist(),
                                       self._ab.tolist(), self._angle_offset.tolist()))
        self._constant_list = constant.tolist()
        self._last_upper: tuple[tuple, np.ndarray] | None = None  # see upper()
        self._check_derived(where)

    def _check_derived(self, where: str) -> None:
        """Every bound the table gives (the constants times ``scale``, each linkage profile over
        a full turn of its joint) finite and at most :data:`MAX_JOINT_TORQUE`: numbers each fine
        alone can multiply out to bounds no joint has."""
        angles = np.linspace(-np.pi, np.pi, 361)
        with np.errstate(all="ignore"):
            samples = np.array([self.upper(np.full(len(self.joint_names), q)) for q in angles])
        worst = np.where(np.isfinite(samples), samples, np.inf).max(axis=0)
        for i in np.flatnonzero(~(worst <= MAX_JOINT_TORQUE)):
            k = int(np.argmax(~np.isfinite(samples[:, i]) | (samples[:, i] > MAX_JOINT_TORQUE)))
            raise DescriptionError(
                f"{where}: torque_limits give joint '{self.joint_names[i]}' a bound of "
                f"{float(samples[k, i])!r} Nm (at q = {angles[k]:.2f} rad; scale {self.scale:g}): "
                f"expected finite torques up to {MAX_JOINT_TORQUE:g} Nm")

    @property
    def linkage(self) -> tuple[np.ndarray, np.ndarray]:
        """(joint indices, rows [a, b, force, q_peak]) of the joints with a linkage profile."""
        return self._linkage_rows, self._linkage

    @property
    def has_profile(self) -> bool:
        """True when some bound depends on the joint position."""
        return self._linkage_rows.size > 0

    def upper(self, q_joints: np.ndarray) -> np.ndarray:
        """tau_max(q) for the actuated joint positions ``q_joints`` (a new array). With a
        linkage profile the last answer is kept with the profiled joints' angles it came from:
        a control cycle and the simulator's step ask for the same state several times. The
        profile is evaluated in Python numbers, joint by joint (the simulator asks every step,
        where numpy's per-call overhead is most of the cost): the same operations in the same
        order as the array expression of :meth:`_upper_array`, which takes what they cannot
        (a square root of a negative number, a division by zero)."""
        if not self.has_profile:
            hi = self.constant.copy()
            return self.scale * hi if self.scale != 1.0 else hi
        q = q_joints.tolist() if type(q_joints) is np.ndarray else list(q_joints)
        key = (*[q[i] for i in self._linkage_index], self.scale)  # (the scale may change)
        last = self._last_upper
        if last is not None and last[0] == key:
            return last[1].copy()
        out = self._constant_list.copy()
        try:
            for i, a, (force_ab, a2b2, ab, offset) in zip(self._linkage_index, key[:-1],
                                                           self._linkage_terms):
                t = a + offset
                out[i] = force_ab * abs(math.sin(t)) / math.sqrt(a2b2 - 2.0 * ab * math.cos(t))
            hi = np.array(out)
        except (ValueError, ZeroDivisionError, TypeError, OverflowError):
            hi = self._upper_array(np.asarray(q_joints))
        hi = self.scale * hi if self.scale != 1.0 else hi
        # (a NaN angle never equals itself: such a key is never found again)
        self._last_upper = (key, hi)
        return hi.copy()

    def _upper_array(self, q_joints: np.ndarray) -> np.ndarray:
        """The unscaled tau_max(q) of the linkage profile as one numpy expression (warnings
        off: a degenerate triangle gives NaN or inf, which the caller reports)."""
        hi = self.constant.copy()
        t = q_joints[self._linkage_rows] + self._angle_offset
        with np.errstate(all="ignore"):
            hi[self._linkage_rows] = (self._force_ab * np.abs(np.sin(t))
                                      / np.sqrt(self._a2b2 - 2.0 * self._ab * np.cos(t)))
        return hi

    def bounds(self, q_joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tau_min(q), tau_max(q))."""
        hi = self.upper(q_joints)
        return -hi, hi
