"""The greedy loop (otjax.decimation.loop) over a fake engine: no geometry, no JAX.

The fake (:mod:`tests.decimation.fake_engines`) knows every cost in closed
form, so the exhaustive queue is checked against a brute-force greedy, the
multiple-choice queue against a replay of its draws, and the parallel queue
against its selection rule; the fake itself refuses any stale score.
"""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.decimation import loop
from otjax.decimation.loop import QUEUES, DecimationStats, Engine, decimate
from otjax.decimation.sampling import LiveVertices, lock_set, sample_half_edges
from tests.decimation.fake_engines import (Collapse, CycleEngine, Move, greedy_oracle, lazy_oracle, moves_grouped,
                                          random_cycle)


def test_the_fake_engine_implements_the_protocol():
    members = {n for n in vars(Engine) if not n.startswith("_")} | set(Engine.__annotations__)
    fake = random_cycle(0, 12)
    missing = sorted(n for n in members if not hasattr(fake, n))
    assert not missing, f"the Engine protocol grew: {missing}"
    assert {"versions", "degree_bound", "score", "take", "apply", "live_sources", "ring"} <= members


# ------------------------------------------------------------ exhaustive
@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(8, 40), data=st.data())
def test_exhaustive_collapses_in_increasing_cost_order_to_the_target(seed, n, data):
    target = data.draw(st.integers(1, n - 3 - 1))  # 3 pinned vertices
    relocation = data.draw(st.integers(0, 6))
    engine = random_cycle(seed, n, speculate=data.draw(st.sampled_from([1, 3, 8])))
    stats = decimate(engine, target, relocation=relocation)
    want = greedy_oracle(random_cycle(seed, n), target, relocation)
    # The same collapses, in the same order, and the same moves after each.
    assert moves_grouped(engine.events) == moves_grouped(want.events)
    # At the target, or nothing collapsible left (live vertices between pinned ones).
    assert len(engine.live_sources()) == target or not engine.eligible()
    assert len(engine.live_sources()) >= target
    assert stats.collapses == n - 3 - len(engine.live_sources()) == len(engine.collapses())
    assert stats.rounds == stats.collapses
    assert stats.relocations == sum(e[0] == "move" for e in engine.events)
    assert stats.scored == engine.n_scored and stats.kernel_calls == engine.calls
    assert stats.switched_at is None


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(8, 40), regular=st.booleans(), relocation=st.integers(0, 6),
       queue=st.sampled_from(["exhaustive", "parallel"]), fraction=st.sampled_from([0.05, 0.5, 1.0]))
def test_quiet_vertices_pop_as_if_they_were_scored_again(seed, n, regular, relocation, queue, fraction):
    """Vertices a change leaves quiet are not scored again, yet every queue
    makes the same collapses and moves in the same order as when they are
    reported dirty: exact ties included (a regular polygon ties every cost),
    and the parallel queue's random tie keys drawn alike (a deferred
    candidate of a quiet source goes back on the heap once, not twice)."""
    def run(beyond):
        if regular:
            angle = 2 * np.pi * np.arange(n) / n
            engine = CycleEngine(np.stack([np.cos(angle), np.sin(angle)], 1), pinned=[0], beyond=beyond)
        else:
            engine = random_cycle(seed, n, beyond=beyond)
        decimate(engine, 2, queue=queue, relocation=relocation, seed=seed % 1000, round_fraction=fraction)
        return engine

    quiet, dirty = run("quiet"), run("dirty")
    assert quiet.events == dirty.events
    assert quiet.n_scored <= dirty.n_scored
    if queue == "exhaustive" and n >= 16:  # some change leaves a vertex quiet
        assert quiet.n_scored < dirty.n_scored


def test_relocation_moves_the_ring_of_each_of_the_last_collapses_only():
    engine = random_cycle(3, 30, n_pinned=0)
    stats = decimate(engine, 5, relocation=4)
    grouped = moves_grouped(engine.events)
    collapse_at = [i for i, e in enumerate(grouped) if not isinstance(e, frozenset)]
    moved_after = [grouped[i + 1] if i + 1 < len(grouped) and isinstance(grouped[i + 1], frozenset) else None
                   for i in collapse_at]
    assert len(collapse_at) == stats.collapses == 25
    assert all(m is None for m in moved_after[:-4])
    for i, moved in zip(collapse_at[-4:], moved_after[-4:]):
        # Nothing is pinned and every move gains: the whole ring moves.
        assert moved == set(engine.rings[grouped[i][1]])
    assert stats.relocations == 8
    # Without a known end (tolerance mode), nothing is relocated.
    engine = random_cycle(3, 30)
    decimate(engine, None, relocation=4, veto=lambda cand, cost: cost < 0.02)
    assert engine.collapses() and not any(e[0] == "move" for e in engine.events)


