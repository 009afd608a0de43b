"""Greedy decimation: collapse half-edges in increasing order of cost increase.

The driver of de Goes et al. 2011, Fig. 4, with the three queues otjax offers:

``"exhaustive"``
  every half-edge is scored up front; after each collapse (and the
  relocations that follow it near the end) the half-edges leaving the dirty
  vertices are re-exported and re-scored in one batched kernel call. Stale
  queue entries are skipped lazily by a per-vertex version counter.
``"multiple-choice"``
  paper §3.5: each step draws ``choices`` half-edges uniformly at random,
  scores those without a fresh score in one batched call, and collapses the
  cheapest. Nothing is scored that is not drawn, so a step costs the same
  whatever the size of the triangulation. Below ``switch_factor`` times the
  target the loop switches to the exhaustive queue, where the few remaining
  choices matter most.
``"parallel"``
  not in the paper: each round takes, among the ``2 k`` cheapest
  candidates, up to ``k`` whose regions do not overlap (an independent set;
  ``k = round_fraction`` of the collapses left), collapses them all, and
  re-scores the union of their dirty regions in one batch. Rounds are what a GPU pays for;
  the README measures what the order change costs.
"""

from __future__ import annotations

import copy
import heapq
import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from otjax.curves.plan import TransportPlan
from otjax.curves.relocation import relocate

QUEUES = ("exhaustive", "multiple-choice", "parallel")
# Kernel calls of one re-scoring dispatched ahead of the one being collected.
IN_FLIGHT = 3
# Parallel rounds look at most this many times their budget down the queue.
PARALLEL_SCAN = 2
# Collapses whose stencil has fewer rows are scored again in full rather
# than updated on their link (see _Scores.records): a record and an update
# cost ~70 us of host time against ~130 ns a row saved. Measured: updating
# every collapse made a 1000-point exhaustive run 9.6 -> 12.3 s; from 512
# rows, 9.7 s, while the exhaustive end of a 50k run takes 6.5 s (6.4 s
# updating all, 7.0 s from 2048 rows).
UPDATE_MIN_ROWS = 512


@dataclass
class DecimationStats:
    """What a decimation run did.

    Attributes:
      collapses: number of half-edge collapses applied.
      relocations: number of vertex moves applied.
      scored: number of candidate stencils scored.
      updated: number of scored collapses brought up to date on their
        changed link edges only (see :class:`~otjax.curves.plan.LinkRecord`).
      partial: number of scored collapses scored again on the part of
        their stencil that moves of ring vertices changed (also in
        ``scored``; :meth:`~otjax.curves.plan.TransportPlan.partial_job`).
      kernel_calls: number of batched kernel calls.
      rounds: number of rounds (one per collapse, except in parallel mode).
      switched_at: live vertex count at which the multiple-choice queue
        handed over to the exhaustive one (``None`` if it never did).
      seconds: wall time, split into ``export`` (stencils and flip plans),
        ``score`` (kernel calls), ``apply`` (topology and plan updates),
        ``relocate`` and ``sample`` (drawing half-edges).
    """

    collapses: int = 0
    relocations: int = 0
    scored: int = 0
    updated: int = 0
    partial: int = 0
    kernel_calls: int = 0
    rounds: int = 0
    switched_at: int | None = None
    seconds: dict = field(default_factory=lambda: {
        "export": 0.0, "score": 0.0, "apply": 0.0, "relocate": 0.0, "sample": 0.0})


def within_tolerance(tolerance: float):
    """Veto for the tolerance mode (paper §3.5), as a candidate filter.

    A change is admissible when, on every edge of its stencil that carries
    mass ``M_e``, the root-mean-square transport distance of each part stays
    under ``tolerance``: ``sqrt(N_e / M_e)`` and ``sqrt(T_e / M_e)`` for a
    solid edge, ``sqrt(V_e / M_e)`` (its points go to the endpoints) for a
    ghost edge. RMS distances are in the units of the input, so the
    tolerance reads like a distance, independent of how masses are scaled.

    Returns:
      ``(candidate, cost) -> bool``, ``cost`` its
      :class:`~otjax.curves.plan.CandidateCost`.
    """
    tol2 = float(tolerance) ** 2

    def ok(cand, cost) -> bool:
        solid = cost.solid
        first = np.where(solid, cost.normal, cost.vertex)
        second = np.where(solid, cost.tangential, 0.0)
        bound = tol2 * cost.edge_mass
        return bool(np.all((first <= bound) & (second <= bound)))

    return ok


