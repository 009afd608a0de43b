"""The result of a finished plan: which of its edges and vertices are kept.

:func:`result_from_plan` sums the mass each solid edge and each vertex
receives (:func:`vertex_and_edge_masses`), keeps the relevant edges
(:func:`relevant_edges`: relevance and density), drops redundant chords and
what does not stand out of the background (:mod:`otjax.curves.filtering`),
and numbers what is left as a :class:`~otjax.curves.result.CurveResult`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.background import Background
from otjax.curves import filtering
from otjax.curves.plan import TransportPlan
from otjax.curves.result import CurveResult


class Holders(NamedTuple):
    """Where each point of a plan sends its mass.

    Attributes:
      solid: ``(n,)`` bool, whether the point stays on its edge.
      keys: ``(n, 2)`` the edge key each point is assigned to.
      vertex: ``(n,)`` int64, the vertex a point of a ghost edge goes to (its
        nearer end, ties to the lower id, as ``min`` in the kernel gives the
        same cost either way); -1 for a point on a solid edge.
    """

    solid: np.ndarray
    keys: np.ndarray
    vertex: np.ndarray


def point_holders(plan: TransportPlan) -> Holders:
    """The :class:`Holders` of ``plan``'s points."""
    xy = plan.tri.xy
    keys = plan.pt_edge
    solid = plan.solid_of(keys)
    p = plan.points
    da = ((p - xy[keys[:, 0]]) ** 2).sum(1)
    db = ((p - xy[keys[:, 1]]) ** 2).sum(1)
    return Holders(solid, keys, np.where(solid, -1, np.where(da <= db, keys[:, 0], keys[:, 1])))


def vertex_and_edge_masses(plan: TransportPlan) -> tuple[dict, dict]:
    """Mass transported to each solid edge and to each vertex.

    Points of a solid edge stay on it; points of a ghost edge go to its
    nearer endpoint (:func:`point_holders`).

    Returns:
      ``(edge_mass, vertex_mass)`` dicts keyed by edge key / vertex id.
    """
    solid, keys, to_vertex = point_holders(plan)
    edge_mass: dict = {}
    vertex_mass: dict = {}
    if solid.any():
        code, inv = np.unique(keys[solid], axis=0, return_inverse=True)
        sums = np.bincount(inv.ravel(), plan.mass[solid])
        edge_mass = {(int(a), int(b)): float(s) for (a, b), s in zip(code, sums)}
    ghost = ~solid
    if ghost.any():
        end = to_vertex[ghost]
        sums = np.bincount(end, plan.mass[ghost], minlength=len(plan.tri.xy))
        vertex_mass = {int(v): float(sums[v]) for v in np.unique(end)}
    return edge_mass, vertex_mass


def _points_of(plan: TransportPlan, keys: list) -> list[np.ndarray]:
    """Per edge key of ``keys``, the ids of the points assigned to it."""
    held, parts = plan.points_by_edge()
    by_key = {(int(u), int(v)): p[0] for (u, v), p in zip(held, parts)}
    return [by_key.get(k, np.zeros(0, np.int64)) for k in keys]


def result_from_plan(plan: TransportPlan, relevance: float, params: dict, seconds: float,
                     density: float = 0.0, background: Background | None = None,
                     input_mass: np.ndarray | None = None, chords: bool = False) -> CurveResult:
    """Filters the solid edges of a plan; packs a result.

    Kept: solid edges with relevance ``M_e |e|^2 / (N_e + T_e) >= relevance``
    and ``M_e / |e| >= density * max`` (max over the solid edges); with
    ``chords``, minus the redundant chords of 3-cycles and spurs at
    junctions (:func:`~otjax.curves.filtering.redundant_edges`); with a ``background``
    that was found, minus the edges (and isolated vertices) whose band of
    the input (``input_mass``, default the plan's masses) does not stand out
    of it (:func:`~otjax.curves.filtering.above_background`). Then their
    endpoints, and isolated vertices (vertices that receive mass but lie on
    no kept edge). Vertices are numbered in increasing internal id. The
    pinned box corners and every edge touching them are scaffolding and
    never appear; the shape end of a scaffolding edge that carries mass
    counts as receiving it, so a run decimated to a few vertices whose
    points all sit on edges towards the box still reports those vertices.
    """
    tri = plan.tri
    edge_mass, vertex_mass = vertex_and_edge_masses(plan)
    kept = relevant_edges(plan, edge_mass, relevance, density)
    spur_ends: set = set()
    if chords and kept.keys:
        points = _points_of(plan, kept.keys)
        before = kept.vertices()
        kept = kept.where(filtering.redundant_edges(kept.keys, tri.xy, points, plan.points, plan.mass))
        # A dropped spur's free end held the points the edges kept hold:
        # it is not reported as an isolated vertex either.
        spur_ends = before - kept.vertices()
    on_edges = kept.vertices()
    received = set(v for v, m in vertex_mass.items() if m > 0) | _scaffolding_ends(tri.pinned, edge_mass)
    isolated = sorted(v for v in received if v not in on_edges and v not in spur_ends and not tri.pinned[v])
    if background is not None and background.found and (kept.keys or isolated):
        kept, isolated = _above_background(plan, kept, isolated, background,
                                           plan.mass if input_mass is None else input_mass)
    return _packed(plan, kept, isolated, params, seconds)


