"""The score table: fresh and stale entries, pop order, ties."""

from collections import Counter

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.decimation.score_table import ScoreTable


def table(n=10, tie_rng=None):
    versions = [0] * n
    t = ScoreTable(versions, tie_rng)
    t.use_heap = True
    return t, versions


def pop_all(t, live=lambda v: True):
    """Pops until empty, discarding each popped key (as the loop does)."""
    out = []
    while (key := t.pop(live)) is not None:
        out.append(key)
        t.discard([key])
    return out


def test_fresh_until_the_source_moves_on():
    t, versions = table()
    t.enter([((1, 2), 0.5), ((3, 4), 0.25)], order=lambda k: k)
    assert t.fresh((1, 2)) and t.fresh((3, 4)) and not t.fresh((2, 1))
    versions[1] += 1
    assert not t.fresh((1, 2)) and t.fresh((3, 4))
    assert t.delta((1, 2)) == 0.5  # a stale score is still readable
    versions[4] += 1  # the target's version does not matter
    assert t.fresh((3, 4))
    t.enter([((1, 2), 0.75)], order=lambda k: k)
    assert t.fresh((1, 2)) and t.delta((1, 2)) == 0.75
    t.discard([(1, 2), (9, 9)])  # unknown keys are ignored
    assert not t.fresh((1, 2))


def test_pop_skips_stale_dead_and_discarded_entries():
    t, versions = table()
    t.enter([((0, 1), 3.0), ((2, 3), 1.0), ((4, 5), 2.0), ((6, 7), 0.5), ((8, 9), 4.0)], order=lambda k: k)
    versions[6] += 1  # (6, 7) stale: skipped
    t.discard([(4, 5)])  # taken elsewhere
    assert t.pop(lambda v: v != 2) == (0, 1)  # (2, 3) not live: skipped, and consumed
    assert t.pop(lambda v: True) == (8, 9)
    assert t.pop(lambda v: True) is None
    # A stale entry scored again is pushed at its new score.
    t.enter([((6, 7), 0.1)], order=lambda k: k)
    assert t.pop(lambda v: True) == (6, 7)


def test_without_the_heap_entries_are_kept_but_not_queued():
    versions = [0] * 4
    t = ScoreTable(versions)
    assert not t.use_heap
    t.enter([((0, 1), 1.0)], order=None)
    assert t.fresh((0, 1)) and t.pop(lambda v: True) is None
    t.use_heap = True
    t.push((0, 1))
    assert t.pop(lambda v: True) == (0, 1)


def test_exact_ties_pop_in_insertion_order():
    t, _ = table(40)
    keys = [(v, v + 1) for v in range(0, 40, 2)]
    # One batch pushed in the order given (the loop: source, then ring order) ...
    t.enter([(k, 0.0) for k in keys], order=lambda k: -k[0])
    # ... then a later batch: after the first among equal scores.
    t.enter([((1, 0), 0.0), ((3, 2), -1.0)], order=lambda k: k)
    assert pop_all(t) == [(3, 2)] + sorted(keys, key=lambda k: -k[0]) + [(1, 0)]


def test_seeded_random_ties():
    """With a generator, exact ties pop in a random order set by its seed;
    different scores still pop by score."""
    keys = [(v, v + 1) for v in range(0, 60, 2)]

    def order(seed):
        t, _ = table(64, np.random.default_rng(seed))
        t.enter([(k, 0.0) for k in keys] + [((61, 60), -1.0), ((63, 62), 1.0)], order=lambda k: k)
        return pop_all(t)

    a, b, c = order(1), order(1), order(2)
    assert a == b and a != c
    for got in (a, c):
        assert got[0] == (61, 60) and got[-1] == (63, 62)
        assert sorted(got[1:-1]) == keys and got[1:-1] != keys  # all of them, not in insertion order


