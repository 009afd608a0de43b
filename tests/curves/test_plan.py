"""The transport plan (state only) and the engine that fills it, against a
from-scratch recomputation, and its invariants; the Change an apply returns."""

import copy
import logging

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.curves.engine import CurveEngine
from otjax.curves.plan import Change, TransportPlan
from otjax.curves.triangulation import Triangulation, edge_key
from otjax.predicates import in_triangle_perturbed
from tests.curves.helpers import collapse_randomly, free_vertices, make_engine, noisy_shape, scratch_cost
from tests.point_sets import make_points
from tests.profiles import examples  # CI count, thorough count (--hypothesis-profile=thorough)

log = logging.getLogger(__name__)


def test_initial_plan_matches_scratch(rng):
    engine = make_engine(rng)
    plan = engine.plan
    assert plan.total_cost() == pytest.approx(scratch_cost(plan.tri, plan.points, plan.mass), rel=1e-9)
    assert engine.total_cost() == plan.total_cost()
    # Every point sits in exactly one triangle list: mass is conserved.
    listed = np.concatenate([ids for ids in plan.face_pts if len(ids)])
    assert np.array_equal(np.sort(listed), np.arange(len(plan.points)))


def test_the_plan_is_state_and_runs_no_kernel():
    """A bare plan locates and assigns points on the host (no x64 needed) and
    holds no edge costs; the engine's kernel sets them, matching scratch."""
    rng = np.random.default_rng(3)
    pts = noisy_shape(rng, 120)
    mass = rng.uniform(0.5, 1.5, len(pts))
    with jax.enable_x64(False):
        bare = TransportPlan(Triangulation(pts[::3]), pts, mass)
    assert bare.edge_cost == {} and bare.edge_solid == {} and bare.total_cost() == 0.0
    engine = CurveEngine(Triangulation(pts[::3]), pts, mass)
    np.testing.assert_array_equal(engine.plan.pt_edge, bare.pt_edge)
    np.testing.assert_array_equal(engine.plan.pt_face, bare.pt_face)
    assert set(engine.plan.edge_cost) == {tuple(k) for k in np.unique(bare.pt_edge, axis=0).tolist()}
    assert engine.total_cost() == pytest.approx(scratch_cost(bare.tri, pts, mass), rel=1e-9)
    # The kernel needs float64: an engine refuses to start without it.
    with jax.enable_x64(False), pytest.raises(RuntimeError, match="float64"):
        CurveEngine(Triangulation(pts[::3]), pts, mass)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_delta_equals_scratch_difference(seed):
    rng = np.random.default_rng(seed)
    engine = make_engine(rng)
    plan = engine.plan
    collapse_randomly(engine, rng, 40)  # reach a state where costs are non-trivial
    before = scratch_cost(plan.tri, plan.points, plan.mass)
    assert engine.total_cost() == pytest.approx(before, rel=1e-9)
    assert before > 0
    half = plan.tri.half_edges()
    pick = rng.choice(len(half), size=min(48, len(half)), replace=False)
    cands = [engine.candidate(*half[i]) for i in pick]
    assert all(c is not None for c in cands)
    delta, rows = engine.score_candidates(cands)
    flipped = 0
    for row, c in enumerate(cands):
        trial = copy.deepcopy(engine)
        trial.apply(c, rows[row])
        trial.plan.tri.check()
        after = scratch_cost(trial.plan.tri, trial.plan.points, trial.plan.mass)
        np.testing.assert_allclose(delta[row], after - before, rtol=1e-9, atol=1e-12 * before)
        np.testing.assert_allclose(trial.total_cost(), after, rtol=1e-9, atol=1e-12 * before)
        flipped += len(c.plan.clipped) > 0
    log.info("candidates needing flips: %d of %d", flipped, len(cands))


@settings(max_examples=examples(15, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["uniform", "duplicates", "near_collinear", "grid"]),
       seed=st.integers(0, 2**31 - 1))
def test_plan_invariants_under_collapses(kind, seed):
    rng = np.random.default_rng(seed)
    pts = make_points(kind, 120, seed)
    mass = rng.uniform(0.0, 1.0, len(pts))
    engine = CurveEngine(Triangulation(np.unique(pts, axis=0)), pts, mass)
    plan = engine.plan
    steps = min(60, int((plan.tri.alive & ~plan.tri.pinned).sum()) - 1)
    collapse_randomly(engine, rng, steps)
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


def test_apply_returns_what_the_change_touched():
    """A collapse's Change: the removed source and its ring, the vertices it
    touched (the ring and the far vertices across the new triangles' link
    whose shared link edges changed), the link edges of those far vertices,
    and the live free ones as dirty; the other far vertices quiet; a move's
    Change keeps its source."""
    rng = np.random.default_rng(21)
    engine = make_engine(rng, n=200)
    tri = engine.plan.tri
    s, t = next((s, t) for s, t in tri.half_edges() if engine.candidate(s, t) is not None)
    cand = engine.candidate(s, t)
    ring = tri.star(s)[0]
    _, (cost,) = engine.score_candidates([cand])
    change = engine.apply(cand, cost)
    assert isinstance(change, Change)
    assert (change.source, change.target, change.ring, change.moved) == (s, t, ring, False)
    assert not tri.alive[s] and s not in change.touched
    assert set(ring) <= change.touched
    assert change.dirty == frozenset(v for v in change.touched if tri.alive[v] and not tri.pinned[v])
    assert set(change.links) <= change.touched and not set(change.links) & set(ring)
    for v, keys in change.links.items():
        r = tri.star(v)[0]
        link = {edge_key(r[k], r[(k + 1) % len(r)]) for k in range(len(r))}
        assert keys <= link  # none: not a link change, a collapse of v gained or lost the link condition
    # The far vertices whose shared link edges kept their points and costs are quiet instead.
    assert not change.quiet & change.touched and not change.quiet & set(ring)
    # A move: its source stays, and is dirty (its own stencils changed).
    v = next(u for u in free_vertices(engine) if not set(tri.star(u)[0]) & set(np.nonzero(tri.pinned)[0]))
    move = engine.relocation_candidate(v, tri.xy[v] + 1e-4 * (tri.xy[tri.star(v)[0][0]] - tri.xy[v]))
    assert move is not None
    assert (move.plan.source, move.plan.target, move.plan.flipped_out) == (v, v, ())
    _, (mcost,) = engine.score_candidates([move])
    ring = tri.star(v)[0]
    moved = engine.apply(move, mcost)
    assert (moved.source, moved.target, moved.ring, moved.moved) == (v, v, ring, True)
    assert {v, *ring} <= moved.touched and v in moved.dirty
    np.testing.assert_array_equal(tri.xy[v], move.moved)
    assert engine.total_cost() == pytest.approx(scratch_cost(tri, engine.plan.points, engine.plan.mass),
                                                rel=1e-9)
