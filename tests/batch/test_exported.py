"""Exported kernel shapes: the same outputs as the jitted kernel, kept once, rebuilt when unreadable."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from otjax.batch import exported
from otjax.batch.exported import entry_name, export_dir, exported_kernel
from otjax.batch.fields import PackedBuffers
from otjax.curves import scoring
from otjax.curves.engine import CurveEngine
from otjax.curves.triangulation import Triangulation


@functools.partial(jax.jit, static_argnames=("rows", "dtype"))
def small_kernel(x, y, rows, dtype):
    """Row sums of ``x[:rows]`` scaled by ``y``, in ``dtype``."""
    return (x[:rows].sum(1) * y[0]).astype(dtype), jnp.cumsum(x[:rows, 0])


@pytest.fixture
def cache_dir(tmp_path):
    """JAX's compilation cache directory set to a fresh folder for the test."""
    before = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", str(tmp_path))
    yield tmp_path
    jax.config.update("jax_compilation_cache_dir", before)


def _args(seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((16, 3)), rng.standard_normal(2)


def test_the_scoring_kernel_exported_and_read_back_gives_the_same_bits(cache_dir):
    rng = np.random.default_rng(3)
    pts = rng.random((300, 2))
    mass = rng.uniform(0.5, 2.0, 300)
    with jax.enable_x64(True):
        engine = CurveEngine(Triangulation(pts[::2]), pts, mass)
        batch = engine.export(list(range(0, 150, 7)))
        layout = engine.scorer.layout
        rows = scoring.SHAPES.shape_for(batch.need(layout))
        buffers = PackedBuffers(layout.fields, rows)
        buffers.fill(batch.values(pts, mass))
        args = (buffers.floats, buffers.ints)
        static = {"rows": rows, "dtype": np.float64, "edges_per_row": layout.edges_per_row}
        plain = scoring.score_packed(*args, **static)
        first = exported_kernel(scoring.score_packed, static, args)(*args)  # exports the entry
        again = exported_kernel(scoring.score_packed, static, args)(*args)  # reads it back
    assert (export_dir() / entry_name(scoring.score_packed, static)).is_file()
    for out in (first, again):
        assert isinstance(out, scoring.Scores)
        for a, b in zip(jax.tree_util.tree_leaves(plain), jax.tree_util.tree_leaves(out)):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.isfinite(np.asarray(plain.total)).all() and np.asarray(plain.total).any()


def test_an_entry_is_exported_once_then_read(cache_dir, monkeypatch):
    args = _args()
    static = {"rows": 8, "dtype": np.float32}
    exported_kernel(small_kernel, static, args)
    (path,) = export_dir().iterdir()
    stamp = path.stat().st_mtime_ns

    def refuse(*a, **k):
        raise AssertionError("exported again although the entry was readable")

    monkeypatch.setattr(jax.export, "export", refuse)
    out = exported_kernel(small_kernel, static, args)(*args)
    assert path.stat().st_mtime_ns == stamp
    want = small_kernel(*args, **static)
    for a, b in zip(want, out):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.asarray(out[0]).dtype == np.float32


@pytest.mark.parametrize("garbage", [b"", b"\x00" * 3, b"not an export at all, just text"])
def test_an_unreadable_entry_is_exported_again(cache_dir, garbage):
    args = _args(1)
    static = {"rows": 5, "dtype": np.float64}
    path = export_dir() / entry_name(small_kernel, static)
    path.parent.mkdir(parents=True)
    path.write_bytes(garbage)
    with jax.enable_x64(True):
        out = exported_kernel(small_kernel, static, args)(*args)
        want = small_kernel(*args, **static)
    np.testing.assert_array_equal(np.asarray(out[0]), np.asarray(want[0]))
    assert jax.export.deserialize(bytearray(path.read_bytes())) is not None
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temporary file left


def test_without_a_compilation_cache_the_kernel_runs_as_it_is():
    before = jax.config.jax_compilation_cache_dir
    jax.config.update("jax_compilation_cache_dir", None)
    try:
        assert export_dir() is None
        args = _args(2)
        static = {"rows": 4, "dtype": np.float32}
        out = exported_kernel(small_kernel, static, args)(*args)
        want = small_kernel(*args, **static)
    finally:
        jax.config.update("jax_compilation_cache_dir", before)
    np.testing.assert_array_equal(np.asarray(out[1]), np.asarray(want[1]))


def test_entry_names_change_with_static_arguments_and_sources(monkeypatch):
    a = entry_name(small_kernel, {"rows": 4, "dtype": np.float32})
    assert a == entry_name(small_kernel, {"dtype": np.float32, "rows": 4})
    assert a != entry_name(small_kernel, {"rows": 8, "dtype": np.float32})
    assert a != entry_name(small_kernel, {"rows": 4, "dtype": np.float64})
    assert a != entry_name(scoring.score_packed, {"rows": 4, "dtype": np.float32})
    monkeypatch.setattr(exported, "source_digest", lambda: "edited")
    assert a != entry_name(small_kernel, {"rows": 4, "dtype": np.float32})
