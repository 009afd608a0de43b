"""Open ends of the curve moved to where their points end.

The transport cost holds an open end short of the points: the points
around the end that its solid edge does not keep go to the end vertex
itself (through its ghost edges), and relocation puts the vertex near
their mean, inside the last points by about half their spread. On the
X/T junctions of ``scripts/compare_reference.py`` the five free ends sat
up to 1.7% D inside (docs/decisions.md#end_fit).

For every end (a vertex on exactly one solid edge that carries points,
the scaffolding edges to the pinned box corners left out) the points of
its edge and the points it holds itself within the edge's tube are
projected on the edge's line, and the end moves along that line to
:func:`otjax.uniform_ends.uniform_end` of the projections: past the
farthest by the mean spacing, the noise's overshoot taken off. The move
goes through the engine like a relocation (the plan is updated, a move
that would fold a triangle is not made) but is not asked to lower the
cost: the cost is what pulls the end in.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from otjax.curves.engine import Scored
from otjax.curves.plan import TransportPlan
from otjax.curves.plan_result import point_holders
from otjax.uniform_ends import uniform_end

#: An end moves only when at least this many points (its edge's and its own)
#: say where the curve ends; the spacing and the noise come from them.
MIN_END_POINTS = 5
#: The end vertex's own points count when they lie within this many noise
#: standard deviations of the edge's line (or within the mean spacing, the
#: larger): points around a corner or of another branch do not.
TUBE_SIGMAS = 3.0


class EndMove(NamedTuple):
    """Where an open end goes.

    Attributes:
      vertex: the end's vertex id.
      other: the vertex at the other end of its solid edge.
      position: ``(2,)`` its new position.
    """

    vertex: int
    other: int
    position: np.ndarray


def open_ends(plan: TransportPlan, solid: np.ndarray, keys: np.ndarray) -> dict[int, int]:
    """``{end: other}``: the vertices on exactly one solid edge that carries
    points (edges to pinned vertices not counted), with that edge's other end."""
    pinned = plan.tri.pinned
    edges = np.unique(keys[solid], axis=0)
    edges = edges[~(pinned[edges[:, 0]] | pinned[edges[:, 1]])] if len(edges) else edges.reshape(0, 2)
    degree = np.bincount(edges.ravel(), minlength=len(plan.tri.xy))
    out = {}
    for a, b in edges.tolist():
        if degree[a] == 1:
            out[a] = b
        if degree[b] == 1:
            out[b] = a
    return out


def end_position(on_edge: np.ndarray, own: np.ndarray, end: np.ndarray,
                 other: np.ndarray) -> np.ndarray | None:
    """Where the curve through ``other`` and ``end`` ends, from the points
    ``on_edge (k, 2)`` of that edge and ``own (j, 2)`` of the end vertex;
    ``None`` when too few points say it.

    Example:
      >>> x = np.linspace(0.0, 1.0, 101)  # evenly spaced points of [0, 1] on the x axis
      >>> on_edge = np.stack([x[:80], 0 * x[:80]], 1); own = np.stack([x[80:], 0 * x[80:]], 1)
      >>> end_position(on_edge, own, np.array([0.9, 0.0]), np.array([0.0, 0.0])).round(3).tolist()
      [1.01, 0.0]
    """
    if len(on_edge) < 2 or len(on_edge) + len(own) < MIN_END_POINTS:
        return None
    along = end - other
    length = math.hypot(*along)
    if not length > 0:
        return None
    u = along / length
    normal = np.array([-u[1], u[0]])
    x, r = (on_edge - other) @ u, (on_edge - other) @ normal
    noise = float(np.sqrt(np.mean(r * r)))
    spacing = float(np.ptp(x)) / (len(x) - 1)
    if len(own):
        ox, orr = (own - other) @ u, (own - other) @ normal
        x = np.concatenate([x, ox[np.abs(orr) <= max(TUBE_SIGMAS * noise, spacing)]])
    reach = uniform_end(x, noise)
    if not reach > 0:
        return None
    return other + reach * u


def propose_end_moves(plan: TransportPlan, vertices=None) -> list[EndMove]:
    """An :class:`EndMove` for each open end (of ``vertices`` only, if given)
    whose points say where it ends and that is not there already."""
    solid, keys, holder = point_holders(plan)
    ends = open_ends(plan, solid, keys)
    if vertices is not None:
        ends = {v: o for v, o in ends.items() if v in vertices}
    if not ends:
        return []
    xy, pts = plan.tri.xy, plan.points
    code = keys[:, 0] * len(xy) + keys[:, 1]
    # The points of every end's edge and of every end vertex, grouped once (not one pass each).
    edge_codes = [min(v, o) * len(xy) + max(v, o) for v, o in ends.items()]
    by_edge = _groups(code, solid & np.isin(code, edge_codes))
    by_vertex = _groups(holder, np.isin(holder, list(ends)))
    none = np.zeros(0, np.int64)
    moves = []
    for v, o in sorted(ends.items()):
        on_edge = pts[by_edge.get(min(v, o) * len(xy) + max(v, o), none)]
        pos = end_position(on_edge, pts[by_vertex.get(v, none)], xy[v], xy[o])
        if pos is not None and np.all(np.isfinite(pos)) and np.any(pos != xy[v]):
            moves.append(EndMove(v, o, pos))
    return moves


def _groups(values: np.ndarray, mask: np.ndarray) -> dict[int, np.ndarray]:
    """``{value: ids}``: the ids (increasing) of the entries of ``values (n,)``
    where ``mask``, grouped by value."""
    ids = np.flatnonzero(mask)
    order = np.argsort(values[ids], kind="stable")
    keys, starts = np.unique(values[ids][order], return_index=True)
    return {int(k): ids[chunk] for k, chunk in zip(keys, np.split(order, starts[1:]))}


def fit_ends(engine, veto=None) -> int:
    """Moves every open end of ``engine``'s plan where its points end
    (:func:`propose_end_moves`), through the engine; returns how many moved.

    Moves are scored together and applied in order; one whose stencil an
    earlier move changed is proposed again on the new state. Each end is
    tried once. A move that would fold a triangle, or that ``veto(*scored)``
    (if given) refuses, is not made.

    Args:
      engine: a :class:`~otjax.curves.engine.CurveEngine`.
      veto: optional admissibility filter of scored moves (the tolerance mode's).
    """
    waiting = None
    moved = 0
    tried: set[int] = set()
    while True:
        moves = [m for m in propose_end_moves(engine.plan, waiting) if m.vertex not in tried]
        if not moves:
            return moved
        cands = engine.relocation_candidates([(m.vertex, m.position) for m in moves])
        _, costs = engine.score_candidates(cands) if cands else (None, [])
        dirty: set[int] = set()
        for cand, cost in zip(cands, costs):
            v = cand.plan.source
            if v in dirty:
                continue
            tried.add(v)
            scored = Scored(cand, cost)
            if veto is not None and not veto(*scored):
                continue
            dirty |= engine.apply(*scored).dirty
            moved += 1
        tried.update(m.vertex for m in moves if m.vertex not in dirty)
        waiting = dirty - tried
        if not waiting:
            return moved
