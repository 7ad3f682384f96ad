"""robust-push: push recovery on mismatched twins (Herzog et al. 2016, robustness of the momentum gains).

The CoG judged is the simulated robot's own CoM (from the mismatched MuJoCo model), checked here
against Pinocchio on the exact twin and shown to differ from the controller's estimate on a
mismatched one.
"""

import numpy as np
import pytest

from wholebody.scenarios import get_scenario
from wholebody.scenarios.robust_push import NOMINAL, mismatch_for, nominal_force
from wholebody.sim.simulator import Simulator
from wholebody.sim.true_com import TrueCoM


def test_true_com_is_the_simulated_robots_com(robots):
    robot = robots["talos14"]
    exact = Simulator(robot, record=False)
    com = TrueCoM(exact)
    q, v = exact.state()
    robot.update(q, v)
    np.testing.assert_allclose(com(), robot.com, atol=1e-9)
    assert com.mass == pytest.approx(robot.mass, rel=1e-12)
    # a mismatched twin: same state, different mass distribution -> a different CoM and mass
    params = get_scenario("robust-push").validate(robot)
    wrong = Simulator(robot, mismatch=mismatch_for(params, 0), record=False)
    wrong_com = TrueCoM(wrong)
    assert np.linalg.norm(wrong_com() - robot.com) > 1e-3
    assert abs(wrong_com.mass - robot.mass) > 0.1
    assert mismatch_for(params, 1).torque_delay == 2 and mismatch_for(params, 0).seed == 0


def test_nominal_force_defaults_and_override(robots):
    """The nominal forces were measured on talos14 (exactly those there); on romeo the same
    velocity change: the force times its mass over talos14's; ``--set nominal_force`` as given."""
    talos14, romeo = robots["talos14"], robots["romeo"]
    params = get_scenario("robust-push").resolve({})
    assert nominal_force("pd", "front", params, talos14) == NOMINAL["pd"]["front"] == 190.0
    assert nominal_force("lqr", "back", params, talos14) == 180.0
    assert nominal_force("pd", "front", {**params, "angular_weight": 1e4}, talos14) == 150.0
    assert nominal_force("pd", "front", params, romeo) == pytest.approx(
        190.0 * romeo.mass / talos14.mass, rel=1e-12)
    assert nominal_force("pd", "hip-left", {**params, "nominal_force": 90.0}, romeo) == 90.0
    with pytest.raises(ValueError, match="nominal_force"):
        nominal_force("pd", "hip-left", params, talos14)


def test_push_at_70_percent_survives_a_mismatched_twin(robots, tmp_path):
    """PD, front above the hip, 70 % of the 190 N survived on the exact twin (133 N), on a
    twin with link masses +-10 %, CoM offsets 1 cm, 1 ms torque delay and 1 Nm torque noise.

    One mismatch seed (seed 0). The issue's robustness claim is the full CLI study (5 seeds x 4
    locations): PD survives 20/20 at 70 % (see README for LQR)."""
    robot = robots["talos14"]
    res = get_scenario("robust-push").run(
        robot, "pd", {"locations": "front", "seeds": "1", "duration": "2.8", "start": "0.8",
                      "baseline": "false"},
        out_dir=tmp_path)
    front = res.metrics["per_location"]["front"]
    (run,) = front["runs"]
    assert res.success and run["survived"], run
    assert run["peak_force_N"] == pytest.approx(0.7 * NOMINAL["pd"]["front"])
    assert run["torque_delay_ms"] == pytest.approx(1.0)
    assert abs(run["true_mass_kg"] - robot.mass) > 0.1  # the twin really differs
    # the push moved the true CoG by more than a millimetre, and it came back within 5 mm
    assert 1e-3 < run["max_cog_error_m"] < 0.05 and run["final_cog_error_m"] < 5e-3
    assert run["max_foot_tilt_deg"] < 2.0 and run["max_foot_slip_m"] < 0.01
    # the controller regulates its own estimate; the true CoG sits elsewhere (model mismatch)
    assert run["final_true_vs_reference_m"] > run["final_model_vs_reference_m"]
    assert (tmp_path / "robust_push_front.png").stat().st_size > 10_000
    assert (tmp_path / "robust_push_summary.png").stat().st_size > 10_000


def test_push_far_above_nominal_is_reported_as_a_failure(robots):
    robot = robots["talos14"]
    res = get_scenario("robust-push").run(
        robot, "pd", {"locations": "front", "seeds": "1", "fraction": "2.5", "duration": "1.5",
                      "baseline": "false", "start": "0.5"})
    (run,) = res.metrics["per_location"]["front"]["runs"]
    assert not res.success and not run["survived"] and res.metrics["success_rate"] == 0.0
    assert run["max_foot_tilt_deg"] > 2.0 or run["max_cog_error_m"] > 0.05


def test_trunk_orientation_is_held_on_a_mismatched_twin(robots):
    """Mismatch seed 3 (link CoM offsets 1 cm, masses +-10 %), no push, PD, 2 s: with the
    angular-momentum rows at the paper's single weight 1e4 the posture task has no say in the
    three angular directions and the pelvis drifts (> 5 deg in 2 s, measured 13 deg); with the
    Table 2 default (1e-4) the posture's base rows hold it (measured < 1 deg)."""
    import pinocchio as pin

    from wholebody.control.balance import MomentumBalance
    from wholebody.scenarios.loop import run_closed_loop

    robot = robots["talos14"]
    params = get_scenario("robust-push").validate(robot)
    tilt = {}
    for weight in (1e4, None):
        kw = {} if weight is None else {"angular_weight": weight}
        ctrl = MomentumBalance(robot, gains="pd", **kw)
        sim = Simulator(robot, mismatch=mismatch_for(params, 3), record=False)
        run_closed_loop(sim, ctrl, 2.0)
        q, _ = sim.state()
        R = pin.Quaternion(q[6], q[3], q[4], q[5]).toRotationMatrix()
        tilt[weight] = np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))
    assert tilt[1e4] > 5.0 and tilt[None] < 2.0, tilt
