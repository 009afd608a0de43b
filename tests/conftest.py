"""Shared test configuration: float64 everywhere, CPU only, seeded RNG."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

# The oracle comparisons are at 1e-9 relative: they need float64 kernels.
jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng():
    return np.random.default_rng(20111)
