"""Plan entries of a list of simplices packed as padded arrays, the input of
the fixed-plan kernels (:mod:`otjax.surfaces.fixed_plan_cost`).

:func:`pack_entries` gathers the entries of vertex bins and facet bins over
compact vertex rows and pads every axis to a power of two, so that the
targets of :mod:`otjax.surfaces.relocation` and the refinement of
:mod:`otjax.surfaces.refinement` compile few shapes.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from otjax.lp.problem import capacity_class
from otjax.surfaces.fixed_plan_cost import FixedPlanEntries
from otjax.surfaces.plan import SurfacePlan

# Smallest padded sizes (powers of two): a relocation of a one-ring or a
# refinement of a few stars fits the first class, so one shape compiles.
_MIN_VERTICES = 32
_MIN_POINTS = 64
_MIN_ENTRIES = 256


class PackedEntries(NamedTuple):
    """Plan entries of a list of simplices, padded, over compact vertex rows.

    Attributes:
      vertex_ids: ``(V,)`` int64 global id of each real position row.
      positions: ``(Vc, 3)`` float64 positions, rows past ``V`` are 0.
      points: ``(Pc, 3)`` float64 the entries' points, pad rows 0.
      entries: :class:`FixedPlanEntries` (NumPy), ``Ec`` rows, mass 0 past the real ones.
      segment: ``(Ec,)`` int64 index in the simplex list of each entry. Pad 0.
    """

    vertex_ids: np.ndarray
    positions: np.ndarray
    points: np.ndarray
    entries: FixedPlanEntries
    segment: np.ndarray


class SimplexEntries(NamedTuple):
    """The entries of one simplex: ``point (n,)``, bin ``corners (n, 3)`` and
    ``barycentric (n, 3)`` coordinates (a vertex bin: corners all the vertex,
    weights ``(1, 0, 0)``), ``mass (n,)``."""

    point: np.ndarray
    corners: np.ndarray
    barycentric: np.ndarray
    mass: np.ndarray


def _simplex_entries(plan: SurfacePlan, simplex) -> SimplexEntries | None:
    """The :class:`SimplexEntries` of one simplex, or None when it has none."""
    e = plan.entries(simplex)
    if e is None:
        return None
    n = len(e.point)
    if isinstance(simplex, tuple):
        corners = np.broadcast_to(np.array(simplex, np.int64), (n, 3))
        return SimplexEntries(e.point, corners, plan.bins[simplex].barycentric[e.bin], e.mass)
    bary = np.zeros((n, 3))
    bary[:, 0] = 1.0
    return SimplexEntries(e.point, np.full((n, 3), int(simplex), np.int64), bary, e.mass)


def pack_entries(plan: SurfacePlan, simplices: Sequence, vertices: Sequence[int] = ()) -> PackedEntries:
    """The entries of ``simplices`` (vertex ids or facet keys; one may repeat)
    as padded arrays; ``vertices`` get position rows even if no entry uses them.

    Example:
      >>> from otjax.surfaces.complex import SimplicialComplex
      >>> from otjax.surfaces.plan import BinSettings
      >>> c = SimplicialComplex(np.eye(3), np.array([[0, 1, 2]]))
      >>> plan = SurfacePlan(c, np.eye(3) * 0.9, np.ones(3), BinSettings(diagonal=1.0))
      >>> p = pack_entries(plan, [0, 1])
      >>> p.vertex_ids.tolist(), float(p.entries.mass.sum()), p.segment[:2].tolist()
      ([0, 1], 2.0, [0, 1])
    """
    found = (_simplex_entries(plan, x) for x in simplices)
    parts = [(s, got) for s, got in enumerate(found) if got is not None]
    if parts:
        point, corners, bary, mass = (np.concatenate(column) for column in zip(*(g for _, g in parts)))
        segment = np.concatenate([np.full(len(g.point), s, np.int64) for s, g in parts])
    else:
        point, corners = np.zeros(0, np.int64), np.zeros((0, 3), np.int64)
        bary, mass, segment = np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64)
    wanted = np.concatenate([corners.ravel(), np.asarray(vertices, np.int64).ravel()])
    ids, rows = np.unique(wanted, return_inverse=True)
    pids, prow = np.unique(point, return_inverse=True)
    n, cap = len(point), capacity_class(len(point), _MIN_ENTRIES)
    pad = (lambda a, size: np.concatenate([a, np.zeros((size - len(a),) + a.shape[1:], a.dtype)]))
    positions = pad(plan.complex.positions[ids], capacity_class(len(ids), _MIN_VERTICES))
    points = pad(plan.points[pids], capacity_class(len(pids), _MIN_POINTS))
    corner_rows = rows[:3 * n].reshape(n, 3).astype(np.int64)
    entries = FixedPlanEntries(pad(prow.astype(np.int64), cap), pad(corner_rows, cap), pad(bary, cap),
                               pad(mass, cap))
    return PackedEntries(ids, positions, points, entries, pad(segment, cap))


def rows_of(packed: PackedEntries, vertices) -> np.ndarray:
    """The position rows of ``packed`` of global vertex ids ``vertices`` (each must have one)."""
    return np.searchsorted(packed.vertex_ids, np.asarray(vertices, np.int64))


def star_simplices(plan: SurfacePlan, v: int) -> list:
    """``[v]`` and the facets containing ``v``, sorted: the simplices whose
    bins move with ``v``."""
    return [int(v)] + sorted(plan.complex.vertex_triangles[v])
