"""The momentum-based W_ext observer (Fahmi et al. 2019 eq. 4): converges to a known external
wrench, and in closed loop in the twin it estimates a push it is not told about and removes the
trunk offset the push causes."""

import numpy as np
import pytest

from wholebody.control.observer import GRAVITY, MomentumObserver
from wholebody.scenarios.locomotion import run_gait
from wholebody.sim.disturbance import Push


def test_observer_converges_to_the_external_wrench_of_known_centroidal_dynamics(rng):
    """h_G integrated from ḣ = W_c + W_g + W_ext with random commanded W_c and a constant unknown
    W_ext: the residual follows W_ext with the rate K_O, and it is zero without W_ext."""
    mass, dt, gain = 30.0, 0.004, 10.0
    w_ext = np.array([40.0, -25.0, 10.0, 3.0, -2.0, 1.0])
    for external in (w_ext, np.zeros(6)):
        observer = MomentumObserver(gain=gain)
        h = rng.normal(size=6)
        observer.update(h, np.zeros(6), mass, dt)  # anchors h_G(t0)
        errors = []
        for _ in range(500):  # 2 s = 20 time constants
            w_c = rng.normal(scale=50.0, size=6)
            w_c[2] += mass * GRAVITY
            h = h + dt * (w_c + np.r_[0, 0, -mass * GRAVITY, 0, 0, 0] + external)
            errors.append(np.abs(observer.update(h, w_c, mass, dt) - external).max())
        assert errors[-1] < 1e-6 * max(1.0, np.abs(external).max())
        if external.any():  # after one time constant, 1 - e^-1 of the way (discrete: 1 - 0.96^25)
            assert errors[24] == pytest.approx((1 - gain * dt) ** 25 * np.abs(external).max(),
                                               rel=1e-6)


@pytest.mark.slow  # closed loop in the twin
def test_observer_rejects_a_constant_push_on_hyq_in_the_twin(robots):
    """A constant 80 N lateral push on the trunk for 2 s while HyQ stands: with the observer the
    estimate finds the push (the controller is not told about it) and the CoM offset that the
    trunk impedance (K_x = 2000 N/m, i.e. ~4 cm) would leave is removed."""
    robot = robots["hyq"]
    push_force = 80.0
    results = {}
    for use in (False, True):
        log = {"t": [], "estimate": [], "com_error": []}

        def on_cycle(t, result, ctrl, sim):
            if not log["t"]:
                sim.add_push(Push(frame="base_link", direction=(0.0, 1.0, 0.0),
                                  peak_force=push_force, start=1.0, duration=2.0,
                                  profile="constant"))
            log["t"].append(t)
            log["estimate"].append(ctrl.impedance.external_wrench.copy())
            log["com_error"].append(ctrl.impedance.last_errors[:3].copy())

        run = run_gait(robot, "passive", "stand", duration=3.0,
                       controller_options={"observer": MomentumObserver(gain=10.0) if use else None},
                       on_cycle=on_cycle)
        assert not run.fell
        t = np.array(log["t"])
        late = (t > 2.5) & (t < 3.0)
        results[use] = (np.array(log["estimate"])[late].mean(axis=0),
                        np.abs(np.array(log["com_error"])[late, 1]).mean())
    estimate, offset_with = results[True]
    _, offset_without = results[False]
    assert estimate[1] == pytest.approx(push_force, rel=0.1)
    assert abs(estimate[0]) < 5.0 and abs(estimate[2]) < 5.0
    assert offset_without == pytest.approx(push_force / 2000.0, rel=0.3)  # K_x = 2000 N/m
    assert offset_with < 0.1 * offset_without
