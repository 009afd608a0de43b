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


# The suite's slowest files, slowest first (measured with --durations on a
# 2-core CPU, cold compile cache). The workers (``-n 2 --dist loadfile``) take
# whole files in collection order, so these start first and the many quick
# files fill in behind them; started last, one of them would run on one
# worker while the other sits idle.
SLOW_FILES = (
    "tests/curves/test_reconstruct.py",
    "tests/curves/test_reconstruct_clean_star.py",
    "tests/test_bench.py",
    "tests/notebooks/test_gradient_relocation.py",
    "tests/curves/test_reconstruct_junctions.py",
    "tests/curves/test_reconstruct_star.py",
    "tests/test_cli.py",
    "tests/notebooks/test_reconstruction_gallery.py",
    "tests/curves/test_rescoring.py",
    "tests/notebooks/test_batched_collapse_scoring.py",
    "tests/notebooks/test_surface_reconstruction.py",
    "tests/curves/test_reconstruct_skyline.py",
    "tests/curves/test_refinement.py",
    "tests/lp/test_batched.py",
    "tests/curves/test_filtering.py",
    "tests/surfaces/test_features.py",
    "tests/notebooks/test_feature_recovery.py",
    "tests/surfaces/test_initial_complex.py",
    "tests/surfaces/test_collapse_scoring.py",
    "tests/curves/test_scoring.py",
    "tests/curves/test_reconstruct_outliers.py",
    "tests/test_cli_surfaces.py",
    "tests/curves/test_triangulation.py",
    "tests/surfaces/test_engine.py",
    "tests/fuzz/test_api3d.py",
    "tests/surfaces/test_reconstruct.py",
    "tests/curves/test_decimate.py",
)


def pytest_configure(config):
    # xdist otherwise sorts the files by their number of tests, which puts the
    # slowest ones (a notebook is one test) last; keep the order below.
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False


def pytest_collection_modifyitems(config, items):
    rank = {path: i for i, path in enumerate(SLOW_FILES)}
    root = config.rootpath
    # sorted() is stable: the other files keep their order, after these.
    items[:] = sorted(items, key=lambda item: rank.get(item.path.relative_to(root).as_posix(), len(rank)))
