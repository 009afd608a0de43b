"""Fake engines for the greedy loop: pure Python, no geometry kernel, no JAX.

:class:`CycleEngine` implements the :class:`otjax.decimation.loop.Engine`
protocol over the vertices of a closed polygon. A half-edge ``(v, w)`` joins
``v`` to a polygon neighbour ``w``; collapsing it removes ``v`` and joins its
two neighbours. Its cost is known in closed form (:meth:`CycleEngine.delta`),
so a brute-force greedy (:func:`greedy_oracle`) says what the loop must do.

The fake checks what the loop hands it: :meth:`CycleEngine.apply` refuses a
collapse whose score is stale (scored at an older version of its source, or
no longer its cost), so a loop that ever applies a stale score fails.

A helper module, not a test file.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


class Collapse(NamedTuple):
    """A fake collapse candidate: ``source`` goes, ``target`` stays."""

    source: int
    target: int


class Move(NamedTuple):
    """A fake move candidate: ``vertex`` to ``position``."""

    vertex: int
    position: tuple[float, float]


class FakeChange(NamedTuple):
    """What the loop reads of an applied change."""

    dirty: frozenset
    ring: tuple[int, ...]
    quiet: frozenset = frozenset()


CENTRE = (0.5, 0.5)


class CycleEngine:
    """An :class:`~otjax.decimation.loop.Engine` over a closed polygon.

    Args:
      xy: ``(n, 2)`` vertex positions, in polygon order.
      pinned: vertex ids that are never removed nor collapse targets.
      degree_bound: the engine's ``degree_bound`` (every ring has 2 vertices).
      meddle: after each collapse, raise the cost of the vertex the loop
        would most likely take next (the cheapest live one outside the ring)
        fifty-fold and bump its version: a fresh score becomes stale.
      report_meddled: also report that vertex as dirty (to be re-scored).
      beyond: what to make of the vertex beyond each end of a change's ring
        (its score did not change): ``None`` nothing, ``"dirty"`` bump its
        version and report it dirty, ``"quiet"`` report it quiet.
      speculate: vertices a relocation call proposes at least.

    Costs: ``delta(v, w) = weight[v] * (area(prev, v, next) + |v w| / 10)``,
    positive and, for random positions, without ties. A move sends ``v``
    half-way to :data:`CENTRE` (whatever the order of moves, the same end
    state) and always gains 1. Both relocation rounds and the brute-force
    oracle apply moves through :meth:`apply`.
    """

    def __init__(self, xy, pinned=(), degree_bound: int = 2, meddle: bool = False, report_meddled: bool = True,
                 beyond: str | None = None, speculate: int = 1):
        self.xy = [tuple(map(float, p)) for p in xy]
        self.speculate = speculate
        n = len(self.xy)
        self.nxt = {v: (v + 1) % n for v in range(n)}
        self.prv = {v: (v - 1) % n for v in range(n)}
        self.alive = set(range(n))
        self.pinned = frozenset(pinned)
        self.weight = [1.0] * n
        self.versions = [0] * n  # mutated in place: the score table holds this list
        # The oldest version whose scores still hold: a "dirty" bump beyond a
        # ring changes a version, not a cost.
        self.valid_from = [0] * n
        self.degree_bound = degree_bound
        self.meddle = meddle
        self.report_meddled = report_meddled
        self.beyond = beyond
        self.scored: dict[Collapse, tuple[float, int]] = {}  # latest score of each half-edge, and its version
        self.events: list[tuple] = []  # ("collapse", v, w) and ("move", v), in order
        self.score_calls: list[list[int]] = []  # the sources of each score call
        self.take_calls: list[list[tuple[int, int]]] = []
        self.meddled: list[tuple[int, int]] = []  # (collapses before, vertex) of each meddling
        self.traps = 0  # meddlings that left a stale score cheaper than every fresh one
        self.rings: dict[int, tuple[int, int]] = {}  # ring of each collapsed vertex
        self.prefetched: list[tuple[int, int]] = []
        self.n_scored = 0
        self.calls = 0

    # ------------------------------------------------------------ geometry
    def delta(self, v: int, w: int) -> float:
        """The current cost of collapsing ``v`` onto ``w``."""
        (px, py), (vx, vy), (qx, qy) = self.xy[self.prv[v]], self.xy[v], self.xy[self.nxt[v]]
        area = abs((vx - px) * (qy - py) - (vy - py) * (qx - px)) / 2
        return self.weight[v] * (area + math.dist(self.xy[v], self.xy[w]) / 10)

    def proposal(self, v: int) -> tuple[Move, float]:
        x, y = self.xy[v]
        return Move(v, ((x + CENTRE[0]) / 2, (y + CENTRE[1]) / 2)), -1.0

    def eligible(self, veto=None) -> list[tuple[float, tuple[int, int]]]:
        """``[(delta, half-edge)]`` of every admissible collapse now."""
        out = []
        for v in sorted(self.alive - self.pinned):
            ring = self.ring(v)
            if len(ring) > self.degree_bound:
                continue
            for w in ring:
                if self.free(w) and (veto is None or veto(Collapse(v, w), self.delta(v, w))):
                    out.append((self.delta(v, w), (v, w)))
        return out

    def collapses(self) -> list[tuple[int, int]]:
        return [(e[1], e[2]) for e in self.events if e[0] == "collapse"]

    # ------------------------------------------------------------ Engine protocol
    def live_sources(self) -> list[int]:
        return sorted(self.alive - self.pinned)

    def ring(self, v: int) -> tuple[int, ...]:
        return (self.prv[v], self.nxt[v])

    def free(self, v: int) -> bool:
        return v not in self.pinned

    def movable(self, v: int) -> bool:
        return v in self.alive and v not in self.pinned

    def score(self, sources, targets=None, *, veto=None, keep=True, while_waiting=None, cheapest_only=False):
        """As the protocol; with ``cheapest_only`` it leaves out every
        admissible candidate but the cheapest (and its ties), the most a
        real engine may leave out."""
        sources = sorted(sources)
        self.score_calls.append(sources)
        found = []
        for v in sources:
            if v not in self.alive or v in self.pinned or len(self.ring(v)) > self.degree_bound:
                continue
            for w in self.ring(v):
                if (targets is not None and w not in targets[v]) or not self.free(w):
                    continue
                cand, d = Collapse(v, w), self.delta(v, w)
                found.append((cand, d, veto is None or veto(cand, d)))
        if cheapest_only:
            best = min((d for _, d, ok in found if ok), default=None)
            found = [f for f in found if f[2] and f[1] == best]
        out = []
        for cand, d, ok in found:
            self.n_scored += 1
            self.scored[cand] = (d, self.versions[cand.source])
            if ok:
                out.append(((cand.source, cand.target), d))
        self.calls += 1
        if while_waiting is not None:
            while_waiting()
        return out

    def take(self, keys):
        keys = [tuple(k) for k in keys]
        self.take_calls.append(keys)
        return [(Collapse(*k), *self.scored[Collapse(*k)]) for k in keys]

    def apply(self, cand, cost, scored_at=None) -> FakeChange:
        if isinstance(cand, Move):
            return self._move(cand)
        v, w = cand
        assert v in self.alive and v not in self.pinned and w in self.ring(v), f"not a half-edge: {cand}"
        assert scored_at is not None and self.valid_from[v] <= scored_at <= self.versions[v], (
            f"stale score applied: {cand} scored at {scored_at}, now {self.versions[v]}")
        assert cost == self.delta(v, w), f"the score of {cand} is not its cost"
        p, q = self.prv[v], self.nxt[v]
        self.nxt[p], self.prv[q] = q, p
        self.alive.remove(v)
        self._bump(p)
        self._bump(q)
        dirty = {u for u in (p, q) if self.free(u)}
        self.events.append(("collapse", v, w))
        self.rings[v] = (p, q)
        if self.meddle:
            u = self._meddle(exclude={p, q})
            if u is not None and self.report_meddled:
                dirty.add(u)
        return self._change(dirty, (p, q), {self.prv[p], self.nxt[q]} - {p, q})

    def _bump(self, u: int) -> None:
        """A change of ``u``'s cost: its older scores are stale."""
        self.versions[u] += 1
        self.valid_from[u] = self.versions[u]

    def _change(self, dirty: set, ring: tuple, beyond: set) -> FakeChange:
        """The change of ``dirty`` and ``ring``, with the vertices ``beyond``
        the ring (their scores unchanged) made of as :attr:`beyond` says."""
        beyond = {u for u in beyond if self.free(u)} - dirty
        if self.beyond == "dirty":
            for u in beyond:
                self.versions[u] += 1
            return FakeChange(frozenset(dirty | beyond), ring)
        return FakeChange(frozenset(dirty), ring, frozenset(beyond) if self.beyond == "quiet" else frozenset())

    def _meddle(self, exclude) -> int | None:
        options = [(d, k) for d, k in self.eligible() if k[0] not in exclude]
        if not options:
            return None
        u = min(options)[1][0]
        stale = min(d for d, k in options if k[0] == u)  # what the table holds for u
        fresh = [d for d, k in self.eligible() if k[0] != u]
        self.traps += not fresh or stale < min(fresh)
        self.weight[u] *= 50.0
        self._bump(u)
        self.meddled.append((len(self.rings) - 1, u))
        return u

    def _move(self, move: Move) -> FakeChange:
        v = move.vertex
        assert self.movable(v) and move == self.proposal(v)[0], f"stale move {move}"
        self.xy[v] = move.position
        touched = (v, self.prv[v], self.nxt[v])
        for u in touched:
            self._bump(u)
        self.events.append(("move", v))
        return self._change({u for u in touched if self.free(u)}, self.ring(v),
                            {self.prv[self.prv[v]], self.nxt[self.nxt[v]]} - set(touched))

    def propose_moves(self, vertices) -> list:
        """``[(vertex, delta, scored)]``: each vertex's move, always a gain
        (applied by :func:`otjax.decimation.relocation.relocate`)."""
        return [(v, gain, (move, gain)) for v in vertices for move, gain in [self.proposal(v)]]

    def prefetch(self, half_edges) -> None:
        self.prefetched.extend(half_edges)

    def stats(self) -> dict:
        return {"scored": self.n_scored, "updated": 0, "partial": 0, "kernel_calls": self.calls,
                "seconds": {"export": 0.0, "score": 0.0}}


