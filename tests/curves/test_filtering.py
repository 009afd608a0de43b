"""Edge filters decided by the data (otjax.curves.filtering), alone and at
the defaults of reconstruct_curve."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import otjax
from otjax import datasets, metrics
from otjax.background import estimate_background
from otjax.curves import filtering
from otjax.curves.reconstruct import EXHAUSTIVE_COLLAPSES, LAZY_COLLAPSES, default_initial_vertices, default_queue
from tests.profiles import examples  # CI count, thorough count (--hypothesis-profile=thorough)


def nearest_edge_ids(points, xy, keys):
    d = np.stack([filtering.segment_sqdist(points, xy[a], xy[b]) for a, b in keys], 1)
    k = d.argmin(1)
    return [np.flatnonzero(k == i) for i in range(len(keys))]


def test_segment_distance_matches_brute_force():
    rng = np.random.default_rng(0)
    p, a, b = rng.normal(size=(50, 2)), rng.normal(size=2), rng.normal(size=2)
    t = np.linspace(0, 1, 20001)
    brute = ((p[:, None] - (a + t[:, None] * (b - a))[None]) ** 2).sum(-1).min(1)
    np.testing.assert_allclose(filtering.segment_sqdist(p, a, b), brute, rtol=1e-6, atol=1e-12)


def test_the_chord_of_a_thin_triangle_goes():
    rng = np.random.default_rng(1)
    x = rng.random(400)
    points = np.c_[x, 0.01 * rng.standard_normal(400)]
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.03]])
    keys = [(0, 1), (0, 2), (1, 2)]
    kept = filtering.redundant_edges(keys, xy, nearest_edge_ids(points, xy, keys), points, np.ones(400))
    assert kept.sum() == 2  # one edge goes, the cycle is broken
    left = [k for k, keep in zip(keys, kept) if keep]
    d = np.min([filtering.segment_sqdist(points, xy[a], xy[b]) for a, b in left], 0)
    assert np.sqrt(d.mean()) < 0.03  # what is left still holds the points


def test_a_true_triangle_keeps_its_sides():
    rng = np.random.default_rng(2)
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3) / 2]])
    keys = [(0, 1), (0, 2), (1, 2)]
    side = rng.integers(0, 3, 600)
    t = rng.random(600)
    a, b = xy[np.array(keys)[side, 0]], xy[np.array(keys)[side, 1]]
    points = a + t[:, None] * (b - a) + 0.02 * rng.standard_normal((600, 2))
    kept = filtering.redundant_edges(keys, xy, nearest_edge_ids(points, xy, keys), points, np.ones(600))
    assert kept.all()


def t_junction(branch_end, rng, noise=0.01):
    """A T (a bar from (0, 0) to (2, 0), a stem from (1, 0) to (1, 1)) sampled
    with ``noise``, and a fifth vertex ``branch_end`` joined to the junction:
    vertices, edges and their points (each point on its nearest edge)."""
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 1.0], branch_end])
    keys = [(0, 1), (1, 2), (1, 3), (1, 4)]
    t = rng.random(900)
    truth = np.array([[[0.0, 0.0], [2.0, 0.0]], [[1.0, 0.0], [1.0, 1.0]]])[np.arange(900) % 2]
    points = truth[:, 0] + t[:, None] * (truth[:, 1] - truth[:, 0]) + noise * rng.standard_normal((900, 2))
    return xy, keys, points


def test_a_spur_along_a_stem_goes():
    """The stem carried by two edges 5 degrees apart, one ending half-way
    up: the short one holds points the stem holds as well, and goes."""
    rng = np.random.default_rng(7)
    xy, keys, points = t_junction([1.0 + 0.5 * np.sin(np.radians(5)), 0.5 * np.cos(np.radians(5))], rng)
    kept = filtering.redundant_edges(keys, xy, nearest_edge_ids(points, xy, keys), points, np.ones(900))
    assert kept.tolist() == [True, True, True, False]


@pytest.mark.parametrize("angle", [30.0, 60.0])
def test_a_true_branch_keeps_its_edge(angle):
    """A third branch off the junction, with points of its own."""
    rng = np.random.default_rng(8)
    end = np.array([1.0 + 0.6 * np.sin(np.radians(angle)), 0.6 * np.cos(np.radians(angle))])
    xy, keys, points = t_junction(end, rng)
    t = rng.random(300)
    branch = xy[1] + t[:, None] * (end - xy[1]) + 0.01 * rng.standard_normal((300, 2))
    points = np.vstack([points, branch])
    kept = filtering.redundant_edges(keys, xy, nearest_edge_ids(points, xy, keys), points, np.ones(1200))
    assert kept.all()


def test_a_spur_ending_by_another_vertex_stays():
    """A spur along the bar that ends by the bar's far vertex: the remains of
    a thin triangle at that vertex, kept though the bar holds its points."""
    rng = np.random.default_rng(7)
    xy, keys, points = t_junction([0.1, 0.005], rng)
    kept = filtering.redundant_edges(keys, xy, nearest_edge_ids(points, xy, keys), points, np.ones(900))
    assert kept.all()


def test_an_open_end_is_not_a_spur():
    """A bend of 5 degrees at the last vertex of an open polyline: the end
    edge starts at a vertex of degree 2, not at a junction, and stays."""
    rng = np.random.default_rng(9)
    bend = np.radians(175)
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [1.0 + 0.5 * np.cos(bend), 0.5 * np.sin(bend)]])
    keys = [(0, 1), (1, 2)]
    points = np.c_[rng.random(400), 0.01 * rng.standard_normal(400)]
    kept = filtering.redundant_edges(keys, xy, nearest_edge_ids(points, xy, keys), points, np.ones(400))
    assert kept.all()


def redundant_from_scratch(keys, xy, edge_points, points, mass):
    """Oracle of redundant_edges: every round, every candidate's points measured
    against every other kept edge, the straight way."""
    kept = np.ones(len(keys), bool)
    seg = [(xy[a], xy[b]) for a, b in keys]
    w = [mass[ids] for ids in edge_points]
    total = sum(x.sum() for x in w)
    noise2 = sum(x @ filtering.segment_sqdist(points[ids], *seg[i]) for i, (x, ids) in
                 enumerate(zip(w, edge_points))) / total
    while True:
        alive = list(np.flatnonzero(kept))
        live = {keys[i] for i in alive}
        candidates = set()
        for i in alive:
            a, b = keys[i]
            for j in alive:
                c = set(keys[j]) - {a, b}
                if len(c) == 1 and tuple(sorted((a, *c))) in live and tuple(sorted((b, *c))) in live:
                    candidates.add(i)
            degree = {v: sum(v in k for k in live) for v in (a, b)}
            for end, junction in ((a, b), (b, a)):
                if degree[end] == 1 and degree[junction] >= 3:
                    others = {v for k in live for v in k} - {end}
                    nearest = min(others, key=lambda v: np.linalg.norm(xy[v] - xy[end]))
                    if nearest == junction:
                        candidates.add(i)
        if not candidates:
            return kept
        scores = {}
        for e in sorted(candidates):
            if not w[e].sum() > 0:
                scores[e] = 0.0
                continue
            p = points[edge_points[e]]
            d2 = np.min([filtering.segment_sqdist(p, *seg[i]) for i in alive if i != e], 0)
            scores[e] = float(w[e] @ d2) / float(w[e].sum())
        best = min(scores, key=lambda e: (scores[e], e))
        if scores[best] > filtering.CHORD_FACTOR * noise2:
            return kept
        kept[best] = False


@settings(max_examples=examples(100, 1000), deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_vertices=st.integers(3, 9), n_pendant=st.integers(0, 4),
       n_points=st.integers(20, 300), noise=st.sampled_from([0.002, 0.02, 0.1]))
def test_redundant_edges_match_the_oracle_on_random_graphs(seed, n_vertices, n_pendant, n_points, noise):
    """Many overlapping 3-cycles (a near-complete graph) and pendant edges
    (candidate spurs), points near some edges: the kept edges are exactly
    the oracle's, round after round of removals."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n_vertices + n_pendant, 2))
    keys = [(a, b) for a in range(n_vertices) for b in range(a + 1, n_vertices) if rng.random() < 0.8]
    keys += [(int(rng.integers(n_vertices)), n_vertices + i) for i in range(n_pendant)]
    if not keys:
        return
    on = rng.integers(0, len(keys), n_points)
    t = rng.random(n_points)
    ends = np.array([[xy[a], xy[b]] for a, b in keys])[on]
    points = ends[:, 0] + t[:, None] * (ends[:, 1] - ends[:, 0]) + noise * rng.standard_normal((n_points, 2))
    mass = rng.choice([0.0, 0.5, 1.0, 2.0], n_points, p=[0.1, 0.3, 0.4, 0.2])
    edge_points = nearest_edge_ids(points, xy, keys)
    if not mass.sum() > 0:
        return
    got = filtering.redundant_edges(keys, xy, edge_points, points, mass)
    np.testing.assert_array_equal(got, redundant_from_scratch(keys, xy, edge_points, points, mass))


