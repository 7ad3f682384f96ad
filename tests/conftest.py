import os
import shutil
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest

import wholebody as wb

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import fuzz  # noqa: E402  (the fuzz harness's state and plan samplers)

PRESETS = ("talos14", "talos", "hyq", "anymal_c", "romeo")


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


@pytest.fixture
def plan_for():
    """``plan_near(robot, rng, stance, swing_noise=, normal=)`` of benchmarks/fuzz.py: a PassiveWBC
    plan near the robot's cached state, for tests that build such plans."""
    return fuzz.plan_near
