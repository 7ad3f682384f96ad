"""Every number of a robot description, and the URDF values the description relies on, is checked
at load: bad input raises DescriptionError naming the field path and the bad value, instead of
loading and failing later (a NaN torque bound gave tau = NaN with status "ok")."""

import copy
import logging
import math
import re
import tomllib
from importlib import resources

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.control.standing import StandingController
from wholebody.robot import check_inertias
from wholebody.robots.description import DescriptionError, RobotDescription
from wholebody.robots.locate import resolve_model_path
from wholebody.robots.torque_limits import TorqueProfile

from conftest import ICUB_RIGHT_LEG_INERTIAS
from conftest import icub_description as icub

NAN, INF = math.nan, math.inf


def preset(name: str) -> dict:
    """A preset's description as a dict (a fresh copy, to patch)."""
    text = (resources.files("wholebody.robots") / "presets" / f"{name}.toml").read_text()
    return tomllib.loads(text)


def patched(name: str, path: tuple, value) -> dict:
    """The preset ``name`` with the entry at ``path`` (keys and list indices) set to ``value``."""
    data = copy.deepcopy(preset(name))
    node = data
    for key in path[:-1]:
        if isinstance(node, dict):
            node = node.setdefault(key, {})
        else:
            node = node[key]
    node[path[-1]] = value
    return data


def raises_naming(data_or_call, *needles):
    """The DescriptionError of loading ``data_or_call``; its message contains every needle."""
    with pytest.raises(DescriptionError) as info:
        if callable(data_or_call):
            data_or_call()
        else:
            RobotDescription.from_dict(data_or_call)
    message = str(info.value)
    for needle in needles:
        assert needle in message, f"{needle!r} not in {message!r}"
    return message


# --------------------------------------------------------------- numbers of the description
HYQ_BAD = [  # (path in the hyq preset, bad value, field path named, value shown)
    (("torque_limits", "scale"), NAN, "torque_limits.scale", "nan"),
    (("torque_limits", "scale"), -0.5, "torque_limits.scale", "-0.5"),
    (("torque_limits", "scale"), 0.0, "torque_limits.scale", "0.0"),
    (("torque_limits", "scale"), INF, "torque_limits.scale", "inf"),
    (("torque_limits", "scale"), "0.9", "torque_limits.scale", "'0.9'"),
    (("torque_limits", "overrides", "lf_haa_joint"), NAN, "torque_limits.overrides.lf_haa_joint",
     "nan"),
    (("torque_limits", "overrides", "lf_haa_joint"), -10.0,
     "torque_limits.overrides.lf_haa_joint", "-10.0"),
    (("torque_limits", "overrides", "lf_haa_joint"), 0, "torque_limits.overrides.lf_haa_joint",
     "0"),
    (("torque_limits", "linkage", "lf_kfe_joint", "force"), NAN,
     "torque_limits.linkage.lf_kfe_joint.force", "nan"),
    (("torque_limits", "linkage", "lf_kfe_joint", "force"), -4000.0,
     "torque_limits.linkage.lf_kfe_joint.force", "-4000.0"),
    (("torque_limits", "linkage", "lf_kfe_joint", "a"), 0.0,
     "torque_limits.linkage.lf_kfe_joint.a", "0.0"),
    (("torque_limits", "linkage", "lf_kfe_joint", "b"), INF,
     "torque_limits.linkage.lf_kfe_joint.b", "inf"),
    (("torque_limits", "linkage", "lf_kfe_joint", "q_peak"), NAN,
     "torque_limits.linkage.lf_kfe_joint.q_peak", "nan"),
    (("torque_limits", "linkage", "lf_kfe_joint", "b"), 0.045,  # = a: the bound is 0/0 at t = 0
     "torque_limits.linkage.lf_kfe_joint", "0.045"),
    (("torque_limits", "linkage", "lf_kfe_joint", "gain"), 2.0,
     "torque_limits.linkage.lf_kfe_joint", "'gain'"),
    (("torque_limits", "linkage", "lf_kfe_joint"), 3.0, "torque_limits.linkage.lf_kfe_joint",
     "3.0"),
    (("torque_limits", "overrides", "lf_kfe_joint"), 100.0,  # has a linkage: would be ignored
     "torque_limits.overrides.lf_kfe_joint", "linkage"),
    (("torque_limits", "gain"), 1.0, "torque_limits", "'gain'"),
    (("friction",), INF, "friction", "inf"),
    (("friction",), NAN, "friction", "nan"),
    (("friction",), 0.0, "friction", "0.0"),
    (("friction",), -0.7, "friction", "-0.7"),
    (("contacts", 2, "radius"), NAN, "contacts[2].radius", "nan"),
    (("contacts", 2, "radius"), -0.02, "contacts[2].radius", "-0.02"),
    (("contacts", 2, "radius"), INF, "contacts[2].radius", "inf"),
    (("contacts", 1, "colour"), "red", "contacts[1]", "'colour'"),
    (("contacts", 1, "half_size"), [0.1, 0.1], "contacts[1]", "'half_size'"),
    (("contacts", 0, "name"), 3, "contacts[0].name", "3"),
    (("armature",), -0.1, "armature", "-0.1"),
    (("armature",), NAN, "armature", "nan"),
    (("armature",), {"lf_haa_joint": 0.1, "lf_kfe_joint": NAN}, "armature.lf_kfe_joint", "nan"),
    (("armature",), {"lf_haa_joint": -0.1}, "armature.lf_haa_joint", "-0.1"),
    (("posture",), {"lf_kfe_joint": NAN}, "posture.lf_kfe_joint", "nan"),
    (("posture",), {"lf_kfe_joint": "bent"}, "posture.lf_kfe_joint", "'bent'"),
    (("locked_joints",), "lf_haa_joint", "locked_joints", "'lf_haa_joint'"),
]


