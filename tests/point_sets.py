"""Hypothesis strategies for hostile 2D point sets."""

import numpy as np
from hypothesis import strategies as st

KINDS = ("uniform", "near_collinear", "clustered", "duplicates", "grid")


def make_points(kind: str, n: int, seed: int) -> np.ndarray:
    """``(m, 2)`` float64 points of a given hostile kind (``m <= n``)."""
    rng = np.random.default_rng(seed)
    if kind == "uniform":
        return rng.random((n, 2))
    if kind == "near_collinear":
        t = rng.random(n)
        eps = 10.0 ** rng.integers(-15, -6)
        return np.stack([t, 0.3 * t + eps * rng.standard_normal(n)], 1)
    if kind == "clustered":
        centres = rng.random((max(1, n // 20), 2))
        spread = 10.0 ** rng.integers(-12, -4)
        return centres[rng.integers(len(centres), size=n)] + spread * rng.standard_normal((n, 2))
    if kind == "duplicates":
        pool = rng.random((max(3, n // 4), 2))
        return pool[rng.integers(len(pool), size=n)]
    if kind == "grid":  # many exactly collinear and cocircular points
        k = int(np.ceil(np.sqrt(n)))
        g = np.stack(np.meshgrid(np.arange(k), np.arange(k)), -1).reshape(-1, 2).astype(float)
        return g[rng.permutation(len(g))[:n]]
    raise ValueError(kind)


point_sets = st.builds(
    make_points,
    kind=st.sampled_from(KINDS),
    n=st.integers(3, 260),
    seed=st.integers(0, 2**31 - 1),
)
