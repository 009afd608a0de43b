"""Packed integer keys and index types: each checks its range and falls back
to an exact path or raises, tested at the boundary on abstract shapes (no
array of the boundary's size is ever allocated)."""

import functools

import jax
import jax.extend
import jax.numpy as jnp
import numpy as np
import pytest

from otjax.curves import mass_before
from otjax.validation import MAX_POINTS, check_points

I32 = np.iinfo(np.int32).max
I64 = np.iinfo(np.int64).max


@pytest.mark.parametrize(
    ("num_bins", "n", "x64", "expected"),
    [
        (1, 46340, True, jnp.int32),  # 46340^2 - 1 <= 2^31 - 1
        (1, 46341, False, None),  # 46341^2 - 1 > 2^31 - 1, no int64 without x64
        (1, 46341, True, jnp.int64),
        (2**31 // 2**30, 2**15, True, jnp.int32),  # 2 * 2^30 - 1 = 2^31 - 1 exactly
        (2**21, 2**21, True, jnp.int64),  # 2^63 - 1 exactly
        (2**21, 2**21 + 1, True, None),  # one more point: past int64
        (3_000_000, 3_000_000, True, None),
    ],
)
def test_exact_key_type_at_its_boundaries(num_bins, n, x64, expected):
    assert mass_before.exact_key_type(num_bins, n, x64) == expected
    if expected is not None:
        assert num_bins * n * n - 1 <= np.iinfo(expected).max


def _sorts_in(jaxpr) -> list:
    """The sort equations of a jaxpr, nested calls and branches included."""
    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "sort":
            found.append(eqn)
        for sub in jax.extend.core.jaxprs_in_params(eqn.params):
            found += _sorts_in(sub)
    return found


def _trace(n, num_bins, fn=mass_before.sort_order):
    """The jaxpr of ``fn`` on ``n`` points (abstract: nothing of size ``n`` exists)."""
    args = (jax.ShapeDtypeStruct((n,), jnp.int32), jax.ShapeDtypeStruct((n,), jnp.float64))
    with jax.enable_x64(True):
        return jax.make_jaxpr(functools.partial(fn, num_bins=num_bins))(*args).jaxpr


@pytest.mark.parametrize("n", [2**21 + 1, 3_000_000])
def test_a_key_past_int64_sorts_by_two_keys(n):
    """``num_bins n^2`` past int64: no packed key (it would wrap), one two-key sort."""
    jaxpr = _trace(n, n)
    sorts = _sorts_in(jaxpr)
    assert sorts and all(s.params["num_keys"] == 2 for s in sorts), sorts
    assert all(len(s.invars) == 3 for s in sorts)


def test_a_key_within_int64_stays_packed():
    """At the int64 boundary itself the packed key is used, one operand."""
    sorts = _sorts_in(_trace(2**21, 2**21, mass_before._sort_order_exact))
    assert sorts and all(len(s.invars) == 1 and s.invars[0].aval.dtype == jnp.int64 for s in sorts)


def test_beyond_int32_sizes_is_an_error():
    with pytest.raises(ValueError, match="int32"):
        _trace(I32 + 1, 4)
    with pytest.raises(ValueError, match="int32"):
        _trace(8, I32 + 1)
    assert _sorts_in(_trace(I32, 4))  # 2^31 - 1 points still trace


@pytest.mark.parametrize("force", ["lex", "int32", "int64"])
def test_every_exact_path_sorts_like_a_lexsort(force, monkeypatch, rng):
    """The two-key fallback and the packed keys give the lexsort of ``(edge, t, index)``."""
    n, bins = 300, 7
    edge = rng.integers(0, bins, n)
    t = rng.choice(np.array([-1.5, -0.0, 0.0, 2.5, 5e-324, 1e300]), n)  # ties, signed zeros, a subnormal
    key_type = {"lex": None, "int32": jnp.int32, "int64": jnp.int64}[force]
    monkeypatch.setattr(mass_before, "exact_key_type", lambda *args: key_type)
    with jax.enable_x64(True):
        got = np.asarray(mass_before._sort_order_exact(jnp.asarray(edge, jnp.int32), jnp.asarray(t), bins))
    expected = np.lexsort((np.arange(n), t + 0.0, edge))
    np.testing.assert_array_equal(got, expected)


def test_point_count_beyond_int32_is_refused_before_any_copy():
    # A zero-stride view: 2^31 rows without allocating them.
    huge = np.broadcast_to(np.zeros(2), (MAX_POINTS + 1, 2))
    with pytest.raises(ValueError, match="at most 2147483647 points"):
        check_points(huge)