class _Scores:
    """Scored candidates keyed by half-edge, valid while the source's version holds.

    ``version[v]`` is bumped whenever a change touches the stencils of the
    half-edges leaving ``v``; an entry scored at an older version is stale.
    """

    def __init__(self, plan: TransportPlan, stats: DecimationStats, admissible, shuffle_ties=None):
        self.plan = plan
        self.stats = stats
        self.admissible = admissible
        self.version = [0] * len(plan.tri.xy)
        # The queue keeps scores only. A stencil holds every point of a star
        # (late in a run, thousands): keeping the stencils of every scored
        # half-edge took 1.9 GB at 200k points. The stencils of the latest
        # scoring call stay at hand ("hot"), because the winner is usually
        # among them; any other winner is exported again when it is applied.
        self.entries: dict[tuple[int, int], tuple[float, int]] = {}  # key -> (delta, version)
        self.hot: dict[tuple[int, int], tuple] = {}  # key -> (candidate, cost, version)
        self.heap: list = []
        self.use_heap = False
        # Once every change is followed by a re-scoring of all it made dirty
        # (the exhaustive and parallel loops), collapses whose link only
        # changed are updated on the changed link edges instead of being
        # scored again (LinkRecord): {source: {target: record}}. Not with a
        # veto, which reads every edge's parts.
        self.records: dict[int, dict] | None = None
        self.entered: list = []  # keys scored by the current rescore, to push
        self.partial: dict = {}  # key -> what finish_partial needs, this rescore
        # Exact ties (zero-cost collapses along clean straight runs) pop in
        # insertion order, i.e. by vertex id, i.e. along the run: neighbours
        # first. The parallel queue wants them spread out, so it breaks ties
        # by a seeded random key instead.
        self._tie = itertools.count() if shuffle_ties is None else iter(
            lambda: float(shuffle_ties.random()), None)

    def fresh(self, key) -> bool:
        entry = self.entries.get(key)
        return entry is not None and entry[1] == self.version[key[0]]

    def push(self, key) -> None:
        delta, ver = self.entries[key]
        heapq.heappush(self.heap, (delta, next(self._tie), key, ver))

    def pop(self):
        """Cheapest fresh entry of the heap (removed), or ``None``."""
        while self.heap:
            _, _, key, ver = heapq.heappop(self.heap)
            entry = self.entries.get(key)
            if entry is None or entry[1] != ver or ver != self.version[key[0]]:
                continue
            if not self.plan.tri.alive[key[0]]:
                continue
            return key
        return None

    def _collect(self, flat, pending) -> list:
        """The batch's :class:`CandidateCost` list (waits for its kernel)."""
        t1 = time.perf_counter()
        _delta, costs = self.plan.collect(flat, pending)
        self.stats.seconds["score"] += time.perf_counter() - t1
        self.stats.scored += len(costs)
        return costs

    def _settle(self, flat, pending, keep_hot: bool) -> None:
        """Enters a dispatched batch's scores in the queue."""
        for c, r in zip(flat.cands, self._collect(flat, pending)):
            key = (c.plan.source, c.plan.target)
            part = self.partial.pop(key, None)
            if part is not None:  # scored in part: not a whole stencil, never hot
                rec, delta = self.plan.finish_partial(part, c, r)
                self.records.setdefault(key[0], {})[key[1]] = rec
                self._enter(key, delta)
                self.stats.partial += 1
                continue
            if self.admissible is not None and not self.admissible(c, r):
                continue
            delta = r.delta
            if self.records is not None and len(c.point_ids) >= UPDATE_MIN_ROWS:
                rec = self.plan.link_record(c, r)
                self.records.setdefault(key[0], {})[key[1]] = rec
                delta = rec.delta(c.before)
            self._enter(key, delta)
            if keep_hot:
                self.hot[key] = (c, r, self.version[key[0]])

    def _enter(self, key, delta: float) -> None:
        self.entries[key] = (delta, self.version[key[0]])
        self.entered.append(key)

    def _split(self, sources):
        """Sources' half-edges to score in full (``{source: targets}``),
        ``(record, changed links)`` of those only their link changed, and
        ``(job, pending)`` of those a ring move changed in part
        (:meth:`TransportPlan.partial_job`)."""
        plan = self.plan
        tri = plan.tri
        full: dict[int, list[int]] = {}
        updates, partial = [], []
        for v in sources:
            recs = self.records.pop(v, {})
            if not tri.alive[v] or tri.pinned[v]:
                continue
            for w in tri.star(v)[0]:
                rec = recs.get(w)
                changes = None if rec is None else plan.record_changes(rec)
                if changes is not None and changes[1]:
                    part = plan.partial_job(rec, *changes)
                    if part is not None:
                        partial.append(part)
                        continue
                elif changes is not None:
                    updates.append((rec, changes[0]))
                    continue
                full.setdefault(v, []).append(w)
        return full, updates, partial

    def _dispatch(self, exports):
        """Next batch of ``exports`` (a generator: exports as it goes), dispatched."""
        t0 = time.perf_counter()
        flat = next(exports, None)
        if flat is None:
            return None
        t1 = time.perf_counter()
        pending = self.plan.dispatch(flat)
        self.stats.seconds["export"] += t1 - t0
        self.stats.seconds["score"] += time.perf_counter() - t1
        return flat, pending

    def rescore(self, sources, targets: dict | None = None, keep_hot: bool = True, while_waiting=None) -> None:
        """Exports and scores the half-edges leaving ``sources`` (see
        :meth:`TransportPlan.exports`), batch by batch.

        ``while_waiting``: called once every batch is dispatched, before the
        last ones are read: host work that overlaps the kernels.
        """
        self.hot = {}
        self.entered = []
        sources = sorted(sources)
        full, updates, partial = sources, [], []
        if self.records is not None and targets is None:
            t0 = time.perf_counter()
            targets, updates, partial = self._split(sources)
            self.stats.seconds["export"] += time.perf_counter() - t0
            full = sorted(targets)
        self.partial = {(job[0].source, job[0].target): pending for job, pending in partial}
        exports = self.plan.exports(full, targets, extra=[job for job, _ in partial])
        # Batches are exported while earlier ones are scored, and a few are
        # kept in flight: XLA:CPU then runs two at once on two cores (a 64k-row
        # batch: 10.6 ms each instead of 13.7 ms, measured).
        in_flight = []
        while True:
            exported = self._dispatch(exports)
            if exported is None:
                break
            in_flight.append(exported)
            if len(in_flight) > IN_FLIGHT:
                self._settle(*in_flight.pop(0), keep_hot)
        if while_waiting is not None:
            while_waiting()
        for flat, pending in in_flight:
            self._settle(flat, pending, keep_hot)
        if updates:
            t0 = time.perf_counter()
            for rec, delta in self.plan.link_updates(updates):
                key = (rec.plan.source, rec.plan.target)
                self.records.setdefault(key[0], {})[key[1]] = rec
                self._enter(key, delta)
            self.stats.seconds["score"] += time.perf_counter() - t0
            self.stats.updated += len(updates)
        self._push_entered(sources)

    def _push_entered(self, sources) -> None:
        """Pushes the keys just scored, by source then ring order: the order
        in which a full re-scoring enters them, which decides exact ties."""
        entered, self.entered = self.entered, []
        if not self.use_heap:
            return
        rank = {v: i for i, v in enumerate(sources)}
        tri = self.plan.tri
        entered.sort(key=lambda k: (rank[k[0]], tri.star(k[0])[0].index(k[1])))
        for key in entered:
            self.push(key)

    def take(self, keys) -> list[tuple]:
        """``(candidate, cost)`` of fresh entries, exporting again what is not hot.

        The entries leave the queue. A re-export of a fresh entry is the same
        stencil (nothing around it changed), scored again in one batch.
        """
        out: dict = {}
        again: dict[int, list[int]] = {}
        for key in keys:
            h = self.hot.pop(key, None)
            if h is not None and h[2] == self.version[key[0]]:
                out[key] = h[:2]
            else:
                again.setdefault(key[0], []).append(key[1])
            self.entries.pop(key, None)
            if self.records is not None:
                self.records.pop(key[0], None)
        if again:
            flat, pending = self._dispatch(iter([self.plan.export(sorted(again), again)]))
            for c, r in zip(flat.cands, self._collect(flat, pending)):
                out[(c.plan.source, c.plan.target)] = (c, r)
        return [out[key] for key in keys]

    def bump(self, vertices) -> None:
        for v in vertices:
            self.version[v] += 1


