import numpy as np
import pytest

import tbd_taichi


@pytest.fixture(scope="session", autouse=True)
def taichi_cpu():
    """One CPU runtime for the whole session (tests that restart it restore it)."""
    return tbd_taichi.init("cpu")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