def test_no_background_keeps_everything():
    rng = np.random.default_rng(3)
    points = rng.random((100, 2))
    seg = rng.random((5, 2, 2))
    none = estimate_background(datasets.star(1000, noise=0.01)[0])
    e, v = filtering.above_background(seg, rng.random((2, 2)), points, np.ones(100), none, 0.1)
    assert e.all() and v.all()


def test_a_band_of_background_alone_is_dropped():
    rng = np.random.default_rng(4)
    noise = rng.random((3000, 2))
    line = np.c_[rng.random(1000) * 0.6 + 0.2, 0.5 + 0.003 * rng.standard_normal(1000)]
    points = np.vstack([line, noise])
    est = estimate_background(points)
    assert est.found
    seg = np.array([[[0.2, 0.5], [0.8, 0.5]], [[0.2, 0.2], [0.8, 0.25]]])
    e, v = filtering.above_background(seg, np.array([[0.5, 0.8], [0.5, 0.5]]), points, np.ones(len(points)),
                                      est, 0.01)
    assert e.tolist() == [True, False] and v.tolist() == [False, True]


# --------------------------------------------------------- at the defaults
def output_segments(r):
    return metrics.edges_to_segments(r.vertices, r.edges)


@pytest.mark.parametrize("name", ["clean", "noise-1", "uneven"])
def test_the_automatic_filter_keeps_every_edge_of_a_shape_without_outliers(name):
    pts, truth = {"clean": lambda: datasets.star(250, noise=0.0, seed=0),
                  "noise-1": lambda: datasets.star(400, noise=0.01, seed=1),
                  "uneven": lambda: _uneven(800)}[name]()
    auto = otjax.reconstruct_curve(pts, n_vertices=10, seed=0)
    bare = otjax.reconstruct_curve(pts, n_vertices=10, seed=0, background="none")
    assert auto.history["background_fraction"] == 0
    np.testing.assert_array_equal(auto.edges, bare.edges)  # nothing was filtered
    np.testing.assert_array_equal(auto.vertices, bare.vertices)
    if name != "uneven":  # ten vertices cannot follow the sparse half: not the filter's doing
        d = truth["diagonal"]
        assert metrics.length_within(truth["segments"], output_segments(auto), 0.02 * d) > 0.97