class _LiveVertices:
    """Interior live vertices in an array with O(1) removal, for sampling."""

    def __init__(self, tri):
        self.ids = np.nonzero(tri.alive & ~tri.pinned)[0].tolist()
        self.where = {v: i for i, v in enumerate(self.ids)}

    def __len__(self) -> int:
        return len(self.ids)

    def remove(self, v: int) -> None:
        i = self.where.pop(v)
        last = self.ids.pop()
        if last != v:
            self.ids[i] = last
            self.where[last] = i


def _sample_half_edges(plan: TransportPlan, live: _LiveVertices, rng: np.random.Generator,
                       k: int, n_live: int | None = None) -> list[tuple[int, int]]:
    """Up to ``k`` distinct half-edges, uniform over the eligible ones.

    Rejection sampling: draw a live interior vertex ``u`` and a slot
    ``j < D`` (``D`` = the degree bound of candidate sources), keep
    ``(u, ring(u)[j])`` if the slot exists and the target is not pinned.
    Every eligible half-edge then has probability ``1 / (V D)`` per draw.
    ``n_live``: draw among the first ``n_live`` live vertices only.
    """
    tri = plan.tri
    bound = plan.max_source_degree
    out: dict[tuple[int, int], None] = {}
    ids = live.ids
    n_live = len(ids) if n_live is None else n_live
    for _ in range(64):  # each round accepts ~deg/D of its draws
        need = k - len(out)
        if need <= 0 or not n_live:
            break
        n = 4 * need * bound // 6 + 8
        us = rng.integers(0, n_live, n)
        js = rng.integers(0, bound, n)
        for ui, j in zip(us.tolist(), js.tolist()):
            u = ids[ui]
            ring = tri.star(u)[0]
            if j >= len(ring) or len(ring) > bound:
                continue
            w = ring[j]
            if tri.pinned[w]:
                continue
            out[(u, w)] = None
            if len(out) == k:
                break
    return list(out)


