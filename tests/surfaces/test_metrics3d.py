"""Surface metrics against brute-force NumPy oracles and closed forms."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from otjax import datasets3d, metrics3d
from otjax.datasets3d import SurfaceTruth, cube_truth, holed_square_truth
from tests.profiles import examples


def closest_on_triangle(p, a, b, c):
    """Ericson, Real-Time Collision Detection 5.1.5: the closest point of triangle abc to p, by Voronoi regions."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    if d1 <= 0 and d2 <= 0:
        return a
    bp = p - b
    d3, d4 = ab @ bp, ac @ bp
    if d3 >= 0 and d4 <= d3:
        return b
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        return a + d1 / (d1 - d3) * ab
    cp = p - c
    d5, d6 = ab @ cp, ac @ cp
    if d6 >= 0 and d5 <= d6:
        return c
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        return a + d2 / (d2 - d6) * ac
    va = d3 * d6 - d5 * d4
    if va <= 0 and d4 - d3 >= 0 and d5 - d6 >= 0:
        return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)
    denom = 1.0 / (va + vb + vc)
    return a + ab * vb * denom + ac * vc * denom


def oracle_triangles(points, tris):
    return np.array([min(np.linalg.norm(p - closest_on_triangle(p, *t)) for t in tris) for p in points])


def oracle_segments(points, segs):
    out = []
    for p in points:
        best = np.inf
        for a, b in segs:
            d = b - a
            t = 0.0 if d @ d == 0 else min(1.0, max(0.0, (p - a) @ d / (d @ d)))
            best = min(best, np.linalg.norm(p - (a + t * d)))
        out.append(best)
    return np.array(out)


def test_point_triangle_distance_matches_ericson():
    rng = np.random.default_rng(0)
    tris = rng.normal(size=(40, 3, 3))
    tris[:5, 2] = tris[:5, 0] + 1e-3 * rng.normal(size=(5, 3))  # thin ones
    points = rng.normal(size=(300, 3)) * 1.5
    np.testing.assert_allclose(metrics3d.point_triangle_distance(points, tris), oracle_triangles(points, tris),
                               rtol=1e-10, atol=1e-12)
    assert np.all(np.isinf(metrics3d.point_triangle_distance(points[:3], np.zeros((0, 3, 3)))))


@settings(max_examples=examples(40, 400))
@given(seed=st.integers(0, 2**32 - 1), scale=st.sampled_from([1e-3, 1.0, 1e3]))
def test_point_triangle_distance_property(seed, scale):
    rng = np.random.default_rng(seed)
    tris = rng.normal(size=(rng.integers(1, 8), 3, 3)) * scale
    points = rng.normal(size=(20, 3)) * 2 * scale
    np.testing.assert_allclose(metrics3d.point_triangle_distance(points, tris), oracle_triangles(points, tris),
                               rtol=1e-9, atol=1e-12 * scale)


def test_triangle_samples_cover_each_triangle_with_its_area():
    rng = np.random.default_rng(1)
    v = rng.normal(size=(12, 3))
    tri = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [9, 10, 11]])
    v[9:12] = [[0, 0, 0], [3, 0, 0], [1.5, 0.01, 0]]  # long and thin
    step = 0.1
    p, w = metrics3d.triangle_samples(v, tri, step)
    t = v[tri]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    assert w.sum() == pytest.approx(area.sum(), rel=1e-12)
    assert np.all(w > 0)
    # Every sample lies on a triangle; every point of a triangle is within sqrt(2) step of a sample.
    assert oracle_triangles(p[::7], t).max() < 1e-10
    a, b = rng.random((2, 4000, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    for k in range(len(tri)):
        q = t[k, 0] + a * (t[k, 1] - t[k, 0]) + b * (t[k, 2] - t[k, 0])
        assert cKDTree(p).query(q)[0].max() <= np.sqrt(2) * step
    thin, _ = metrics3d.triangle_samples(v, tri[3:], step)
    assert len(thin) <= 3 / step + 2  # a column per step of length (and one at the apex), not (length / step)^2


def square_truth(z=0.5):
    """The unit square at height z, built from the generic patch description."""
    base = holed_square_truth()
    rect = np.array([[[0, 0, z], [1, 0, 0], [0, 1, 0]]], float)
    mesh = base.mesh._replace(vertices=np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z]], float),
                              triangles=np.array([[0, 1, 2], [0, 2, 3]]))
    return SurfaceTruth(rect, np.zeros((0, 4)), np.zeros((0, 2, 3)), np.zeros((0, 2, 3)), np.zeros((0, 3)),
                        float(np.sqrt(2)), mesh)


