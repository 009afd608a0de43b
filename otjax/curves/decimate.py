"""Greedy decimation: collapse half-edges in increasing order of cost increase.

The driver of de Goes et al. 2011, Fig. 4: an exhaustive priority queue of
half-edge collapses keyed by ``delta``; after each collapse (and the
relocations that follow it near the end) the half-edges leaving the dirty
vertices are re-exported and re-scored in one batched kernel call. Stale queue
entries are skipped lazily by a per-vertex version counter.
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass, field

import numpy as np

from otjax.curves.plan import TransportPlan
from otjax.curves.relocation import relocate


@dataclass
class DecimationStats:
    """What a decimation run did.

    Attributes:
      collapses: number of half-edge collapses applied.
      relocations: number of vertex moves applied.
      scored: number of candidate stencils scored.
      kernel_calls: number of batched kernel calls.
      seconds: wall time, split into ``export``, ``score``, ``apply`` and
        ``relocate``.
    """

    collapses: int = 0
    relocations: int = 0
    scored: int = 0
    kernel_calls: int = 0
    seconds: dict = field(
        default_factory=lambda: {"export": 0.0, "score": 0.0, "apply": 0.0, "relocate": 0.0})


def _interior_count(plan: TransportPlan) -> int:
    t = plan.tri
    return int((t.alive & ~t.pinned).sum())


def within_tolerance(tolerance: float):
    """Veto for the tolerance mode (paper §3.5), as a candidate filter.

    A change is admissible when, on every edge of its stencil that carries
    mass ``M_e``, the root-mean-square transport distance of each part stays
    under ``tolerance``: ``sqrt(N_e / M_e)`` and ``sqrt(T_e / M_e)`` for a
    solid edge, ``sqrt(V_e / M_e)`` (its points go to the endpoints) for a
    ghost edge. RMS distances are in the units of the input, so the
    tolerance reads like a distance, independent of how masses are scaled.

    Returns:
      ``(candidate, result, row) -> bool``.
    """
    tol2 = float(tolerance) ** 2

    def ok(cand, res, row) -> bool:
        e = len(cand.keys)
        m = np.asarray(res.edge_mass[row, :e])
        solid = np.asarray(res.solid[row, :e])
        first = np.where(solid, res.normal[row, :e], res.vertex[row, :e])
        second = np.where(solid, res.tangential[row, :e], 0.0)
        bound = tol2 * m
        return bool(np.all((first <= bound) & (second <= bound)))

    return ok


def decimate(plan: TransportPlan, n_vertices: int | None = None, *, tolerance: float | None = None,
             relocation: int = 0, progress: bool = False) -> DecimationStats:
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
      progress: show a tqdm progress bar.

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
    admissible = within_tolerance(tolerance) if tolerance is not None else None
    target = n_vertices if n_vertices is not None else 1
    stats = DecimationStats()
    tri = plan.tri
    version = [0] * len(tri.xy)
    entries: dict[tuple[int, int], tuple] = {}
    heap: list = []
    tie = itertools.count()

    def rescore(sources) -> None:
        t0 = time.perf_counter()
        cands = plan.candidates(sorted(sources))
        t1 = time.perf_counter()
        delta, rows = plan.score(cands)
        stats.seconds["export"] += t1 - t0
        stats.seconds["score"] += time.perf_counter() - t1
        stats.scored += len(cands)
        for c, d, r in zip(cands, delta, rows):
            if admissible is not None and not admissible(c, *r):
                continue
            key = (c.plan.source, c.plan.target)
            entries[key] = (c, r, version[key[0]])
            heapq.heappush(heap, (float(d), next(tie), key, version[key[0]]))

    rescore(range(len(tri.xy)))
    live = _interior_count(plan)  # kept up to date below: one collapse removes one vertex
    bar = None
    if progress:
        from tqdm.auto import tqdm

        total = max(live - target, 0) if n_vertices is not None else None
        bar = tqdm(total=total, desc="collapses", unit="collapse")
    while live > target and heap:
        _, _, key, ver = heapq.heappop(heap)
        entry = entries.get(key)
        if entry is None or entry[2] != ver or ver != version[key[0]] or not tri.alive[key[0]]:
            continue
        cand, scored, _ = entry
        t0 = time.perf_counter()
        dirty = plan.apply(cand, scored)
        stats.seconds["apply"] += time.perf_counter() - t0
        entries.pop(key)
        stats.collapses += 1
        live -= 1
        remaining = live - target
        if relocation > 0 and n_vertices is not None and remaining < relocation:
            t0 = time.perf_counter()
            more, moved = relocate(plan, sorted(cand.plan.ring), admissible)
            dirty |= more
            stats.relocations += moved
            stats.seconds["relocate"] += time.perf_counter() - t0
        for v in dirty | {key[0]}:
            version[v] += 1
        if bar is not None:
            bar.update(1)
        rescore(dirty)
    if bar is not None:
        bar.close()
    stats.kernel_calls = plan.n_kernel_calls
    return stats