@pytest.mark.parametrize("path,value,field,shown", HYQ_BAD,
                         ids=[f"{f}={v!r}" for _, v, f, _ in HYQ_BAD])
def test_bad_number_is_named(path, value, field, shown):
    raises_naming(patched("hyq", path, value), field, shown)


TALOS_BAD = [
    (("contacts", 0, "half_size"), 0.1, "contacts[0].half_size", "0.1"),
    (("contacts", 0, "half_size"), [0.1], "contacts[0].half_size", "[0.1]"),
    (("contacts", 0, "half_size"), "wide", "contacts[0].half_size", "'wide'"),
    (("contacts", 0, "half_size"), [0.105, NAN], "contacts[0].half_size[1]", "nan"),
    (("contacts", 1, "half_size"), [-0.105, 0.065], "contacts[1].half_size[0]", "-0.105"),
    (("contacts", 1, "half_size"), [0.105, 0.0], "contacts[1].half_size[1]", "0.0"),
    (("contacts", 1, "radius"), 0.02, "contacts[1]", "'radius'"),
    (("contacts", 0, "offset"), [0.0, 0.1], "contacts[0].offset", "[0.0, 0.1]"),
    (("contacts", 0, "offset"), 0.1, "contacts[0].offset", "0.1"),
    (("contacts", 1, "offset"), [0.0, NAN, 0.0], "contacts[1].offset[1]", "nan"),
]


@pytest.mark.parametrize("path,value,field,shown", TALOS_BAD,
                         ids=[f"{f}={v!r}" for _, v, f, _ in TALOS_BAD])
def test_bad_sole_is_named(path, value, field, shown):
    message = raises_naming(patched("talos14", path, value), field, shown)
    if "half_size" in field:
        assert "positive" in message


def test_unknown_contact_key_lists_the_allowed_ones():
    message = raises_naming(patched("hyq", ("contacts", 0, "raduis"), 0.02), "contacts[0]",
                            "'raduis'")
    assert all(f"'{key}'" in message for key in ("name", "frame", "type", "radius"))
    # the same rule as the top level: unknown fields are errors that list the known ones
    message = raises_naming(patched("hyq", ("frictoin",), 0.7), "'frictoin'")
    assert "'friction'" in message


def test_nan_in_a_toml_file_is_named(tmp_path):
    """TOML has nan and inf literals: a robot file with `scale = nan` is refused at load."""
    path = tmp_path / "bad.toml"
    text = (resources.files("wholebody.robots") / "presets" / "hyq.toml").read_text()
    path.write_text(text.replace("[torque_limits.linkage]", "[torque_limits]\nscale = nan\n"
                                 "[torque_limits.linkage]"))
    raises_naming(lambda: RobotDescription.from_toml(path), "torque_limits.scale", "nan")


