"""Scenarios of Fahmi et al. 2019 Sect. V-A to V-D on HyQ in the MuJoCo twin: friction mismatch,
weak joint, joint limit with swing slacks, regularisation schemes.

Every closed-loop assertion uses the simulator's measurements (its state, the torques it received and
applied, its contact forces), not the controller's own numbers. Runs are short (a few seconds); the
full experiments are the CLI scenarios.
"""

import numpy as np
import pytest

from wholebody.control.passive import relative_slack_weight
from wholebody.robot import FREE_FLYER_NQ
from wholebody.scenarios.friction_mismatch import crawl_run
from wholebody.scenarios.gait_measures import (intervals, outcome, settled_stance, slip_events,
                                               stance_phases)
from wholebody.scenarios.joint_limit import controller_joint_limits, limit_run, swing_tracking
from wholebody.scenarios.regularization import grf_measures, regularization_run
from wholebody.scenarios.weak_joint import leg_load, stance_posture, weak_joint_runs

LH_HFE = "lh_hfe_joint"


@pytest.fixture(scope="module")
def hyq(robots):
    return robots["hyq"]


# ---------------------------------------------------------------------- helpers (no simulation)
def test_slip_events_threshold_duration_and_impact_skip():
    t = np.arange(0.0, 1.0, 0.004)
    stance = np.ones((len(t), 2), dtype=bool)
    stance[:25, 1] = False  # leg 1 touches down at 0.1 s
    speed = np.zeros((len(t), 2))
    speed[2:4, 0] = 1.0  # inside the 20 ms impact window of leg 0: ignored
    speed[50:54, 0] = 0.05  # 16 ms above threshold: too short
    speed[100:110, 0] = 0.05  # 40 ms: one event
    speed[200:210, 0] = 0.01  # below the threshold
    speed[30:40, 1] = 0.03  # 20 ms after leg 1's touchdown, 40 ms long: one event
    log = {"t": t, "stance": stance, "contact_speed": speed}
    events = slip_events(log, slip_speed=0.02, slip_time=0.02)
    assert [(e["leg"], round(e["duration_s"], 3)) for e in events] == [(0, 0.04), (1, 0.04)]
    assert events[1]["start_after_touchdown_s"] == pytest.approx(0.02, abs=1e-9)
    assert [p[0] for p in stance_phases(t, stance)] == [0, 1]


def test_intervals_settled_stance_and_outcome():
    t = np.arange(10) * 0.25
    flags = np.array([0, 1, 1, 0, 0, 1, 1, 1, 0, 0], dtype=bool)
    assert intervals(t, flags) == [(0.25, 0.75), (1.25, 2.0)]
    stance = np.stack([~flags, np.ones(10, dtype=bool)], axis=1)
    settled = settled_stance(t, stance, skip=0.25)  # the first sample of each stance dropped
    assert np.flatnonzero(settled[:, 0]).tolist() == [4, 9]
    assert np.flatnonzero(settled[:, 1]).tolist() == list(range(1, 10))

    class Run:
        fell, failures, distance, fell_at = False, np.int64(2), 0.5, None
    assert outcome(Run) == {"fell": False, "failed_cycles": 2, "distance_m": 0.5}

    class Fallen:
        fell, failures, distance, fell_at = True, 0, 0.1, 1.5
    assert outcome(Fallen) == {"fell": True, "failed_cycles": 0, "distance_m": 0.1,
                               "fell_at_s": 1.5}


def test_controller_joint_limits_touch_only_the_controller_side(hyq):
    i = hyq.joint_names.index(LH_HFE)
    q_min, model_lo = hyq.q_min.copy(), hyq.model.lowerPositionLimit.copy()
    with controller_joint_limits(hyq, LH_HFE, lower=-0.85) as (lo, hi):
        assert lo == -0.85 and hyq.q_min[i] == -0.85 and hi == hyq.q_max[i]
        np.testing.assert_array_equal(hyq.model.lowerPositionLimit, model_lo)
    np.testing.assert_array_equal(hyq.q_min, q_min)
    with pytest.raises(ValueError):
        with controller_joint_limits(hyq, "no_such_joint", lower=0.0):
            pass


# ---------------------------------------------------------------------- Sect. V-B friction
def test_stance_task_bounds_slip_on_a_slippery_floor(hyq):
    """Floor mu 0.4, WBC mu 1.0: with the stance task the robot keeps crawling and slips a bounded
    distance per stance; without it the feet run away and the robot falls (Sect. V-B)."""
    with_task = crawl_run(hyq, 0.4, 1.0, 0.11, 3.5, K_st=200.0, D_st=30.0)
    without = crawl_run(hyq, 0.4, 1.0, 0.11, 3.5, K_st=0.0, D_st=0.0)
    assert len(slip_events(with_task.log)) > 0  # the floor is slippery for this controller
    assert not with_task.fell and with_task.failures == 0
    slip = with_task.stance_slip().max()
    assert slip < 0.25
    assert without.fell or without.stance_slip().max() > 2 * slip