def _uneven(n):
    pts, truth = datasets.star(n, noise=0.01, seed=2)
    keep = (pts[:, 0] < 0) | (np.random.default_rng(9).random(len(pts)) < 0.1)
    return pts[keep], truth


def test_the_automatic_filter_removes_outlier_edges():
    pts, truth = datasets.star(500, noise=0.02, seed=3)
    mixed, truth = datasets.with_outliers(pts, truth, 500, margin=0.2, seed=4)
    d = truth["diagonal"]
    auto = otjax.reconstruct_curve(mixed, n_vertices=10, seed=0)
    bare = otjax.reconstruct_curve(mixed, n_vertices=10, seed=0, background="none")
    assert auto.history["background_fraction"] == pytest.approx(0.5, abs=0.1)
    ours, theirs = output_segments(auto), output_segments(bare)

    def in_background(segs):
        # Edges whose ends and middle are all far from the shape.
        probes = np.concatenate([segs, segs.mean(1, keepdims=True)], 1).reshape(-1, 2)
        far = metrics.point_segment_distance(probes, truth["segments"]) > 0.05 * d
        return int(far.reshape(len(segs), 3).all(1).sum())

    assert in_background(ours) == 0 and in_background(theirs) >= 3
    precision = metrics.length_within(ours, truth["segments"], 0.03 * d)
    assert precision > max(0.5, 2 * metrics.length_within(theirs, truth["segments"], 0.03 * d))


