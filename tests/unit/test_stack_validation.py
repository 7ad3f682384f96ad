"""Contact lists and constructor arguments of the stack builders and controllers
(control/stacks.py, control/balance.py, control/standing.py).

Defects this guards against (adversarial review): ``contacts=[]`` meant *all* contacts in
``table2_stack`` and ``MomentumBalance`` (``tuple(contacts or robot.contact_names)``), ``mu=0`` in
the builders meant the robot's friction, and NaN or out-of-range controller arguments (gains,
weights, margins) were accepted and failed, or silently misbehaved, cycles later."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from wholebody.control.balance import CoMSineReference, MomentumBalance, SoleFrameReference
from wholebody.control.stacks import COP_MARGIN, table1_stack, table2_stack, table4_stack
from wholebody.control.standing import StandingController
from wholebody.formulation import Formulation
from wholebody.variables import Variables

NAN, INF = math.nan, math.inf
CONTACT_TASKS = ("contacts", "friction", "force regularizer")


def raises_naming(call, field: str, shown: str):
    """``call()`` raises a ValueError whose message starts with ``field`` and shows ``shown``."""
    with pytest.raises(ValueError) as exc_info:
        call()
    message = str(exc_info.value)
    assert message.startswith(f"{field}:"), message
    assert shown in message, f"{shown!r} not in {message!r}"


@pytest.fixture
def talos(robots):
    robot = robots["talos14"]
    yield robot
    robot.update(robot.q_ref, np.zeros(robot.nv))


# ------------------------------------------------------------------------------ contacts = []
def test_table2_stack_with_no_contacts_has_no_contact_rows(talos):
    """Before: [] gave the tasks of both soles. Now an empty list is no contact: the contact
    tasks have no rows, there is no CoP task, and the stack solves with no active contact (the
    robot falls: the base accelerates at -g)."""
    stack = table2_stack(talos, [])
    for name in CONTACT_TASKS:
        assert stack.find(name).contacts == ()
    assert "center of pressure" not in [t.name for level in stack.levels for t in level]
    talos.update(talos.q_ref, np.zeros(talos.nv))
    for name in CONTACT_TASKS:
        assert stack.find(name).rows(talos, Variables(talos)).m == 0
    solution = Formulation(talos).solve(stack, Variables(talos, []))
    assert solution.ok and solution.lam.size == 0
    gravity = float(np.linalg.norm(talos.model.gravity.linear))
    assert solution.qdd[2] == pytest.approx(-gravity, abs=1e-2)


def test_table2_stack_none_means_all_contacts(talos):
    stack = table2_stack(talos)
    for name in CONTACT_TASKS:
        assert stack.find(name).contacts == tuple(talos.contact_names)
    assert stack.find("center of pressure").contacts == tuple(talos.contact_names)


@pytest.mark.parametrize("builder", [
    lambda r, c: table1_stack(r, c), lambda r, c: table4_stack(r, c)], ids=["table1", "table4"])
def test_single_support_builders_take_an_empty_stance(talos, builder):
    stack = builder(talos, [])
    assert stack.find("contacts").contacts == ()
    assert stack.find("friction").contacts == ()


@pytest.mark.parametrize("contacts,shown", [("left_sole", "'left_sole'"), (["nose"], "'nose'"),
                                            (["left_sole", "left_sole"], "duplicate")])
def test_table2_stack_bad_contacts(talos, contacts, shown):
    with pytest.raises(ValueError, match=r"^(contacts|contact): .*" + re.escape(shown)):
        table2_stack(talos, contacts)


@pytest.mark.parametrize("gains", ["lqr", "pd"])
def test_momentum_balance_refuses_no_contacts(talos, gains):
    """Before: contacts=[] balanced on all contacts. Balancing needs a support: ValueError."""
    raises_naming(lambda: MomentumBalance(talos, gains=gains, contacts=[]), "contacts",
                  "at least one contact")
    ctrl = MomentumBalance(talos, gains=gains, contacts=None)
    assert ctrl.contacts == tuple(talos.contact_names)


def test_sole_frame_reference_refuses_no_contacts(talos):
    raises_naming(lambda: SoleFrameReference(talos, contacts=[]), "contacts",
                  "at least one contact")
    raises_naming(lambda: SoleFrameReference(talos, contacts="left_sole"), "contacts",
                  "'left_sole'")
    assert SoleFrameReference(talos).contacts == tuple(talos.contact_names)


# ------------------------------------------------------------------------- builder arguments
@pytest.mark.parametrize("mu,shown", [(0.0, "0.0"), (-0.5, "-0.5"), (NAN, "nan"), (INF, "inf")])
@pytest.mark.parametrize("builder", [
    lambda r, mu: table2_stack(r, mu=mu),
    lambda r, mu: table1_stack(r, r.contact_names, mu=mu),
    lambda r, mu: table4_stack(r, ["left_sole"], mu=mu)], ids=["table2", "table1", "table4"])
def test_builders_check_mu(talos, builder, mu, shown):
    """Before: mu=0 meant the robot's friction (``mu or robot.friction``)."""
    raises_naming(lambda: builder(talos, mu), "mu", shown)
    assert table2_stack(talos, mu=None).find("friction").mu == talos.friction
    assert table2_stack(talos, mu=0.3).find("friction").mu == 0.3


