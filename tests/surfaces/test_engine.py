"""SurfaceEngine under the shared decimation loop: invariants after every collapse."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.decimation import decimate
from otjax.surfaces.engine import SurfaceEngine
from otjax.surfaces.plan import BinSettings, SurfacePlan
from tests.surfaces.complexes import delaunay_complex
from tests.surfaces.test_collapse_scoring import sphere_plan


def points_on(c, rng, per_facet=3):
    """Points on the complex's facets and near its vertices, slightly off."""
    tris = c.triangle_array()
    out = [c.positions[np.flatnonzero(c.alive)]]
    if len(tris):
        w = rng.dirichlet(np.ones(3), (len(tris), per_facet))
        out.append(np.einsum("tnk,tkd->tnd", w, c.positions[tris]).reshape(-1, 3))
    p = np.concatenate(out)
    return p + 0.01 * rng.standard_normal(p.shape)


def check_state(engine, running_cost):
    plan = engine.plan
    plan.complex.check()
    np.testing.assert_allclose(plan.point_mass(), plan.masses, rtol=1e-12, atol=0)
    scratch = plan.total_cost()
    assert scratch == pytest.approx(running_cost, rel=1e-9, abs=1e-12)
    for f in plan.facet_entries:
        assert f in plan.complex.triangles and f in plan.bins
    for v in plan.vertex_entries:
        assert plan.complex.alive[v]


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1), st.integers(5, 12), st.floats(0.2, 1.0), st.integers(1, 3))
def test_every_applied_collapse_keeps_the_complex_the_masses_and_the_cost(seed, n, keep, min_bins):
    rng = np.random.default_rng(seed)
    c = delaunay_complex(seed, n, keep)
    p = points_on(c, rng)
    plan = SurfacePlan(c, p, rng.uniform(0.5, 2.0, len(p)), BinSettings(np.sqrt(3), min_bins=min_bins, max_bins=4))
    engine = SurfaceEngine(plan, method="exact")
    cost = plan.total_cost()
    for _ in range(2):
        halves = c.half_edges()
        if not halves:
            break
        picks = [halves[i] for i in rng.choice(len(halves), min(3, len(halves)), replace=False)]
        targets = {}
        for s, t in picks:
            targets.setdefault(s, []).append(t)
        scored = engine.score(targets, targets)
        if not scored:
            continue
        key = min(scored, key=lambda kd: kd[1])[0]
        change = engine.apply(*engine.take([key])[0])
        assert not c.alive[key[0]] and change.target == key[1]
        assert {key[1], *c.neighbors(key[1])} <= change.dirty
        cost += change.delta
        check_state(engine, cost)


