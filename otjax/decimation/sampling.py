"""Live vertices, uniform half-edge draws, and independent sets of collapses."""

from __future__ import annotations

import numpy as np


class LiveVertices:
    """Removable vertices in an array with O(1) removal, for sampling.

    Args:
      ids: the removable vertex ids.
    """

    def __init__(self, ids):
        self.ids = list(ids)
        self.where = {v: i for i, v in enumerate(self.ids)}

    def __len__(self) -> int:
        return len(self.ids)

    def __contains__(self, v: int) -> bool:
        return v in self.where

    def remove(self, v: int) -> None:
        i = self.where.pop(v)
        last = self.ids.pop()
        if last != v:
            self.ids[i] = last
            self.where[last] = i


def sample_half_edges(engine, live: LiveVertices, rng: np.random.Generator, k: int,
                      n_live: int | None = None) -> list[tuple[int, int]]:
    """Up to ``k`` distinct half-edges, uniform over the eligible ones.

    Rejection sampling: draw a live vertex ``u`` and a slot ``j < D`` (``D`` =
    ``engine.degree_bound``), keep ``(u, engine.ring(u)[j])`` if the slot
    exists and the target is free. Every eligible half-edge then has
    probability ``1 / (V D)`` per draw.

    Args:
      engine: gives ``ring(v)``, ``free(v)`` and ``degree_bound``.
      live: the live vertices to draw from.
      rng: the generator (advanced).
      k: half-edges wanted.
      n_live: draw among the first ``n_live`` live vertices only.
    """
    bound = engine.degree_bound
    ring_of, free = engine.ring, engine.free
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
            ring = ring_of(u)
            if j >= len(ring) or len(ring) > bound:
                continue
            w = ring[j]
            if not free(w):
                continue
            out[(u, w)] = None
            if len(out) == k:
                break
    return list(out)


def lock_set(engine, source: int) -> set[int]:
    """Vertices of the closed star of a collapse's source: it and its one-ring."""
    return {source, *engine.ring(source)}


class IndependentSet:
    """Collapses of one parallel round, chosen so that they do not interact.

    Two collapses ``A`` and ``B`` are independent when their lock sets (closed
    stars, :func:`lock_set`) share at most one vertex:

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
    go per round. The cost change of a round is then the sum of its deltas.
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
