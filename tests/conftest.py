import numpy as np
import pytest

import wholebody as wb

PRESETS = ("talos14", "talos", "hyq")


@pytest.fixture(scope="session")
def robots():
    """Each preset loaded once per test session."""
    return {name: wb.load_robot(name) for name in PRESETS}


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
