"""Shared helpers of the curve tests: engines on noisy shapes, the
from-scratch cost oracle, the padded reference kernel, recorded runs.

A helper module, not a test file: test files import from here, never from
each other.
"""

from __future__ import annotations

from collections import defaultdict

import jax
import numpy as np

from otjax.curves import cost
from otjax.curves.decimate import decimate
from otjax.curves.engine import CurveEngine
from otjax.curves.triangulation import Triangulation
from otjax.predicates import in_triangle_perturbed
from otjax.stencil import Buckets, pack_edge_stencils
from tests.oracles import oracle_edge_cost, oracle_segment_sqdist


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


def make_engine(rng, n=160, subset=0.6, zero_mass=0.1, **options) -> CurveEngine:
    """An engine over ``n`` noisy circle points, a random ``subset`` of them
    as vertices (points off the vertices exercise location), some massless."""
    pts = noisy_shape(rng, n)
    mass = rng.uniform(0.2, 2.0, n)
    mass[rng.random(n) < zero_mass] = 0.0
    keep = rng.random(n) < subset
    tri = Triangulation(np.unique(pts[keep], axis=0))
    return CurveEngine(tri, pts, mass, **options)


def free_vertices(engine: CurveEngine) -> list[int]:
    """Live, non-pinned vertex ids, increasing (computed from the triangulation)."""
    tri = engine.plan.tri
    return np.nonzero(tri.alive & ~tri.pinned)[0].tolist()


def check_scratch(engine: CurveEngine) -> float:
    """From-scratch cost of the engine's current triangulation."""
    plan = engine.plan
    return scratch_cost(plan.tri, plan.points, plan.mass)


def collapse_randomly(engine: CurveEngine, rng, steps):
    for _ in range(steps):
        half = engine.plan.tri.half_edges()
        s, d = half[rng.integers(len(half))]
        c = engine.candidate(s, d)
        _, rows = engine.score_candidates([c])
        engine.apply(c, rows[0])


def padded_reference(engine: CurveEngine, cands):
    """Scores host-located candidates with the plain padded kernel, one row each."""
    plan = engine.plan
    stencils = [(c.edges, plan.points[c.point_ids], plan.mass[c.point_ids], c.cand) for c in cands]
    batch = pack_edge_stencils(stencils, Buckets(max_batch=1 << max(len(cands) - 1, 0).bit_length(),
                                                 point_budget=2**62))
    with jax.enable_x64(True):
        return jax.device_get(cost.batched_stencil_cost(batch))


def assert_costs_match(cands, costs, ref):
    for i, (c, r) in enumerate(zip(cands, costs)):
        e, n = len(c.keys), len(c.point_ids)
        np.testing.assert_array_equal(r.assignment, ref.assignment[i, :n])
        np.testing.assert_array_equal(r.solid, ref.solid[i, :e])
        for name in ("edge_cost", "normal", "tangential", "vertex", "edge_mass"):
            np.testing.assert_allclose(getattr(r, name), getattr(ref, name)[i, :e], rtol=1e-12, atol=1e-15,
                                       err_msg=name)
        np.testing.assert_allclose(r.delta, ref.total[i] - c.before, rtol=1e-12, atol=1e-12)


def record_applied(engine: CurveEngine) -> list:
    """Wraps ``engine.apply`` (the instance's) to record each collapse and
    move in order: ``(source, target, new position or None)``."""
    applied = []
    apply = engine.apply

    def recording(cand, scored):
        applied.append((cand.plan.source, cand.plan.target, None if cand.moved is None else tuple(cand.moved)))
        return apply(cand, scored)

    engine.apply = recording
    return applied


def run_queue(engine: CurveEngine, queue, target=8, relocation=15):
    """``decimate``, recording each collapse and relocation in order."""
    applied = record_applied(engine)
    stats_ = decimate(engine, target, queue=queue, relocation=relocation, seed=2)
    return applied, stats_