def test_valid_values_still_load():
    """Edge values that are valid: radius 0, armature 0 and per joint, integer numbers."""
    data = patched("hyq", ("contacts", 0, "radius"), 0)
    data["armature"] = {"lf_haa_joint": 0, "lf_kfe_joint": 0.05}
    data["torque_limits"]["scale"] = 1
    data["torque_limits"]["overrides"] = {"lf_haa_joint": np.float64(120.0)}
    description = RobotDescription.from_dict(data)
    assert description.contacts[0].radius == 0.0
    assert description.torque_limits["overrides"] == {"lf_haa_joint": 120.0}


# --------------------------------------------------------------- defect: NaN torque bound
@pytest.mark.parametrize("path", [("torque_limits", "scale"),
                                  ("torque_limits", "overrides", "lf_haa_joint"),
                                  ("torque_limits", "linkage", "rf_kfe_joint", "force")])
def test_nan_torque_limit_fails_at_load_not_in_the_controller(path):
    """Before: the robot loaded and StandingController.compute returned tau = NaN, status "ok"."""
    data = patched("hyq", path, NAN)

    def load_and_stand():
        robot = wb.load_robot(data)
        result = StandingController(robot).compute(robot.q_ref, np.zeros(robot.nv))
        assert np.all(np.isfinite(result.tau)), (result.status, result.tau)

    raises_naming(load_and_stand, ".".join(str(k) for k in path), "nan")


def test_torque_profile_checks_its_config():
    """TorqueProfile built directly (not through a description) checks the same numbers."""
    names = ("j1", "j2")
    with pytest.raises(DescriptionError, match=re.escape("torque_limits.scale")):
        TorqueProfile(names, np.array([10.0, 10.0]), {"scale": NAN})
    with pytest.raises(DescriptionError, match=re.escape("torque_limits.overrides.j2")):
        TorqueProfile(names, np.array([10.0, 10.0]), {"overrides": {"j2": -1.0}})



def test_torque_profile_linkage_bounds_follow_the_formula_and_the_scale():
    """A linkage profile's bound (Fahmi et al. 2019, eq. 15): force · a · b · |sin t| /
    sqrt(a² + b² − 2ab cos t), t = π/2 + q − q_peak, written here with math's functions, times
    ``scale``; the kept last answer is not reused when only the scale changes."""
    names = ("hip", "knee")
    link = {"a": 0.045, "b": 0.33, "force": 4000.0, "q_peak": 0.3}
    profile = TorqueProfile(names, np.array([50.0, 0.0]), {"linkage": {"knee": link}})
    for q in (-1.2, 0.0, 0.3, 0.9):
        t = math.pi / 2 + q - link["q_peak"]
        a, b = link["a"], link["b"]
        expected = link["force"] * a * b * abs(math.sin(t)) / math.sqrt(
            a * a + b * b - 2 * a * b * math.cos(t))
        for scale in (1.0, 0.5, 1.0):
            profile.scale = scale
            np.testing.assert_allclose(profile.upper(np.array([0.0, q])),
                                       [50.0 * scale, expected * scale], rtol=1e-14)

# --------------------------------------------------------------- names checked against the model
MODEL_BAD = [  # (preset, path, value, needles): each needs the model (one URDF load)
    ("hyq", ("posture",), {"lf_kfe_jiont": -1.5}, ("posture", "'lf_kfe_jiont'")),
    ("hyq", ("posture",), {"root_joint": 1.0}, ("posture", "'root_joint'")),
    ("hyq", ("posture",), {"lf_kfe_joint": 3.0}, ("posture.lf_kfe_joint", "3.0", "limits")),
    ("hyq", ("armature",), {"lf_kfe_jiont": 0.1}, ("armature.lf_kfe_jiont",)),
    ("hyq", ("locked_joints",), ["lf_kfe_jiont"], ("locked_joints", "'lf_kfe_jiont'")),
    ("hyq", ("locked_joints",), ["root_joint"], ("locked_joints", "'root_joint'")),
    ("hyq", ("torque_limits", "overrides", "lf_kfe_jiont"), 10.0,
     ("torque_limits.overrides", "'lf_kfe_jiont'")),
    ("hyq", ("torque_limits", "linkage", "lf_haa_jiont"),
     {"a": 0.045, "b": 0.33, "force": 4000.0, "q_peak": 0.0},
     ("torque_limits.linkage", "'lf_haa_jiont'")),
    ("hyq", ("contacts", 1, "frame"), "rf_fooot", ("contacts[1].frame", "'rf_fooot'")),
    ("talos14", ("armature",), {"head_1_joint": 0.1}, ("armature.head_1_joint", "locked")),
]


