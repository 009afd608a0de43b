"""The filtered JAX point location against the exact host predicate."""

from fractions import Fraction
from unittest import mock

import jax
import numpy as np
import pytest

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.curves import location
from otjax.curves.location import CHUNK, MIN_PAIRS, locate_pairs
from otjax.curves.triangulation import Triangulation
from otjax.predicates import in_triangle_perturbed, orient_perturbed
from tests.point_sets import make_points
from tests.profiles import examples  # CI count, thorough count (--hypothesis-profile=thorough)


def rows(tri: np.ndarray, p: np.ndarray):
    """``(N, 3, 2)``, ``(N, 2)`` -> the planar layout of :func:`locate_pairs`."""
    return np.ascontiguousarray(tri.reshape(-1, 6).T), np.ascontiguousarray(p.T)


def all_pairs(tri: Triangulation, queries: np.ndarray):
    t = tri.xy[tri.triangles()]
    i, j = np.meshgrid(np.arange(len(queries)), np.arange(len(t)), indexing="ij")
    return t[j.ravel()], queries[i.ravel()]


@settings(max_examples=examples(100, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["uniform", "near_collinear", "clustered", "duplicates", "grid"]),
       n=st.integers(8, 60), seed=st.integers(0, 10_000))
def test_filtered_location_equals_the_exact_predicate(kind, n, seed):
    rng = np.random.default_rng(seed)
    pts = make_points(kind, n, seed)
    tri = Triangulation(np.unique(pts, axis=0))
    # Queries on vertices, on edge midpoints (often inexact), at random.
    t = tri.triangles()
    mid = (tri.xy[t[:, 0]] + tri.xy[t[:, 1]]) / 2
    inner = tri.xy[tri.alive & ~tri.pinned]
    span = float(np.ptp(inner, axis=0).max()) or 1.0  # the box is relative to the data
    queries = np.concatenate([inner, mid, pts + 1e-3 * span * rng.standard_normal(pts.shape)])
    a, p = all_pairs(tri, queries)
    want = in_triangle_perturbed(a, p)
    got = locate_pairs(*rows(a, p))
    np.testing.assert_array_equal(got, want)
    # Both paths whatever the size: the filter in the kernel, in NumPy.
    np.testing.assert_array_equal(locate_pairs(*rows(a, p), min_pairs=0), want)
    np.testing.assert_array_equal(locate_pairs(*rows(a, p), min_pairs=len(p) + 1), want)
    # Each query is in exactly one triangle.
    assert np.all(got.reshape(len(queries), -1).sum(1) == 1)


def test_filtered_location_over_chunk_boundaries():
    rng = np.random.default_rng(1)
    n = 5 * CHUNK + 12_345  # several chunks, the last one padded
    a = rng.random((n, 3, 2))
    u, v = a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]
    flip = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] < 0
    a[flip] = a[flip][:, [0, 2, 1]]
    p = rng.random((n, 2))
    p[::7] = a[::7, 1]  # exactly on a corner: the perturbation decides
    np.testing.assert_array_equal(locate_pairs(*rows(a, p)), in_triangle_perturbed(a, p))


@settings(max_examples=examples(100, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["uniform", "near_collinear", "clustered", "duplicates", "grid"]),
       n=st.integers(8, 60), seed=st.integers(0, 10_000), collapses=st.integers(0, 5))
def test_whole_triangulation_location_equals_the_exact_predicate(kind, n, seed, collapses):
    """``Triangulation.locate`` (nearest vertex's star, then a full scan)
    against the exact predicate over every triangle, before and after
    collapses (which change the stars)."""
    from otjax.curves.collapse import plan_collapse

    rng = np.random.default_rng(seed)
    pts = make_points(kind, n, seed)
    tri = Triangulation(np.unique(pts, axis=0))
    for _ in range(collapses):
        free = np.flatnonzero(tri.alive & ~tri.pinned)
        for v in rng.permutation(free):
            ring, _ = tri.star(int(v))
            plans = [plan_collapse(tri, int(v), int(u)) for u in ring]
            plans = [pl for pl in plans if pl is not None]
            if plans:
                tri.collapse(plans[0])
                break
    t = tri.triangles()
    inner_edge = ~(tri.pinned[t[:, 0]] & tri.pinned[t[:, 1]])  # the box's own edges bound the domain
    mid = (tri.xy[t[inner_edge, 0]] + tri.xy[t[inner_edge, 1]]) / 2
    span = float(np.ptp(pts, axis=0).max()) or 1.0
    queries = np.concatenate([tri.xy[tri.alive & ~tri.pinned], mid, pts,
                              pts + 1e-3 * span * rng.standard_normal(pts.shape)])
    a, p = all_pairs(tri, queries)
    inside = in_triangle_perturbed(a, p).reshape(len(queries), len(t))
    assert (inside.sum(1) == 1).all()
    ids = np.asarray(tri.triangle_ids())
    np.testing.assert_array_equal(tri.locate(queries), ids[inside.argmax(1)])