def test_parallel_square_is_at_its_offset_both_ways():
    truth = square_truth(0.5)
    out = truth.mesh.vertices + [0, 0, 0.03]
    d = metrics3d.surface_distances(out, truth.mesh.triangles, truth=truth, samples=2000)
    for value in d:
        assert value == pytest.approx(0.03, rel=1e-12)


def test_surface_distances_match_a_brute_force_oracle():
    truth = cube_truth()
    rng = np.random.default_rng(2)
    vertices = rng.uniform(-0.2, 1.2, (7, 3))
    triangles, edges, isolated = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]]), np.array([[4, 5]]), np.array([6])
    step = 0.05
    got = metrics3d.surface_distances(vertices, triangles, edges, isolated, truth=truth, samples=300, step=step,
                                      seed=4)
    out = metrics3d.complex_samples(vertices, triangles, edges, isolated, step=step)
    exact = truth.mesh.vertices[truth.mesh.triangles]  # the cube's mesh is exact
    to_truth = oracle_triangles(out.points, exact)
    ref = truth.sample(300, np.random.default_rng(4))
    from_truth = np.minimum(oracle_triangles(ref, vertices[triangles]),
                            oracle_segments(ref, np.concatenate([vertices[edges], vertices[[[6, 6]]]])))
    to_mean = out.weights @ to_truth / out.weights.sum()
    want = [0.5 * (to_mean + from_truth.mean()), max(to_truth.max(), from_truth.max()), to_mean, to_truth.max(),
            from_truth.mean(), from_truth.max()]
    np.testing.assert_allclose(got, want, rtol=1e-10)
    # An edge weighs step per unit length and an isolated vertex step^2.
    n_tri = len(metrics3d.triangle_samples(vertices, triangles, step)[0])
    length = np.linalg.norm(vertices[4] - vertices[5])
    assert out.weights[n_tri:-1].sum() == pytest.approx(length * step)
    assert out.weights[-1] == step**2


@pytest.mark.parametrize("name, tol", [("cube", 1e-12), ("staircase", 1e-12), ("crossing", 1e-12),
                                       ("cylinder", 1e-4), ("cone", 1e-4)])
def test_true_mesh_is_near_its_own_samples(name, tol):
    truth = datasets3d.SURFACES[name](10).truth
    d = metrics3d.surface_distances(truth.mesh.vertices, truth.mesh.triangles, truth=truth, samples=2000,
                                    step=0.01 * truth.diagonal)
    assert d.chamfer <= tol * truth.diagonal and d.hausdorff <= tol * truth.diagonal
    assert metrics3d.chamfer(truth.mesh.vertices, truth.mesh.triangles, truth=truth, samples=500) == pytest.approx(
        metrics3d.surface_distances(truth.mesh.vertices, truth.mesh.triangles, truth=truth, samples=500).chamfer)


def hinge(opening, rng):
    """Two triangles on the edge (0, 0, 0)-(1, 0, 0) whose half planes open by ``opening``, moved rigidly."""
    v = np.array([[0, 0, 0], [1, 0, 0], [0.5, 1, 0], [0.5, np.cos(opening), np.sin(opening)]], float)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return v @ q.T + rng.normal(size=3), np.array([[0, 1, 2], [1, 0, 3]])


@pytest.mark.parametrize("opening", [np.pi, 2.5, np.pi / 2, 0.6])
def test_edge_sharpness_of_a_hinge(opening):
    v, tri = hinge(opening, np.random.default_rng(5))
    s = metrics3d.edge_sharpness(v, tri)
    shared = np.flatnonzero(s.n_triangles == 2)
    assert s.edges[shared].tolist() == [[0, 1]]
    assert s.angle[shared[0]] == pytest.approx(np.pi - opening, abs=1e-12)
    assert np.all(s.angle[s.n_triangles == 1] == 0)
    assert len(metrics3d.boundary_edges(tri)) == 4


