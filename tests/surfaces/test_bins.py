"""Facet bins: exact partitions, centroidal cells, and the facet's second moment."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from otjax.surfaces.bins import (
    DEFAULT_DENSITY, bin_counts, bin_positions, facet_bins, local_frames, voronoi_cells,
)

TRI = np.array([[0, 1, 2]])


def skinny(aspect: float, kind: str) -> np.ndarray:
    """A triangle with longest side ``aspect`` and height 1 on it, in 3D:
    ``cap`` has its apex inside the base, ``needle`` is right-angled."""
    apex_x = 0.4 * aspect if kind == "cap" else aspect
    return np.array([[0.0, 0, 0], [aspect, 0, 0], [apex_x, 1.0, 0]])


def lattice(corners: np.ndarray, m: int) -> np.ndarray:
    """Centroids of the ``m * m`` congruent sub-triangles: an equal-weight
    quadrature of the uniform measure on the triangle ``corners`` ``(3, d)``."""
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    up = (i + j < m)
    down = (i + j < m - 1)
    lam = np.concatenate([np.stack([i[up] + 1 / 3, j[up] + 1 / 3], 1), np.stack([i[down] + 2 / 3, j[down] + 2 / 3], 1)])
    lam = lam / m
    w = np.column_stack([1 - lam.sum(1), lam])
    return w @ corners


def lloyd_step_capacities(corners: np.ndarray, centroids: np.ndarray) -> np.ndarray:
    """Capacities after one Lloyd step on lattice samples started at
    ``centroids``: cells of the centroids, moved to their sample means, cells
    again. Centroidal bins are a fixed point of the step, so their capacities
    come back unchanged up to the sampling error (12000 samples a cell: ~1%)."""
    m = int(np.ceil(np.sqrt(12000 * len(centroids))))
    x = lattice(corners, m)
    label = cKDTree(centroids).query(x)[1]
    moved = np.array([x[label == k].mean(0) for k in range(len(centroids))])
    return np.bincount(cKDTree(moved).query(x)[1], minlength=len(centroids)) / len(x)


def polar_moment(corners: np.ndarray) -> float:
    """``E|x - g|^2`` for ``x`` uniform on the triangle: ``(a^2 + b^2 + c^2) / 36``.

    With ``x = sum_k l_k v_k`` and ``l`` uniform on the simplex (Dirichlet(1, 1, 1):
    ``E l_k^2 = 1/6``, ``E l_k l_m = 1/12``) and ``u_k = v_k - g`` summing to 0,
    ``E|x - g|^2 = (1/6 - 1/12) sum |u_k|^2 = sum |u_k|^2 / 12``, and
    ``sum |u_k|^2 = (a^2 + b^2 + c^2) / 3`` for the side lengths ``a, b, c``."""
    a, b, c = (np.linalg.norm(corners[i] - corners[j]) for i, j in ((0, 1), (1, 2), (2, 0)))
    return float((a * a + b * b + c * c) / 36)


def bins_second_moment(corners: np.ndarray, b) -> float:
    pos = b.barycentric @ corners
    return float(b.capacity @ ((pos - corners.mean(0)) ** 2).sum(1))


def test_polar_moment_formula_matches_sampling(rng):
    corners = rng.random((3, 3))
    x = rng.dirichlet(np.ones(3), 10**6) @ corners
    assert abs(((x - x.mean(0)) ** 2).sum(1).mean() / polar_moment(corners) - 1) < 0.01


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 6), log_aspect=st.floats(0, np.log(50)))
def test_bins_partition_each_facet(seed, n, log_aspect):
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((3, 3))
    v[2] = v[0] + np.exp(log_aspect) * (v[2] - v[0])  # stretch one side
    b = facet_bins(v, TRI, min_bins=n, max_bins=n, seed=seed % 7)
    assert b.count.tolist() == [n] and (b.facet == 0).all()
    assert abs(b.capacity.sum() - 1.0) < 1e-12
    assert (b.capacity > 0).all()
    np.testing.assert_allclose(b.barycentric.sum(1), 1.0, atol=1e-12)
    assert (b.barycentric > -1e-12).all()
    # Cells partition the facet and each bin is its cell's centroid: the
    # capacity-weighted bins have the facet's centroid.
    scale = np.ptp(v, axis=0).max()
    np.testing.assert_allclose(b.capacity @ bin_positions(v, TRI, b), v.mean(0), atol=1e-9 * scale)


@pytest.mark.parametrize("aspect", [10, 30])
@pytest.mark.parametrize("kind", ["cap", "needle"])
@pytest.mark.parametrize("n", [3, 10, 32])
def test_capacities_match_a_fine_lloyd_on_skinny_triangles(aspect, kind, n):
    v = skinny(aspect, kind)
    b = facet_bins(v, TRI, min_bins=n, max_bins=n)
    ref = lloyd_step_capacities(v[:, :2], (b.barycentric @ v)[:, :2])
    assert np.max(np.abs(b.capacity - ref) / ref) <= 0.05


def test_affine_template_alone_is_not_centroidal_on_a_skinny_triangle():
    v = skinny(10, "needle")
    b = facet_bins(v, TRI, min_bins=10, max_bins=10, max_stretch=np.inf)
    ref = lloyd_step_capacities(v[:, :2], (b.barycentric @ v)[:, :2])
    assert np.max(np.abs(b.capacity - ref) / ref) > 0.05


@pytest.mark.parametrize("shape", ["equilateral", "cap10", "needle30"])
def test_bins_carry_the_second_moment_at_the_default_density(shape):
    if shape == "equilateral":
        v = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0]])
    else:
        v = skinny(float(shape[-2:]), shape[:-2])
    # A facet of 0.2 D^2 on an input of diagonal D = 1: the default gives it 30 bins.
    area = 0.5 * np.linalg.norm(np.cross(v[1] - v[0], v[2] - v[0]))
    v = v * np.sqrt(0.2 / area)
    b = facet_bins(v, TRI, diagonal=1.0)
    assert b.count[0] == round(DEFAULT_DENSITY * 0.2) == 30
    j = polar_moment(v)
    assert 0.96 * j <= bins_second_moment(v, b) <= j


def test_one_bin_keeps_no_spread_and_more_bins_keep_more():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [0.3, 0.8, 0]])
    moments = [bins_second_moment(v, facet_bins(v, TRI, min_bins=n, max_bins=n)) for n in (1, 3, 10, 30)]
    assert moments[0] == pytest.approx(0.0, abs=1e-15)
    assert moments == sorted(moments) and moments[-1] < polar_moment(v)


def test_bins_do_not_depend_on_units_or_placement(rng):
    v = rng.random((6, 3))
    tris = np.array([[0, 1, 2], [1, 2, 3], [3, 4, 5], [0, 4, 5]])
    b = facet_bins(v, tris, density=2000.0, diagonal=1.0)
    q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    w = 37.5 * v @ q.T + np.array([1e3, -2e3, 5.0])
    c = facet_bins(w, tris, density=2000.0, diagonal=37.5)
    np.testing.assert_array_equal(b.count, c.count)
    np.testing.assert_allclose(b.capacity, c.capacity, atol=1e-9)
    np.testing.assert_allclose(b.barycentric, c.barycentric, atol=1e-9)
    np.testing.assert_allclose(bin_positions(w, tris, c), 37.5 * bin_positions(v, tris, b) @ q.T + w[0] - 37.5 * v[0] @ q.T,
                               atol=1e-8)


def test_bins_are_deterministic_and_grouped_by_facet(rng):
    v = rng.random((8, 3))
    tris = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6], [5, 6, 7], [0, 3, 7]])
    a = facet_bins(v, tris, density=400.0, seed=3)
    b = facet_bins(v, tris, density=400.0, seed=3)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.facet, np.repeat(np.arange(5), a.count))
    sums = np.bincount(a.facet, weights=a.capacity)
    np.testing.assert_allclose(sums, 1.0, atol=1e-12)
    assert len(np.unique(a.count)) > 1  # the test covers several bin counts


def test_bin_counts_follow_area_over_squared_diagonal():
    areas = np.array([0.0, 0.02, 0.1, 1.0])
    np.testing.assert_array_equal(bin_counts(areas, 2.0, density=150.0, min_bins=1, max_bins=20), [1, 1, 4, 20])
    np.testing.assert_array_equal(bin_counts(areas, 1.0, density=150.0, min_bins=3, max_bins=32), [3, 3, 15, 32])
    with pytest.raises(ValueError, match="diagonal"):
        bin_counts(areas, 0.0)
    with pytest.raises(ValueError, match="min_bins"):
        bin_counts(areas, 1.0, min_bins=4, max_bins=3)


def test_flat_facet_gets_valid_bins():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    b = facet_bins(v, np.array([[0, 1, 2], [0, 1, 3]]), min_bins=4, max_bins=4)
    np.testing.assert_allclose(np.bincount(b.facet, weights=b.capacity), 1.0, atol=1e-12)
    assert np.all(np.isfinite(b.barycentric))


def test_clipped_voronoi_cells_match_sampling(rng):
    v = skinny(5, "cap")[:, :2]
    gens = rng.dirichlet(np.ones(3), 7) @ v
    cells = voronoi_cells(v[None], gens[None])
    x = lattice(v, 300)
    label = cKDTree(gens).query(x)[1]
    area = 0.5 * 5.0
    assert cells.area.sum() == pytest.approx(area, rel=1e-12)
    np.testing.assert_allclose(cells.area[0], np.bincount(label, minlength=7) / len(x) * area, rtol=0.01)
    for k in range(7):
        np.testing.assert_allclose(cells.centroid[0, k], x[label == k].mean(0), atol=0.01)


def test_local_frames_keep_lengths(rng):
    v = rng.random((3, 3))
    c = local_frames(v, TRI)[0]
    for i, j in ((0, 1), (1, 2), (2, 0)):
        assert np.linalg.norm(c[i] - c[j]) == pytest.approx(np.linalg.norm(v[i] - v[j]), rel=1e-12)


def test_no_facets_give_no_bins():
    b = facet_bins(np.random.default_rng(0).random((4, 3)), np.zeros((0, 3), np.int64))
    assert [x.shape for x in b] == [(0,), (0, 3), (0,), (0,)]


def test_bin_length_gives_a_long_sliver_one_bin_per_length_and_leaves_small_facets():
    v = np.array([[0.0, 0, 0], [0.02, 0, 0], [0.01, 0.9, 0], [0.05, 0.05, 0], [0.0, 0.05, 0]])
    tris = np.array([[0, 1, 2], [0, 3, 4]])
    plain = facet_bins(v, tris, min_bins=1, diagonal=1.0)
    assert plain.count.tolist() == [1, 1]  # both small in area
    long = facet_bins(v, tris, min_bins=1, diagonal=1.0, bin_length=0.25)
    # the sliver's longest edge is just over 0.9: ceil(0.9 / 0.25) = 4 bins
    assert long.count.tolist() == [4, 1]
    np.testing.assert_allclose(np.bincount(long.facet, long.capacity), 1.0)
    pos = bin_positions(v, tris, long)[:4]
    assert np.ptp(pos[:, 1]) > 0.4  # spread along the sliver, not bunched at its centroid
    with pytest.raises(ValueError, match="bin_length"):
        facet_bins(v, tris, bin_length=0.0)