def test_corrected_mu_removes_slip_events(hyq):
    """With the WBC's pyramid inside the floor's cone (mu 0.4/sqrt(2)) no slip event occurs up to
    0.16 m/s; the pyramid with mu = 0.4 itself (corners at 0.57) still slips."""
    inscribed = crawl_run(hyq, 0.4, 0.4 / np.sqrt(2.0), 0.16, 4.0, K_st=200.0, D_st=30.0)
    same = crawl_run(hyq, 0.4, 0.4, 0.16, 4.0, K_st=200.0, D_st=30.0)
    assert not inscribed.fell and inscribed.failures == 0
    assert inscribed.distance > 0.3
    assert slip_events(inscribed.log) == []
    assert inscribed.stance_slip().max() < 0.005
    assert len(slip_events(same.log)) > 0


def test_force_parallel_regularizer_keeps_the_plain_pyramid_from_slipping(hyq):
    """mu corrected to the floor's 0.4 with the plain pyramid: the paper's regulariser pushes a
    lightly loaded foot to a pyramid corner (|f_t| up to sqrt(2) mu f_n) and it slips; leaning
    every force like the desired net force keeps each foot at the net force's friction ratio: no
    slip event (the twin's measured contact-point speeds)."""
    paper = crawl_run(hyq, 0.4, 0.4, 0.11, 4.0, K_st=200.0, D_st=30.0)
    parallel = crawl_run(hyq, 0.4, 0.4, 0.11, 4.0, K_st=200.0, D_st=30.0,
                         regularization="force-parallel")
    assert len(slip_events(paper.log)) > 0
    assert not parallel.fell and parallel.failures == 0 and parallel.distance > 0.2
    assert slip_events(parallel.log) == []
    assert parallel.stance_slip().max() < 0.005


# ---------------------------------------------------------------------- Sect. V-C weak joint
def test_weak_knee_limit_holds_and_the_hip_takes_the_load(hyq):
    """LF-KFE limited to 60 Nm in the WBC (nominal stance peak > 100 Nm): the twin never receives
    more than 60 Nm on it, HFE carries more, trunk tracking is unchanged."""
    runs = weak_joint_runs(hyq, "lf_kfe_joint", [60.0], 0.11, 4.0)
    nom, weak = runs["nominal"], runs["limit 60 Nm"]
    k = hyq.joint_names.index("lf_kfe_joint")
    sent_nom = np.abs(np.asarray(nom.sim.log.tau_applied)[:, k]).max()
    sent = np.abs(np.asarray(weak.sim.log.tau_command)[:, k]).max()
    applied = np.abs(np.asarray(weak.sim.log.tau_applied)[:, k]).max()
    assert sent_nom > 80.0  # the limit is active
    assert sent <= 60.0 + 1e-6 and applied <= 60.0 + 1e-6
    assert weak.post_solve_clips == 0 and weak.sim_saturation_max == 0.0
    assert not weak.fell and weak.failures == 0
    joints = ["lf_haa_joint", "lf_hfe_joint", "lf_kfe_joint"]
    load_n = leg_load(nom, hyq, joints, "lf_foot")["mean_abs_tau_Nm"]
    load_w = leg_load(weak, hyq, joints, "lf_foot")["mean_abs_tau_Nm"]
    assert load_w["lf_hfe_joint"] > load_n["lf_hfe_joint"] + 5.0
    assert load_w["lf_kfe_joint"] < load_n["lf_kfe_joint"]
    tn, tw = nom.tracking(1.0), weak.tracking(1.0)
    assert tw["linear_rms_m"] < tn["linear_rms_m"] + 0.002
    assert tw["angular_rms_rad"] < tn["angular_rms_rad"] + 0.002


def test_weak_knee_at_26_nm_walks_in_the_taller_stance_and_falls_in_the_standing_posture(hyq):
    """The paper's 26 Nm: from the knee_flexion 0.8 stance the crawl walks with the knee at the
    limit and the hip taking the load; from the standing posture (static LP: 43 Nm needed) the
    limit still holds but the robot falls."""
    k = hyq.joint_names.index("lf_kfe_joint")
    joints = ["lf_haa_joint", "lf_hfe_joint", "lf_kfe_joint"]
    tall = weak_joint_runs(hyq, "lf_kfe_joint", [26.0], 0.11, 5.0, q0=stance_posture(hyq, 0.8))
    nom, weak = tall["nominal"], tall["limit 26 Nm"]
    for r in (nom, weak):
        assert not r.fell and r.failures == 0 and r.distance > 0.3
    assert np.abs(np.asarray(weak.sim.log.tau_applied)[:, k]).max() <= 26.0 + 1e-6
    assert np.abs(np.asarray(nom.sim.log.tau_applied)[:, k]).max() > 52.0
    assert weak.post_solve_clips == 0 and weak.sim_saturation_max == 0.0
    load_n = leg_load(nom, hyq, joints, "lf_foot")["mean_abs_tau_Nm"]
    load_w = leg_load(weak, hyq, joints, "lf_foot")["mean_abs_tau_Nm"]
    assert load_w["lf_hfe_joint"] > load_n["lf_hfe_joint"] + 10.0
    assert load_w["lf_haa_joint"] > load_n["lf_haa_joint"]
    tn, tw = nom.tracking(1.0), weak.tracking(1.0)
    assert tw["linear_rms_m"] < tn["linear_rms_m"] + 0.005
    assert tw["angular_rms_rad"] < tn["angular_rms_rad"] + 0.005
    srdf = weak_joint_runs(hyq, "lf_kfe_joint", [26.0], 0.11, 5.0)["limit 26 Nm"]
    assert np.abs(np.asarray(srdf.sim.log.tau_applied)[:, k]).max() <= 26.0 + 1e-6
    assert srdf.fell