def _lock_set(plan: TransportPlan, source: int) -> set[int]:
    """Vertices of the closed star of a collapse's source: it and its one-ring."""
    return {source, *plan.tri.star(source)[0]}


class IndependentSet:
    """Collapses of one parallel round, chosen so that they do not interact.

    Two collapses ``A`` and ``B`` are independent when their lock sets (closed
    stars, :func:`_lock_set`) share at most one vertex:

    * a shared triangle or edge would put two shared vertices in both;
    * a face across ``A``'s link that lies in ``B``'s star (its points are
      read by ``A``'s stencil, reassigned by ``B``) has ``B``'s source as its
      far vertex, so both ends of that link edge are in both lock sets;
    * ``B`` joins vertices of its lock set only, so a new common neighbour
      ``y`` of ``A``'s source and target (breaking ``A``'s link condition)
      would put both ``y`` and ``A``'s target in both lock sets.

    One shared vertex is allowed because Delaunay fans (a far vertex joined
    to a long straight run of points) put one hub in the closed star of every
    collapse along the run: with disjoint lock sets, only one of them could
    go per round. The cost change of a round is then the sum of its deltas
    (tested exactly).
    """

    def __init__(self):
        self.owners: dict[int, list[int]] = {}
        self.size = 0

    def admits(self, lock: set[int]) -> bool:
        seen: set[int] = set()
        for v in lock:
            for a in self.owners.get(v, ()):
                if a in seen:
                    return False
                seen.add(a)
        return True

    def add(self, lock: set[int]) -> None:
        for v in lock:
            self.owners.setdefault(v, []).append(self.size)
        self.size += 1