BUILDERS = [lambda r, **kw: table2_stack(r, **kw),
            lambda r, **kw: table1_stack(r, r.contact_names, **kw),
            lambda r, **kw: table4_stack(r, ["left_sole"], **kw)]


@pytest.mark.parametrize("bad,shown", [(NAN, "nan"), (-0.1, "-0.1"), (1.0, "1.0")])
@pytest.mark.parametrize("builder", BUILDERS, ids=["table2", "table1", "table4"])
def test_builders_check_cop_margin(talos, builder, bad, shown):
    raises_naming(lambda: builder(talos, cop_margin=bad), "cop_margin", shown)


@pytest.mark.parametrize("builder", BUILDERS, ids=["table2", "table1", "table4"])
def test_builders_keep_the_cop_inside_the_soles_by_default(talos, builder):
    """Every hierarchy's CoP rows have the library's margin unless told otherwise (0: the
    paper's whole sole), and it is a share strictly inside the sole."""
    assert 0.0 < COP_MARGIN < 0.5
    assert builder(talos).find("center of pressure").margin == COP_MARGIN
    assert builder(talos, cop_margin=0.0).find("center of pressure").margin == 0.0


@pytest.mark.parametrize("bad,shown", [(NAN, "nan"), (-1.0, "-1.0"), (INF, "inf")])
def test_table2_stack_checks_angular_weight(talos, bad, shown):
    raises_naming(lambda: table2_stack(talos, angular_weight=bad), "angular_weight", shown)


# ---------------------------------------------------------------------- MomentumBalance arguments
MOMENTUM_BALANCE_BAD = [
    (dict(cop_margin=-0.1), "cop_margin", "-0.1"),
    (dict(cop_margin=1.0), "cop_margin", "1.0"),
    (dict(cop_margin=NAN), "cop_margin", "nan"),
    (dict(angular_weight=NAN), "angular_weight", "nan"),
    (dict(angular_weight=-1e-4), "angular_weight", "-0.0001"),
    (dict(integral_limit=0.0), "integral_limit", "0.0"),
    (dict(integral_limit=NAN), "integral_limit", "nan"),
    (dict(com_ref=[0.0, NAN, 0.9]), "com_ref", "nan"),
    (dict(com_ref=[0.0, 0.9]), "com_ref", "(2,)"),
    (dict(gains="pd", P=-np.eye(6)), "P", "eigenvalue -1"),
    (dict(gains="pd", D=np.full(6, NAN)), "D", "nan"),
    (dict(gains="pd", P=np.ones(4)), "P", "shape (4,)"),
    (dict(gains="lqr", P=np.eye(6)), "P", "gains='lqr'"),
    (dict(gains="pd", Q=np.eye(9)), "Q", "gains='pd'"),
    (dict(gains="pd", R=np.eye(6)), "R", "gains='pd'"),
    (dict(gains="lqr", Q=np.full(9, NAN)), "Q", "NaN"),
    (dict(gains="lqr", R=-np.eye(6)), "R", "definite"),
    (dict(engine="fast"), "engine", "'fast'"),
    (dict(reference=3.0), "reference", "3.0"),
    (dict(gains="PD"), "gains", "'PD'"),
]


