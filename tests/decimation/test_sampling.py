"""Live vertices, uniform half-edge draws, lock sets and independent sets."""

import itertools
from collections import Counter

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from otjax.decimation.sampling import IndependentSet, LiveVertices, lock_set, sample_half_edges
from tests.decimation.fake_engines import GraphEngine, random_cycle


@settings(max_examples=200, deadline=None)
@given(ids=st.lists(st.integers(0, 10**6), unique=True, max_size=60), data=st.data())
def test_live_vertices_remove_in_constant_time_and_stay_consistent(ids, data):
    live = LiveVertices(ids)
    assert live.ids == ids  # the given order, until removals
    gone = data.draw(st.lists(st.sampled_from(ids), unique=True) if ids else st.just([]))
    left = set(ids)
    for v in gone:
        live.remove(v)
        left.discard(v)
        assert len(live) == len(left) and v not in live
    assert set(live.ids) == left and len(live.ids) == len(left)
    assert all(live.where[v] == i for i, v in enumerate(live.ids))
    assert all(v in live for v in left)


graphs = st.integers(2, 12).flatmap(lambda n: st.tuples(
    st.lists(st.lists(st.integers(0, n - 1), unique=True, max_size=7), min_size=n, max_size=n),
    st.sets(st.integers(0, n - 1)),
    st.integers(1, 6)))


@settings(max_examples=200, deadline=None)
@given(graph=graphs, k=st.integers(1, 12), seed=st.integers(0, 2**32 - 1), data=st.data())
def test_sampled_half_edges_are_distinct_eligible_and_at_most_k(graph, k, seed, data):
    rings, pinned, bound = graph
    n = len(rings)
    engine = GraphEngine({v: [w for w in r if w != v] for v, r in enumerate(rings)}, pinned, bound)
    sources = [v for v in range(n) if v not in pinned]
    live = LiveVertices(sources)
    n_live = data.draw(st.none() | st.integers(0, len(sources)))
    got = sample_half_edges(engine, live, np.random.default_rng(seed), k, n_live=n_live)
    pool = sources if n_live is None else live.ids[:n_live]
    assert len(got) == len(set(got)) <= k
    assert set(got) <= engine.eligible(pool)
    if not engine.eligible(pool):
        assert got == []


def test_sampled_half_edges_are_uniform_over_the_eligible_ones():
    """Mixed degrees (some over the bound), pinned targets: every eligible
    half-edge is drawn, none other, with the same frequency (chi-square)."""
    rng = np.random.default_rng(0)
    n = 30
    rings = {v: [int(w) for w in rng.choice(np.delete(np.arange(n), v), int(rng.integers(2, 9)), replace=False)]
             for v in range(n)}
    engine = GraphEngine(rings, pinned={0, 1, 2}, degree_bound=6)
    live = LiveVertices(range(3, n))
    eligible = engine.eligible(live.ids)
    assert any(len(r) > 6 for r in rings.values())  # some sources are over the bound
    assert any(w in engine.pinned for v in live.ids for w in rings[v] if len(rings[v]) <= 6)
    counts = Counter()
    for _ in range(20_000):
        (h,) = sample_half_edges(engine, live, rng, 1)
        counts[h] += 1
    assert set(counts) == eligible
    assert stats.chisquare([counts[h] for h in sorted(eligible)]).pvalue > 1e-3
    # The first n_live vertices only.
    first = set(live.ids[:5])
    drawn = {h for _ in range(500) for h in sample_half_edges(engine, live, rng, 3, n_live=5)}
    assert drawn == engine.eligible(first)


def test_sampling_asks_for_more_than_there_is():
    engine = random_cycle(0, 10, n_pinned=0)
    live = LiveVertices(engine.live_sources())
    got = sample_half_edges(engine, live, np.random.default_rng(1), 100)
    assert sorted(got) == sorted((v, w) for v in range(10) for w in engine.ring(v))


def test_lock_set_is_the_closed_star():
    engine = GraphEngine({0: (1, 2, 3), 1: (0, 2), 2: (0, 1), 3: (0,)})
    assert lock_set(engine, 0) == {0, 1, 2, 3}
    assert lock_set(engine, 3) == {0, 3}


@settings(max_examples=200, deadline=None)
@given(locks=st.lists(st.sets(st.integers(0, 15), min_size=1, max_size=5), max_size=25))
def test_an_independent_set_admits_what_shares_at_most_one_vertex_with_each_member(locks):
    chosen = IndependentSet()
    members = []
    for lock in locks:
        want = all(len(lock & m) <= 1 for m in members)
        assert chosen.admits(lock) == want
        if want:
            chosen.add(lock)
            members.append(lock)
    assert chosen.size == len(members)
    for a, b in itertools.combinations(members, 2):
        assert len(a & b) <= 1