def test_the_size_rule_picks_the_documented_queue():
    assert default_queue(LAZY_COLLAPSES + 10, 10) == "exhaustive"
    assert default_queue(LAZY_COLLAPSES + 11, 10) == "lazy"
    assert default_queue(EXHAUSTIVE_COLLAPSES + 10, 10) == "lazy"
    assert default_queue(EXHAUSTIVE_COLLAPSES + 11, 10) == "multiple-choice"
    assert default_queue(EXHAUSTIVE_COLLAPSES, None) == "exhaustive"  # tolerance mode: no known end
    assert default_queue(EXHAUSTIVE_COLLAPSES + 1, None) == "multiple-choice"
    pts, _ = datasets.star(100, noise=0.01)
    assert otjax.reconstruct_curve(pts, n_vertices=10).params["queue"] == "exhaustive"
    assert otjax.reconstruct_curve(pts, n_vertices=10, queue="parallel").params["queue"] == "parallel"


@pytest.mark.parametrize("n_points, target, expected", [
    (50, 10, 50), (300, 10, 300),  # every point up to 300
    (301, 10, 300), (900, 10, 300), (1000, 10, 334), (2000, 10, 667), (4530, 10, 1510), (4531, 10, 1511),
    (5999, 10, 2000),  # a third
    (6001, 10, 2000), (1_000_000, 10, 2000),  # at most 2000
    (3000, 150, 3000), (10_000, 150, 3000),  # 20 per target vertex
])
def test_the_initial_subset_rule(n_points, target, expected):
    assert default_initial_vertices(n_points, target) == expected
    # The documented queue follows for a 10-vertex target: exhaustive up to 4530 points, lazy above.
    if target == 10:
        assert default_queue(expected, target) == ("lazy" if n_points > 4530 else "exhaustive")


@pytest.mark.parametrize("n_points, target, expected", [
    (1000, 10, 1000), (2000, 10, 2000), (2001, 10, 2000), (1_000_000, 10, 2000), (10_000, 150, 3000),
])
def test_exact_samples_and_tolerance_mode_start_from_every_point_up_to_2000(n_points, target, expected):
    assert default_initial_vertices(n_points, target, noisy=False) == expected
    assert default_initial_vertices(n_points, None) == min(n_points, 2000)


def test_the_initial_subset_grows_with_the_input():
    sizes = np.arange(1, 8000)
    for target, noisy in itertools.product((None, 10, 40), (False, True)):
        counts = np.array([default_initial_vertices(int(n), target, noisy) for n in sizes])
        assert np.all(np.diff(counts) >= 0)  # never fewer vertices for more points
        assert np.all(counts <= sizes)
        assert np.all(np.diff(counts) <= 1)  # and no jump: one more point, at most one more vertex