@pytest.mark.parametrize("opening", [0.0, 0.2, 0.5])
def test_a_folded_hinge_is_not_a_crease(opening):
    # half planes closer than FOLD_ANGLE (0.52 rad) lie over each other: a fold, however sharp the turn
    v, tri = hinge(opening, np.random.default_rng(7))
    s = metrics3d.edge_sharpness(v, tri)
    assert s.angle[s.n_triangles == 2].tolist() == [0.0]
    assert metrics3d.crease_error(v, tri, v[None, [0, 1]]).mean == np.inf
    # a third triangle that is not folded over either makes the edge a crease again
    v3 = np.vstack([v, v[0] + np.cross(v[1] - v[0], v[2] - v[0])])
    s3 = metrics3d.edge_sharpness(v3, np.vstack([tri, [[0, 1, 4]]]))
    assert s3.angle[s3.n_triangles == 3][0] == pytest.approx(np.pi / 2 + opening, abs=1e-9)


@pytest.mark.parametrize("opening", [0.0, 0.2, 0.5])
def test_a_folded_hinge_ends_its_patch(opening):
    # the two triangles double one patch: their shared edge is where it ends, a boundary edge
    v, tri = hinge(opening, np.random.default_rng(8))
    s = metrics3d.edge_sharpness(v, tri)
    assert s.layers[s.n_triangles == 2].tolist() == [1]
    assert metrics3d.boundary_error(v, tri, v[None, [0, 1]]).max < 1e-12
    # a third triangle turned away from both closes it: two layers, not a boundary any more
    v3 = np.vstack([v, v[0] - (v[2] - v[0])])
    s3 = metrics3d.edge_sharpness(v3, np.vstack([tri, [[0, 1, 4]]]))
    assert s3.layers[s3.n_triangles == 3].tolist() == [2]
    assert metrics3d.boundary_error(v3, np.vstack([tri, [[0, 1, 4]]]), v[None, [0, 1]]).max > 0.1


def test_an_open_hinge_has_two_layers():
    v, tri = hinge(0.6, np.random.default_rng(9))
    s = metrics3d.edge_sharpness(v, tri)
    assert s.layers[s.n_triangles == 2].tolist() == [2] and np.all(s.layers[s.n_triangles == 1] == 1)


