"""Robot presets, descriptions and the per-cycle cache, checked against independent Pinocchio
algorithms (RNEA) and finite differences."""

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.robots.description import DescriptionError, RobotDescription

EXPECTED = {  # name: (actuated DoF, contact type, number of contacts)
    "talos14": (14, "rectangle", 2),
    "talos": (32, "rectangle", 2),
    "hyq": (12, "point", 4),
}


@pytest.mark.parametrize("name", list(EXPECTED))
def test_preset_shape(robots, name):
    robot = robots[name]
    dof, kind, ncontacts = EXPECTED[name]
    assert robot.na == dof and robot.nv == dof + 6 and robot.nq == dof + 7
    assert len(robot.contacts) == ncontacts
    assert all(c.spec.type == kind for c in robot.contacts)
    assert robot.mass > 50
    lo, hi = robot.torque_bounds()
    assert np.all(hi > 0) and np.all(lo == -hi)
    assert np.all(robot.q_min < robot.q_max) and np.all(robot.v_max > 0)


def test_talos14_is_talos_with_locked_upper_body(robots):
    """Locking joints keeps the mass and the legs; the locked joints sit at half_sitting."""
    t14, t32 = robots["talos14"], robots["talos"]
    assert t14.mass == pytest.approx(t32.mass, rel=1e-12)
    assert t14.joint_names == t32.joint_names[:14]
    # same standing CoM: arms locked exactly where the full model's posture puts them
    t14.update(t14.q_ref, np.zeros(t14.nv))
    t32.update(t32.q_ref, np.zeros(t32.nv))
    np.testing.assert_allclose(t14.com, t32.com, atol=1e-12)


@pytest.mark.parametrize("name", list(EXPECTED))
def test_reference_posture_rests_on_ground(robots, name):
    robot = robots[name]
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_ref)
    lowest = [robot.contact_lowest_point(c, data.oMf[c.frame_id])[2] for c in robot.contacts]
    assert min(lowest) == pytest.approx(0.0, abs=1e-12)
    assert max(lowest) < 1e-3  # every foot within 1 mm of the ground
    for c in robot.contacts:
        if c.spec.type == "rectangle":  # half_sitting soles are flat to 0.1 degree
            assert np.degrees(np.arccos(data.oMf[c.frame_id].rotation[2, 2])) < 0.2


@pytest.mark.parametrize("name", list(EXPECTED))
def test_update_dynamics_match_rnea(robots, name, rng):
    """M qdd + h from the cache equals RNEA(q, v, qdd), an independent algorithm."""
    robot = robots[name]
    data = robot.model.createData()
    for _ in range(3):
        q, v = robot.random_state(rng)
        a = rng.normal(size=robot.nv)
        robot.update(q, v)
        np.testing.assert_allclose(robot.M, robot.M.T, atol=0)
        expected = pin.rnea(robot.model, data, q, v, a)
        np.testing.assert_allclose(robot.M @ a + robot.h, expected, rtol=1e-10, atol=1e-8)


def _moving(robot, q, v, eps):
    """States at t = -eps, +eps along the trajectory with constant v (zero acceleration)."""
    return (pin.integrate(robot.model, q, -eps * v), pin.integrate(robot.model, q, eps * v))


def _contact_offset(robot, name) -> np.ndarray:
    """World offset from the contact frame to the contact point at the cached state (a sphere's
    bottom for point feet with a radius, zero for sole frames)."""
    c = robot.contact(name)
    return (np.array([0.0, 0.0, -c.spec.radius]) if c.dim == 3 else np.zeros(3))


def _material_point_velocity(robot, name, offset_local) -> np.ndarray:
    """Velocity [linear(; angular)] of the point fixed in the contact frame at ``offset_local``."""
    c = robot.contact(name)
    twist = robot.frame_velocity(c.frame)
    R = robot.data.oMf[c.frame_id].rotation
    out = twist.copy()
    out[:3] += np.cross(twist[3:], R @ offset_local)
    return out[:c.dim]


