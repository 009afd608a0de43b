"""Open ends moved to where their points end: the position from the points
(against direct formulas), which vertices move (against the degrees of the
solid edges), the plan after the moves (against from-scratch costs), and the
ends of reconstructed open curves (against the truth)."""

from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import otjax
from otjax import datasets
from otjax.curves.decimate import decimate
from otjax.curves.end_fit import MIN_END_POINTS, end_position, fit_ends, open_ends
from otjax.curves.engine import CurveEngine
from otjax.curves.plan_result import point_holders, vertex_and_edge_masses
from otjax.curves.triangulation import Triangulation
from tests.curves.helpers import check_scratch

ORIGIN = np.zeros(2)


def bent_line(rng, n, noise):
    """``n`` points along (0, 0) - (1, 0) - (1, 0.6), uniform by length, with Gaussian noise."""
    s = rng.random(n) * 1.6
    pts = np.where(s[:, None] < 1, np.c_[s, 0 * s], np.c_[np.ones(n), s - 1])
    return pts + noise * rng.standard_normal((n, 2))


def decimated_open(seed, n=240, keep=6):
    rng = np.random.default_rng(seed)
    pts = bent_line(rng, n, 0.01)
    engine = CurveEngine(Triangulation(pts[::3]), pts, rng.uniform(0.5, 1.5, n))
    decimate(engine, keep)
    return engine


def test_the_end_goes_past_the_farthest_point_by_the_mean_spacing():
    # Noise-free points of [0, 1] on a line: k points, the last at 1, spacing 1 / (k - 1).
    x = np.linspace(0.0, 1.0, 41)
    on_edge, own = np.c_[x[:30], 0 * x[:30]], np.c_[x[30:], 0 * x[30:]]
    got = end_position(on_edge, own, np.array([0.8, 0.0]), ORIGIN)
    np.testing.assert_allclose(got, [1.0 + 1.0 / 40, 0.0], rtol=1e-12)


def test_the_end_vertexs_points_off_the_edges_line_do_not_count():
    # A branch leaves the line at x = 0.8 at 45 degrees; its points project up to x = 1.3.
    x = np.linspace(0.0, 0.8, 81)
    branch = np.linspace(0.05, 0.5, 10)
    own = np.r_[np.c_[x[70:], 0 * x[70:]], np.c_[0.8 + branch, branch]]
    got = end_position(np.c_[x[:70], 0 * x[:70]], own, np.array([0.7, 0.0]), ORIGIN)
    np.testing.assert_allclose(got, [0.8 + 0.8 / 80, 0.0], rtol=1e-12)  # the line's points alone


def test_too_few_points_or_a_zero_length_edge_give_no_position():
    pts = np.c_[np.linspace(0, 1, MIN_END_POINTS), np.zeros(MIN_END_POINTS)]
    assert end_position(pts[:-1], np.zeros((0, 2)), np.array([1.0, 0.0]), ORIGIN) is None
    assert end_position(pts[:1], pts[1:], np.array([1.0, 0.0]), ORIGIN) is None  # one point on the edge
    assert end_position(pts, np.zeros((0, 2)), ORIGIN, ORIGIN) is None
    assert end_position(pts, np.zeros((0, 2)), np.array([1.0, 0.0]), ORIGIN) is not None


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31 - 1), st.floats(0, 2 * np.pi), st.floats(-1e3, 1e3), st.floats(1e-3, 1e3),
       st.floats(0.0, 0.05))
def test_the_end_moves_with_the_points(seed, angle, shift, scale, noise):
    """Rotating, translating and scaling the points and the edge does the same to the end."""
    rng = np.random.default_rng(seed)
    k = int(rng.integers(MIN_END_POINTS, 60))
    x = np.sort(rng.random(k))
    pts = np.c_[x, noise * rng.standard_normal(k)]
    cut = int(rng.integers(2, k + 1))
    end, other = np.array([x[cut - 1], 0.0]), np.array([-0.1 * rng.random(), 0.0])
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    move = (lambda p: scale * p @ rot.T + shift)  # noqa: E731
    base = end_position(pts[:cut], pts[cut:], end, other)
    moved = end_position(move(pts[:cut]), move(pts[cut:]), move(end), move(other))
    assert base is not None and moved is not None
    np.testing.assert_allclose(moved, move(base), rtol=1e-9, atol=1e-9 * (abs(shift) + scale))


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_fit_ends_moves_the_open_ends_along_their_edges_and_keeps_the_plan_exact(seed):
    engine = decimated_open(seed)
    plan, tri = engine.plan, engine.plan.tri
    # The ends from the solid edges' masses, pinned corners left out.
    edge_mass, _ = vertex_and_edge_masses(plan)
    shape = [e for e, m in edge_mass.items() if m > 0 and not (tri.pinned[e[0]] or tri.pinned[e[1]])]
    degree = Counter(v for e in shape for v in e)
    expect = {v: (b if a == v else a) for a, b in shape for v in (a, b) if degree[v] == 1}
    solid, keys, _ = point_holders(plan)
    assert open_ends(plan, solid, keys) == expect and expect

    xy = tri.xy.copy()
    moved = fit_ends(engine)
    assert moved == len(expect)
    changed = {v for v in range(len(xy)) if np.any(tri.xy[v] != xy[v])}
    assert changed == set(expect)
    for v, o in expect.items():  # along the edge's line, by less than the edge is long
        before, after = xy[v] - xy[o], tri.xy[v] - xy[o]
        assert abs(before[0] * after[1] - before[1] * after[0]) <= 1e-9 * np.dot(before, before)
        assert np.linalg.norm(after - before) < np.linalg.norm(before)
    tri.check()
    assert engine.total_cost() == pytest.approx(check_scratch(engine), rel=1e-9)


def end_errors(result, truth):
    ends = np.asarray(truth["ends"])
    return np.min(np.linalg.norm(ends[:, None] - result.vertices[None], axis=2), 1) / truth["diagonal"]


def test_reconstructed_open_curves_end_nearer_the_true_ends():
    """The X/T junctions (five free ends), three seeds: with the fit the ends are
    nearer on average and on every seed no worse by more than a point spacing."""
    on, off = [], []
    for seed in range(3):
        pts, truth = datasets.junctions(800, noise=0.005, seed=seed)
        fitted = otjax.reconstruct_curve(pts, n_vertices=9, seed=seed)
        plain = otjax.reconstruct_curve(pts, n_vertices=9, seed=seed, fit_ends=False)
        assert fitted.params["fit_ends"] and fitted.history["ends_fitted"] >= 3
        assert plain.history["ends_fitted"] == 0
        on.append(end_errors(fitted, truth))
        off.append(end_errors(plain, truth))
        assert on[-1].mean() <= off[-1].mean() + 1 / 800
    assert np.mean(on) < 0.75 * np.mean(off)


def test_in_tolerance_mode_the_fitted_ends_keep_the_bound():
    pts, _ = datasets.junctions(600, noise=0.005, seed=4)
    tol = 0.03
    r = otjax.reconstruct_curve(pts, tolerance=tol)
    assert r.history["ends_fitted"] > 0
    length2 = ((r.vertices[r.edges[:, 0]] - r.vertices[r.edges[:, 1]]) ** 2).sum(1)
    rms = np.sqrt(length2 / r.edge_relevance)  # sqrt((N + T) / M) per kept edge
    assert np.all(rms <= np.sqrt(2) * tol * (1 + 1e-9))
