"""Transverse facets: facets standing across the surface of their points (not in the paper).

The points a facet takes should lie along it: the flat through each
point's neighbours should run in the facet's plane. Where the decimation
leaves a facet spanning three vertices of one curved sheet (three of a
ring round an open cylinder, a lid over its rim, a fin inside it) the
facet's edges lie on the sheet and it takes the sheet's points along them
at as little distance as the sheet's own facets: the transport cost keeps
it, and its mass density reads like theirs, so the density filter keeps
it too. It is no part of the shape, and where it lies over an open
border the output's border runs along its edge instead of the sheet's.

Such a facet is told by its points: their normals lie in its plane. Its
*alignment* is the mass-weighted mean, over its plan entries whose
point's normal is reliable, of ``|cos|`` between its normal and the
normal of its point's flat (:func:`otjax.background.point_normals`): near
1 for a facet on its points' surface (a coarse facet spanning a curved
sheet: the cosine of half its bend), near 0 for one across it. A point
whose neighbours straddle a crease or a crossing has a normal of neither
sheet and is no evidence; a facet with less than :data:`EVIDENCE` of its
mass on reliable points has no alignment. A facet whose alignment is
below :data:`ALIGNMENT` is transverse; its mass goes to the vertex bins
of its corners, each entry to the corner nearest its bin, and the caller
relaxes the plan afterwards (docs/decisions.md#transverse).
"""

from __future__ import annotations

import numpy as np

from otjax.background import PointNormals
from otjax.surfaces.complex import Triangle
from otjax.surfaces.fit_input import unit_normals
from otjax.surfaces.plan import SurfacePlan
from otjax.surfaces.t_junctions import remove_facets
from otjax.validation import check_number

#: A facet whose points' normals stand, on a mass-weighted mean of ``|cos|``,
#: below this from its own is transverse (60 degrees; docs/decisions.md#transverse).
ALIGNMENT = 0.5
#: A facet has an alignment where at least this share of its mass is on
#: points with reliable normals (docs/decisions.md#transverse).
EVIDENCE = 0.5


def facet_alignment(plan: SurfacePlan, normals: PointNormals) -> dict[Triangle, float]:
    """``{facet: alignment}`` (module doc) of every facet of ``plan.complex``
    that has an area and carries mass, at least :data:`EVIDENCE` of it on
    points with reliable normals.

    Args:
      plan: the transport plan; its points are the rows of ``normals``.
      normals: the plan's points' :class:`~otjax.background.PointNormals`.
    """
    facets = sorted(plan.complex.triangles)
    unit = unit_normals(plan.complex.positions, np.array(facets, np.int64).reshape(-1, 3))
    out = {}
    for t, n in zip(facets, unit):
        e = plan.entries(t)
        if e is None or not np.any(n):
            continue
        weight = e.mass * normals.reliable[e.point]
        if weight.sum() > 0 and weight.sum() >= EVIDENCE * e.mass.sum():
            out[t] = float(weight @ np.abs(normals.normal[e.point] @ n) / weight.sum())
    return out


def find_transverse(plan: SurfacePlan, normals: PointNormals, alignment: float = ALIGNMENT) -> list[Triangle]:
    """The facets of ``plan.complex`` whose alignment is below ``alignment``
    (in ``(0, 1)``; else ``ValueError``), in facet order (:func:`facet_alignment`)."""
    if not 0 < check_number("alignment", alignment) < 1:
        raise ValueError(f"alignment must be in (0, 1), got {alignment!r}")
    return [t for t, a in facet_alignment(plan, normals).items() if a < alignment]


def remove_transverse(plan: SurfacePlan, normals: PointNormals, alignment: float = ALIGNMENT) -> int:
    """Removes the transverse facets of ``plan.complex`` in place
    (:func:`find_transverse`), their mass handed to their corners; returns
    how many."""
    return remove_facets(plan, find_transverse(plan, normals, alignment))