@pytest.mark.parametrize("name", list(EXPECTED))
def test_drifts_match_finite_differences(robots, name, rng):
    """Contact drifts J̇v, CoM drift and Ȧ_G v are the time derivatives, at zero acceleration, of the
    contact-point velocity (the material point under a foot sphere, the sole frame), CoM velocity
    and centroidal momentum (central differences)."""
    robot = robots[name]
    eps = 1e-6
    q, v = robot.random_state(rng, velocity_scale=0.5)
    robot.update(q, v)
    drifts = {n: robot.contact_drifts[n].copy() for n in robot.contact_names}
    local = {n: robot.data.oMf[robot.contact(n).frame_id].rotation.T @ _contact_offset(robot, n)
             for n in robot.contact_names}
    for n in robot.contact_names:  # the Jacobian maps v to that point's velocity
        np.testing.assert_allclose(robot.contact_jacobians[n] @ v,
                                   _material_point_velocity(robot, n, local[n]), atol=1e-10)
    com_drift, agdv, J_com = robot.com_drift.copy(), robot.A_G_dot_v.copy(), robot.J_com.copy()
    samples = []
    for qs in _moving(robot, q, v, eps):
        robot.update(qs, v)
        samples.append(({n: _material_point_velocity(robot, n, local[n])
                         for n in robot.contact_names}, robot.vcom.copy(), robot.h_G.copy()))
    (vel0, vcom0, hg0), (vel1, vcom1, hg1) = samples
    for n in robot.contact_names:
        fd = (vel1[n] - vel0[n]) / (2 * eps)
        np.testing.assert_allclose(drifts[n], fd, rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(com_drift, (vcom1 - vcom0) / (2 * eps), rtol=1e-4, atol=1e-4)
    np.testing.assert_allclose(agdv, (hg1 - hg0) / (2 * eps), rtol=1e-4, atol=1e-3)
    robot.update(q, v)
    np.testing.assert_allclose(J_com @ v, robot.vcom, atol=1e-10)
    np.testing.assert_allclose(robot.A_G[:3] @ v, robot.mass * robot.vcom, atol=1e-9)


def test_frame_cache_is_per_cycle(robots, rng):
    robot = robots["hyq"]
    q, v = robot.random_state(rng)
    robot.update(q, v)
    J1 = robot.frame_jacobian("lf_foot")
    assert robot.frame_jacobian("lf_foot") is J1  # second request in the cycle: cached
    q2, v2 = robot.random_state(rng)
    robot.update(q2, v2)
    J2 = robot.frame_jacobian("lf_foot")
    assert J2 is not J1 and not np.allclose(J1, J2)
    r = robot.contact("lf_foot").spec.radius  # the contact point is r below the frame origin
    expected = J2[:3] + np.cross(J2[3:].T, np.array([0.0, 0.0, -r])).T
    np.testing.assert_allclose(robot.contact_jacobians["lf_foot"], expected, atol=1e-12)


@pytest.mark.parametrize("field,bad", [("q", "size"), ("q", "nan"), ("v", "size"), ("v", "inf")])
def test_update_rejects_bad_state(robots, field, bad):
    robot = robots["hyq"]
    q, v = robot.q_ref.copy(), np.zeros(robot.nv)
    arr = q if field == "q" else v
    if bad == "size":
        arr = arr[:-1]
    else:
        arr[-1] = np.nan if bad == "nan" else np.inf
    args = (arr, v) if field == "q" else (q, arr)
    with pytest.raises(ValueError, match=rf"^{field}:"):
        robot.update(*args)


def test_unknown_frame_is_named(robots):
    with pytest.raises(ValueError, match="no_such_frame"):
        robots["hyq"].frame_jacobian("no_such_frame")


def test_hyq_linkage_torque_profile(robots):
    """HFE/KFE bounds depend on the joint angle (Fahmi et al. 2019, eq. 15); HAA keeps the URDF value."""
    robot = robots["hyq"]
    names = robot.joint_names
    kfe, haa = names.index("lf_kfe_joint"), names.index("lf_haa_joint")
    q = robot.q_ref.copy()
    hi_peak = robot.torque_bounds(q)[1]
    a, b, force = 0.045, 0.33, 4000.0  # the preset's linkage parameters
    assert hi_peak[kfe] == pytest.approx(force * a * b / np.hypot(a, b), rel=1e-12)
    q[7 + kfe] = robot.q_max[kfe]
    hi_bent = robot.torque_bounds(q)[1]
    assert hi_bent[kfe] < 0.9 * hi_peak[kfe]
    assert hi_bent[haa] == hi_peak[haa] == 150.0


HYQ_DICT = {
    "name": "myhyq",
    "urdf": "erd:hyq_description/robots/hyq_no_sensors.urdf",
    "srdf": "erd:hyq_description/srdf/hyq.srdf",
    "posture": "standing",
    "contacts": [{"name": f"{leg}_foot", "frame": f"{leg}_foot", "type": "point", "radius": 0.02}
                 for leg in ("lf", "rf", "lh", "rh")],
    "torque_limits": {"overrides": {"lf_kfe_joint": 26.0}},
}


def test_robot_from_dict_and_toml(tmp_path):
    robot = wb.load_robot(HYQ_DICT)
    assert robot.name == "myhyq" and robot.na == 12
    assert robot.torque_bounds()[1][robot.joint_names.index("lf_kfe_joint")] == 26.0
    path = tmp_path / "solo.toml"
    path.write_text(
        'name = "mytalos"\nurdf = "erd:talos_data/robots/talos_reduced.urdf"\n'
        'srdf = "erd:talos_data/srdf/talos.srdf"\nposture = "half_sitting"\n'
        'locked_joints = ["head_1_joint", "head_2_joint"]\n'
        '[[contacts]]\nname = "l"\nframe = "left_sole_link"\ntype = "rectangle"\n'
        'half_size = [0.1, 0.05]\n')
    robot = wb.load_robot(str(path))
    assert robot.name == "mytalos" and robot.na == 30


@pytest.mark.parametrize("missing", ["name", "urdf", "posture", "contacts"])
def test_missing_field_is_named(missing):
    data = {k: v for k, v in HYQ_DICT.items() if k != missing}
    with pytest.raises(DescriptionError, match=f"'{missing}'"):
        RobotDescription.from_dict(data)


@pytest.mark.parametrize("patch,needle", [
    ({"contacts": [{"name": "a", "frame": "lf_foot", "type": "point"}]}, "contacts[0].radius"),
    ({"contacts": [{"name": "a", "frame": "lf_foot", "type": "disc", "radius": 1}]}, "contacts[0].type"),
    ({"posture": "flying"}, "posture"),
    ({"locked_joints": ["no_joint"]}, "locked_joints"),
    ({"contacts": [{"name": "a", "frame": "nowhere", "type": "point", "radius": 0.0}]}, "nowhere"),
    ({"torque_limits": {"overrides": {"no_joint": 1.0}}}, "torque_limits.overrides"),
    ({"colour": "red"}, "colour"),
])
def test_bad_description_is_named(patch, needle):
    with pytest.raises(ValueError, match=__import__("re").escape(needle)):
        wb.load_robot({**HYQ_DICT, **patch})


def test_unknown_preset_lists_presets():
    with pytest.raises(ValueError, match="a1, anymal_c, go1, go2, hyq, romeo, solo12, talos, talos14"):
        wb.load_robot("atlas")