@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_pop_order_is_score_then_push_order_over_fresh_live_keys(data):
    n = data.draw(st.integers(1, 12))
    t, versions = table(n)
    keys = data.draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), unique=True, max_size=30))
    scores = data.draw(st.lists(st.sampled_from([0.0, 0.5, 1.0, -2.0]), min_size=len(keys), max_size=len(keys)))
    cut = data.draw(st.integers(0, len(keys)))
    pushed = []  # push order: each batch sorted by its order function
    for batch in (list(zip(keys, scores))[:cut], list(zip(keys, scores))[cut:]):
        t.enter(batch, order=lambda k: (-k[1], k[0]))
        pushed += sorted((k for k, _ in batch), key=lambda k: (-k[1], k[0]))
    bumped = data.draw(st.sets(st.integers(0, n - 1)))
    for v in bumped:
        versions[v] += 1
    dead = data.draw(st.sets(st.integers(0, n - 1)))
    score = dict(zip(keys, scores))
    want = sorted((k for k in pushed if k[0] not in bumped | dead), key=lambda k: (score[k], pushed.index(k)))
    assert pop_all(t, lambda v: v not in dead) == want
    assert t.pop(lambda v: True) is None  # stale and dead entries were consumed


def rounds_of(n: int):
    """Rounds of (scores entered, sources bumped, whether one pop follows)."""
    return st.lists(st.tuples(
        st.lists(st.tuples(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)),
                           st.sampled_from([0.0, 0.5, 1.0, -2.0])), max_size=12),
        st.sets(st.integers(0, n - 1)), st.booleans()), min_size=1, max_size=8)


def replay(rounds, n: int, compact_min: int, lazy: bool) -> list:
    """Plays ``rounds`` on a fresh table that sweeps its heap from
    ``compact_min`` items on, then pops it empty; returns what came up, in
    order (keys from ``pop``; with ``lazy``, ``(key, fresh)`` from
    ``pop_any`` over a table that keeps stale items)."""
    import otjax.decimation.score_table as module

    saved = module.COMPACT_MIN
    module.COMPACT_MIN = compact_min
    try:
        t, versions = table(n)
        t.keep_stale = lazy
        out = []

        def take():
            item = t.pop_any(lambda v: True) if lazy else t.pop(lambda v: True)
            if item is not None:
                out.append(item)
                t.discard([item.key if lazy else item])
            return item

        for batch, bumped, pop_one in rounds:
            t.enter(list(dict(batch).items()), order=lambda k: (-k[1], k[0]))  # one score a key per batch
            for v in bumped:
                versions[v] += 1
            if pop_one:
                take()
        while take() is not None:
            pass
        return out
    finally:
        module.COMPACT_MIN = saved


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_sweeping_stale_heap_items_changes_no_pop(data):
    """Re-scored keys leave stale items behind; sweeping them out of the heap
    (as often as after every batch) pops the same keys in the same order as
    never sweeping."""
    n = data.draw(st.integers(1, 8))
    rounds = data.draw(rounds_of(n))
    assert replay(rounds, n, 0, lazy=False) == replay(rounds, n, 10**9, lazy=False)


def test_pop_any_returns_stale_entries_as_such():
    t, versions = table()
    t.enter([((0, 1), 3.0), ((2, 3), 1.0), ((4, 5), 2.0)], order=lambda k: k)
    versions[2] += 1
    t.discard([(4, 5)])
    assert t.pop_any(lambda v: True) == ((2, 3), False)  # stale, at its old score
    t.enter([((0, 1), 5.0)], order=lambda k: k)  # replaced: its first item is skipped
    assert t.pop_any(lambda v: True) == ((0, 1), True)
    assert t.pop_any(lambda v: True) is None


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_sweeping_keeps_stale_items_for_the_lazy_queue(data):
    """With ``keep_stale``, sweeping drops only replaced and discarded
    items: ``pop_any`` returns the same keys, stale or fresh, in the same
    order as never sweeping."""
    n = data.draw(st.integers(1, 8))
    rounds = data.draw(rounds_of(n))
    popped = replay(rounds, n, 0, lazy=True)
    assert popped == replay(rounds, n, 10**9, lazy=True)
    # Every key entered comes up, none more often than it was entered.
    entered = Counter(k for batch, _, _ in rounds for k in dict(batch))
    came_up = Counter(k for k, _ in popped)
    assert set(came_up) == set(entered) and all(came_up[k] <= entered[k] for k in came_up)
