"""Controllers and their building blocks: each controller turns a robot state into joint torques
(``compute(q, v, t) -> Solution``, the :class:`Controller` protocol).

- humanoid (Herzog et al. 2016): :class:`MomentumBalance` (Tables 1/2/4 with PD or LQR momentum
  gains), :class:`ContactSwitch` (double -> single support), :class:`Stepping`; ``stacks`` builds
  the hierarchies, ``lqr`` and ``momentum_model`` the momentum gains; :class:`Walking` (walking
  and push recovery by stepping on the same hierarchies, capture-point reference);
- quadruped (Fahmi et al. 2019): :class:`PassiveWBC` and the :class:`QuasiStaticController`
  baseline;
- any robot: :class:`StandingController`.
"""

from .balance import MomentumBalance, lqr_q
from .base import Controller
from .contact_switch import ContactSwitch, ContactSwitchConfig
from .lqr import MomentumLQR, lqr_gains
from .momentum_model import momentum_model
from .observer import MomentumObserver
from .passive import PassiveConfig, PassiveWBC, SwingGains
from .passivity import StorageMeter, SwingFeedForwardOff
from .quasi_static import QuasiStaticController
from .stacks import table1_stack, table2_stack, table4_stack
from .standing import StandingController
from .stepping import Stepping, SteppingConfig
from .walking import Walking, WalkingConfig

__all__ = ["ContactSwitch", "ContactSwitchConfig", "Controller", "MomentumBalance",
           "MomentumLQR", "MomentumObserver", "PassiveConfig", "PassiveWBC",
           "QuasiStaticController", "StandingController", "StorageMeter", "SwingFeedForwardOff", "Stepping", "SteppingConfig",
           "SwingGains", "Walking", "WalkingConfig", "lqr_gains", "lqr_q", "momentum_model", "table1_stack", "table2_stack",
           "table4_stack"]
