"""Field layouts and packed buffers against a plain NumPy oracle (no JAX)."""

import copy
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.batch.fields import Dims, Field, FieldSpec, Gather, PackedBuffers, Prefix, aligned_zeros

rows = Dims()
rows2 = Dims(tail=(2,))
quarter3 = Dims(4, tail=(3,))
six_by_quarter = Dims(4, head=(6,))


# A module-level pad function: a spec made of it can be pickled.
def last_quarter(r):
    return r // 4 - 1


SPEC = FieldSpec([
    Field("xy", "float", rows2),
    Field("w", "float", rows, pad=np.inf),
    Field("job", "int", rows, pad=last_quarter),
    Field("ok", "bool", rows),
    Field("tri", "float", six_by_quarter),
    Field("ears", "int", quarter3, pad=-1),
    Field("seen", "bool", quarter3),
])
CAPACITIES = (4, 8, 16)


def oracle(spec, values: dict, r: int) -> tuple[dict, np.ndarray, np.ndarray]:
    """Fresh padded arrays holding ``values`` (plain arrays, the filled axis
    first), and the two buffers they pack to, in field order per kind."""
    full = {}
    for f in spec.fields:
        dtype = np.float64 if f.kind == "float" else np.int64
        pad = f.pad(r) if callable(f.pad) else f.pad
        a = np.full(f.dims(r), pad, dtype)
        if f.name in values:
            v = np.asarray(values[f.name])
            np.moveaxis(a, f.axis, 0)[:len(v)] = v
        full[f.name] = a if f.kind != "bool" else a != 0
    floats = np.concatenate([full[f.name].ravel() for f in spec.fields if f.kind == "float"])
    ints = np.concatenate([full[f.name].astype(np.int32).ravel() for f in spec.fields if f.kind != "float"])
    return full, floats, ints


def plain(value):
    """The array a field value stands for."""
    if isinstance(value, Gather):
        return np.take(value.source, value.index, axis=0)
    return value


@st.composite
def batches(draw, r):
    """A batch at capacity ``r``: some fields, each a prefix of its axis,
    given as an array, a Gather or a Prefix."""
    out = {}
    for f in SPEC.fields:
        if not draw(st.booleans()):
            continue
        shape = f.dims(r)
        whole = np.moveaxis(np.zeros(shape), f.axis, 0).shape
        n = draw(st.integers(0, whole[0]))
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        row = whole[1:]
        if f.kind == "float":
            data = rng.standard_normal((n, *row))
        elif f.kind == "int":
            data = rng.integers(-5, 50, (n, *row))
        else:
            data = rng.random((n, *row)) < 0.5
        form = draw(st.sampled_from(["array", "gather", "prefix"]))
        if form == "gather":
            # Rows of a larger source, in any order.
            source = np.concatenate([data, data[:3]])
            index = rng.permutation(len(source))[:n]
            source[index] = data
            out[f.name] = Gather(source, index)
        elif form == "prefix":
            value = data.flat[0] if n else 1
            out[f.name] = Prefix(n, value)
        else:
            out[f.name] = data
    return out


def as_plain(values, r):
    out = {}
    for name, v in values.items():
        if isinstance(v, Prefix):
            f = next(f for f in SPEC.fields if f.name == name)
            row = np.moveaxis(np.zeros(f.dims(r)), f.axis, 0).shape[1:]
            out[name] = np.full((v.n, *row), v.value)
        else:
            out[name] = plain(v)
    return out


def test_layout_places_each_kind_end_to_end_in_field_order():
    places, (n_float, n_int) = SPEC.layout(16)
    assert SPEC.layout(16)[0] is places  # cached per capacity
    offset = {True: 0, False: 0}
    for f in SPEC.fields:
        p = places[f.name]
        assert p.is_float == (f.kind == "float")
        assert p.shape == f.dims(16) and p.offset == offset[p.is_float]
        offset[p.is_float] += int(np.prod(p.shape))
    assert (n_float, n_int) == (offset[True], offset[False]) == (16 * 2 + 16 + 6 * 4, 16 + 16 + 4 * 3 + 4 * 3)


