"""Shape policy, the kernel pipeline with a tiny jitted kernel, x64 guard."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.batch.fields import Dims, Field, FieldSpec, Prefix
from otjax.batch.pipeline import Handle, KernelPipeline, ShapePolicy, pipelined, require_x64

SPEC = FieldSpec([
    Field("x", "float", Dims()),
    Field("group", "int", Dims(), pad=lambda r: r - 1),  # padding rows: the last group
    Field("valid", "bool", Dims()),
])
POLICY = ShapePolicy(8, 32)


@functools.partial(jax.jit, static_argnames=("rows", "dtype"))
def kernel(floats, ints, rows, dtype):
    """Sum of the valid rows' ``x`` per group, and in all (in ``dtype``)."""
    f = SPEC.unpack(floats, ints, rows)
    x = jnp.where(f["valid"], f["x"], 0).astype(dtype)
    return jax.ops.segment_sum(x, f["group"], num_segments=rows), jnp.sum(x)


def batch(n, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    group = rng.integers(0, 3, n)
    return {"x": x, "group": group, "valid": Prefix(n, 1)}, x, group


def expected(x, group, r):
    per = np.zeros(r)
    np.add.at(per, group, x)
    return per, x.sum()


@settings(max_examples=200, deadline=None)
@given(need=st.integers(0, 1000), min_rows=st.sampled_from([1, 8, 4096]), factor=st.sampled_from([1, 2, 8]),
       tiny=st.sampled_from([0, 1, 2]))
def test_shape_for_few_shapes_up_to_the_budget_then_the_need(need, min_rows, factor, tiny):
    policy = ShapePolicy(min_rows, min_rows * factor, min_rows // 4 * tiny // 2)
    r = policy.shape_for(need)
    assert r >= need
    if need <= policy.budget:
        small = [s for s in (policy.tiny_rows, policy.min_rows) if s > 0]
        assert r == next((s for s in small if need <= s), policy.budget)
    else:
        assert r == need
    assert policy.shape_for(need + 1) >= r  # monotone


def test_dispatch_and_wait_score_each_batch_at_its_shape():
    pipe = KernelPipeline(SPEC, kernel, POLICY)
    for n, need in [(5, 5), (8, 8), (9, 9), (30, 30), (3, 3), (40, 40), (20, 60)]:
        values, x, group = batch(n, seed=n)
        h = pipe.dispatch(values, need)
        assert isinstance(h, Handle) and h.buffers.r == POLICY.shape_for(need)
        per, total = pipe.wait(h)
        want_per, want_total = expected(x, group, h.buffers.r)
        np.testing.assert_allclose(per, want_per, rtol=1e-14, atol=1e-14)
        assert total == pytest.approx(want_total, rel=1e-14, abs=1e-14)
        assert per.dtype == np.float64
    assert pipe.calls == 7
    assert pipe.shapes_seen == {8, 32, 40, 60}


def test_buffers_are_reused_once_their_call_was_waited_for():
    pipe = KernelPipeline(SPEC, kernel, POLICY)
    big, xb, gb = batch(30, seed=1)
    small, xs, gs = batch(2, seed=2)
    h1 = pipe.dispatch(big, 30)
    h2 = pipe.dispatch(small, 20)  # same shape, h1 still in flight: other buffers
    assert h2.buffers is not h1.buffers and h2.buffers.r == h1.buffers.r == 32
    out1, out2 = pipe.wait(h1), pipe.wait(h2)
    h3 = pipe.dispatch(small, 2)  # another shape: other buffers
    assert h3.buffers.r == 8 and h3.buffers not in (h1.buffers, h2.buffers)
    pipe.wait(h3)
    # A waited-for call's buffers serve the next call of their shape; what
    # the larger batch left in them is reset.
    h4 = pipe.dispatch(small, 20)
    assert h4.buffers in (h1.buffers, h2.buffers)
    h5 = pipe.dispatch(small, 20)
    assert {id(h4.buffers), id(h5.buffers)} == {id(h1.buffers), id(h2.buffers)}
    out4, out5 = pipe.wait(h4), pipe.wait(h5)
    for per, total in (out2, out4, out5):
        want_per, want_total = expected(xs, gs, 32)
        np.testing.assert_allclose(per, want_per, rtol=1e-14, atol=1e-14)
        assert total == pytest.approx(want_total)
    np.testing.assert_allclose(out1[0], expected(xb, gb, 32)[0], rtol=1e-14, atol=1e-14)
    assert pipe.calls == 5 and pipe.shapes_seen == {8, 32}


def test_the_dtype_is_an_argument_of_every_call():
    pipe = KernelPipeline(SPEC, kernel, POLICY, dtype=jnp.float32)
    values, x, group = batch(6)
    per, total = pipe.wait(pipe.dispatch(values, 6))
    assert per.dtype == np.float32 and total.dtype == np.float32
    np.testing.assert_allclose(per, expected(x, group, 8)[0], rtol=1e-6, atol=1e-6)


def test_require_x64_raises_outside_x64_mode():
    require_x64("this")  # the suite runs in x64
    with jax.enable_x64(False):
        with pytest.raises(RuntimeError, match="this needs JAX's float64 mode"):
            require_x64("this")
        pipe = KernelPipeline(SPEC, kernel, POLICY)
        with pytest.raises(RuntimeError, match="float64"):
            pipe.dispatch(batch(4)[0], 4)
        assert pipe.calls == 0 and pipe.shapes_seen == set()
    require_x64("this")


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 12), in_flight=st.integers(0, 4), waiting=st.booleans())
def test_pipelined_keeps_in_flight_calls_ahead_and_settles_each_once_in_order(n, in_flight, waiting):
    events = []

    def produce():
        for i in range(n):
            events.append(("make", i))
            yield i

    pipelined(produce(), lambda b: events.append(("dispatch", b)) or f"h{b}",
              lambda b, h: events.append(("settle", b, h)),
              in_flight=in_flight, while_waiting=(lambda: events.append(("wait",))) if waiting else None)
    settled = [e[1] for e in events if e[0] == "settle"]
    assert settled == list(range(n))
    assert all(e[2] == f"h{e[1]}" for e in events if e[0] == "settle")
    pos = {e: i for i, e in enumerate(events)}
    for i in range(n):
        # Built lazily: batch i is made after batch i - 1 was dispatched.
        assert i == 0 or pos[("make", i)] > pos[("dispatch", i - 1)]
        # Settled once in_flight later batches were dispatched (or at the end).
        later = min(i + in_flight, n - 1)
        assert pos[("settle", i, f"h{i}")] > pos[("dispatch", later)]
        if i + in_flight + 1 < n:
            assert pos[("settle", i, f"h{i}")] < pos[("dispatch", i + in_flight + 1)]
    if waiting:
        w = pos[("wait",)]
        assert all(pos[("dispatch", i)] < w for i in range(n))
        assert sum(1 for e in events[w:] if e[0] == "settle") == min(n, in_flight)
