"""Shared test configuration: float64 everywhere, CPU only, seeded RNG."""

import os
import tempfile
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
# One persistent compilation cache for the whole session: the xdist workers,
# the notebook kernels and the CLI subprocesses inherit it through the
# environment (JAX reads these variables at import), so a kernel shape is
# compiled by one process and loaded by the others. Compiling dominates many
# small tests; the executables are the same, so are the results.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(Path(tempfile.gettempdir()) / "otjax-tests-compile-cache"))
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")
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
