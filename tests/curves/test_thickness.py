"""``local_thickness`` against a brute-force oracle, its invariances, and
how the defaults read it."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import otjax
from otjax import datasets
from otjax.curves.reconstruct import NOISY_THICKNESS
from otjax.curves.thickness import local_thickness
from tests.profiles import examples  # CI count, thorough count (--hypothesis-profile=thorough)


def brute_force_thickness(points, k):
    """Every pairwise distance, a full eigendecomposition per point."""
    k = min(k, len(points))
    dist = np.linalg.norm(points[:, None] - points[None], axis=-1)
    ratios = []
    for row in dist:
        local = points[np.argsort(row, kind="stable")[:k]]
        cov = np.cov(local.T, bias=True)
        low, high = np.linalg.eigvalsh(cov)
        ratios.append(0.0 if high <= 0 else np.sqrt(max(low, 0.0) / high))
    return np.median(ratios)


@settings(max_examples=examples(120, 600), deadline=None)
@given(st.integers(2, 60), st.integers(3, 12), st.floats(0.0, 1.0), st.integers(0, 2**32 - 1))
def test_matches_a_brute_force_oracle(n, k, spread, seed):
    rng = np.random.default_rng(seed)
    # Points near a random line, from exactly on it to an isotropic cloud.
    t = rng.uniform(-1, 1, n)
    points = np.c_[t, spread * rng.normal(size=n)] @ np.array([[0.6, 0.8], [-0.8, 0.6]]) + rng.normal(size=2)
    # On a line the smaller eigenvalue is rounding (~1e-16 of the larger): ~1e-8 after the square root.
    assert local_thickness(points, k) == pytest.approx(brute_force_thickness(points, k), abs=1e-6)


@pytest.mark.parametrize("scale", [1e-170, 1e-9, 1.0, 3e7, 1e170])
def test_independent_of_units_position_and_orientation(scale):
    pts, _ = datasets.star(800, noise=0.003, seed=2)
    angle = 0.7
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moved = (pts @ rot.T + [5.0, -2.0]) * scale
    assert local_thickness(moved) == pytest.approx(local_thickness(pts), rel=1e-6)


def test_exact_samples_are_thin_and_noisy_ones_thick():
    line = np.c_[np.linspace(0, 1, 50), np.linspace(0, 2, 50)]
    assert local_thickness(line) < 1e-6
    assert local_thickness(np.zeros((10, 2))) == 0.0  # coincident points: no direction, no thickness
    for make in (lambda s: datasets.star(1000, noise=0.0, seed=s), lambda s: datasets.junctions(1000, seed=s)):
        assert local_thickness(make(3)[0]) < 1e-6  # only the corners' neighbourhoods bend
    for n in (1000, 3000):
        assert local_thickness(datasets.star(n, noise=0.01, seed=3)[0]) > NOISY_THICKNESS + 0.05
    cloud = np.random.default_rng(0).normal(size=(500, 2))
    assert local_thickness(cloud) > 0.5


def test_rejects_bad_arguments():
    with pytest.raises(ValueError, match="points"):
        local_thickness(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="points"):
        local_thickness(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="neighbours"):
        local_thickness(np.zeros((5, 2)), neighbours=2)


def test_the_defaults_start_noisy_points_from_a_third_and_exact_samples_from_every_point():
    noisy, _ = datasets.star(600, noise=0.01, seed=4)
    exact, _ = datasets.star(600, noise=0.0, seed=4)
    assert otjax.reconstruct_curve(noisy, n_vertices=10).params["initial_vertices"] == 300
    assert otjax.reconstruct_curve(exact, n_vertices=10).params["initial_vertices"] == 600
    assert otjax.reconstruct_curve(noisy, n_vertices=10, initial_vertices=450).params["initial_vertices"] == 450