def degenerate_pairs(rng, n: int, lattice: bool) -> tuple[np.ndarray, np.ndarray]:
    """``(n, 3, 2)`` mostly CCW triangles and ``(n, 2)`` points on or by their edges.

    Points on an edge's line (inside the edge or beyond it) rounded, then
    moved by a few ulps; on a vertex; on the lattice (exactly collinear,
    where the perturbation decides); and at random. ``lattice`` puts the
    corners on a coarse power-of-two lattice, where many differences and
    products are exact.
    """
    scale = 2.0 ** rng.integers(-20, 20)
    offset = rng.choice([0.0, 1.0, 1e3]) * scale * rng.standard_normal(2)  # rounded translations
    if lattice:
        tri = rng.integers(-4, 5, size=(n, 3, 2)) * scale
    else:
        tri = offset + rng.standard_normal((n, 3, 2)) * scale
    u, v = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    flip = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] < 0
    tri[flip] = tri[flip][:, [0, 2, 1]]
    edge = rng.integers(0, 3, n)
    a, b = tri[np.arange(n), edge], tri[np.arange(n), (edge + 1) % 3]
    kind = rng.integers(0, 5, n)
    t = rng.choice([0.0, 0.25, 0.5, 1.0, 1.5, -0.5], n) if lattice else rng.uniform(-0.5, 1.5, n)
    p = a + t[:, None] * (b - a)
    ulps = rng.integers(-2, 3, size=(n, 2))
    nudge = kind == 1
    # Not off zero: a subnormal coordinate, which the kernel flushes to zero
    # (XLA on CPU), is outside what the library asks about.
    p[nudge] = p[nudge] + np.where(p[nudge] != 0, ulps[nudge] * np.spacing(np.abs(p[nudge])), 0.0)
    p[kind == 2] = tri[kind == 2, rng.integers(0, 3)]
    lo, hi = tri.min((0, 1)), tri.max((0, 1))
    p[kind == 3] = lo + rng.random(((kind == 3).sum(), 2)) * (hi - lo)
    return tri, p


