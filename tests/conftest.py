"""Shared test configuration: float64 everywhere, CPU only, seeded RNG."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
# The command line keeps compiled kernels in ~/.cache by default; in-process
# CLI tests must not switch that on for the whole test session (JAX's setting
# is global). tests/test_cli.py checks the cache in subprocesses.
os.environ["OTJAX_COMPILE_CACHE"] = "off"

import jax
import numpy as np
import pytest

# The oracle comparisons are at 1e-9 relative: they need float64 kernels.
jax.config.update("jax_enable_x64", True)


@pytest.fixture
def rng():
    return np.random.default_rng(20111)
