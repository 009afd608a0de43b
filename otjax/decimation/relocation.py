"""A pass of vertex moves, in order, its proposals scored in batches."""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np


class Moves(NamedTuple):
    """What a pass of :func:`relocate` did: ``dirty`` vertices (their stencils
    changed), ``quiet`` ones (next to a move, nothing of theirs changed:
    the engine's ``quiet``, less ``dirty``) and how many vertices ``moved``."""

    dirty: set
    quiet: set
    moved: int


def relocate(engine, vertices, veto: Callable | None = None) -> Moves:
    """One pass over ``vertices``, in order: each moves where its engine
    proposes if the engine's gain for that move is negative.

    The result is that of visiting the vertices one at a time, each proposal
    made and scored on the state the moves before it left; the work is
    batched: the proposals of a prefix of the waiting vertices that lie
    more than two edges apart (paths through immovable vertices do not
    count), or of the next ``engine.speculate`` if that prefix is shorter,
    are made and scored in one call, then applied in order. A vertex that an
    applied move made dirty (or quiet) ends the prefix: its proposal is
    dropped and the next call resumes there, proposing again only the
    vertices without a proposal still valid. Speculating pays where a call
    costs more than a proposal (docs/decisions.md#relocation_batch).

    Args:
      engine: gives ``movable(v)``, ``propose_moves(vertices) -> [(vertex,
        gain, scored)]`` (scored against the current state),
        ``apply(*scored)`` returning a change with ``dirty`` (and optionally
        ``quiet``), and ``speculate`` (an int, at least 1).
      vertices: vertex ids (duplicates and immovable ones are skipped).
      veto: optional ``(*scored) -> bool`` admissibility filter.

    Returns:
      :class:`Moves`.
    """
    waiting = [v for v in dict.fromkeys(vertices) if engine.movable(v)]
    dirty: set[int] = set()
    quiet: set[int] = set()
    moved = 0
    held: dict = {}  # vertex -> (gain, scored), made on a state nothing of it changed since
    while waiting:
        chunk = _independent_prefix(engine, waiting)
        if len(chunk) < engine.speculate:
            chunk = waiting[:engine.speculate]
        fresh = [v for v in chunk if v not in held]
        held.update({v: (gain, scored) for v, gain, scored in engine.propose_moves(fresh)})
        for v in fresh:
            held.setdefault(v, (0.0, None))
        changed: set[int] = set()
        done = 0
        for v in chunk:
            if v in changed:
                break
            done += 1
            gain, scored = held.pop(v)
            if not gain < 0 or (veto is not None and not veto(*scored)):
                continue
            change = engine.apply(*scored)
            # A quiet vertex ends the prefix too: its proposal is made again,
            # on the state the move left, as a dirty one's is.
            near = getattr(change, "quiet", frozenset())
            changed |= change.dirty | near
            dirty |= change.dirty
            quiet |= near
            moved += 1
        for v in changed:
            held.pop(v, None)
        waiting = waiting[done:]
    return Moves(dirty, quiet - dirty, moved)


def _independent_prefix(engine, waiting: list[int]) -> list[int]:
    """The longest prefix of ``waiting`` in which no vertex is within two
    edges of an earlier one through a movable vertex: a move dirties at most its vertex's neighbours
    and the vertices across its link, so the proposals of such a prefix,
    made on one state, are those that visiting it in order would make.
    (A vertex across a link edge from ``v`` is in the ring of that edge's
    free end; a link edge with two pinned ends makes ``v`` go alone.)"""
    near: set[int] = set()
    chunk = []
    for v in waiting:
        if v in near:
            break
        ring = engine.ring(v)
        free = [engine.movable(u) for u in ring]
        if any(not a and not b for a, b in zip(free, free[1:] + free[:1])):
            # Across a link edge between two pinned vertices lies a vertex no
            # free neighbour's ring names: this one goes alone.
            return chunk or [v]
        chunk.append(v)
        near.add(v)
        near.update(ring)
        for u, ok in zip(ring, free):
            if ok:
                near.update(engine.ring(u))
    return chunk
