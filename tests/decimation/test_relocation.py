"""Relocation rounds (otjax.decimation.relocation) over a fake engine.

The fake: values on a path; a vertex's proposal is the mean of its two
neighbours, so a move makes its neighbours' proposals stale. The fake's
``apply`` refuses a stale proposal: a round that applied a move next to
another one of the same round fails.
"""

from typing import NamedTuple

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.decimation.relocation import relocate


class Shift(NamedTuple):
    vertex: int
    value: float


class PathMover:
    """Values ``x`` on the path ``0 - 1 - ... - n-1``; the ends and ``pinned``
    never move; a vertex in ``content`` proposes a move that gains nothing."""

    def __init__(self, x, pinned=(), content=()):
        self.x = [float(v) for v in x]
        self.pinned = {0, len(self.x) - 1, *pinned}
        self.content = set(content)
        self.rounds: list[list[int]] = []  # the vertices proposed in each round
        self.gains: list[dict[int, float]] = []  # their gains when proposed
        self.applied: list[list[tuple[int, float]]] = []  # (vertex, gain) applied in each round

    def movable(self, v):
        return 0 <= v < len(self.x) and v not in self.pinned

    def proposal(self, v):
        target = (self.x[v - 1] + self.x[v + 1]) / 2
        gain = 0.0 if v in self.content else -((self.x[v] - target) ** 2)
        return Shift(v, target), gain

    def propose_moves(self, vertices):
        vertices = list(vertices)
        assert all(self.movable(v) for v in vertices)
        out = [(v, gain, (move, gain)) for v in vertices for move, gain in [self.proposal(v)]]
        self.rounds.append(vertices)
        self.gains.append({v: gain for v, gain, _ in out})
        self.applied.append([])
        return out

    def apply(self, move, gain):
        now, now_gain = self.proposal(move.vertex)
        assert (move, gain) == (now, now_gain), f"stale move applied: {move}"
        self.x[move.vertex] = move.value
        self.applied[-1].append((move.vertex, gain))
        v = move.vertex

        class Change(NamedTuple):
            dirty: frozenset

        return Change(frozenset(u for u in (v - 1, v, v + 1) if self.movable(u)))


@settings(max_examples=200, deadline=None)
@given(x=st.lists(st.integers(-50, 50), min_size=3, max_size=25, unique=True), data=st.data())
def test_rounds_apply_fresh_moves_by_decreasing_gain_each_vertex_once(x, data):
    n = len(x)
    pinned = data.draw(st.sets(st.integers(0, n - 1), max_size=3))
    content = data.draw(st.sets(st.integers(0, n - 1), max_size=3))
    vertices = data.draw(st.lists(st.integers(-1, n), max_size=2 * n))  # duplicates, ends, out of range
    vetoed = data.draw(st.sets(st.integers(0, n - 1), max_size=3))
    engine = PathMover(x, pinned, content)
    dirty, moved = relocate(engine, vertices, lambda move, gain: move.vertex not in vetoed)
    wanted = [v for v in dict.fromkeys(vertices) if engine.movable(v)]
    applied = [v for r in engine.applied for v, _ in r]
    assert moved == len(applied) == len(set(applied))  # each vertex moves at most once
    assert set(applied) <= set(wanted) - vetoed - content
    # The first round proposes every movable vertex, once; later rounds only
    # those a move of the round before blocked.
    if wanted:
        assert engine.rounds[0] == wanted
    else:
        assert engine.rounds == []
    for k, (r, gains, moves) in enumerate(zip(engine.rounds, engine.gains, engine.applied)):
        g = [gain for _, gain in moves]
        assert g == sorted(g) and all(x < 0 for x in g)  # by decreasing gain, improving only
        moved_here = {v for v, _ in moves}
        nxt = engine.rounds[k + 1] if k + 1 < len(engine.rounds) else []
        # The next round: improving vertices of this one that did not move,
        # in order, each next to a move of this round (its proposal changed;
        # a vetoed one too, if it was blocked before the veto judged it) ...
        assert nxt == [v for v in r if v in nxt]
        assert all(v not in moved_here and gains[v] < 0 for v in nxt)
        assert all(any(abs(v - m) == 1 for m in moved_here) for v in nxt)
        # ... and every improving, admissible one that did not move is in it.
        assert {v for v in r if v not in moved_here and gains[v] < 0 and v not in vetoed} <= set(nxt)
    assert dirty == {u for v in applied for u in (v - 1, v, v + 1) if engine.movable(u)}


def test_a_blocked_vertex_is_judged_by_the_veto_in_a_later_round():
    engine = PathMover([0.0, 1.0, 5.0, 0.0, 0.0])
    seen = []
    dirty, moved = relocate(engine, [1, 2, 3], lambda m, g: seen.append(m.vertex) or m.vertex != 1)
    assert engine.rounds == [[1, 2, 3], [1, 3]]  # 2 moves first; 1 and 3 wait
    assert [v for r in engine.applied for v, _ in r] == [2, 3] and moved == 2
    assert seen == [2, 1, 3] and dirty == {1, 2, 3}


def test_a_round_defers_the_neighbours_of_its_moves():
    engine = PathMover([0.0, 1.0, 5.0, 0.0, 3.0, 0.0])
    dirty, moved = relocate(engine, [1, 2, 3, 4])
    assert engine.rounds[0] == [1, 2, 3, 4]
    first = engine.applied[0]
    assert len(first) >= 1 and len(engine.rounds) >= 2  # neighbours waited for a later round
    assert all(abs(a - b) > 1 for (a, _), (b, _) in zip(first, first[1:]))
    assert moved == 4 and dirty == {1, 2, 3, 4}


def test_nothing_to_move():
    engine = PathMover([0.0, 0.0, 0.0, 0.0])
    assert relocate(engine, []) == (set(), 0) and engine.rounds == []
    assert relocate(engine, [0, 3, 9]) == (set(), 0) and engine.rounds == []  # immovable only
    # Already in place: no gain, nothing moves, one round.
    assert relocate(engine, [1, 2]) == (set(), 0) and engine.rounds == [[1, 2]]