@pytest.mark.parametrize("kwargs,field,shown", MOMENTUM_BALANCE_BAD,
                         ids=[f"{k}" for k, _, _ in MOMENTUM_BALANCE_BAD])
def test_momentum_balance_bad_arguments(talos, kwargs, field, shown):
    raises_naming(lambda: MomentumBalance(talos, **kwargs), field, shown)


def test_momentum_balance_valid_arguments(talos):
    ctrl = MomentumBalance(talos, gains="pd", P=np.full(6, 10.0), D=np.eye(6), cop_margin=0.2,
                           com_ref=[0.0, 0.0, 0.8])
    np.testing.assert_array_equal(ctrl.momentum.P, 10.0 * np.eye(6))
    assert ctrl.stack.find("center of pressure").margin == ctrl.cop_margin == 0.2
    assert MomentumBalance(talos, gains="pd").cop_margin == COP_MARGIN


def test_cop_margin_needs_a_sole(robots):
    """A CoP margin given for a robot with point feet (no CoP task) is an error, not ignored;
    the default margin (None) and 0 are not given margins."""
    hyq = robots["hyq"]
    try:
        raises_naming(lambda: MomentumBalance(hyq, gains="pd", cop_margin=0.1), "cop_margin",
                      "0.1")
        for margin in (None, 0.0):
            assert MomentumBalance(hyq, gains="pd", cop_margin=margin).cop_margin == 0.0
    finally:
        hyq.update(hyq.q_ref, np.zeros(hyq.nv))


COM_SINE_BAD = [
    (dict(amplitude=[0.02, NAN, 0.0]), "amplitude", "nan"),
    (dict(amplitude=[0.02, 0.0]), "amplitude", "(2,)"),
    (dict(frequency=[-0.3, 0.3, 0.3]), "frequency", "-0.3"),
    (dict(frequency=[INF, 0.3, 0.3]), "frequency", "inf"),
    (dict(ramp=-1.0), "ramp", "-1.0"),
    (dict(ramp=NAN), "ramp", "nan"),
    (dict(start=NAN), "start", "nan"),
    (dict(x0=[0.0, 0.0]), "x0", "(2,)"),
]


@pytest.mark.parametrize("kwargs,field,shown", COM_SINE_BAD,
                         ids=[f"{k}" for k, _, _ in COM_SINE_BAD])
def test_com_sine_reference_bad_arguments(talos, kwargs, field, shown):
    args = {"amplitude": [0.02, 0.0, 0.03], "frequency": [0.3, 0.3, 0.3], **kwargs}
    raises_naming(lambda: CoMSineReference(talos, **args), field, shown)


# ------------------------------------------------------------------- StandingController arguments
STANDING_BAD = [
    (dict(kp=-1.0), "kp", "-1.0"), (dict(kp=NAN), "kp", "nan"), (dict(kp=INF), "kp", "inf"),
    (dict(kd=-30.0), "kd", "-30.0"), (dict(kd=NAN), "kd", "nan"),
    (dict(kp=np.ones(3)), "kp", "shape (3,)"), (dict(kd=np.ones((14, 14))), "kd", "(14, 14)"),
    (dict(kp="stiff"), "kp", "'stiff'"),
]


@pytest.mark.parametrize("kwargs,field,shown", STANDING_BAD,
                         ids=[f"{k}"[:40] for k, _, _ in STANDING_BAD])
def test_standing_controller_bad_gains(talos, kwargs, field, shown):
    raises_naming(lambda: StandingController(talos, **kwargs), field, shown)


def test_standing_controller_bad_posture(talos):
    q_ref = talos.q_ref.copy()
    q_ref[9] = NAN
    raises_naming(lambda: StandingController(talos, q_ref=q_ref), "q_ref", "nan")
    raises_naming(lambda: StandingController(talos, q_ref=q_ref[:-1]), "q_ref",
                  f"({talos.nq - 1},)")
    ctrl = StandingController(talos, kp=np.linspace(100.0, 200.0, talos.na), kd=0.0)
    assert ctrl.kp.shape == (talos.na,) and not ctrl.kd.any()