@pytest.mark.parametrize("name,path,value,needles", MODEL_BAD,
                         ids=[f"{n}:{'.'.join(map(str, p))}" for n, p, _, _ in MODEL_BAD])
def test_bad_name_is_named_at_load(name, path, value, needles):
    data = patched(name, path, value)
    raises_naming(lambda: wb.load_robot(data), *needles)


# --------------------------------------------------------------- the URDF's numbers
def hyq_with_effort(tmp_path, joint: str, effort: str):
    """A copy of HyQ's URDF with the effort limit of ``joint`` replaced by ``effort``."""
    urdf = resolve_model_path(preset("hyq")["urdf"]).read_text()
    start = urdf.index(f'<joint name="{joint}"')
    end = urdf.index("</joint>", start)
    element = re.sub(r'effort="[^"]*"', f'effort="{effort}"', urdf[start:end])
    path = tmp_path / "hyq.urdf"
    path.write_text(urdf[:start] + element + urdf[end:])
    data = preset("hyq")
    data["urdf"] = str(path)
    return data


def test_zero_urdf_effort_limit_names_joint_and_fix(tmp_path):
    data = hyq_with_effort(tmp_path, "lf_haa_joint", "0")
    raises_naming(lambda: wb.load_robot(data), "'lf_haa_joint'", "0.0", "torque_limits.overrides")
    data["torque_limits"]["overrides"] = {"lf_haa_joint": 120.0}  # the fix the message gives
    robot = wb.load_robot(data)
    assert robot.torque_bounds()[1][robot.joint_names.index("lf_haa_joint")] == 120.0


@pytest.mark.parametrize("effort", [0.0, -5.0, NAN, INF])
def test_bad_urdf_effort_limit_is_named(effort):
    limits = np.array([40.0, effort, 40.0])
    raises_naming(lambda: TorqueProfile(("haa", "hfe", "kfe"), limits), "'hfe'", repr(effort),
                  "torque_limits.overrides")
    # a linkage profile replaces the URDF constant: no error
    TorqueProfile(("haa", "hfe", "kfe"), limits,
                  {"linkage": {"hfe": {"a": 0.045, "b": 0.33, "force": 4000.0, "q_peak": 0.0}}})


def test_placeholder_effort_limit_warns(caplog):
    """Solo12's URDF says 1000 Nm for a 2.5 kg robot: loads, with a warning naming the joints."""
    data = {"name": "solo12", "urdf": "erd:solo_description/robots/solo12.urdf", "posture": {},
            "contacts": [{"name": leg, "frame": f"{leg}_FOOT", "type": "point", "radius": 0.0}
                         for leg in ("FL", "FR", "HL", "HR")]}
    with caplog.at_level(logging.WARNING, logger="wholebody.robot"):
        robot = wb.load_robot(data)
    assert robot.na == 12
    text = " ".join(r.getMessage() for r in caplog.records if r.levelno == logging.WARNING)
    assert "FL_HAA" in text and "1000" in text and "torque_limits.overrides" in text


def test_icub_zero_inertia_is_named():
    """iCub's URDF gives the right hip link mass but zero rotational inertia."""
    data = {"name": "icub", "urdf": "erd:icub_description/robots/icub_reduced.urdf",
            "posture": {},
            "contacts": [{"name": side, "frame": f"{side}_sole", "type": "rectangle",
                          "half_size": [0.1, 0.05]} for side in ("l", "r")]}
    raises_naming(lambda: wb.load_robot(data), "'r_hip_1'", "'r_hip_pitch'", "positive definite")


@pytest.fixture(scope="module")
def hyq_model():
    urdf = resolve_model_path(preset("hyq")["urdf"])
    return pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer())


