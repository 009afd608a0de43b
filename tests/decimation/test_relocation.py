"""A relocation pass (otjax.decimation.relocation) over a fake engine.

The fake: values on a path; a vertex's proposal is the mean of its two
neighbours, so a move makes its neighbours' proposals stale. The fake's
``apply`` refuses a stale proposal: a pass that applied a move proposed
before a neighbour's move fails.
"""

from typing import NamedTuple

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.curves.engine import SPECULATE
from otjax.decimation.relocation import relocate


class Shift(NamedTuple):
    vertex: int
    value: float


class PathMover:
    """Values ``x`` on the path ``0 - 1 - ... - n-1``; the ends and ``pinned``
    never move; a vertex in ``content`` proposes a move that gains nothing.
    It speculates as the curve engine does."""

    speculate = SPECULATE

    def __init__(self, x, pinned=(), content=()):
        self.x = [float(v) for v in x]
        self.pinned = {0, len(self.x) - 1, *pinned}
        self.content = set(content)
        self.rounds: list[list[int]] = []  # the vertices proposed in each round
        self.gains: list[dict[int, float]] = []  # their gains when proposed
        self.applied: list[list[tuple[int, float]]] = []  # (vertex, gain) applied in each round

    def movable(self, v):
        return 0 <= v < len(self.x) and v not in self.pinned

    def ring(self, v):
        return tuple(u for u in (v - 1, v + 1) if 0 <= u < len(self.x))

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


def sequential(x, pinned, content, vertices, vetoed):
    """The oracle: visit the vertices in order, one proposal at a time."""
    engine = PathMover(x, pinned, content)
    engine.applied.append([])
    order = []
    for v in dict.fromkeys(vertices):
        if not engine.movable(v):
            continue
        move, gain = engine.proposal(v)
        if gain < 0 and v not in vetoed:
            engine.apply(move, gain)
            order.append(v)
    return engine.x, order


@settings(max_examples=200, deadline=None)
@given(x=st.lists(st.integers(-50, 50), min_size=3, max_size=25, unique=True), data=st.data())
def test_a_pass_is_the_sequential_visit_in_order(x, data):
    n = len(x)
    pinned = data.draw(st.sets(st.integers(0, n - 1), max_size=3))
    content = data.draw(st.sets(st.integers(0, n - 1), max_size=3))
    vertices = data.draw(st.lists(st.integers(-1, n), max_size=2 * n))  # duplicates, ends, out of range
    vetoed = data.draw(st.sets(st.integers(0, n - 1), max_size=3))
    engine = PathMover(x, pinned, content)
    dirty, _, moved = relocate(engine, vertices, lambda move, gain: move.vertex not in vetoed)
    want_x, want_order = sequential(x, pinned, content, vertices, vetoed)
    applied = [v for r in engine.applied for v, _ in r]
    assert engine.x == want_x  # bitwise: same proposals on the same states
    assert applied == want_order and moved == len(applied)
    # Every vertex is proposed, in order, and again only after a move next to
    # it (applied in the round of its last proposal or later) made that stale.
    wanted = [v for v in dict.fromkeys(vertices) if engine.movable(v)]
    first = {}
    for i, r in enumerate(engine.rounds):
        assert len(set(r)) == len(r)
        for v in r:
            if v in first:
                moves = [u for a in engine.applied[first[v]:i] for u, _ in a]
                assert any(abs(u - v) <= 1 for u in moves), (v, first[v], i)
            first[v] = i
    assert list(first) == wanted
    # A call ends at a move or after at least SPECULATE waiting vertices.
    assert len(engine.rounds) <= len(applied) + -(-len(wanted) // SPECULATE)
    assert dirty == {u for v in applied for u in (v - 1, v, v + 1) if engine.movable(u)}


def test_far_apart_vertices_share_one_call():
    engine = PathMover([0.0] * 30)
    far = [3, 6, 9, 12, 15, 18, 21, 24, 27]
    relocate(engine, far)
    assert engine.rounds == [far]  # longer than SPECULATE: the independent run


def test_near_vertices_are_proposed_together_and_used_while_valid():
    engine = PathMover([0.0, 0.0, 1.0, 5.0, 0.0, 0.0, 3.0, 0.0, 0.0, 2.0, 0.0, 0.0])
    dirty, _, moved = relocate(engine, [3, 6, 9, 1])
    # 1 is two edges from 3, but 3's move leaves 1's proposal as it was: one call.
    assert engine.rounds == [[3, 6, 9, 1]] and moved == 4
    assert [v for r in engine.applied for v, _ in r] == [3, 6, 9, 1]


def test_a_move_drops_the_proposals_it_made_stale():
    engine = PathMover([0.0, 1.0, 5.0, 0.0, 0.0])
    seen = []
    dirty, _, moved = relocate(engine, [1, 2, 3], lambda m, g: seen.append(m.vertex) or m.vertex != 1)
    assert engine.rounds == [[1, 2, 3], [3]]  # 2's move made 3's first proposal stale
    assert [v for r in engine.applied for v, _ in r] == [2, 3] and moved == 2
    assert seen == [1, 2, 3] and dirty == {1, 2, 3}


def test_nothing_to_move():
    engine = PathMover([0.0, 0.0, 0.0, 0.0])
    assert relocate(engine, []) == (set(), set(), 0) and engine.rounds == []
    assert relocate(engine, [0, 3, 9]) == (set(), set(), 0) and engine.rounds == []  # immovable only
    # Already in place: no gain, nothing moves, one call.
    assert relocate(engine, [1, 2]) == (set(), set(), 0) and engine.rounds == [[1, 2]]
