"""Topology invariants of the triangulation under collapses and flips."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.predicates import orient, orient_perturbed, orient_scalar
from otjax.curves.collapse import _Corners, plan_flips, plan_flips_from
from otjax.curves.triangulation import Triangulation
from tests.point_sets import make_points, point_sets
from tests.profiles import examples  # CI count, thorough count (--hypothesis-profile=thorough)

SETTINGS = settings(max_examples=examples(40, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])


def unique_rows(p):
    return np.unique(p, axis=0)


def random_collapses(t: Triangulation, rng, steps: int):
    """Collapses random eligible half-edges; returns (done, refused)."""
    done = refused = 0
    for _ in range(steps):
        half = t.half_edges()
        if not half:
            break
        s, d = half[rng.integers(len(half))]
        plan = t.plan_collapse(s, d)
        if plan is None:
            refused += 1
            continue
        assert len(plan.clipped) <= len(plan.ring) - 3  # termination bound
        v_before, f_before = t.n_vertices, len(t.triangles())
        t.collapse(plan)
        t.check()
        assert t.n_vertices == v_before - 1
        assert len(t.triangles()) == f_before - 2  # a vertex, three edges, two triangles
        done += 1
    return done, refused


@SETTINGS
@given(pts=point_sets, seed=st.integers(0, 2**31 - 1))
def test_collapses_keep_an_embedding(pts, seed):
    t = Triangulation(unique_rows(pts))
    t.check()
    n_interior = int((t.alive & ~t.pinned).sum())
    done, refused = random_collapses(t, np.random.default_rng(seed), 200)
    # Every eligible half-edge is made collapsible by flips: none refused, and
    # the loop only stops when one interior vertex is left (no eligible edge).
    assert refused == 0
    assert done == min(200, max(n_interior - 1, 0))


@SETTINGS
@given(pts=point_sets, seed=st.integers(0, 2**31 - 1))
def test_flips_planned_together_match_flips_planned_alone(pts, seed):
    """plan_flips_from shares a source's star between its targets: each
    target's flips are still those of planning it alone (pinned and
    non-adjacent targets included), on hostile inputs too."""
    t = Triangulation(unique_rows(pts))
    random_collapses(t, np.random.default_rng(seed), 20)
    corners = np.flatnonzero(t.pinned).tolist()
    for s in np.flatnonzero(t.alive & ~t.pinned).tolist():
        ring = t.star(s)[0]
        far = [v for v in np.flatnonzero(t.alive).tolist() if v != s and v not in ring][:1]
        targets = [*ring, *corners[:1], *far]
        together = plan_flips_from(t, s, targets)
        assert together == [plan_flips_from(t, s, (w,))[0] for w in targets]
        assert together == [plan_flips(t, s, w) for w in targets]
        for w, flips in zip(targets, together):
            assert (flips is None) == (t.pinned[w] or w not in ring)
    assert plan_flips_from(t, corners[0], [0]) == [None]


@SETTINGS
@given(pts=point_sets, seed=st.integers(0, 2**31 - 1))
def test_shared_ear_tests_match_their_definition(pts, seed):
    """_Corners answers a corner's ear tests once per source for every
    polygon cut from the ring: the same answers as testing that polygon."""
    t = Triangulation(unique_rows(pts))
    rng = np.random.default_rng(seed)
    random_collapses(t, rng, 10)
    xyl = t.xy_list

    def orient_ids(a, b, c):  # the oracle: the predicate itself, not collapse.py's inlined filter
        return orient_scalar(*xyl[a], *xyl[b], *xyl[c])

    for s in np.flatnonzero(t.alive & ~t.pinned).tolist()[:20]:
        ring = t.star(s)[0]
        corners = _Corners(xyl, s, ring)
        for _ in range(3):  # polygons: subsequences of the ring, shared memo
            poly = [v for v in ring if rng.random() < 0.7]
            for j in range(len(poly) if len(poly) >= 3 else 0):
                c, a, b = poly[j - 1], poly[j], poly[(j + 1) % len(poly)]
                convex = orient_ids(c, a, b) > 0
                assert corners.flips(c, a, b) == (convex and orient_ids(s, c, b) > 0)
                empty = not any(orient_ids(c, a, x) >= 0 and orient_ids(a, b, x) >= 0
                                and orient_ids(b, c, x) >= 0 for x in poly if x not in (c, a, b))
                assert corners.clips(c, a, b, poly) == (convex and empty)


def test_initial_triangulation_is_delaunay_and_complete(rng):
    p = rng.random((300, 2))
    t = Triangulation(p)
    t.check()
    assert t.n_vertices == 304
    # Euler for a triangulated disk with 4 boundary vertices: F = 2V - 2 - 4.
    assert len(t.triangles()) == 2 * 304 - 6


@pytest.mark.parametrize("kind", ["near_collinear", "clustered", "duplicates", "grid"])
def test_degenerate_inputs_build_valid_triangulations(kind):
    for seed in range(5):
        t = Triangulation(unique_rows(make_points(kind, 200, seed)))
        t.check()


def test_flip_procedure_needed_and_sufficient():
    """A half-edge whose direct collapse folds over is fixed by flips (paper Fig. 7)."""
    # A vertex whose ring has a reflex-blocking edge towards one neighbour.
    rng = np.random.default_rng(3)
    needed = 0
    for seed in range(30):
        t = Triangulation(rng.random((60, 2)))
        for s, d in t.half_edges():
            ring, _ = t.star(s)
            if not t.in_kernel(ring, d):
                plan = t.plan_collapse(s, d)
                assert plan is not None and len(plan.clipped) >= 1
                t.collapse(plan)
                t.check()
                needed += 1
                break
    assert needed >= 10


def test_orient_is_exact_near_zero():
    # Points on a line with coordinates that are not exactly representable
    # combinations: the float determinant is noise, the exact one decides.
    a = np.array([0.5, 0.5])
    b = np.array([12.0, 12.0])
    c = np.array([24.0, 24.0])
    assert orient(a, b, c) == 0
    nudged = np.array([24.0, np.nextafter(24.0, 25.0)])
    assert orient(a, b, nudged) == 1
    assert orient(b, a, nudged) == -1
    # Classic failure case of naive float orientation (Kettner et al. style).
    p = np.array([0.5 + k * 2.0**-53 for k in range(64)])
    q = np.array([[x, x] for x in p])
    s = orient(np.array([12.0, 12.0]), np.array([24.0, 24.0]), q)
    assert (s == 0).all()


def test_perturbed_orientation_never_zero_for_proper_edges(rng):
    a = rng.random((1000, 2))
    b = a + rng.standard_normal((1000, 2))
    p = a.copy()  # on the edge's endpoint: plain orientation is zero
    s = orient_perturbed(a, b, p)
    assert (s != 0).all()
    assert (orient_perturbed(b, a, p) == -s).all()
