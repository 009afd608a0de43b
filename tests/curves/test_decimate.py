"""The greedy queues over the curve engine: sampling against the uniform law
(chi-square), a parallel round against the sum of its deltas and a
from-scratch recomputation, the queues' end states, prefetching, seeds."""

from collections import Counter

import numpy as np
import pytest
from scipy import stats

import otjax
from otjax.curves.decimate import decimate
from otjax.curves.engine import CurveEngine
from otjax.curves.plan_result import vertex_and_edge_masses
from otjax.curves.triangulation import Triangulation
from otjax.decimation.sampling import IndependentSet, LiveVertices, lock_set, sample_half_edges
from tests.curves.helpers import check_scratch, free_vertices, make_engine, noisy_shape, run_queue, scratch_cost


# ------------------------------------------------------------------ sampling
def eligible_half_edges(engine):
    tri = engine.plan.tri
    out = []
    for u in np.nonzero(tri.alive & ~tri.pinned)[0]:
        ring = tri.star(int(u))[0]
        if len(ring) <= engine.degree_bound:
            out += [(int(u), w) for w in ring if not tri.pinned[w]]
    return out


def test_sampled_half_edges_are_uniform_and_eligible():
    rng = np.random.default_rng(4)
    pts = rng.random((25, 2))
    engine = CurveEngine(Triangulation(pts), pts, np.ones(len(pts)))
    everything = eligible_half_edges(engine)
    live = LiveVertices(engine.live_sources())
    assert sorted(live.ids) == free_vertices(engine)
    counts = Counter()
    for _ in range(3000):
        got = sample_half_edges(engine, live, rng, 3)
        assert len(set(got)) == len(got) == 3
        assert set(got) <= set(everything)
        counts.update(got[:1])  # the first draw of each sample is one uniform draw
    observed = np.array([counts[h] for h in everything])
    assert stats.chisquare(observed).pvalue > 1e-3, "first draws are not uniform over half-edges"


# ------------------------------------------------------------------ queues
def independent_round(engine):
    """The parallel queue's selection rule, applied to every candidate."""
    cands = engine.candidates(free_vertices(engine))
    delta, rows_ = engine.score_candidates(cands)
    chosen, independent = [], IndependentSet()
    for i in np.argsort(delta, kind="stable"):
        lock = lock_set(engine, cands[i].plan.source)
        if independent.admits(lock):
            chosen.append(i)
            independent.add(lock)
    return cands, delta, rows_, chosen


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_an_independent_round_changes_the_cost_by_the_sum_of_its_deltas(seed):
    engine = make_engine(np.random.default_rng(seed), n=200)
    before = engine.total_cost()
    cands, delta, rows_, chosen = independent_round(engine)
    assert len(chosen) >= 5
    for i in chosen:
        engine.apply(cands[i], rows_[i])
    engine.plan.tri.check()
    after = engine.total_cost()
    assert after - before == pytest.approx(delta[chosen].sum(), rel=1e-9, abs=1e-12)
    assert after == pytest.approx(check_scratch(engine), rel=1e-9, abs=1e-15)


@pytest.mark.parametrize("queue", ["multiple-choice", "parallel"])
def test_queues_keep_the_embedding_and_an_exact_plan(queue):
    rng = np.random.default_rng(8)
    pts = noisy_shape(rng, 600)
    mass = rng.uniform(0.5, 2.0, len(pts))
    keep = np.sort(rng.choice(len(pts), 300, replace=False))  # a random subset as vertices
    engine = CurveEngine(Triangulation(pts[keep]), pts, mass)
    plan = engine.plan
    stats_ = decimate(engine, 12, queue=queue, relocation=20, seed=1)
    plan.tri.check()
    assert int((plan.tri.alive & ~plan.tri.pinned).sum()) == 12
    assert engine.total_cost() == pytest.approx(scratch_cost(plan.tri, pts, mass), rel=1e-9)
    if queue == "parallel":
        assert stats_.rounds < stats_.collapses
    else:
        assert stats_.switched_at == 60  # 5 x the target
    # Every point is located in a live triangle that holds it.
    faces = plan.pt_face
    assert all(plan.tri.tri[f] is not None for f in np.unique(faces))


def test_prefetching_the_next_draw_changes_nothing_but_the_caches():
    def run(prefetch):
        rng = np.random.default_rng(15)
        pts = noisy_shape(rng, 500)
        engine = CurveEngine(Triangulation(pts[::2]), pts, np.ones(len(pts)))
        engine.prefetch = prefetch(engine)  # the instance's: what the loop calls
        return run_queue(engine, "multiple-choice", target=10, relocation=10)

    prefetched = []

    def counting(engine):
        prefetch = engine.prefetch

        def spy(half_edges):
            half_edges = list(half_edges)
            prefetched.extend(half_edges)
            prefetch(half_edges)

        return spy

    with_prefetch, stats_ = run(counting)
    without, _ = run(lambda engine: (lambda half_edges: None))
    assert with_prefetch == without
    assert len(prefetched) > 5 * stats_.switched_at  # it did read ahead, most steps