@settings(max_examples=examples(100, 1000))
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(4, 30), fold=st.floats(0.0, 0.45))
def test_layers_of_a_height_field(seed, n, fold):
    """A graph ``z = f(x, y)`` with slopes at most 1 cannot fold (half planes
    across an edge at least 90 degrees apart): its one-layer edges are its
    one-triangle edges. A triangle folded onto a border triangle (``fold``
    radians off it) keeps that border edge a boundary."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2))
    tri = Delaunay(xy).simplices
    z = 0.3 * np.sin(3 * xy[:, 0] + rng.random()) * np.cos(2 * xy[:, 1])
    # The slope that matters is each triangle's (a sliver's can far exceed |grad z|): scaled to at most 1.
    e = xy[tri[:, 1:]] - xy[tri[:, :1]]
    dz = z[tri[:, 1:]] - z[tri[:, :1]]
    slope = np.linalg.norm(np.linalg.solve(e, dz[..., None])[..., 0], axis=1)
    v = np.c_[xy, z / max(1.0, float(slope.max()))]
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    v = v @ q.T + rng.normal(size=3)
    s = metrics3d.edge_sharpness(v, tri)
    assert np.array_equal(s.n_triangles, s.layers)
    ones = s.edges[s.layers == 1]
    assert np.array_equal(ones, metrics3d.boundary_edges(tri))
    # fold a copy of one border triangle's far vertex about the border edge
    a, b = ones[rng.integers(len(ones))]
    c = next(int(t[(t != a) & (t != b)][0]) for t in tri if a in t and b in t)
    axis = (v[b] - v[a]) / np.linalg.norm(v[b] - v[a])
    w = v[c] - v[a]
    w_along = (w @ axis) * axis
    across = w - w_along
    turned = np.cos(fold) * across + np.sin(fold) * np.cross(axis, across)
    v2 = np.vstack([v, v[a] + w_along + turned])
    tri2 = np.vstack([tri, [[a, b, len(v)]]])
    s2 = metrics3d.edge_sharpness(v2, tri2)
    k = np.flatnonzero((s2.edges[:, 0] == min(a, b)) & (s2.edges[:, 1] == max(a, b)))[0]
    assert s2.n_triangles[k] == 2 and s2.layers[k] == 1


def test_cube_and_crossing_creases():
    cube = cube_truth()
    s = metrics3d.edge_sharpness(cube.mesh.vertices, cube.mesh.triangles)
    assert np.sum(np.isclose(s.angle, np.pi / 2)) == 12 and np.sum(s.angle == 0) == 6
    assert metrics3d.crease_error(cube.mesh.vertices, cube.mesh.triangles, cube.creases).max == 0.0
    cross = datasets3d.crossing_truth()
    s = metrics3d.edge_sharpness(cross.mesh.vertices, cross.mesh.triangles)
    assert s.n_triangles.max() == 4 and np.isclose(s.angle[s.n_triangles == 4], np.pi / 2).all()
    assert metrics3d.crease_error(cross.mesh.vertices, cross.mesh.triangles, cross.creases).max < 1e-15


def test_crease_error_of_a_shifted_hinge_and_the_oracle():
    v, tri = hinge(np.pi / 2, np.random.default_rng(6))
    edge = v[[0, 1]]
    normal = np.cross(edge[1] - edge[0], v[2] - v[0])
    normal /= np.linalg.norm(normal)
    crease = (edge + 0.1 * normal)[None]  # the true crease, 0.1 off the output's sharp edge, same length
    err = metrics3d.crease_error(v, tri, crease, step=0.01)
    assert err.mean == pytest.approx(0.1) and err.max == pytest.approx(0.1) and err.n_edges == 1
    # A longer true crease, checked against brute force over its samples.
    long = np.array([[edge[0] - 0.5 * (edge[1] - edge[0]), edge[1] + 0.1 * normal]])
    pts, w = metrics3d.sample_segments(long, 0.01)
    want = oracle_segments(pts, [edge])
    got = metrics3d.crease_error(v, tri, long, step=0.01)
    assert got.mean == pytest.approx(w @ want / w.sum(), rel=1e-12) and got.max == pytest.approx(want.max())
    # Flatten the hinge: no sharp edge is left.
    v, tri = hinge(np.pi * 0.9, np.random.default_rng(6))
    assert metrics3d.crease_error(v, tri, crease).mean == np.inf


def test_boundary_error():
    truth = holed_square_truth()
    m = truth.mesh
    assert metrics3d.boundary_error(m.vertices, m.triangles, truth.boundaries).max < 1e-15
    full = datasets3d.holed_square(10, resolution=4).mesh  # covers the hole: its border is the outer one only
    err = metrics3d.boundary_error(full.vertices, full.triangles, truth.boundaries, step=0.01)
    pts, w = metrics3d.sample_segments(truth.boundaries, 0.01)
    b = metrics3d.boundary_edges(full.triangles)
    want = oracle_segments(pts, full.vertices[b])
    assert err.mean == pytest.approx(w @ want / w.sum(), rel=1e-12)
    assert err.max == pytest.approx(0.35)  # the hole's corners, from the outer border


def test_no_triangles_have_no_sharp_or_boundary_edge():
    """A result reduced to vertices and dangling edges: no edge has an angle,
    so every true crease and boundary is infinitely far (not an IndexError)."""
    truth = datasets3d.staircase_truth()
    v = truth.corners
    none = np.zeros((0, 3), np.int64)
    assert metrics3d.edge_sharpness(v, none).edges.shape == (0, 2)
    assert metrics3d.crease_error(v, none, truth.creases).mean == np.inf
    assert metrics3d.boundary_error(v, none, truth.boundaries).max == np.inf


def test_bad_input_is_a_value_error():
    with pytest.raises(ValueError, match="triangles index out of range"):
        metrics3d.triangle_samples(np.eye(3), [[0, 1, 3]], 0.1)
    with pytest.raises(ValueError, match="step"):
        metrics3d.triangle_samples(np.eye(3), [[0, 1, 2]], 0.0)
    with pytest.raises(ValueError, match="shape"):
        metrics3d.point_triangle_distance(np.zeros((3, 2)), np.zeros((1, 3, 3)))
