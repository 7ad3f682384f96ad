import os
import shutil
import sysconfig
from types import SimpleNamespace

import numpy as np
import pinocchio as pin
import pytest

import wholebody as wb
from wholebody.planning.trunk import TrunkState

PRESETS = ("talos14", "talos", "hyq")


@pytest.fixture(scope="session")
def robots():
    """Each preset loaded once per test session."""
    return {name: wb.load_robot(name) for name in PRESETS}


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def native_cycle_or_skip(module: str = "_passive_cycle"):
    """Import a compiled part of wholebody (``_passive_cycle``, ``_cascade``). Skip only where it
    cannot have been built (no C++ compiler on this machine, or WHOLEBODY_NO_NATIVE set at
    install); anywhere else a missing extension is a broken build and fails the test."""
    import importlib
    try:
        return importlib.import_module(f"wholebody.{module}")
    except ImportError:
        compiler = (sysconfig.get_config_var("CXX") or "c++").split()[0]
        if os.environ.get("WHOLEBODY_NO_NATIVE") or shutil.which(compiler) is None:
            pytest.skip(f"wholebody.{module} not built here (no C++ compiler '{compiler}' or "
                        "WHOLEBODY_NO_NATIVE set)", allow_module_level=True)
        raise


def pytest_collection_modifyitems(config, items):
    """Every test under tests/closed_loop/ runs the MuJoCo twin for seconds: marked slow, so the
    fast subset is ``pytest -m "not slow"``."""
    for item in items:
        if "closed_loop" in item.path.parts:
            item.add_marker(pytest.mark.slow)


def passive_plan(robot, rng, stance, *, swing_noise=(0.02, 0.1, 0.5), normal=(0.0, 0.0, 1.0)):
    """A plan for PassiveWBC at the robot's cached state: the trunk reference near the current
    trunk, swing targets near the current feet (position, velocity and acceleration drawn with the
    standard deviations ``swing_noise``), touchdown where the feet are, on ground of ``normal``."""
    legs = robot.contact_names
    feet = np.array([robot.data.oMf[robot.contact(n).frame_id].translation for n in legs])
    R = pin.Quaternion(robot.q[3:7]).normalized().toRotationMatrix()
    trunk = TrunkState(position=robot.com + rng.normal(scale=0.01, size=3),
                       velocity=rng.normal(scale=0.05, size=3),
                       acceleration=rng.normal(scale=0.2, size=3),
                       rotation=R @ pin.exp3(rng.normal(scale=0.02, size=3)),
                       angular_velocity=rng.normal(scale=0.05, size=3))
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    position, velocity, acceleration = swing_noise
    return SimpleNamespace(legs=legs, contact=np.array(stance, dtype=bool),
                           foot_position=feet + rng.normal(scale=position, size=feet.shape),
                           foot_velocity=rng.normal(scale=velocity, size=feet.shape),
                           foot_acceleration=rng.normal(scale=acceleration, size=feet.shape),
                           touchdown_position=feet.copy(),
                           touchdown_normal=np.tile(n, (len(legs), 1)), trunk=trunk)


@pytest.fixture
def plan_for():
    """:func:`passive_plan`, for tests that build PassiveWBC plans."""
    return passive_plan