def random_cycle(seed: int, n: int, n_pinned: int = 3, **options) -> CycleEngine:
    """A :class:`CycleEngine` on ``n`` random positions, ``n_pinned`` of them
    (spread around the polygon) pinned."""
    rng = np.random.default_rng(seed)
    pinned = [int(i * n // n_pinned) for i in range(n_pinned)]
    return CycleEngine(rng.random((n, 2)), pinned=pinned, **options)


def moves_grouped(events) -> list:
    """Events with each run of moves as one frozenset (their order within a
    relocation pass is the relocation driver's business)."""
    out: list = []
    for e in events:
        if e[0] == "move":
            if out and isinstance(out[-1], frozenset):
                out[-1] = out[-1] | {e[1]}
            else:
                out.append(frozenset({e[1]}))
        else:
            out.append(e)
    return out


def greedy_oracle(engine: CycleEngine, target: int | None, relocate_last: int = 0, veto=None) -> CycleEngine:
    """The exhaustive greedy by brute force: every admissible half-edge
    costed afresh before each collapse; after each of the last
    ``relocate_last`` collapses, the live free vertices of its ring move."""
    stop = 1 if target is None else target
    while len(engine.live_sources()) > stop:
        options = engine.eligible(veto)
        if not options:
            break
        d, (v, w) = min(options)
        ring = engine.ring(v)
        engine.apply(Collapse(v, w), d, engine.versions[v])
        if target is not None and len(engine.live_sources()) - target < relocate_last:
            for u in sorted(ring):
                if engine.movable(u):
                    move, gain = engine.proposal(u)
                    if veto is None or veto(move, gain):
                        engine.apply(move, gain)
    return engine


def lazy_oracle(engine: CycleEngine, target: int, relocate_last: int = 0, tail: int = 0) -> CycleEngine:
    """The lazy greedy by brute force: each source keeps the scores of its
    last scoring; before each collapse, every source whose version changed
    since and that holds a score below the cheapest current one is scored
    again, until none is (one without a score counts as below every
    other); then the cheapest current score is collapsed. The last ``tail``
    collapses are :func:`greedy_oracle`'s."""
    held: dict[int, dict[int, float]] = {}
    at: dict[int, int] = {}

    def rescore(v):
        held[v] = {w: d for d, (u, w) in engine.eligible() if u == v}
        at[v] = engine.versions[v]

    if len(engine.live_sources()) > target + tail:
        for v in engine.live_sources():
            rescore(v)
    while len(engine.live_sources()) > target + tail:
        live = engine.live_sources()
        fresh = [(d, (v, w)) for v in live if at[v] == engine.versions[v] for w, d in held[v].items()]
        best = min(fresh, default=(math.inf, None))
        below = [v for v in live if at[v] != engine.versions[v] and min(held[v].values(), default=-math.inf) < best[0]]
        if below:
            for v in below:
                rescore(v)
            continue
        if best[1] is None:
            break
        v, w = best[1]
        ring = engine.ring(v)
        engine.apply(Collapse(v, w), best[0], engine.versions[v])
        if len(engine.live_sources()) - target < relocate_last:
            for u in sorted(ring):
                if engine.movable(u):
                    engine.apply(*engine.proposal(u))
    return greedy_oracle(engine, target, relocate_last)


class GraphEngine:
    """What sampling reads of an engine: ``ring``, ``free``, ``degree_bound``,
    over given rings (no geometry)."""

    def __init__(self, rings: dict, pinned=(), degree_bound: int = 4):
        self.rings = {v: tuple(r) for v, r in rings.items()}
        self.pinned = frozenset(pinned)
        self.degree_bound = degree_bound

    def ring(self, v: int) -> tuple[int, ...]:
        return self.rings[v]

    def free(self, v: int) -> bool:
        return v not in self.pinned

    def eligible(self, sources) -> set[tuple[int, int]]:
        """Every half-edge a uniform draw may return: from ``sources``, with
        a ring within the bound, to a free target."""
        return {(u, w) for u in sources if len(self.rings[u]) <= self.degree_bound
                for w in self.rings[u] if self.free(w)}