def _scaffolding_ends(pinned: np.ndarray, edge_mass: dict) -> set:
    """The unpinned ends of edges to a pinned box corner that carry mass."""
    return {b if pinned[a] else a for (a, b), m in edge_mass.items() if m > 0 and pinned[a] != pinned[b]}


class KeptEdges(NamedTuple):
    """Kept solid edges: their keys, masses ``M_e`` and relevances, in step."""

    keys: list
    masses: list
    relevance: list

    def where(self, keep) -> KeptEdges:
        """The edges whose flag in ``keep`` is true, in order."""
        return KeptEdges(*([x for x, k in zip(seq, keep) if k] for seq in self))

    def vertices(self) -> set:
        """The endpoints of the edges."""
        return {v for e in self.keys for v in e}


def relevant_edges(plan: TransportPlan, edge_mass: dict, relevance: float, density: float) -> KeptEdges:
    """The solid edges of ``plan`` (``edge_mass``: their masses, by key)
    whose relevance ``M_e |e|^2 / (N_e + T_e)`` is at least ``relevance``
    and whose mass per unit length ``M_e / |e|`` is at least ``density``
    times the largest one, in increasing key; edges touching the pinned box
    corners are left out."""
    tri = plan.tri
    kept = KeptEdges([], [], [])
    # Edges touching the box corners are scaffolding, not shape.
    shape_edges = [k for k in sorted(edge_mass) if not (tri.pinned[k[0]] or tri.pinned[k[1]])]
    length = {k: float(np.linalg.norm(tri.xy[k[0]] - tri.xy[k[1]])) for k in shape_edges}
    floor = density * max((edge_mass[k] / length[k] for k in shape_edges), default=0.0)
    for key in shape_edges:
        if edge_mass[key] / length[key] < floor:
            continue
        cost = plan.edge_cost[key]
        r = edge_mass[key] * length[key] ** 2 / cost if cost > 0 else float(np.finfo(np.float64).max)
        if r >= relevance:
            kept.keys.append(key)
            kept.masses.append(edge_mass[key])
            kept.relevance.append(r)
    return kept


def _above_background(plan: TransportPlan, kept: KeptEdges, isolated: list, background: Background,
                      mass: np.ndarray) -> tuple[KeptEdges, list]:
    """``kept`` and ``isolated`` without the edges and isolated vertices
    whose band of the input (masses ``mass``) does not stand out of the
    background (:func:`~otjax.curves.filtering.above_background`)."""
    xy = plan.tri.xy
    normal = np.array([plan.edge_normal.get(k, 0.0) for k in kept.keys])
    width = filtering.BAND_WIDTHS * filtering.noise_width(normal, np.array(kept.masses))
    seg = np.array([[xy[a], xy[b]] for a, b in kept.keys]).reshape(-1, 2, 2)
    keep, keep_v = filtering.above_background(seg, xy[isolated].reshape(-1, 2), plan.points, mass, background,
                                              width)
    kept = kept.where(keep)
    on_edges = kept.vertices()
    return kept, [v for v, k in zip(isolated, keep_v) if k and v not in on_edges]


def _packed(plan: TransportPlan, kept: KeptEdges, isolated: list, params: dict,
            seconds: float) -> CurveResult:
    """The result of the kept edges and isolated vertices, vertices numbered
    in increasing internal id."""
    ids = sorted(kept.vertices() | set(isolated))
    index = {v: i for i, v in enumerate(ids)}
    return CurveResult(
        vertices=plan.tri.xy[ids].reshape(-1, 2).copy(),
        edges=np.array([[index[a], index[b]] for a, b in kept.keys], np.int64).reshape(-1, 2),
        isolated=np.array([index[v] for v in isolated], np.int64),
        edge_mass=np.array(kept.masses, np.float64),
        edge_relevance=np.array(kept.relevance, np.float64),
        total_cost=plan.total_cost(),
        params=dict(params),
        seconds=float(seconds),
        points=plan.points,
        masses=plan.mass,
    )
