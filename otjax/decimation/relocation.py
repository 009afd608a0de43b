"""Rounds of vertex moves: proposals scored in batches, applied by decreasing gain."""

from __future__ import annotations

from typing import Callable

import numpy as np


def relocate(engine, vertices, veto: Callable | None = None) -> tuple[set[int], int]:
    """Moves each of ``vertices`` where its engine proposes, if that lowers the cost.

    Moves of adjacent vertices interact (they share simplices), so the work
    is done in rounds: each round has the engine propose and score a move for
    every vertex still waiting (one batched call), and applies the improving
    ones by decreasing gain, skipping any vertex that a move of this round
    made dirty; those wait for the next round. Every vertex is considered
    once; a vertex without an admissible proposal drops out.

    Args:
      engine: gives ``movable(v)``, ``propose_moves(vertices) -> [(vertex,
        delta, scored)]`` (scored against the current state) and
        ``apply(*scored)`` returning a change with ``dirty``.
      vertices: vertex ids (duplicates and immovable ones are skipped).
      veto: optional ``(*scored) -> bool`` admissibility filter.

    Returns:
      ``(dirty, moved)``: vertices whose stencils the moves changed, and how
      many vertices moved.
    """
    waiting = [v for v in dict.fromkeys(vertices) if engine.movable(v)]
    dirty: set[int] = set()
    moved = 0
    while waiting:
        proposals = engine.propose_moves(waiting)
        if not proposals:
            break
        blocked: set[int] = set()
        done: set[int] = set()
        delta = np.array([p[1] for p in proposals], np.float64)
        for i in np.argsort(delta, kind="stable"):
            v, gain, scored = proposals[i]
            if gain >= 0:
                done.add(v)
                continue
            if v in blocked:
                continue
            if veto is not None and not veto(*scored):
                done.add(v)
                continue
            changed = engine.apply(*scored).dirty
            dirty |= changed
            blocked |= changed
            moved += 1
            done.add(v)
        proposed = {p[0] for p in proposals}
        waiting = [v for v in waiting if v in proposed and v not in done]
    return dirty, moved
