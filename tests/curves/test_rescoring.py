"""Re-scoring only what changed: the change log's versions and link changes,
link updates and partial updates against full re-scorings.

The stencils of these small cases are below the size that makes an update
worth it (``update_min_rows``); the properties under test hold for any
threshold, so the engines here update everything (``update_min_rows=0``).
"""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.curves.decimate import decimate
from otjax.curves.engine import CurveEngine
from otjax.curves.triangulation import Triangulation, edge_key
from tests.curves.helpers import check_scratch, make_engine, noisy_shape, run_queue
from tests.profiles import examples  # CI count, thorough count (--hypothesis-profile=thorough)


def link_of(tri, v):
    ring = tri.star(v)[0]
    return {tuple(sorted((ring[k], ring[(k + 1) % len(ring)]))) for k in range(len(ring))}


@settings(max_examples=examples(12, 1000), deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(queue=st.sampled_from(["exhaustive", "parallel"]), n=st.integers(60, 220), seed=st.integers(0, 10_000),
       subset=st.sampled_from([0.5, 1.0]))
def test_link_updates_make_the_same_greedy_as_full_rescoring(queue, n, seed, subset):
    def engine(incremental):
        rng = np.random.default_rng(seed)
        pts = noisy_shape(rng, n)
        mass = rng.uniform(0.2, 2.0, n)
        keep = rng.random(n) < subset
        tri = Triangulation(np.unique(pts[keep], axis=0) if subset < 1 else pts)
        return CurveEngine(tri, pts, mass, incremental=incremental, update_min_rows=0)

    full, full_stats = run_queue(engine(False), queue)
    updated, stats_ = run_queue(engine(True), queue)
    # The same changes in the same order: every score, exact ties included,
    # is the same as a full re-scoring's.
    assert updated == full
    assert full_stats.updated == 0 < stats_.updated
    assert full_stats.partial == 0 < stats_.partial
    assert stats_.scored < full_stats.scored


@pytest.mark.parametrize("seed", [12, 13])
def test_each_link_update_equals_a_full_scoring(seed):
    rng = np.random.default_rng(seed)
    pts = noisy_shape(rng, 200)
    mass = rng.uniform(0.5, 2.0, len(pts))
    engine = CurveEngine(Triangulation(pts[::2]), pts, mass, update_min_rows=0)
    tri = engine.plan.tri
    checked = []
    finish_links = engine.links.finish_links

    def checking(items, parts, costs):
        out = finish_links(items, parts, costs)
        for (rec, changed), (new, delta) in zip(items, out):
            v, w = rec.plan.source, rec.plan.target
            # The star kept its triangles; what changed lies on its link.
            assert changed and changed <= link_of(tri, v)
            cands = engine.candidates([v], {v: [w]})  # located on the host: another path
            _, (cost,) = engine.score_candidates(cands)
            np.testing.assert_array_equal(new.keys, cands[0].keys)
            np.testing.assert_allclose(new.edge_cost, cost.edge_cost, rtol=1e-12, atol=1e-15)
            assert delta == pytest.approx(cost.delta, rel=1e-12, abs=1e-14)
            checked.append(delta)
        return out

    engine.links.finish_links = checking
    stats_ = decimate(engine, 10, queue="exhaustive", relocation=20)
    assert stats_.updated == len(checked) > 100
    tri.check()
    assert engine.total_cost() == pytest.approx(check_scratch(engine), rel=1e-9)


@pytest.mark.parametrize("seed", [12, 16])
def test_each_partial_update_equals_a_full_scoring(seed):
    """After a ring vertex moved, the collapse re-scored on the part the move
    reaches has the full kernel scoring's edge costs bit for bit, and its
    record the full scoring's triangle and edge of every point."""
    rng = np.random.default_rng(seed)
    pts = noisy_shape(rng, 500)
    mass = rng.uniform(0.5, 2.0, len(pts))
    engine = CurveEngine(Triangulation(pts[::2]), pts, mass, update_min_rows=0)
    checked, smaller = [], []
    finish = engine.links.finish_partial

    def checking(pending, cand, scored):
        rec, delta = finish(pending, cand, scored)
        v, w = rec.plan.source, rec.plan.target
        rows = len(rec.inside) + len(engine.stencils.region(v).outside)
        assert len(cand.point_ids) <= rows
        smaller.append(len(cand.point_ids) < rows)
        _, full_delta, (cost,) = engine.score_batches(engine.exports([v], {v: [w]}))
        np.testing.assert_array_equal(rec.edge_cost, cost.edge_cost)
        n = len(rec.inside)
        np.testing.assert_array_equal(rec.triangle, cost.triangle[:n])
        np.testing.assert_array_equal(rec.edge, cost.assignment[:n])
        assert delta == pytest.approx(full_delta[0], rel=1e-12, abs=1e-14)
        checked.append(delta)
        return rec, delta

    engine.links.finish_partial = checking
    stats_ = decimate(engine, 10, queue="exhaustive", relocation=40)
    assert stats_.partial == len(checked) > 50
    assert sum(smaller) > len(smaller) / 2  # most are a part of the stencil only
    engine.plan.tri.check()
    assert engine.total_cost() == pytest.approx(check_scratch(engine), rel=1e-9)


@pytest.mark.parametrize("seed, step", [(12, 2), (17, 2), (12, 1)])
def test_quiet_vertices_keep_every_score(seed, step):
    """A vertex a change leaves quiet (across the changed region, each link
    edge it shares with it kept its points and its cost) has, after the
    change, the same admissible collapses at the same costs, bit for bit, as
    before it, each scored from scratch (caches dropped). With every point a
    vertex (``step`` 1) many link edges carry no point before or after: a
    far vertex across one is quiet too."""
    rng = np.random.default_rng(seed)
    pts = noisy_shape(rng, 300)
    mass = rng.uniform(0.5, 2.0, len(pts))
    engine = CurveEngine(Triangulation(pts[::step]), pts, mass)
    tri = engine.plan.tri
    apply = engine.apply
    checked = []

    def scores(v):
        engine.stencils.forget(v)
        cands, delta, _ = engine.score_batches(engine.exports([v]))
        return {c.plan.target: d for c, d in zip(cands, delta.tolist())}

    def checking(cand, cost):
        ring = [u for u in cand.plan.ring if tri.alive[u] and not tri.pinned[u]]
        near = {a for u in ring for a in tri.star(u)[0]} - set(cand.plan.ring) - {cand.plan.source}
        before = {a: scores(a) for a in sorted(near) if engine.stencils.collapsible_source(a)}
        empty = {k for k in map(tuple, cand.keys.tolist()) if k not in engine.plan.edge_cost}
        change = apply(cand, cost)
        for a in change.quiet:
            if engine.stencils.collapsible_source(a):
                r = tri.star(a)[0]
                through_empty.append(bool({edge_key(x, y) for x, y in zip(r, r[1:] + r[:1])} & empty))
                assert scores(a) == before[a]
                checked.append(a)
        return change

    through_empty: list = []
    engine.apply = checking
    decimate(engine, 10, queue="exhaustive", relocation=20)
    assert len(checked) > 100
    if step == 1:
        assert sum(through_empty) > 50
    tri.check()
    assert engine.total_cost() == pytest.approx(check_scratch(engine), rel=1e-9)


def test_changed_links_reports_star_changes_as_none():
    rng = np.random.default_rng(14)
    engine = make_engine(rng, n=200)
    tri = engine.plan.tri
    version = list(engine.log.version)
    stars = {v: tri.star(v) for v in range(len(tri.xy)) if tri.alive[v] and not tri.pinned[v]}
    s, t = next((s, t) for s, t in tri.half_edges() if engine.candidate(s, t) is not None)
    cand = engine.candidate(s, t)
    _, (cost,) = engine.score_candidates([cand])

    def admissible(v):
        return {x: engine.stencils.collapse_plan(v, x) is not None for x in tri.star(v)[0]}

    before = {v: admissible(v) for v in stars if engine.stencils.collapsible_source(v)}
    dirty = engine.apply(cand, cost).dirty
    for v in dirty:
        changed = engine.log.changed_links(v, version[v])
        if v in cand.plan.ring:
            assert changed is None
        else:
            assert tri.star(v) == stars[v]  # same ring, same faces
            assert changed is not None and changed <= link_of(tri, v)
            if not changed:  # no link edge changed: a collapse gained or lost the link condition
                assert admissible(v) != before[v]
            assert engine.log.changed_links(v, engine.log.version[v]) == set()
    for v in set(stars) - dirty - {s}:
        assert tri.star(v) == stars[v]
    # The loop reads the same versions: what the change touched moved on.
    assert engine.versions is engine.log.version
    assert all(engine.versions[v] > version[v] for v in dirty)
    assert all(engine.versions[v] == version[v] for v in set(stars) - dirty - {s})
