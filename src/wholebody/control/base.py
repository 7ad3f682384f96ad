"""What every controller returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ControlResult:
    """Joint torques plus what the controller assumed (contact forces) and whether it succeeded.

    ``ok`` False means the controller could not do what was asked; ``tau`` is still finite and within
    the torque limits, and ``status`` says why.
    """

    tau: np.ndarray
    contact_forces: dict[str, np.ndarray] = field(default_factory=dict)
    ok: bool = True
    status: str = "ok"