@pytest.mark.parametrize("mass,lever,inertia,needle", [
    (-1.0, 0.0, np.eye(3) * 0.01, "-1.0"),
    (NAN, 0.0, np.eye(3) * 0.01, "nan"),
    (1.5, NAN, np.eye(3) * 0.01, "non-finite"),
    (1.5, 0.0, np.zeros((3, 3)), "positive definite"),
    (1.5, 0.0, np.diag([0.01, 0.01, -0.01]), "positive definite"),
])
def test_bad_body_inertia_is_named(hyq_model, mass, lever, inertia, needle):
    model = pin.Model(hyq_model)
    body = pin.Inertia(1.0, np.zeros(3), np.eye(3))  # Pinocchio's constructor refuses bad values
    body.mass, body.lever, body.inertia = mass, np.full(3, lever), inertia
    model.inertias[model.getJointId("lf_kfe_joint")] = body
    raises_naming(lambda: check_inertias(model, "robot 'x'"), "'lf_lowerleg'", "'lf_kfe_joint'",
                  needle)


def test_massless_moving_body_is_named(hyq_model):
    """A joint's body with neither mass nor inertia cannot move in the MuJoCo twin (MuJoCo refuses
    it at compile time): refused at load, naming the link and the joint."""
    model = pin.Model(hyq_model)
    model.inertias[model.getJointId("lf_kfe_joint")] = pin.Inertia.Zero()
    raises_naming(lambda: check_inertias(model, "robot 'x'"), "'lf_lowerleg'", "'lf_kfe_joint'",
                  "no mass", "locked_joints")


def test_human_massless_ball_joint_links_are_named():
    """human_description splits each ball joint into three revolutes whose first two links have
    no mass: the load names the first one instead of the twin failing with a MuJoCo traceback."""
    data = {"name": "human", "urdf": "erd:human_description/robots/human.urdf", "posture": {},
            "contacts": [{"name": side, "frame": f"{side}_foot", "type": "rectangle",
                          "half_size": [0.1, 0.04]} for side in ("left", "right")]}
    raises_naming(lambda: wb.load_robot(data), "'left_hip_Z'", "no mass")


def test_robot_without_joints_is_refused():
    """A drone (hector's quadrotor: a floating base and nothing else) is not a legged robot."""
    data = {"name": "drone", "urdf": "erd:hector_description/robots/quadrotor_base.urdf",
            "posture": {}, "contacts": [{"name": "c", "frame": "base_link", "type": "point",
                                         "radius": 0.0}]}
    raises_naming(lambda: wb.load_robot(data), "robot 'drone'", "no joints besides the floating "
                  "base", "not a legged robot")


def test_contact_on_the_floating_base_is_refused():
    """A contact must be a foot or a sole: a frame of the base body cannot be lifted or placed."""
    data = copy.deepcopy(preset("hyq"))
    data["contacts"][3]["frame"] = "base_link"
    raises_naming(lambda: wb.load_robot(data), "contacts[3].frame = 'base_link'",
                  "on the floating base")


def test_a_file_that_is_not_urdf_names_the_field():
    """Cassie ships as SDF only: the error names the field 'urdf' and the file, no traceback."""
    data = {"name": "cassie", "urdf": "erd:cassie_description/robots/cassie_v2.sdf",
            "posture": {}, "contacts": [{"name": "l", "frame": "left_toe", "type": "point",
                                         "radius": 0.0}]}
    raises_naming(lambda: wb.load_robot(data), "field 'urdf'", "cassie_v2.sdf",
                  "only URDF and MJCF files")


@pytest.mark.parametrize("name", ["talos14", "talos", "hyq", "go1", "go2", "a1", "solo12"])
def test_presets_pass_every_check_without_warning(name, caplog):
    with caplog.at_level(logging.WARNING, logger="wholebody.robot"):
        robot = wb.load_robot(name)
    assert not [r for r in caplog.records if r.levelno >= logging.WARNING]
    check_inertias(robot.model, name)