@pytest.mark.parametrize("r", CAPACITIES)
def test_unpack_reads_back_what_the_oracle_packed(r):
    rng = np.random.default_rng(r)
    values = {"xy": rng.standard_normal((r - 1, 2)), "job": rng.integers(0, 9, 2), "ok": rng.random(r) < 0.5,
              "tri": rng.standard_normal((1, 6)), "ears": rng.integers(0, 9, (r // 4, 3))}
    full, floats, ints = oracle(SPEC, values, r)
    got = SPEC.unpack(floats, ints, r)
    assert list(got) == [f.name for f in SPEC.fields]
    for name, want in full.items():
        kind = next(f.kind for f in SPEC.fields if f.name == name)
        assert got[name].dtype == {"float": np.float64, "int": np.int32, "bool": np.bool_}[kind], name
        np.testing.assert_array_equal(got[name], want, err_msg=name)
    # And through PackedBuffers.fill.
    buf = PackedBuffers(SPEC, r)
    buf.fill(values)
    np.testing.assert_array_equal(buf.floats, floats)
    np.testing.assert_array_equal(buf.ints, ints)
    assert buf.floats.dtype == np.float64 and buf.ints.dtype == np.int32


@settings(max_examples=150, deadline=None)
@given(data=st.data(), r=st.sampled_from(CAPACITIES), n_batches=st.integers(1, 6))
def test_refilled_buffers_equal_fresh_ones_filled_with_the_last_batch(data, r, n_batches):
    reused = PackedBuffers(SPEC, r)
    for _ in range(n_batches):
        values = data.draw(batches(r))
        reused.fill(values)
        fresh = PackedBuffers(SPEC, r)
        fresh.fill(values)
        _, floats, ints = oracle(SPEC, as_plain(values, r), r)
        np.testing.assert_array_equal(fresh.floats, floats)
        np.testing.assert_array_equal(fresh.ints, ints)
        np.testing.assert_array_equal(reused.floats, fresh.floats)
        np.testing.assert_array_equal(reused.ints, fresh.ints)


def test_a_value_longer_than_its_field_is_refused():
    buf = PackedBuffers(SPEC, 8)
    with pytest.raises(ValueError, match="field xy: 9 entries, capacity 8"):
        buf.fill({"xy": np.zeros((9, 2))})
    with pytest.raises(ValueError, match="field tri: 3 entries, capacity 2"):
        buf.fill({"tri": Gather(np.zeros((5, 6)), np.arange(3))})
    with pytest.raises(ValueError, match="capacity"):
        buf.fill({"ok": Prefix(9, 1)})


def test_specs_refuse_duplicate_names_and_unknown_kinds():
    with pytest.raises(ValueError, match="distinct"):
        FieldSpec([Field("a", "float", rows), Field("a", "int", rows)])
    with pytest.raises(ValueError, match="kind must be one of"):
        FieldSpec([Field("a", "complex", rows)])


@pytest.mark.parametrize("n", [0, 1, 3, 17, 1000])
@pytest.mark.parametrize("dtype", [np.float64, np.int32, np.uint8])
def test_aligned_zeros(n, dtype):
    a = aligned_zeros(n, dtype)
    assert a.shape == (n,) and a.dtype == dtype and not a.any()
    if n:  # (an empty view's data pointer is not its offset: nothing to align)
        assert a.ctypes.data % 64 == 0


def test_fresh_buffers_are_aligned_and_hold_the_padding():
    buf = PackedBuffers(SPEC, 16)
    assert buf.floats.ctypes.data % 64 == 0 and buf.ints.ctypes.data % 64 == 0
    _, floats, ints = oracle(SPEC, {}, 16)
    np.testing.assert_array_equal(buf.floats, floats)
    np.testing.assert_array_equal(buf.ints, ints)


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copy_is_a_fresh_set_whose_views_are_its_own(how):
    buf = PackedBuffers(SPEC, 8)
    buf.fill({"xy": np.ones((5, 2)), "job": np.arange(3), "tri": np.ones((2, 6))})
    twin = copy.deepcopy(buf) if how == "deepcopy" else pickle.loads(pickle.dumps(buf))
    assert twin.r == 8 and twin.floats is not buf.floats
    for name, view in twin.views.items():
        assert np.shares_memory(view, twin.floats) or np.shares_memory(view, twin.ints), name
        assert not np.shares_memory(view, buf.floats) and not np.shares_memory(view, buf.ints), name
    fresh = PackedBuffers(SPEC, 8)
    np.testing.assert_array_equal(twin.floats, fresh.floats)
    np.testing.assert_array_equal(twin.ints, fresh.ints)
    # Filling the copy fills the copy.
    twin.fill({"xy": np.full((2, 2), 7.0)})
    assert twin.floats[:4].tolist() == [7.0] * 4 and buf.floats[:4].tolist() == [1.0] * 4
