"""Where a uniformly sampled interval ends, estimated from its samples."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.uniform_ends import uniform_end


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(2, 30), st.floats(-5, 5), st.floats(1e-3, 1e3))
def test_uniform_end_is_unbiased_where_the_largest_sample_falls_short(seed, k, start, length):
    # 4000 draws of k uniform samples of [start, start + length]: the mean estimate of the end is
    # the end to a few standard errors, while the mean largest sample is short by length / (k + 1).
    x = start + length * np.random.default_rng(seed).random((4000, k))
    ends = np.array([uniform_end(row) for row in x])
    end = start + length
    assert abs(ends.mean() - end) < 5 * ends.std() / np.sqrt(len(ends)) + 1e-12 * abs(end)
    assert x.max(axis=1).mean() < end - length / (k + 1) / 2