def test_posture_overrides_change_only_their_joints():
    """An SRDF state plus a few joints: the SRDF's angles (read here from the SRDF file) except
    the overridden ones."""
    import xml.etree.ElementTree as ET

    from wholebody.robots import preset_description
    from wholebody.robots.locate import resolve_model_path

    d = preset_description("hyq")
    srdf = ET.parse(resolve_model_path(d.srdf, d.base_dir)).getroot()
    state = next(s for s in srdf.iter("group_state") if s.get("name") == "standing")
    srdf_angles = {j.get("name"): float(j.get("value")) for j in state.iter("joint")
                   if j.get("name") != "root_joint"}
    data = {"name": "hyq-tall", "urdf": d.urdf, "srdf": d.srdf, "posture": "standing",
            "posture_overrides": {"lf_kfe_joint": -1.2, "rf_kfe_joint": -1.2},
            "contacts": [{"name": c.name, "frame": c.frame, "type": c.type, "radius": c.radius}
                         for c in d.contacts]}
    robot = wb.load_robot(data)
    angles = dict(zip(robot.joint_names, robot.q_ref[7:]))
    for joint, value in srdf_angles.items():
        expected = -1.2 if joint in ("lf_kfe_joint", "rf_kfe_joint") else value
        assert angles[joint] == pytest.approx(expected, abs=1e-12), joint
    with pytest.raises(DescriptionError, match="posture_overrides.*unknown joint 'knee'"):
        wb.load_robot({**data, "posture_overrides": {"knee": 0.0}})
    with pytest.raises(DescriptionError, match="posture_overrides.lf_kfe_joint = 1.0 is outside"):
        wb.load_robot({**data, "posture_overrides": {"lf_kfe_joint": 1.0}})
    with pytest.raises(DescriptionError, match="posture_overrides.lf_kfe_joint"):
        wb.load_robot({**data, "posture_overrides": {"lf_kfe_joint": float("nan")}})


# ------------------------------------------------------------------ inertia_overrides
def test_zero_inertias_are_listed_together_with_the_field_that_fixes_them():
    with pytest.raises(DescriptionError) as err:
        wb.load_robot(icub())
    message = str(err.value)
    assert all(f"'{link}'" in message or f"{link} = [" in message for link in ICUB_RIGHT_LEG_INERTIAS)
    assert "inertia_overrides = {" in message


def test_inertia_overrides_replace_the_links_inertia():
    """iCub's right leg gets the left leg's moments: the Pinocchio body of each joint has those
    principal moments (rotation-invariant eigenvalues), its mass and centre of mass are the URDF's,
    and the MuJoCo twin built from it has the same total mass."""
    from wholebody.sim.simulator import Simulator

    robot = wb.load_robot(icub(inertia_overrides=ICUB_RIGHT_LEG_INERTIAS))
    reference = pin.buildModelFromUrdf(str(resolve_model_path(
        "erd:icub_description/robots/icub_reduced.urdf")), pin.JointModelFreeFlyer())
    for link, moments in ICUB_RIGHT_LEG_INERTIAS.items():
        fid = robot.model.getFrameId(link)
        jid = robot.model.frames[fid].parentJoint
        body = robot.model.inertias[jid]
        np.testing.assert_allclose(np.linalg.eigvalsh(body.inertia), sorted(moments), rtol=1e-9)
        ref = reference.inertias[reference.getJointId(robot.model.names[jid])]
        assert body.mass == pytest.approx(ref.mass)
        np.testing.assert_allclose(body.lever, ref.lever, atol=1e-12)
    sim = Simulator(robot)
    assert sum(sim.model.body_mass) == pytest.approx(robot.mass, rel=1e-9)


@pytest.mark.parametrize("value,shown", [
    ({"r_hip_1": [0.001, -0.001, 0.001]}, "inertia_overrides.r_hip_1[1]"),
    ({"r_hip_1": [0.001, float("nan"), 0.001]}, "inertia_overrides.r_hip_1[1]"),
    ({"r_hip_1": [0.001, 0.001]}, "inertia_overrides.r_hip_1: expected three principal moments"),
    ({"r_hip_1": 0.001}, "inertia_overrides.r_hip_1: expected three principal moments"),
    ({"r_hip_1": [0.001, 0.001, 0.01]}, "is no rigid body's inertia"),
    ({"no_such_link": [0.001, 0.001, 0.001]}, "inertia_overrides.no_such_link: not a link"),
])
def test_bad_inertia_overrides_are_named(value, shown):
    with pytest.raises(DescriptionError, match=re.escape(shown)):
        wb.load_robot(icub(inertia_overrides={**ICUB_RIGHT_LEG_INERTIAS, **value}))


