"""Greedy decimation: apply changes in increasing order of cost increase.

The driver of de Goes et al. 2011 (Fig. 4) over an *engine* that knows the
geometry; four queues:

:func:`run_exhaustive`
  every half-edge is scored up front; after each collapse (and the
  relocations that follow it near the end) the half-edges leaving the dirty
  vertices are scored again in one batched call. Stale entries are skipped
  lazily by the engine's versions.
:func:`run_lazy`
  not in the paper: as exhaustive, but a dirty half-edge keeps its old score
  on the heap until it comes up, and is scored again only then (with every
  other stale one that comes up before the cheapest fresh score), until the
  last ``lazy_tail`` collapses, which are exhaustive. Most changes leave
  most dirty scores as they were or raise them: far fewer scorings, for a
  collapse order that differs where a cost fell.
:func:`run_multiple_choice`
  paper §3.5: each step draws ``choices`` half-edges uniformly at random,
  scores those without a fresh score in one batched call, and collapses the
  cheapest. A step costs the same whatever the size. Below ``switch_factor``
  times the target it hands over to :func:`run_exhaustive`, where the few
  remaining choices matter most.
:func:`run_parallel`
  not in the paper: each round takes, among the ``2 k`` cheapest candidates,
  up to ``k`` whose regions do not overlap (an independent set; ``k =
  round_fraction`` of the collapses left), applies them all, and scores the
  union of their dirty regions in one batch. Rounds are what a GPU pays for.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol, Sequence

import numpy as np

from otjax.decimation.relocation import relocate as relocate_rounds
from otjax.decimation.sampling import IndependentSet, LiveVertices, lock_set, sample_half_edges
from otjax.decimation.score_table import ScoreTable

QUEUES = ("exhaustive", "multiple-choice", "parallel", "lazy")
# Parallel rounds look at most this many times their budget down the queue
# (docs/decisions.md#parallel_scan).
PARALLEL_SCAN = 2
# The lazy queue hands the last this many collapses to the exhaustive one
# (docs/decisions.md#lazy_tail).
LAZY_TAIL = 200


class Engine(Protocol):
    """What the loop needs of a dimension (see ``otjax.curves.engine.CurveEngine``).

    Half-edges are ``(source, target)`` vertex pairs; a collapse removes
    ``source``. ``versions[v]`` changes whenever a change touches the
    half-edges leaving ``v``. ``score`` returns ``[(half-edge, delta)]`` of
    the admissible ones (with ``cheapest_only``, it may leave out those it
    can show are not the cheapest); ``take`` returns opaque scored candidates that
    ``apply(*taken)`` applies, returning a change with ``dirty`` (vertices to
    score again), ``ring`` (the source's one-ring) and optionally ``quiet``
    (vertices whose scores the change left as they were although a coarser
    rule would call them dirty: their versions did not change, and the loop
    enters their scores again beside the dirty ones', in the same order). ``propose_moves``
    returns ``[(vertex, delta, scored)]`` for :func:`otjax.decimation.relocation.relocate`,
    which proposes at least ``speculate`` vertices a call.
    """

    versions: Sequence[int]
    degree_bound: int
    speculate: int

    def live_sources(self) -> list[int]: ...
    def ring(self, v: int) -> tuple[int, ...]: ...
    def free(self, v: int) -> bool: ...
    def score(self, sources, targets=None, *, veto=None, keep=True, while_waiting=None,
              cheapest_only=False) -> list: ...
    def take(self, keys) -> list: ...
    def apply(self, *taken): ...
    def movable(self, v: int) -> bool: ...
    def propose_moves(self, vertices) -> list: ...
    def prefetch(self, half_edges) -> None: ...
    def stats(self) -> dict: ...


@dataclass
class DecimationStats:
    """What a decimation run did.

    Attributes:
      collapses: half-edge collapses applied.
      relocations: vertex moves applied.
      scored: candidate stencils scored.
      updated: scored collapses brought up to date on their changed link
        edges only.
      partial: scored collapses scored again on the part of their stencil
        that moves of ring vertices changed (also in ``scored``).
      kernel_calls: batched kernel calls.
      rounds: rounds (one per collapse, except in the parallel queue).
      switched_at: live vertex count at which the multiple-choice queue
        handed over to the exhaustive one (``None`` if it never did).
      seconds: wall time: ``export`` (stencils and flip plans), ``score``
        (kernel calls), ``apply`` (topology and plan updates), ``relocate``
        and ``sample`` (drawing half-edges).
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


@dataclass
class Run:
    """The state one decimation run shares between its steps.

    Attributes:
      engine: the engine.
      table: the :class:`ScoreTable`.
      live: the removable vertices left.
      target: vertices to keep.
      relocate_last: relocate the ring of each of the last this many collapses.
      known_end: whether the run stops at ``target`` (relocation needs it).
      veto: optional ``(candidate, cost) -> bool`` filter of admissible changes.
      stats: the loop's counters.
      on_collapse: called after each collapse (a progress bar).
      quiet: vertices the changes since the last scoring left quiet (see
        :class:`Engine`), entered again by the next :func:`score`.
    """

    engine: Engine
    table: ScoreTable
    live: LiveVertices
    target: int
    relocate_last: int
    known_end: bool
    veto: Callable | None
    stats: DecimationStats
    on_collapse: Callable[[], None] | None = None
    quiet: set = field(default_factory=set)

    def relocating(self) -> bool:
        return self.relocate_last > 0 and self.known_end and len(self.live) - self.target < self.relocate_last


def _rank(run: Run, sources) -> Callable:
    """Heap order of freshly scored half-edges: by source (in ``sources``
    order), then ring order -- the order a full scoring enters them in."""
    rank = {v: i for i, v in enumerate(sorted(sources))}
    ring = run.engine.ring
    slots: dict[int, dict[int, int]] = {}  # source -> {target: place in its ring}

    def order(k):
        slot = slots.get(k[0])
        if slot is None:
            slot = slots[k[0]] = {w: i for i, w in enumerate(ring(k[0]))}
        return rank[k[0]], slot[k[1]]

    return order


def score(run: Run, sources, targets=None, *, keep: bool = True, while_waiting=None,
          cheapest_only: bool = False) -> list:
    """Scores the half-edges leaving ``sources`` into the table (with
    ``cheapest_only``, the engine may leave out those that cannot be the
    cheapest); returns the ``[(half-edge, delta)]`` entered."""
    entries = run.engine.score(sources, targets, veto=run.veto, keep=keep, while_waiting=while_waiting,
                               cheapest_only=cheapest_only)
    quiet, run.quiet = run.quiet, set()
    if run.table.use_heap and targets is None:
        # Their scores go on the heap again with the fresh ones, in the order a
        # scoring of every source would give, so exact ties pop the same way.
        quiet = sorted(v for v in quiet.difference(sources) if v in run.live)
        table = run.table
        entries = entries + [(k, table.delta(k)) for v in quiet for k in ((v, w) for w in run.engine.ring(v))
                             if table.fresh(k)]
        sources = [*sources, *quiet]
    run.table.enter(entries, _rank(run, sources) if run.table.use_heap else None)
    return entries


def relocate(run: Run, vertices) -> set[int]:
    """Relocates ``vertices`` (the live ones); returns the vertices it made dirty."""
    t0 = time.perf_counter()
    moves = relocate_rounds(run.engine, sorted(v for v in vertices if v in run.live), run.veto)
    run.stats.relocations += moves.moved
    run.stats.seconds["relocate"] += time.perf_counter() - t0
    run.quiet |= moves.quiet
    return set(moves.dirty)


def collapse(run: Run, key, taken=None, relocate_ring: bool = True) -> tuple[set[int], tuple[int, ...]]:
    """Applies the scored collapse ``key`` (taking it if not ``taken``), then
    relocates its ring near the end; returns the dirty vertices and the ring."""
    if taken is None:
        run.table.discard([key])
        taken = run.engine.take([key])[0]
    t0 = time.perf_counter()
    change = run.engine.apply(*taken)
    run.stats.seconds["apply"] += time.perf_counter() - t0
    run.quiet |= getattr(change, "quiet", frozenset())
    run.stats.collapses += 1
    run.live.remove(key[0])
    dirty = set(change.dirty)
    if relocate_ring and run.relocating():
        dirty |= relocate(run, change.ring)
    if run.on_collapse is not None:
        run.on_collapse()
    return dirty, change.ring


def run_exhaustive(run: Run) -> None:
    """Scores every half-edge, then collapses the cheapest until the target."""
    if len(run.live) <= run.target:
        return
    run.table.use_heap = True
    # Kept too (within the engine's memory bound): a winner is often a
    # collapse nothing near it changed since this first scoring.
    score(run, run.live.ids, keep=True)
    while len(run.live) > run.target:
        key = run.table.pop(run.live.__contains__)
        if key is None:
            break
        score(run, collapse(run, key)[0])
        run.stats.rounds += 1


def run_lazy(run: Run, tail: int) -> None:
    """Scores every half-edge, then collapses the cheapest fresh one, as
    :func:`run_exhaustive`, except that a change does not score the dirty
    half-edges again: each keeps its old score on the heap, and the sources
    of the stale entries that come up before the cheapest fresh one are
    scored again together, until a fresh entry comes up first. The last
    ``tail`` collapses (of a run with a known end) are
    :func:`run_exhaustive`'s.

    So the collapse applied is the cheapest by scores that are current or,
    for half-edges a change touched since, as they were; where a change
    lowered a cost, that collapse waits until its old score comes up.
    Sources without an admissible half-edge have nothing on the heap: they
    are scored again before the next collapse once a change touches them.
    """
    table, live = run.table, run.live
    if len(live) <= run.target:
        return
    table.use_heap = True
    table.keep_stale = True
    held: dict[int, set[int]] = {v: set() for v in live.ids}  # targets entered at each source's last scoring

    def score_again(sources):
        entered: dict[int, set[int]] = {v: set() for v in sources}
        for (v, w), _ in score(run, sources, keep=True):
            entered[v].add(w)
        for v, targets in entered.items():
            # A half-edge its source no longer has must not come up again.
            table.discard((v, w) for w in held[v] - targets)
            held[v] = targets

    end = run.target + tail if run.known_end else run.target
    if len(live) > end:
        score_again(live.ids)
    waiting: set[int] = set()
    while len(live) > end:
        stale = waiting
        while (item := table.pop_any(live.__contains__)) is not None and not item.fresh:
            stale.add(item.key[0])
        if stale:
            if item is not None:
                table.push(item.key)
            score_again(stale)
            waiting = set()
            continue
        if item is None:
            break
        dirty, _ = collapse(run, item.key)
        waiting = {v for v in dirty if v in live and not held[v]}
        # Quiet vertices kept their versions: their heap items still hold.
        run.quiet = set()
        run.stats.rounds += 1
    table.keep_stale = False
    run_exhaustive(run)


def run_multiple_choice(run: Run, rng: np.random.Generator, choices: int, switch_factor: float) -> None:
    """The best of ``choices`` random half-edges per step, then
    :func:`run_exhaustive` below ``switch_factor`` times the target (or once
    a draw holds nothing admissible)."""
    engine, table, live = run.engine, run.table, run.live
    switch = switch_factor * run.target if run.known_end else 0

    def prefetch_next_draw():
        # The next step's draw, on a copy of the generator: the same numbers
        # as the real draw after the collapse (one vertex fewer in the live
        # list), so mostly the same half-edges; their stars are read into the
        # caches while the kernel runs.
        t0 = time.perf_counter()
        guess = sample_half_edges(engine, live, copy.deepcopy(rng), choices, n_live=len(live) - 1)
        engine.prefetch([h for h in guess if not table.fresh(h)])
        run.stats.seconds["sample"] += time.perf_counter() - t0

    while len(live) > max(run.target, switch):
        t0 = time.perf_counter()
        drawn = sample_half_edges(engine, live, rng, choices)
        run.stats.seconds["sample"] += time.perf_counter() - t0
        stale: dict[int, list[int]] = {}
        for u, w in drawn:
            if not table.fresh((u, w)):
                stale.setdefault(u, []).append(w)
        if stale:
            # Only the cheapest draw is collapsed: a half-edge that cannot beat
            # it may stay unscored (it is scored when drawn again).
            score(run, stale, stale, while_waiting=prefetch_next_draw, cheapest_only=True)
        best = min(((table.delta(h), h) for h in drawn if table.fresh(h)), default=None)
        if best is None:
            break
        collapse(run, best[1])
        run.stats.rounds += 1
    run.stats.switched_at = len(live) if len(live) > run.target else None
    run_exhaustive(run)


def run_parallel(run: Run, round_fraction: float) -> None:
    """Rounds of independent cheap collapses, relocation after each round."""
    engine, table, live = run.engine, run.table, run.live
    if len(live) <= run.target:
        return
    table.use_heap = True
    score(run, live.ids, keep=False)
    while len(live) > run.target:
        budget = max(1, int(round_fraction * (len(live) - run.target)))
        chosen, deferred = [], []
        independent = IndependentSet()
        # Only the PARALLEL_SCAN * budget cheapest candidates are considered:
        # when the cheap ones conflict the round is smaller, rather than
        # reaching far down the queue for collapses the greedy makes later.
        while len(chosen) < budget and len(chosen) + len(deferred) < PARALLEL_SCAN * budget:
            key = table.pop(live.__contains__)
            if key is None:
                break
            lock = lock_set(engine, key[0])
            if not independent.admits(lock):
                deferred.append(key)
                continue
            chosen.append(key)
            independent.add(lock)
        if not chosen:
            break
        dirty: set[int] = set()
        rings: set[int] = set()
        table.discard(chosen)
        for key, taken in zip(chosen, engine.take(chosen)):
            changed, ring = collapse(run, key, taken, relocate_ring=False)
            dirty |= changed
            rings.update(ring)
        # Relocation waits for the round: a move reaches past the lock set.
        if run.relocating():
            dirty |= relocate(run, rings)
        for key in deferred:
            # A quiet source's scores are entered again with the dirty ones'.
            if table.fresh(key) and key[0] in live and key[0] not in run.quiet:
                table.push(key)
        score(run, {v for v in dirty if v in live}, keep=False)
        run.stats.rounds += 1


def decimate(engine: Engine, n_vertices: int | None = None, *, queue: str = "exhaustive", choices: int = 15,
             switch_factor: float = 5.0, round_fraction: float = 0.05, seed: int = 0, relocation: int = 0,
             lazy_tail: int = LAZY_TAIL, veto: Callable | None = None, progress: bool = False) -> DecimationStats:
    """Applies collapses greedily until ``n_vertices`` remain or none is admissible.

    Args:
      engine: the :class:`Engine` (modified in place).
      n_vertices: vertices to keep (>= 1); ``None`` runs until no admissible
        collapse is left (``veto`` then decides).
      queue: one of :data:`QUEUES` (see the module docstring).
      choices: half-edges drawn per multiple-choice step.
      switch_factor: multiple choice hands over to the exhaustive queue below
        ``switch_factor * n_vertices`` vertices (without a target: once a
        draw holds nothing admissible).
      round_fraction: parallel queue: a round applies at most this fraction
        of the collapses still to do (at least one).
      seed: seed of the random draws (multiple choice) and tie order (parallel).
      relocation: relocate the ring of each of the last ``relocation``
        collapses (needs ``n_vertices``).
      lazy_tail: lazy queue: the last this many collapses are the
        exhaustive queue's (with ``n_vertices``).
      veto: optional ``(candidate, cost) -> bool`` admissibility filter.
      progress: show a tqdm progress bar.

    Returns:
      :class:`DecimationStats`.
    """
    if n_vertices is not None and n_vertices < 1:
        raise ValueError(f"n_vertices must be >= 1, got {n_vertices}")
    if n_vertices is None and veto is None:
        raise ValueError("without n_vertices, a veto must end the run")
    if queue not in QUEUES:
        raise ValueError(f"queue must be one of {QUEUES}, got {queue!r}")
    if choices < 1:
        raise ValueError(f"choices must be >= 1, got {choices}")
    if not 0 < round_fraction <= 1:
        raise ValueError(f"round_fraction must be in (0, 1], got {round_fraction}")
    if lazy_tail < 0:
        raise ValueError(f"lazy_tail must be >= 0, got {lazy_tail}")
    target = n_vertices if n_vertices is not None else 1
    rng = np.random.default_rng(seed)
    table = ScoreTable(engine.versions, rng if queue == "parallel" else None)
    live = LiveVertices(engine.live_sources())
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=max(len(live) - target, 0) if n_vertices is not None else None,
                   desc="collapses", unit="collapse")
    start = engine.stats()
    run = Run(engine, table, live, target, relocation, n_vertices is not None, veto, DecimationStats(),
              None if bar is None else (lambda: bar.update(1)))
    if queue == "multiple-choice":
        run_multiple_choice(run, rng, choices, switch_factor)
    elif queue == "parallel":
        run_parallel(run, round_fraction)
    elif queue == "lazy":
        run_lazy(run, lazy_tail)
    else:
        run_exhaustive(run)
    if bar is not None:
        bar.close()
    stats = run.stats
    end = engine.stats()
    stats.scored, stats.updated, stats.partial = (end[k] - start[k] for k in ("scored", "updated", "partial"))
    stats.kernel_calls = end["kernel_calls"]  # the engine's, since it was made
    for k, t in end["seconds"].items():
        stats.seconds[k] = t - start["seconds"][k]
    return stats