def decimate(plan: TransportPlan, n_vertices: int | None = None, *, tolerance: float | None = None,
             relocation: int = 0, queue: str = "exhaustive", choices: int = 15, switch_factor: float = 5.0,
             round_fraction: float = 0.05, seed: int = 0, progress: bool = False,
             incremental: bool = True) -> DecimationStats:
    """Collapses greedily until ``n_vertices`` remain or no collapse is admissible.

    Args:
      plan: transport plan over a triangulation; modified in place.
      n_vertices: target count of vertices (pinned corners not counted), >= 1;
        ``None`` runs until the queue is empty (tolerance mode).
      tolerance: if given, collapses that would push some edge's RMS normal or
        tangential transport distance above it are discarded
        (:func:`within_tolerance`).
      relocation: relocate the vertices of the modified one-ring after each
        of the last ``relocation`` collapses (paper §3.5 postpones relocation
        to the last 100). Needs ``n_vertices`` to know which are the last.
      queue: ``"exhaustive"``, ``"multiple-choice"`` or ``"parallel"`` (see
        the module docstring).
      choices: half-edges drawn per step by the multiple-choice queue.
      switch_factor: the multiple-choice queue hands over to the exhaustive
        one once fewer than ``switch_factor * n_vertices`` vertices are left
        (in tolerance mode: once a draw holds no admissible collapse).
      round_fraction: parallel mode: a round collapses at most this fraction
        of the collapses still to do (at least one).
      seed: seed of the multiple-choice draws.
      progress: show a tqdm progress bar.
      incremental: in the exhaustive and parallel loops, bring the scores of
        collapses whose star kept its triangles up to date on the changed
        link edges only (:class:`~otjax.curves.plan.LinkRecord`), rather
        than scoring them again; same scores, a third fewer scored points
        late in a run. ``False`` scores every dirty half-edge in full.

    Returns:
      :class:`DecimationStats`.

    Example:
      >>> import numpy as np
      >>> from otjax.curves.triangulation import Triangulation
      >>> p = np.random.default_rng(0).random((50, 2))
      >>> plan = TransportPlan(Triangulation(p), p, np.ones(50))
      >>> decimate(plan, 10).collapses
      40
    """
    if n_vertices is None and tolerance is None:
        raise ValueError("give n_vertices, tolerance, or both")
    if n_vertices is not None and n_vertices < 1:
        raise ValueError(f"n_vertices must be >= 1, got {n_vertices}")
    if queue not in QUEUES:
        raise ValueError(f"queue must be one of {QUEUES}, got {queue!r}")
    if choices < 1:
        raise ValueError(f"choices must be >= 1, got {choices}")
    if not 0 < round_fraction <= 1:
        raise ValueError(f"round_fraction must be in (0, 1], got {round_fraction}")
    admissible = within_tolerance(tolerance) if tolerance is not None else None
    target = n_vertices if n_vertices is not None else 1
    stats = DecimationStats()
    tri = plan.tri
    rng = np.random.default_rng(seed)
    scores = _Scores(plan, stats, admissible, rng if queue == "parallel" else None)
    live = _LiveVertices(tri)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        total = max(len(live) - target, 0) if n_vertices is not None else None
        bar = tqdm(total=total, desc="collapses", unit="collapse")

    def relocating() -> bool:
        return relocation > 0 and n_vertices is not None and len(live) - target < relocation

    def collapse(key, taken=None, relocate_ring: bool = True) -> set[int]:
        """Applies the scored collapse ``key``; returns its dirty vertices."""
        cand, row = taken if taken is not None else scores.take([key])[0]
        t0 = time.perf_counter()
        dirty = plan.apply(cand, row)
        stats.seconds["apply"] += time.perf_counter() - t0
        stats.collapses += 1
        live.remove(key[0])
        if relocate_ring and relocating():
            dirty |= relocate_vertices(cand.plan.ring)
        scores.bump(dirty | {key[0]})
        if bar is not None:
            bar.update(1)
        return dirty

    def relocate_vertices(vertices) -> set[int]:
        t0 = time.perf_counter()
        dirty, moved = relocate(plan, sorted(v for v in vertices if tri.alive[v]), admissible)
        stats.relocations += moved
        stats.seconds["relocate"] += time.perf_counter() - t0
        scores.bump(dirty)
        return dirty

    if queue == "multiple-choice":
        switch = switch_factor * target if n_vertices is not None else 0

        def prefetch_next_draw():
            # The next step's draw, on a copy of the generator: the same
            # numbers as the real draw after the collapse (one vertex fewer
            # in the live list), so mostly the same half-edges. Their stars
            # are read into the caches while the kernel runs (the host is
            # idle otherwise); the real draw then finds most of them there.
            t0 = time.perf_counter()
            guess = _sample_half_edges(plan, live, copy.deepcopy(rng), choices, n_live=len(live) - 1)
            plan.prefetch([h for h in guess if not scores.fresh(h)])
            stats.seconds["sample"] += time.perf_counter() - t0

        while len(live) > max(target, switch):
            t0 = time.perf_counter()
            drawn = _sample_half_edges(plan, live, rng, choices)
            stats.seconds["sample"] += time.perf_counter() - t0
            stale: dict[int, list[int]] = {}
            for u, w in drawn:
                if not scores.fresh((u, w)):
                    stale.setdefault(u, []).append(w)
            if stale:
                scores.rescore(stale, stale, while_waiting=prefetch_next_draw)
            best = min(((scores.entries[h][0], h) for h in drawn if scores.fresh(h)), default=None)
            if best is None:  # nothing admissible in this draw: the exhaustive queue decides
                break
            collapse(best[1])
            stats.rounds += 1
        stats.switched_at = len(live) if len(live) > target else None

    if len(live) > target:
        # The multiple-choice phase scored only what it drew: score it all.
        scores.use_heap = True
        if admissible is None and incremental:
            scores.records = {}
        scores.rescore(live.ids, keep_hot=False)
    while len(live) > target and queue != "parallel":
        key = scores.pop()
        if key is None:
            break
        scores.rescore(collapse(key))
        stats.rounds += 1
    while len(live) > target and queue == "parallel":
        budget = max(1, int(round_fraction * (len(live) - target)))
        chosen, deferred = [], []
        independent = IndependentSet()
        # Only the PARALLEL_SCAN * budget cheapest candidates are considered: when the
        # cheap ones conflict, the round is smaller, rather than reaching
        # far down the queue for collapses the greedy would make much later.
        while len(chosen) < budget and len(chosen) + len(deferred) < PARALLEL_SCAN * budget:
            key = scores.pop()
            if key is None:
                break
            lock = _lock_set(plan, key[0])
            if not independent.admits(lock):
                deferred.append(key)
                continue
            chosen.append(key)
            independent.add(lock)
        if not chosen:
            break
        dirty: set[int] = set()
        rings: set[int] = set()
        for key, taken in zip(chosen, scores.take(chosen)):
            rings.update(taken[0].plan.ring)
            dirty |= collapse(key, taken, relocate_ring=False)
        # Relocation waits for the round: a move reaches past the lock set.
        if relocating():
            dirty |= relocate_vertices(rings)
        for key in deferred:
            if scores.fresh(key) and tri.alive[key[0]]:
                scores.push(key)
        scores.rescore({v for v in dirty if tri.alive[v]}, keep_hot=False)
        stats.rounds += 1
    if bar is not None:
        bar.close()
    stats.kernel_calls = plan.n_kernel_calls
    return stats