# ---------------------------------------------------------------------- Sect. V-A joint limit
@pytest.fixture(scope="module")
def joint_limit_runs(hyq):
    """LH-HFE lower limit raised to -0.85 rad in the WBC (the crawl's swing reaches -0.96), the
    joint-limit scenario's default slack ratio 1e-4 to the trunk task; 4.2 s covers two LH
    swings."""
    alpha = relative_slack_weight(hyq, 1e-4)
    return {name: limit_run(hyq, LH_HFE, lim, None, mode, 0.11, 4.2, slack_weight=alpha)
            for name, lim, mode in (("nominal", None, "per-direction"),
                                    ("per-direction", -0.85, "per-direction"))}


def test_raised_joint_limit_clamps_the_joint_in_the_twin(hyq, joint_limit_runs):
    r = joint_limit_runs["per-direction"]
    i = FREE_FLYER_NQ + hyq.joint_names.index(LH_HFE)
    q_nom = np.asarray(joint_limit_runs["nominal"].sim.log.q)[:, i]
    q = np.asarray(r.sim.log.q)[:, i]
    assert q_nom.min() < -0.9  # without the change the swing goes beyond -0.85
    assert q.min() > -0.85 - 0.02  # eq. 18 stops the joint at the controller's limit ...
    assert np.sum(np.abs(q + 0.85) < 0.01) > 100  # ... and it stays there (> 0.1 s)
    lo, _ = r.sim.model.jnt_range[r.sim.model.joint(LH_HFE).id]
    assert lo == pytest.approx(hyq.q_min[hyq.joint_names.index(LH_HFE)])  # twin: real limit
    assert not r.fell and r.failures == 0  # the slack absorbed the conflict


def test_per_direction_slack_keeps_the_lateral_foot_error_small(joint_limit_runs):
    leg = 2  # lh_foot
    nom = np.asarray(swing_tracking(joint_limit_runs["nominal"], leg)["rms_m"])
    pd = np.asarray(swing_tracking(joint_limit_runs["per-direction"], leg)["rms_m"])
    inc = pd - nom
    assert inc[0] > 2e-3 and inc[2] > 2e-3  # X and Z suffer (HFE acts in the sagittal plane)
    assert inc[1] < 0.6 * min(inc[0], inc[2])  # Y much less


def test_the_foot_not_the_trunk_absorbs_the_joint_limit(joint_limit_runs):
    """At the default slack ratio the trunk's orientation error barely changes (Fig. 2)."""
    nom = joint_limit_runs["nominal"].tracking(1.0)
    pd = joint_limit_runs["per-direction"].tracking(1.0)
    assert pd["angular_rms_rad"] < nom["angular_rms_rad"] + 0.005
    assert pd["angular_max_rad"] < 0.03


# ---------------------------------------------------------------------- Sect. V-D regularisation
def test_knee_weight_tilts_the_grfs_and_unloads_the_knees(hyq):
    params = {"gait": "stand", "speed": 0.0, "duration": 1.0}
    kfe = np.array([j.endswith("kfe_joint") for j in hyq.joint_names])
    normal = grf_measures(regularization_run(hyq, "force-normal", None, params), hyq, 0.3)
    light = grf_measures(regularization_run(hyq, "torque", np.where(kfe, 1e-4, 1e-4), params),
                         hyq, 0.3)
    heavy = grf_measures(regularization_run(hyq, "torque", np.where(kfe, 1.0, 1e-4), params),
                         hyq, 0.3)
    assert heavy["grf_angle_from_vertical_deg"] > light["grf_angle_from_vertical_deg"] + 3.0
    assert heavy["mean_abs_tau_kfe_Nm"] < 0.8 * light["mean_abs_tau_kfe_Nm"]
    assert heavy["grf_angle_to_knee_deg"] < light["grf_angle_to_knee_deg"]
    assert normal["grf_angle_from_vertical_deg"] <= heavy["grf_angle_from_vertical_deg"]
