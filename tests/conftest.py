import os

import numpy as np
import pytest

import tbd_taichi

# The backend the kernels run on in tests: CPU unless TBD_TAICHI_TEST_ARCH names a GPU
# backend (e.g. ``TBD_TAICHI_TEST_ARCH=cuda pytest -q`` on a GPU machine).
TEST_ARCH = os.environ.get("TBD_TAICHI_TEST_ARCH", "cpu")


@pytest.fixture(scope="session", autouse=True)
def taichi_runtime():
    """One runtime for the whole session (tests that restart it restore it)."""
    return tbd_taichi.init(TEST_ARCH)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
