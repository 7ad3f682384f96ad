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

from typing import Any, Mapping, Sequence

import numpy as np

from .description import DescriptionError


class TorqueProfile:
    """Joint-dependent symmetric torque bounds for the actuated joints, in model joint order."""

    def __init__(self, joint_names: Sequence[str], urdf_max: np.ndarray,
                 config: Mapping[str, Any] | None = None):
        config = dict(config or {})
        unknown = set(config) - {"scale", "overrides", "linkage"}
        if unknown:
            raise DescriptionError(f"field 'torque_limits' has unknown keys {sorted(unknown)}")
        self.joint_names = tuple(joint_names)
        index = {n: i for i, n in enumerate(self.joint_names)}
        self.scale = float(config.get("scale", 1.0))
        constant = np.asarray(urdf_max, dtype=float).copy()
        for joint, value in dict(config.get("overrides", {})).items():
            if joint not in index:
                raise DescriptionError(f"field 'torque_limits.overrides' names unknown joint '{joint}'")
            constant[index[joint]] = float(value)
        self.constant = constant
        linkage = dict(config.get("linkage", {}))
        rows, params = [], []
        for joint, p in linkage.items():
            if joint not in index:
                raise DescriptionError(f"field 'torque_limits.linkage' names unknown joint '{joint}'")
            try:
                params.append([float(p["a"]), float(p["b"]), float(p["force"]), float(p["q_peak"])])
            except KeyError as exc:
                raise DescriptionError(
                    f"field 'torque_limits.linkage.{joint}' misses key {exc.args[0]!r}") from None
            rows.append(index[joint])
        self._linkage_rows = np.asarray(rows, dtype=int)
        self._linkage = np.asarray(params, dtype=float).reshape(-1, 4)
        a, b, force, q_peak = self._linkage.T  # constants of the profile, evaluated every cycle
        self._ab, self._a2b2, self._force_ab = a * b, a * a + b * b, force * a * b
        self._angle_offset = np.pi / 2 - q_peak

    @property
    def linkage(self) -> tuple[np.ndarray, np.ndarray]:
        """(joint indices, rows [a, b, force, q_peak]) of the joints with a linkage profile."""
        return self._linkage_rows, self._linkage

    @property
    def has_profile(self) -> bool:
        """True when some bound depends on the joint position."""
        return self._linkage_rows.size > 0

    def upper(self, q_joints: np.ndarray) -> np.ndarray:
        """tau_max(q) for the actuated joint positions ``q_joints``."""
        hi = self.constant.copy()
        if self.has_profile:
            t = np.asarray(q_joints)[self._linkage_rows] + self._angle_offset
            hi[self._linkage_rows] = (self._force_ab * np.abs(np.sin(t))
                                      / np.sqrt(self._a2b2 - 2.0 * self._ab * np.cos(t)))
        return self.scale * hi if self.scale != 1.0 else hi

    def bounds(self, q_joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tau_min(q), tau_max(q))."""
        hi = self.upper(q_joints)
        return -hi, hi