def test_multiple_choice_scores_far_fewer_candidates():
    pts, _ = otjax.datasets.star(600, noise=0.01, seed=9)
    # Every point a vertex: a run long enough that the exhaustive end (from
    # 5x the target on) is a small part of it.
    mc = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", relocation=0, initial_vertices=600)
    ex = otjax.reconstruct_curve(pts, n_vertices=10, queue="exhaustive", relocation=0, initial_vertices=600)
    assert mc.history["switched_at"] == 50
    # A step scores at most `choices` half-edges until the switch. Updates
    # on changed link edges (exhaustive loop) count as evaluations too.
    def evaluated(r):
        return r.history["scored"] + r.history["updated"]

    assert evaluated(mc) < evaluated(ex) / 3


def test_same_seed_same_multiple_choice_result_and_seed_matters():
    pts, _ = otjax.datasets.star(400, noise=0.01, seed=10)
    a = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", initial_vertices=200, seed=3)
    b = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", initial_vertices=200, seed=3)
    c = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", initial_vertices=200, seed=4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.edges, b.edges)
    assert a.total_cost == b.total_cost
    assert not np.array_equal(a.vertices, c.vertices)  # another subset, other draws


def test_subset_initialisation_transports_every_point():
    rng = np.random.default_rng(11)
    pts, _ = otjax.datasets.star(1200, noise=0.01, seed=11)
    mass = rng.uniform(0.5, 1.5, len(pts))
    keep = np.sort(rng.choice(len(pts), 300, replace=False))
    engine = CurveEngine(Triangulation(pts[keep]), pts, mass)
    decimate(engine, 10, queue="multiple-choice", seed=0)
    edge_mass, vertex_mass = vertex_and_edge_masses(engine.plan)
    # Every point is sent somewhere: to a solid edge or to a vertex.
    assert sum(edge_mass.values()) + sum(vertex_mass.values()) == pytest.approx(mass.sum(), rel=1e-12)
    r = otjax.reconstruct_curve(pts, mass, n_vertices=10, initial_vertices=300, relocation=0,
                                final_relocations=0)
    assert r.params["initial_vertices"] == 300
    assert r.history["collapses"] == 300 - 10


@pytest.mark.parametrize("bad, message", [
    ({"queue": "random"}, "queue"),
    ({"choices": 0}, "choices"),
    ({"initial_vertices": 5}, "initial_vertices"),
    ({"initial_vertices": 2.5}, "initial_vertices"),
])
def test_bad_queue_parameters_are_named(bad, message):
    pts, _ = otjax.datasets.star(200, noise=0.01)
    with pytest.raises(ValueError, match=message):
        otjax.reconstruct_curve(pts, n_vertices=10, **bad)


def test_curve_decimate_needs_a_target_or_a_tolerance():
    engine = make_engine(np.random.default_rng(1), n=60)
    with pytest.raises(ValueError, match="n_vertices, tolerance"):
        decimate(engine)
    with pytest.raises(ValueError, match="n_vertices must be >= 1"):
        decimate(engine, 0)


def one_at_a_time(engine):
    """Makes ``engine`` score each proposed move in a kernel call of its own."""
    batched = engine.propose_moves

    def propose_moves(vertices):
        return [p for v in vertices for p in batched([v])]

    engine.propose_moves = propose_moves
    return engine


@pytest.mark.parametrize("seed", [0, 1])
def test_relocation_after_every_collapse_is_the_same_batched_or_not(seed):
    import jax

    from otjax.decimation.relocation import relocate

    with jax.enable_x64(True):
        a = make_engine(np.random.default_rng(seed), n=200)
        b = one_at_a_time(make_engine(np.random.default_rng(seed), n=200))
        sa = decimate(a, 40, relocation=10**6)
        sb = decimate(b, 40, relocation=10**6)
        assert sa.relocations == sb.relocations > 0
        # A pass over every vertex, batched, against visiting them one by one.
        vertices = a.live_sources()
        moved = relocate(a, vertices).moved
        for v in vertices:
            relocate(b, [v])
    assert a.scorer.calls < b.scorer.calls  # the batched side did share calls
    np.testing.assert_array_equal(a.plan.tri.xy, b.plan.tri.xy)  # bitwise
    np.testing.assert_array_equal(a.plan.pt_edge, b.plan.pt_edge)
    assert a.total_cost() == b.total_cost()
