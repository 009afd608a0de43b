"""Greedy decimation: collapse half-edges in increasing order of cost increase.

The driver of de Goes et al. 2011, Fig. 4, without relocation (which comes
with the reconstruction API): an exhaustive priority queue of half-edge
collapses keyed by ``delta``; after each collapse the half-edges leaving the
dirty vertices are re-exported and re-scored in one batched kernel call.
Stale queue entries are skipped lazily by a per-vertex version counter.
"""

from __future__ import annotations

import heapq
import itertools
import time
from dataclasses import dataclass, field

from otjax.curves.plan import TransportPlan


@dataclass
class DecimationStats:
    """What a decimation run did.

    Attributes:
      collapses: number of half-edge collapses applied.
      scored: number of candidate stencils scored.
      kernel_calls: number of batched kernel calls.
      seconds: wall time, split into ``export``, ``score`` and ``apply``.
    """

    collapses: int = 0
    scored: int = 0
    kernel_calls: int = 0
    seconds: dict = field(default_factory=lambda: {"export": 0.0, "score": 0.0, "apply": 0.0})


def _interior_count(plan: TransportPlan) -> int:
    t = plan.tri
    return int((t.alive & ~t.pinned).sum())


def decimate(plan: TransportPlan, n_vertices: int, progress: bool = False) -> DecimationStats:
    """Collapses greedily until ``n_vertices`` non-pinned vertices remain.

    Args:
      plan: transport plan over a triangulation; modified in place.
      n_vertices: target count of vertices (pinned corners not counted), >= 1.
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
    if n_vertices < 1:
        raise ValueError(f"n_vertices must be >= 1, got {n_vertices}")
    stats = DecimationStats()
    tri = plan.tri
    version = [0] * len(tri.xy)
    entries: dict[tuple[int, int], tuple] = {}
    heap: list = []
    tie = itertools.count()

    def rescore(sources) -> None:
        t0 = time.perf_counter()
        cands = []
        for v in sorted(sources):
            if tri.alive[v] and not tri.pinned[v]:
                for w in tri.star(v)[0]:
                    c = plan.candidate(v, w)
                    if c is not None:
                        cands.append(c)
        t1 = time.perf_counter()
        delta, rows = plan.score(cands)
        stats.seconds["export"] += t1 - t0
        stats.seconds["score"] += time.perf_counter() - t1
        stats.scored += len(cands)
        for c, d, r in zip(cands, delta, rows):
            key = (c.plan.source, c.plan.target)
            entries[key] = (c, r, version[key[0]])
            heapq.heappush(heap, (float(d), next(tie), key, version[key[0]]))

    rescore(range(len(tri.xy)))
    total = max(_interior_count(plan) - n_vertices, 0)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, desc="collapses", unit="collapse")
    while _interior_count(plan) > n_vertices and heap:
        _, _, key, ver = heapq.heappop(heap)
        entry = entries.get(key)
        if entry is None or entry[2] != ver or ver != version[key[0]] or not tri.alive[key[0]]:
            continue
        cand, scored, _ = entry
        t0 = time.perf_counter()
        dirty = plan.apply(cand, scored)
        stats.seconds["apply"] += time.perf_counter() - t0
        entries.pop(key)
        for v in dirty | {key[0]}:
            version[v] += 1
        stats.collapses += 1
        if bar is not None:
            bar.update(1)
        rescore(dirty)
    if bar is not None:
        bar.close()
    stats.kernel_calls = plan.n_kernel_calls
    return stats