@settings(max_examples=examples(100, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.one_of(st.integers(1, 80), st.integers(MIN_PAIRS - 8, 2 * MIN_PAIRS)), lattice=st.booleans(),
       seed=st.integers(0, 2**32 - 1))
def test_degenerate_location_equals_the_exact_predicate(n, lattice, seed):
    """Points on, within ulps of, and beyond the triangles' edges, on their
    vertices: every path of :func:`locate_pairs` (filter in the kernel or in
    NumPy, unsure pairs settled one at a time or vectorised) gives the exact
    predicate's answer, pair for pair."""
    tri, p = degenerate_pairs(np.random.default_rng(seed), n, lattice)
    want = in_triangle_perturbed(tri, p)
    np.testing.assert_array_equal(locate_pairs(*rows(tri, p)), want)
    for scalar_pairs in (0, n):
        with mock.patch.object(location, "SCALAR_PAIRS", scalar_pairs):
            np.testing.assert_array_equal(locate_pairs(*rows(tri, p), min_pairs=n + 1), want)
            np.testing.assert_array_equal(locate_pairs(*rows(tri, p), min_pairs=0), want)


@pytest.mark.parametrize("seed", range(4))
def test_points_outside_their_nearest_vertex_star_are_located_exactly(seed):
    """A triangulation of 40 of 3000 points: many points lie in no triangle of
    their nearest vertex's star (tried next: the stars of the next nearest,
    then every triangle); every answer matches the exhaustive test."""
    rng = np.random.default_rng(seed)
    pts = rng.random((3000, 2)) * [4.0, 1.0]
    tri = Triangulation(pts[:40])
    t = tri.triangles()
    a, p = all_pairs(tri, pts)
    inside = in_triangle_perturbed(a, p).reshape(len(pts), len(t))
    ids = np.asarray(tri.triangle_ids())
    want = ids[inside.argmax(1)]
    live = np.flatnonzero(tri.alive)
    nearest = live[np.argmin(((pts[:, None] - tri.xy[live][None]) ** 2).sum(-1), 1)]
    in_star = np.array([v in tri.tri[f] for v, f in zip(nearest, want)])
    assert (~in_star).sum() >= 10  # the case under test occurs
    np.testing.assert_array_equal(tri.locate(pts), want)


def _adaptive(a, b, p):
    """:func:`location.orient_adaptive` of ``(N, 2)`` rows, jitted, as NumPy."""
    f = jax.jit(location.orient_adaptive)
    pos, neg = f(a[:, 0], a[:, 1], b[:, 0], b[:, 1], p[:, 0], p[:, 1])
    return np.asarray(pos), np.asarray(neg)


@settings(max_examples=examples(100, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(1, 200), lattice=st.booleans(), seed=st.integers(0, 2**32 - 1))
def test_adaptive_orientation_equals_the_exact_predicate(n, lattice, seed):
    """On points on, within ulps of and beyond triangle edges, and on their
    vertices, every orientation the adaptive stages decide is the exact
    perturbed one, and the point-in-triangle codes built on them are too."""
    tri, p = degenerate_pairs(np.random.default_rng(seed), n, lattice)
    with jax.enable_x64(True):
        for k in range(3):
            a, b = tri[:, k], tri[:, (k + 1) % 3]
            pos, neg = _adaptive(a, b, p)
            want = orient_perturbed(a, b, p)
            assert not np.any(pos & neg)
            np.testing.assert_array_equal(want[pos], 1)
            np.testing.assert_array_equal(want[neg], -1)
        code = np.asarray(jax.jit(location.in_triangle_adaptive)(np.ascontiguousarray(tri.reshape(-1, 6).T),
                                                                 p[:, 0], p[:, 1]))
    inside = in_triangle_perturbed(tri, p)
    assert np.all(inside[code == location.INSIDE])
    assert not np.any(inside[code == location.OUTSIDE])


def test_adaptive_orientation_decides_what_the_filter_cannot():
    """Points rounded onto segments between random points, on lattice lines,
    and a few ulps off them: the float filter leaves most orientations unsure;
    the adaptive stages decide all but a handful, each as the exact predicate."""
    rng = np.random.default_rng(7)
    n = 30_000
    a, b = rng.uniform(-1, 1, (n, 2)), rng.uniform(-1, 1, (n, 2))
    p = a + rng.random(n)[:, None] * (b - a)
    grid = slice(0, n // 3)  # exactly collinear: dyadic coordinates, exact differences
    a[grid], b[grid] = np.round(a[grid] * 64) / 64, np.round(b[grid] * 64) / 64
    p[grid] = a[grid] + np.round(rng.random(n // 3) * 8)[:, None] / 8 * (b[grid] - a[grid])
    off = slice(n // 3, 2 * n // 3)
    p[off] += rng.integers(-3, 4, (n // 3, 2)) * np.spacing(np.abs(p[off]))
    want = orient_perturbed(a, b, p)
    with jax.enable_x64(True):
        pos, neg = _adaptive(a, b, p)
        f_pos, f_neg = location._orient_perturbed_filtered(*a.T, *b.T, *p.T, xp=np)
    assert (~(f_pos | f_neg)).mean() > 0.5
    decided = pos | neg
    assert decided.mean() > 0.999
    np.testing.assert_array_equal(np.where(pos, 1, np.where(neg, -1, 0))[decided], want[decided])


@settings(max_examples=examples(100, 1000), deadline=None)
@given(x=st.lists(st.floats(-1e150, 1e150, allow_nan=False, allow_infinity=False), min_size=4, max_size=4))
def test_dekker_products_are_exact(x):
    """``x + y`` is the exact product, for factors zero or above the
    predicate's floor (below it, the predicate leaves a pair to the host)."""
    a, b, c, d = (np.float64(v) if abs(v) > location._TINY else np.float64(0.0) for v in x)
    with jax.enable_x64(True):
        products = jax.jit(location._two_products)(a, b, c, d)
    for (x, y), (u, v) in zip(products, ((a, b), (c, d))):
        assert Fraction(float(x)) + Fraction(float(y)) == Fraction(float(u)) * Fraction(float(v))