def test_a_group_state_outside_the_joint_limits_is_named():
    """example-robot-data's simple_humanoid: its SRDF half_sitting puts several joints outside the
    URDF's limits (found here from the files with Pinocchio alone); the error names each of them
    and posture_overrides, which makes it load."""
    description = {"name": "simple",
                   "urdf": "erd:simple_humanoid_description/urdf/simple_humanoid.urdf",
                   "srdf": "erd:simple_humanoid_description/srdf/simple_humanoid.srdf",
                   "posture": "half_sitting",
                   "contacts": [{"name": f"{s}_sole", "frame": f"{s[0]}_ankle", "type": "rectangle",
                                 "half_size": [0.12, 0.07]} for s in ("left", "right")]}
    model = pin.buildModelFromUrdf(str(resolve_model_path(description["urdf"])))
    pin.loadReferenceConfigurations(model, str(resolve_model_path(description["srdf"])), False)
    q = model.referenceConfigurations["half_sitting"]
    outside = {name: float(np.clip(q[j.idx_q], model.lowerPositionLimit[j.idx_q],
                                   model.upperPositionLimit[j.idx_q]))
               for name, j in zip(model.names[1:], model.joints[1:])
               if not model.lowerPositionLimit[j.idx_q] <= q[j.idx_q]
               <= model.upperPositionLimit[j.idx_q]}
    assert outside
    with pytest.raises(DescriptionError) as err:
        wb.load_robot(description)
    assert "posture_overrides" in str(err.value)
    assert all(f"'{name}' at" in str(err.value) for name in outside)
    robot = wb.load_robot({**description, "posture_overrides": outside})
    assert robot.na == model.nv


@pytest.mark.parametrize("path,value", [
    (("name",), "../../../../x"), (("name",), "$\\nocommand$"), (("name",), "<!--<script>"),
    (("name",), ".hidden"), (("name",), "a/b"), (("contacts", 0, "name"), "left$sole$"),
    (("contacts", 1, "name"), "../right"),
])
def test_names_that_are_not_names_are_refused(path, value):
    """A robot's or a contact's name becomes a folder, figure text and page text: a path, math
    markup or HTML in it is refused at load, the field and the value named."""
    field = ".".join(str(p) for p in path).replace(".0.", "[0].").replace(".1.", "[1].")
    raises_naming(patched("talos14", path, value), field, repr(value), "is not a name")


def test_ordinary_names_load():
    for name in ("talos14", "g1 with arms", "b1-z1", "anymal_c (arm)", "robot.v2"):
        RobotDescription.from_dict(patched("talos14", ("name",), name))


@pytest.mark.parametrize("config,needles", [
    ({"scale": 1e308}, ("'j1'", "inf", "scale 1e+308")),
    ({"linkage": {"j2": {"a": 1e200, "b": 2e200, "force": 1e-100, "q_peak": -1.5}}},
     ("'j2'", "nan")),
    ({"overrides": {"j1": 1e9}}, ("'j1'", "1000000000.0")),
])
def test_derived_torque_limits_are_checked_by_value(config, needles):
    """Numbers each fine alone that multiply out to bounds no joint has (infinite, NaN, beyond
    1e5 N m) are refused at load, naming the joint; the bounds themselves are
    evaluated here over the joint's whole turn."""
    with pytest.raises(DescriptionError) as info:
        TorqueProfile(("j1", "j2"), np.array([10.0, 10.0]), config)
    for needle in needles:
        assert needle in str(info.value), str(info.value)
    a, b, force, q_peak = 0.1, 0.2, 3000.0, 0.5  # a plausible linkage loads
    profile = TorqueProfile(("j1", "j2"), np.array([10.0, 10.0]),
                            {"linkage": {"j2": {"a": a, "b": b, "force": force,
                                                "q_peak": q_peak}}})
    q = np.linspace(-3.0, 3.0, 7)
    t = q + np.pi / 2 - q_peak
    expected = force * a * b * np.abs(np.sin(t)) / np.sqrt(a * a + b * b - 2 * a * b * np.cos(t))
    np.testing.assert_allclose([profile.upper(np.array([0.0, x]))[1] for x in q], expected)


def test_a_contact_larger_than_its_leg_is_refused():
    """A foot of 1e6 m radius stood the robot 1000 km tall (and its thresholds scaled with it)."""
    raises_naming(lambda: wb.load_robot(patched("hyq", ("contacts", 0, "radius"), 1e6)),
                  "contacts[0].radius", "1000000.0", "larger than")
    raises_naming(lambda: wb.load_robot(patched("talos14", ("contacts", 1, "half_size"),
                                                [5.0, 0.1])), "contacts[1].half_size",
                  "larger than")
