"""The transport plan against a from-scratch recomputation, and its invariants."""

import copy
import logging
from collections import defaultdict

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.curves.plan import TransportPlan
from otjax.curves.predicates import in_triangle_perturbed
from otjax.curves.triangulation import Triangulation
from tests.oracles import oracle_edge_cost, oracle_segment_sqdist
from tests.point_sets import make_points

log = logging.getLogger(__name__)


def scratch_cost(tri: Triangulation, points, mass) -> float:
    """Total squared-W2 cost recomputed from nothing but the triangles.

    Brute-force location of every point over all triangles, nearest edge of
    its triangle (ties to the smaller key), then the oracle edge costs.
    """
    faces = tri.triangles()
    corners = tri.xy[faces]
    groups = defaultdict(list)
    for i, p in enumerate(points):
        hit = np.nonzero(in_triangle_perturbed(corners, p[None, :]))[0]
        assert len(hit) == 1, "a point must lie in exactly one triangle"
        f = faces[hit[0]]
        keys = sorted(tuple(sorted((int(f[k]), int(f[(k + 1) % 3])))) for k in range(3))
        d = [oracle_segment_sqdist(p, tri.xy[a], tri.xy[b]) for a, b in keys]
        groups[keys[int(np.argmin(d))]].append(i)
    total = 0.0
    for (a, b), ids in groups.items():
        n, t, v = oracle_edge_cost(tri.xy[a], tri.xy[b], points[ids], mass[ids])
        solid = mass[ids].sum() > 0 and np.any(tri.xy[a] != tri.xy[b]) and n + t < v
        total += n + t if solid else v
    return total


def noisy_shape(rng, n):
    t = rng.random(n)
    square = np.stack([np.cos(2 * np.pi * t), np.sin(2 * np.pi * t)], 1)
    return square + 0.03 * rng.standard_normal((n, 2))


def make_plan(rng, n=160, subset=0.6, zero_mass=0.1):
    pts = noisy_shape(rng, n)
    mass = rng.uniform(0.2, 2.0, n)
    mass[rng.random(n) < zero_mass] = 0.0
    keep = rng.random(n) < subset  # points off the vertices exercise location
    tri = Triangulation(np.unique(pts[keep], axis=0))
    return TransportPlan(tri, pts, mass)


def collapse_randomly(plan, rng, steps):
    for _ in range(steps):
        half = plan.tri.half_edges()
        s, d = half[rng.integers(len(half))]
        c = plan.candidate(s, d)
        _, rows = plan.score([c])
        plan.apply(c, rows[0])


def test_initial_plan_matches_scratch(rng):
    plan = make_plan(rng)
    assert plan.total_cost() == pytest.approx(scratch_cost(plan.tri, plan.points, plan.mass), rel=1e-9)
    # Every point sits in exactly one triangle list: mass is conserved.
    listed = np.concatenate([ids for ids in plan.face_pts if len(ids)])
    assert np.array_equal(np.sort(listed), np.arange(len(plan.points)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_delta_equals_scratch_difference(seed):
    rng = np.random.default_rng(seed)
    plan = make_plan(rng)
    collapse_randomly(plan, rng, 40)  # reach a state where costs are non-trivial
    before = scratch_cost(plan.tri, plan.points, plan.mass)
    assert plan.total_cost() == pytest.approx(before, rel=1e-9)
    assert before > 0
    half = plan.tri.half_edges()
    pick = rng.choice(len(half), size=min(48, len(half)), replace=False)
    cands = [plan.candidate(*half[i]) for i in pick]
    assert all(c is not None for c in cands)
    delta, rows = plan.score(cands)
    flipped = 0
    for row, c in enumerate(cands):
        trial = copy.deepcopy(plan)
        trial.apply(c, rows[row])
        trial.tri.check()
        after = scratch_cost(trial.tri, trial.points, trial.mass)
        np.testing.assert_allclose(delta[row], after - before, rtol=1e-9, atol=1e-12 * before)
        np.testing.assert_allclose(trial.total_cost(), after, rtol=1e-9, atol=1e-12 * before)
        flipped += len(c.plan.clipped) > 0
    log.info("candidates needing flips: %d of %d", flipped, len(cands))


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["uniform", "duplicates", "near_collinear", "grid"]),
       seed=st.integers(0, 2**31 - 1))
def test_plan_invariants_under_collapses(kind, seed):
    rng = np.random.default_rng(seed)
    pts = make_points(kind, 120, seed)
    mass = rng.uniform(0.0, 1.0, len(pts))
    plan = TransportPlan(Triangulation(np.unique(pts, axis=0)), pts, mass)
    steps = min(60, int((plan.tri.alive & ~plan.tri.pinned).sum()) - 1)
    collapse_randomly(plan, rng, steps)
    plan.tri.check()
    # Mass conserved: every point listed once, in the triangle that holds it.
    listed = np.concatenate([ids for ids in plan.face_pts if len(ids)])
    assert np.array_equal(np.sort(listed), np.arange(len(pts)))
    xy = plan.tri.xy
    for f, ids in enumerate(plan.face_pts):
        if len(ids):
            assert plan.tri.tri[f] is not None
            assert in_triangle_perturbed(xy[plan.tri.tri[f]][None], pts[ids]).all()
    assert plan.total_cost() == pytest.approx(scratch_cost(plan.tri, pts, mass), rel=1e-9, abs=1e-15)


def test_compiled_shapes_stay_few_over_2000_collapses():
    """2000 collapses, dirty candidates re-scored in one batch after each."""
    rng = np.random.default_rng(7)
    n = 2300
    pts = noisy_shape(rng, n)
    plan = TransportPlan(Triangulation(np.unique(pts, axis=0)), pts, np.ones(n))
    dirty = {int(v) for v in np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0][:64]}
    for _ in range(2000):
        cands, _delta, rows = plan.score_batches(plan.exports(sorted(dirty)))  # every half-edge out of them
        pick = int(rng.integers(len(cands)))
        dirty = plan.apply(cands[pick], rows[pick])
    log.info("compiled shapes: %s", sorted(plan.shapes_seen))
    print("distinct compiled shapes:", len(plan.shapes_seen), sorted(plan.shapes_seen))
    assert len(plan.shapes_seen) <= 12