def checking_veto(engine, veto):
    """Wraps ``apply``: every change applied must pass ``veto`` at its cost."""
    apply = engine.apply

    def checked(cand, cost, *rest):
        assert veto(cand, cost), f"a vetoed change was applied: {cand}"
        return apply(cand, cost, *rest)

    engine.apply = checked


@pytest.mark.parametrize("queue", QUEUES)
def test_the_veto_is_respected_and_ends_a_run_without_target(queue):
    banned = {4, 9, 13, 20}

    def veto(cand, cost):
        if isinstance(cand, Move):
            return cand.vertex % 2 == 0
        return cand.target not in banned and cost < 0.05

    engine = random_cycle(11, 30)
    checking_veto(engine, veto)
    stats = decimate(engine, None, queue=queue, veto=veto, seed=4)
    assert stats.collapses == len(engine.collapses()) > 0
    # The run ends when nothing admissible is left (or one vertex).
    assert len(engine.live_sources()) == 1 or not engine.eligible(veto)
    assert engine.eligible()  # the veto, not the polygon, ended it
    # With a target too, it stops there or when nothing admissible is left;
    # the moves near the end pass the veto as well.
    engine = random_cycle(11, 30)
    checking_veto(engine, veto)
    stats = decimate(engine, 20, queue=queue, veto=veto, relocation=5, seed=4)
    assert len(engine.live_sources()) == 20 or not engine.eligible(veto)
    assert stats.relocations == sum(e[0] == "move" for e in engine.events)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), report=st.booleans())
def test_a_stale_score_is_never_applied(seed, report):
    """After each collapse the fake raises the cost of the vertex the loop
    would take next and bumps its version: a fresh score made stale, often
    the cheapest in the table (a trap). The fake's apply refuses any stale
    score. Reported dirty, the vertex is scored again at its new cost right
    away and the run is the brute-force greedy's; unreported, it waits until
    a neighbour's collapse makes it dirty."""
    engine = random_cycle(seed, 30, meddle=True, report_meddled=report)
    decimate(engine, 6)
    assert engine.meddled and engine.traps > 0
    if report:
        assert len(engine.live_sources()) == 6
    else:
        # Unreported, the vertices are never scored again: the run stops early,
        # when every half-edge left has only a stale score.
        assert len(engine.live_sources()) >= 6
        left = [k for _, k in engine.eligible()]
        if len(engine.live_sources()) > 6:
            assert left and all(engine.scored[Collapse(*k)][1] < engine.versions[k[0]] for k in left)
    # The loop scores exactly what a change reports dirty: score_calls[0]
    # scored everything, then one call per collapse.
    for i, u in engine.meddled:
        ring = engine.rings[engine.collapses()[i][0]]
        assert set(engine.score_calls[1 + i]) == {r for r in ring if engine.free(r)} | ({u} if report else set())
    if report:
        want = greedy_oracle(random_cycle(seed, 30, meddle=True, report_meddled=True), 6)
        assert engine.events == want.events


# ------------------------------------------------------------ lazy
@settings(max_examples=150, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(8, 40), data=st.data())
def test_lazy_collapses_as_the_brute_force_lazy_greedy(seed, n, data):
    """Same collapses and moves, in the same order, as a brute force that
    keeps each source's last scores and scores a changed source again only
    when one of them is below the cheapest current score, then takes the
    exhaustive greedy's last ``tail`` collapses; also when a change
    bumps versions beyond its ring without changing costs, or raises the
    cost of the next collapse behind the loop's back (reported)."""
    target = data.draw(st.integers(1, n - 3 - 1))
    relocation = data.draw(st.integers(0, 6))
    tail = data.draw(st.sampled_from([0, 0, 1, 5, n]))
    options = data.draw(st.sampled_from([{}, {"beyond": "dirty"}, {"beyond": "quiet"}, {"meddle": True}]))
    engine = random_cycle(seed, n, speculate=data.draw(st.sampled_from([1, 3, 8])), **options)
    stats = decimate(engine, target, queue="lazy", relocation=relocation, lazy_tail=tail)
    want = lazy_oracle(random_cycle(seed, n, **options), target, relocation, tail)
    assert moves_grouped(engine.events) == moves_grouped(want.events)
    assert len(engine.live_sources()) == target or not engine.eligible()
    assert stats.collapses == len(engine.collapses()) and stats.rounds == stats.collapses
    # Every score call after the first is of stale sources only, each once.
    assert all(len(set(c)) == len(c) for c in engine.score_calls)


