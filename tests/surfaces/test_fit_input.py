"""What the fits share: the guard that undoes moves that flatten a triangle or close an edge."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.surfaces.fit_input import CLOSED, without_flattening
from otjax.surfaces.relocation import MIN_ASPECT


def aspect_oracle(x: np.ndarray, t) -> float:
    """Area over the longest side squared, from Heron's formula."""
    a, b, c = sorted(np.linalg.norm(x[t[k]] - x[t[k - 1]]) for k in range(3))
    s = (a + b + c) / 2
    area = np.sqrt(max(s * (s - a) * (s - b) * (s - c), 0.0))
    return area / c**2 if c > 0 else 0.0


def strip(n: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Two rows of ``n`` vertices in the plane z = 0, triangulated."""
    x = np.array([[i, j, 0.0] for j in (0, 1) for i in range(n)])
    tris = [[i, i + 1, n + i] for i in range(n - 1)] + [[i + 1, n + i + 1, n + i] for i in range(n - 1)]
    return x, np.array(tris)


def test_two_ends_of_an_edge_sent_to_one_point_keep_only_the_longer_move():
    x, tris = strip()
    after = x.copy()
    after[1] = [1.4, 0.0, 0.0]  # moves 0.4
    after[2] = [1.4, 0.0, 0.01]  # moves 0.6, to 0.01 from vertex 1
    fit = without_flattening(x, after, tris, np.array([1, 2]))
    assert fit.moved.tolist() == [2]
    np.testing.assert_array_equal(fit.vertices[1], x[1])
    np.testing.assert_array_equal(fit.vertices[2], after[2])


def test_an_edge_shortened_to_more_than_the_closing_fraction_stays():
    x, tris = strip()
    after = x.copy()
    after[1] = [1.5 - CLOSED, 0.0, 0.0]
    after[2] = [1.5 + CLOSED, 0.0, 0.0]  # the edge 1-2 at twice the closing fraction of its length
    fit = without_flattening(x, after, tris, np.array([1, 2]))
    assert fit.moved.tolist() == [1, 2]


@settings(max_examples=150, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(3, 8), st.floats(0.0, 1.0))
def test_no_kept_move_flattens_a_triangle_or_closes_an_edge(seed, n, spread):
    rng = np.random.default_rng(seed)
    x, tris = strip(n)
    x = x + rng.normal(0, 0.2, x.shape)
    moved = np.flatnonzero(rng.random(len(x)) < 0.6)
    after = x.copy()
    # moves toward a few attractors (points and a line) make closed edges and flat triangles likely
    targets = np.r_[x[rng.integers(len(x), size=2)], [[0.0, 0.5, 0.0]]]
    for v in moved:
        kind = rng.integers(3)
        if kind == 0:
            after[v] = targets[rng.integers(len(targets))] + rng.normal(0, 1e-9 + 1e-3 * spread, 3)
        elif kind == 1:
            after[v] = [after[v, 0], 0.5, 0.0]  # onto the line y = 0.5, z = 0
        else:
            after[v] = x[v] + rng.normal(0, spread, 3)
    fit = without_flattening(x, after, tris, moved)
    assert set(fit.moved.tolist()) <= set(moved.tolist())
    kept = np.isin(np.arange(len(x)), fit.moved)
    np.testing.assert_array_equal(fit.vertices[~kept], x[~kept])
    np.testing.assert_array_equal(fit.vertices[kept], after[kept])
    for t in tris:
        new = aspect_oracle(fit.vertices, t)
        assert new >= MIN_ASPECT * (1 - 1e-9) or new >= aspect_oracle(x, t) * (1 - 1e-9)
        for k in range(3):
            a, b = t[k - 1], t[k]
            length = np.linalg.norm(fit.vertices[a] - fit.vertices[b])
            assert length >= CLOSED * np.linalg.norm(x[a] - x[b]) * (1 - 1e-12)
