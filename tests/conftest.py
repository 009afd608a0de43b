"""Shared test configuration: float64 everywhere, CPU only, seeded RNG."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax
import numpy as np
import pytest

# The oracle comparisons are at 1e-9 relative: they need float64 kernels.
jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng():
    return np.random.default_rng(20111)