def test_lazy_scores_fewer_than_exhaustive_and_differs_where_a_cost_fell():
    """Lazy scores each changed source at most once per change, and only
    when it comes up: fewer than the exhaustive queue. The fake's costs can
    fall (a neighbour's collapse shrinks an area), so the order may differ
    from the exhaustive greedy's, but both reach the target."""
    scored, differ = [], 0
    for seed in range(10):
        lazy, full = random_cycle(seed, 60), random_cycle(seed, 60)
        decimate(lazy, 8, queue="lazy", lazy_tail=0)
        decimate(full, 8)
        assert len(lazy.live_sources()) == len(full.live_sources()) == 8
        scored.append((lazy.n_scored, full.n_scored))
        differ += lazy.collapses() != full.collapses()
    assert all(a <= b for a, b in scored) and sum(a for a, _ in scored) < 0.8 * sum(b for _, b in scored)
    assert differ > 0


# ------------------------------------------------------------ multiple choice
@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), choices=st.integers(1, 8), switch=st.sampled_from([1.0, 2.0, 3.0]))
def test_multiple_choice_takes_the_cheapest_of_each_draw(seed, choices, switch):
    """The draws replayed (the loop's generator is ``default_rng(seed)``, one
    :func:`sample_half_edges` per step): each step collapses the cheapest
    drawn half-edge; below ``switch_factor`` times the target, the rest is
    the exhaustive greedy."""
    n, target = 36, 4
    engine = random_cycle(seed % 1000, n)
    rng = np.random.default_rng(seed)
    shadow = LiveVertices(engine.live_sources())
    switch_at = switch * target
    steps = []
    apply = engine.apply

    def replaying(cand, cost, scored_at=None):
        if isinstance(cand, Collapse) and len(shadow) > max(target, switch_at):
            drawn = sample_half_edges(engine, shadow, rng, choices)
            assert drawn and tuple(cand) in drawn
            assert engine.delta(*cand) == min(engine.delta(*h) for h in drawn)
            steps.append(len(drawn))
        if isinstance(cand, Collapse):
            shadow.remove(cand.source)
        return apply(cand, cost, scored_at)

    engine.apply = replaying
    stats = decimate(engine, target, queue="multiple-choice", choices=choices, switch_factor=switch, seed=seed)
    assert len(engine.live_sources()) == target
    mc_steps = sum(1 for k in range(n - 3, target, -1) if k > max(target, switch_at))
    assert len(steps) == mc_steps
    assert stats.switched_at == (None if mc_steps == n - 3 - target else n - 3 - mc_steps)
    # After the switch: the exhaustive greedy from the state the draws left.
    tail = engine.collapses()[mc_steps:]
    replay = random_cycle(seed % 1000, n)
    for v, w in engine.collapses()[:mc_steps]:
        replay.apply(Collapse(v, w), replay.delta(v, w), replay.versions[v])
    assert tail == greedy_oracle(replay, target).collapses()[mc_steps:]


def test_multiple_choice_scores_only_what_its_draws_lack():
    engine = random_cycle(4, 60)
    stats = decimate(engine, 30, queue="multiple-choice", choices=3, switch_factor=1.0, seed=1)
    assert stats.switched_at is None and stats.collapses == 60 - 3 - 30
    # At most `choices` half-edges per step, never the whole polygon.
    assert stats.scored <= 3 * stats.collapses
    assert all(len(s) <= 3 for s in engine.score_calls)
    # The next draw was read ahead while the kernel ran (most steps).
    assert len(engine.prefetched) > stats.collapses


