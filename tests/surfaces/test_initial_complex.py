"""The initial complex (§4.1) on small inputs with a known surface."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from otjax.surfaces.initial_complex import (box_corners, initial_complex, sample_subset, tetrahedra,
                                            tetrahedra_facets, two_tetrahedra_rule)
from otjax.surfaces.solvers import exact_solver
from tests.surfaces.shapes import CROSS, CUBE, SQUARE, diagonal, fit, point_triangle_distance


def crossing_planes(n, rng):
    """Points on z = 0.5 and on y = 0.5 over the unit square: two planes crossing at a line."""
    h = n // 2
    a, b = rng.random((h, 2)), rng.random((n - h, 2))
    return np.r_[np.c_[a[:, 0], a[:, 1], np.full(h, 0.5)], np.c_[b[:, 0], np.full(n - h, 0.5), b[:, 1]]]


def facet_samples(vertices, triangles, per_facet=20, rng=None):
    rng = rng or np.random.default_rng(0)
    r = rng.random((len(triangles), per_facet, 2))
    flip = r.sum(-1) > 1
    r[flip] = 1 - r[flip]
    v = vertices[triangles]
    return (v[:, None, 0] + r[..., :1] * (v[:, None, 1] - v[:, None, 0])
            + r[..., 1:] * (v[:, None, 2] - v[:, None, 0])).reshape(-1, 3)


@pytest.fixture(scope="module")
def cross():
    rng = np.random.default_rng(7)
    pts = crossing_planes(360, rng)
    return pts, initial_complex(pts, np.ones(len(pts)), exact_solver, max_sweeps=2, seed=3)


def test_two_tetrahedra_stencil_of_an_inside_facet_has_seven_facets_and_five_vertices(rng):
    tets = tetrahedra(rng.random((40, 3)))
    rule = two_tetrahedra_rule(tets)
    facets = tetrahedra_facets(tets)
    shared = {tuple(f) for f in facets.tolist()}
    sizes = {}
    for f in map(tuple, facets.tolist()):
        vertices, around = rule(f)
        assert f in around and set(f) <= set(vertices)
        assert set(around) <= shared
        sizes.setdefault((len(around), len(vertices)), 0)
        sizes[(len(around), len(vertices))] += 1
    # hull facets bound one tetrahedron (4 facets, 4 vertices), inside ones two
    assert set(sizes) == {(4, 4), (7, 5)}
    hull = sum(1 for f in map(tuple, facets.tolist()) if len(rule(f)[1]) == 4)
    assert 4 * len(tets) == hull + 2 * (len(facets) - hull)


def test_subset_is_seeded_and_box_corners_enclose_flat_input(rng):
    a, b = sample_subset(1000, 0.15, seed=5), sample_subset(1000, 0.15, seed=5)
    assert np.array_equal(a, b) and len(a) == 150 and len(np.unique(a)) == 150
    assert not np.array_equal(a, sample_subset(1000, 0.15, seed=6))
    flat = np.c_[rng.random((50, 2)), np.zeros(50)]
    corners = box_corners(flat)
    assert np.all(corners.min(0) < flat.min(0)) and np.all(corners.max(0) > flat.max(0))
    with pytest.raises(ValueError, match="Delaunay"):
        tetrahedra(flat)
    assert len(tetrahedra(np.vstack([flat, corners]))) > 0


def test_every_point_is_transported_and_only_facets_with_mass_are_kept(cross):
    pts, ic = cross
    plan = ic.plan
    np.testing.assert_allclose(plan.point_mass(), 1.0, rtol=1e-12)
    assert set(plan.facet_entries) == plan.complex.triangles
    assert all(plan.simplex_mass(t) > 0 for t in plan.complex.triangles)
    # every vertex of the kept complex is a subset point or carries mass
    for v in np.flatnonzero(plan.complex.alive):
        assert ic.vertex_points[v] >= 0 or plan.simplex_mass(int(v)) > 0
    # kept vertices sit at the input points they came from
    real = ic.vertex_points >= 0
    np.testing.assert_array_equal(plan.complex.positions[real], pts[ic.vertex_points[real]])
    costs = ic.relaxation.costs
    assert all(b <= a for a, b in zip(costs, costs[1:])) and costs[-1] < 0.7 * costs[0]
    assert plan.total_cost() == pytest.approx(costs[-1], rel=1e-9)
    assert ic.delaunay_facets > 3 * plan.complex.n_triangles


def test_a_vertex_kept_for_its_own_mass_alone_is_tethered_so_it_can_be_collapsed():
    """A vertex that carries mass but lies on no kept facet keeps one edge,
    to a vertex of a kept facet: without it the decimation could never
    remove the vertex, and it would hold a place of the vertex budget."""
    from otjax import datasets3d
    from otjax.frame import to_canonical

    tethered = 0
    for n, seed in ((400, 0), (400, 2), (800, 3)):
        _, q, m = to_canonical(datasets3d.crossing(n, seed=seed)[0], np.ones(n))
        plan = initial_complex(q, m, exact_solver, seed=seed).plan
        c = plan.complex
        on_facets = {v for t in c.triangles for v in t}
        for v in np.flatnonzero(c.alive).tolist():
            if v in on_facets:
                continue
            assert plan.simplex_mass(v) > 0
            (w,) = c.neighbors(v)
            assert w in on_facets and not c.edge_triangles(v, w)
            tethered += 1
    assert tethered > 0  # these inputs have such vertices


def test_crossing_planes_are_both_covered_by_facets_near_them(cross):
    pts, ic = cross
    arrays = ic.plan.complex.to_arrays()
    d = float(np.linalg.norm(np.ptp(pts, axis=0)))
    centroids = arrays.vertices[arrays.triangles].mean(axis=1)
    off = np.minimum(np.abs(centroids[:, 2] - 0.5), np.abs(centroids[:, 1] - 0.5))
    assert np.median(off) < 0.01 * d
    on_z = np.abs(centroids[:, 2] - 0.5) < 0.01 * d
    on_y = np.abs(centroids[:, 1] - 0.5) < 0.01 * d
    assert on_z.sum() >= 10 and on_y.sum() >= 10
    # most of each plane's points are within 2% D of a kept facet
    near = cKDTree(facet_samples(arrays.vertices, arrays.triangles)).query(pts)[0]
    for plane in (np.abs(pts[:, 2] - 0.5) < 1e-12, np.abs(pts[:, 1] - 0.5) < 1e-12):
        assert np.mean(near[plane] < 0.02 * d) > 0.5


# Acceptance on noise-free shapes (tests/surfaces/shapes.py measures exact
# distances to the true surface, in units of the bbox diagonal D).
def built(shape, n, seed):
    pts = shape.sample(n, np.random.default_rng(seed))
    ic = initial_complex(pts, np.ones(n), exact_solver, seed=seed)
    arrays = ic.plan.complex.to_arrays()
    return pts, ic, arrays.vertices, arrays.triangles, diagonal(pts)


def test_a_cube_surface_is_covered_by_facets_within_one_percent():
    pts, ic, v, t, d = built(CUBE, 5000, seed=2)
    f = fit(CUBE, v, t, d, within=0.01, samples=4000, seed=2)
    assert f.coverage >= 0.95
    assert f.chamfer <= 0.01
    # kept facets are the surface's: far fewer than the tetrahedralisation's
    assert len(t) < 0.25 * ic.delaunay_facets
    np.testing.assert_allclose(ic.plan.point_mass(), 1.0, rtol=1e-12)


def test_an_open_square_keeps_its_boundary_and_covers_its_inside():
    pts, ic, v, t, d = built(SQUARE, 1500, seed=4)
    f = fit(SQUARE, v, t, d, within=0.01, samples=4000, seed=4)
    # no facet leaves the square (off its plane or past its edges) by 1% D
    assert f.to_surface <= 0.01
    truth = SQUARE.sample(4000, np.random.default_rng(5))
    near = point_triangle_distance(truth, v[t]) / d <= 0.01
    inside = np.min(np.c_[truth[:, :2], 1 - truth[:, :2]], axis=1) > 0.05
    # only a band along the edge, outside the subset's hull, may be bare
    assert np.mean(near[inside]) >= 0.98 and np.mean(near) >= 0.9


def test_two_crossing_planes_are_both_covered():
    pts, ic, v, t, d = built(CROSS, 2000, seed=6)
    truth = CROSS.sample(4000, np.random.default_rng(7))
    dist = point_triangle_distance(truth, v[t]) / d
    on_z = np.abs(truth[:, 2] - 0.5) < 1e-12
    for plane in (on_z, ~on_z):
        assert np.mean(dist[plane] <= 0.01) >= 0.9
        assert np.mean(dist[plane] <= 0.02) >= 0.95
    assert fit(CROSS, v, t, d, samples=2000, seed=6).chamfer <= 0.01