def strip_plan(nx=10, ny=3, per_facet=3, seed=0):
    """A triangulated ``nx x ny`` grid on z = 0 (a long strip) and noisy points on it."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float), indexing="ij")
    v = np.c_[x.ravel(), y.ravel(), np.zeros(nx * ny)]
    i = lambda a, b: a * ny + b  # noqa: E731
    tris = [t for a in range(nx - 1) for b in range(ny - 1)
            for t in ([i(a, b), i(a + 1, b), i(a + 1, b + 1)], [i(a, b), i(a + 1, b + 1), i(a, b + 1)])]
    from otjax.surfaces.complex import SimplicialComplex
    c = SimplicialComplex(v, np.array(tris))
    rng = np.random.default_rng(seed)
    p = points_on(c, rng, per_facet) + [0, 0, 0]
    return SurfacePlan(c, p, np.ones(len(p)), BinSettings(float(nx), min_bins=1, max_bins=3))


def test_scores_outside_the_dirty_set_do_not_change():
    plan = strip_plan()
    engine = SurfaceEngine(plan, method="exact")
    c = plan.complex
    before = dict(engine.score(np.flatnonzero(c.alive).tolist()))
    key = min((h for h in before if c.positions[h[0], 0] < 1.5), key=before.get)
    versions = list(engine.versions)
    change = engine.apply(*engine.take([key])[0])
    after = dict(engine.score(np.flatnonzero(c.alive).tolist()))
    bumped = {v for v in range(len(versions)) if engine.versions[v] != versions[v]}
    assert bumped - {key[0]} == set(change.dirty)
    untouched = [h for h in after if h[0] not in bumped]
    assert len(untouched) > 20  # the strip is longer than the dirty region
    for h in untouched:
        assert after[h] == pytest.approx(before[h], rel=1e-9, abs=1e-12), h
    # and the collapse did change scores inside it
    assert any(after.get(h) != pytest.approx(d, rel=1e-6) for h, d in before.items() if h[0] in change.dirty)


@pytest.mark.parametrize("queue", ["exhaustive", "multiple-choice", "parallel", "lazy"])
def test_decimate_drives_the_engine_to_the_target(queue):
    plan = sphere_plan(seed=2, n_vertices=12, n_points=60, min_bins=1)
    engine = SurfaceEngine(plan, method="exact")
    cost = plan.total_cost()
    stats = decimate(engine, 8, queue=queue, choices=6, seed=1)
    assert plan.complex.n_vertices == 8 and stats.collapses == 4
    assert engine.stats()["scored"] >= 4
    assert plan.total_cost() >= cost - 1e-12  # a collapse never lowers the optimum of a relaxed plan much
    check_state(engine, plan.total_cost())
    dead = int(np.flatnonzero(~plan.complex.alive)[0])
    assert not engine.movable(dead) and engine.propose_moves([dead]) == []


def test_a_move_changes_the_cost_by_its_delta_and_no_score_outside_its_dirty_set():
    plan = strip_plan(seed=1)
    c = plan.complex
    c.move(4, c.positions[4] + [0.1, -0.1, 0.3])  # lifted off the strip's points: it has somewhere to go
    engine = SurfaceEngine(plan, method="exact")
    before = dict(engine.score(np.flatnonzero(c.alive).tolist()))
    cost = plan.total_cost()
    (v, delta, scored), = engine.propose_moves([4])
    lifted = c.positions[4].copy()
    assert v == 4 and delta < 0 and np.array_equal(c.positions[4], lifted)  # proposing moves nothing
    versions = list(engine.versions)
    change = engine.apply(*scored)
    assert change.vertex == 4 and c.positions[4, 2] < 0.3 and change.delta == pytest.approx(delta, rel=1e-9)
    check_state(engine, cost + change.delta)
    bumped = {u for u in range(len(versions)) if engine.versions[u] != versions[u]}
    assert bumped == set(change.dirty) and {4, *c.neighbors(4)} <= bumped
    after = dict(engine.score(np.flatnonzero(c.alive).tolist()))
    untouched = [h for h in after if h[0] not in bumped]
    assert len(untouched) > 20
    for h in untouched:
        assert after[h] == pytest.approx(before[h], rel=1e-9, abs=1e-12), h
    assert any(after.get(h) != pytest.approx(d, rel=1e-6) for h, d in before.items() if h[0] in change.dirty)


def test_decimate_relocates_after_each_collapse_and_keeps_the_plan():
    plan = sphere_plan(seed=2, n_vertices=12, n_points=60, min_bins=1)
    engine = SurfaceEngine(plan, method="exact")
    start = plan.complex.positions.copy()
    stats = decimate(engine, 8, queue="exhaustive", relocation=100)
    assert plan.complex.n_vertices == 8 and stats.collapses == 4 and stats.relocations > 0
    check_state(engine, plan.total_cost())
    alive = plan.complex.alive
    assert np.any(plan.complex.positions[alive] != start[alive])


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1), st.integers(5, 12), st.floats(0.3, 1.0), st.booleans())
def test_scoring_the_cheapest_only_finds_the_same_cheapest_collapse(seed, n, keep, with_veto):
    rng = np.random.default_rng(seed)
    c = delaunay_complex(seed, n, keep)
    p = points_on(c, rng)
    plan = SurfacePlan(c, p, rng.uniform(0.5, 2.0, len(p)), BinSettings(np.sqrt(3), min_bins=1, max_bins=4))
    halves = c.half_edges()
    if not halves:
        return
    targets = {}
    for s, t in (halves[i] for i in rng.choice(len(halves), min(12, len(halves)), replace=False)):
        targets.setdefault(s, []).append(t)
    full = dict(SurfaceEngine(plan, method="exact").score(targets, targets))
    veto = None
    if with_veto and full:  # refuse the cheapest: the bound must then beat the second
        banned = min(full, key=full.get)
        veto = (lambda cand, scored: (cand.source, cand.target) != banned)
        full.pop(banned)
    engine = SurfaceEngine(plan, method="exact")
    cheap = dict(engine.score(targets, targets, veto=veto, cheapest_only=True))
    assert bool(cheap) == bool(full)
    if not full:
        return
    assert min(cheap.values()) == pytest.approx(min(full.values()), rel=1e-9, abs=1e-12)
    for key, delta in cheap.items():
        assert delta == pytest.approx(full[key], rel=1e-9, abs=1e-12)
    assert engine.counts["scored"] + engine.counts["pruned"] >= len(full)