# ------------------------------------------------------------ parallel
def check_rounds(engine, target, round_fraction):
    """Wraps ``take``: each call of the parallel queue is one round; checks
    it against the selection rule before anything of it is applied."""
    take = engine.take
    rounds = []

    def checking(keys):
        keys = [tuple(k) for k in keys]
        live = engine.live_sources()
        budget = max(1, int(round_fraction * (len(live) - target)))
        options = sorted(engine.eligible())
        deltas = [engine.delta(*k) for k in keys]
        assert 1 <= len(keys) <= budget
        assert deltas == sorted(deltas)  # popped in increasing cost
        assert keys[0] == options[0][1]  # the cheapest first
        assert deltas[-1] <= options[min(len(options), loop.PARALLEL_SCAN * budget) - 1][0]
        locks = [lock_set(engine, k[0]) for k in keys]
        for a, b in itertools.combinations(locks, 2):
            assert len(a & b) <= 1, "two collapses of a round share two vertices"
        rounds.append((keys, [k for _, k in options[:len(keys)]]))
        return take(keys)

    engine.take = checking
    return rounds


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), fraction=st.sampled_from([0.1, 0.3, 1.0]))
def test_parallel_rounds_take_independent_cheap_collapses(seed, fraction):
    n, target = 48, 5
    engine = random_cycle(seed, n)
    rounds = check_rounds(engine, target, fraction)
    stats = decimate(engine, target, queue="parallel", round_fraction=fraction, seed=seed)
    assert len(engine.live_sources()) == target
    assert stats.rounds == len(rounds) and stats.collapses == n - 3 - target
    assert sum(len(keys) for keys, _ in rounds) == stats.collapses
    if fraction == 1.0:
        assert stats.rounds < stats.collapses


def test_parallel_rounds_defer_conflicting_collapses():
    engine = random_cycle(1, 80)
    rounds = check_rounds(engine, 6, 0.3)
    decimate(engine, 6, queue="parallel", round_fraction=0.3, seed=0)
    # Some round skipped a cheaper collapse that conflicted with one taken.
    assert any(keys != cheapest for keys, cheapest in rounds)
    assert any(len(keys) > 1 for keys, _ in rounds)


def test_parallel_relocation_waits_for_the_round():
    engine = random_cycle(2, 40)
    rounds = check_rounds(engine, 6, 0.2)
    # Relocating from the start: rounds of several collapses relocate.
    stats = decimate(engine, 6, queue="parallel", round_fraction=0.2, relocation=30, seed=0)
    grouped = moves_grouped(engine.events)
    assert stats.relocations > 0
    assert any(len(keys) > 1 for keys, _ in rounds[:-1])
    # Moves come in runs after whole rounds: never between two collapses of one round.
    i = 0
    for keys, _ in rounds:
        block = grouped[i:i + len(keys)]
        assert not any(isinstance(e, frozenset) for e in block), "a move between collapses of one round"
        assert [(e[1], e[2]) for e in block] == keys
        i += len(keys)
        if i < len(grouped) and isinstance(grouped[i], frozenset):
            i += 1
    assert i == len(grouped)


# ------------------------------------------------------------ arguments
@pytest.mark.parametrize("kwargs, message", [
    ({"n_vertices": 0}, "n_vertices must be >= 1"),
    ({"n_vertices": None}, "veto must end the run"),
    ({"n_vertices": 5, "queue": "random"}, "queue must be one of"),
    ({"n_vertices": 5, "choices": 0}, "choices must be >= 1"),
    ({"n_vertices": 5, "round_fraction": 0.0}, "round_fraction"),
    ({"n_vertices": 5, "round_fraction": 1.5}, "round_fraction"),
    ({"n_vertices": 5, "lazy_tail": -1}, "lazy_tail must be >= 0"),
])
def test_bad_arguments_are_named(kwargs, message):
    engine = random_cycle(0, 12)
    with pytest.raises(ValueError, match=message):
        decimate(engine, **kwargs)
    assert engine.events == [] and engine.score_calls == []


@pytest.mark.parametrize("queue", QUEUES)
def test_nothing_to_do_at_or_below_the_target(queue):
    engine = random_cycle(0, 12)
    stats = decimate(engine, 9, queue=queue)
    assert stats == DecimationStats(seconds=stats.seconds)
    assert engine.events == []
