"""Caps: facets that close a concave corner of an open border (not in the paper).

Where two sheets meet at a concave crease and both end at an open border,
the points along the border lie in a strip that bends round the corner, in
the plane across the crease. A facet in that plane, its corners on the two
sheets' borders, takes those points at almost no distance: the transport
cost keeps it. It is no part of the shape: it spans the empty corner
between the sheets, and the output's border runs along its free edge
instead of along the sheets' own, which stay underneath it
(docs/decisions.md#caps).

A cap is told by its place and its mass: it has a border edge (an edge of
no other facet), every facet on each of its other edges stands at more
than :data:`CAP_ANGLE` from it (folds, at about 0 degrees, do not count),
and it is less dense than the mean (:data:`CAP_DENSITY`; the density as in
:mod:`otjax.surfaces.filtering`). Its mass goes to the vertex bins of its
corners, each entry to the corner nearest its bin; the caller relaxes the
plan afterwards.
"""

from __future__ import annotations

import numpy as np

from otjax.surfaces.complex import SimplicialComplex, Triangle, triangle_edges
from otjax.surfaces.filtering import facet_density
from otjax.surfaces.fit_input import unit_normals
from otjax.surfaces.plan import SurfacePlan
from otjax.surfaces.t_junctions import remove_facets

#: Degrees: every facet on a cap's inner edges stands at more than this from it.
CAP_ANGLE = 60.0
#: A cap's relative mass density (its mass over area, over the mean) is below this.
CAP_DENSITY = 1.0


def find_caps(complex_: SimplicialComplex, mass: dict, angle: float = CAP_ANGLE,
              density: float = CAP_DENSITY) -> list[Triangle]:
    """The caps of ``complex_`` (module doc), in facet order.

    Args:
      complex_: the complex.
      mass: ``{facet: mass}`` for every facet (missing: 0).
      angle: degrees in ``(0, 90)``.
      density: relative density bound.

    Example:
      >>> from otjax.surfaces.complex import SimplicialComplex
      >>> x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 1], [1, 1, 1]], float)
      >>> tread, riser, cap = [0, 1, 2], [1, 3, 4], [0, 1, 4]  # the cap lies in the plane y = 0
      >>> c = SimplicialComplex(x, np.array([tread, [1, 2, 3], riser, [3, 4, 5], cap]))
      >>> find_caps(c, {(0, 1, 2): 1.0, (1, 2, 3): 1.0, (1, 3, 4): 1.0, (3, 4, 5): 1.0, (0, 1, 4): 0.2})
      [(0, 1, 4)]
    """
    facets = sorted(complex_.triangles)
    if not facets:
        return []
    rows = np.array(facets)
    unit = unit_normals(complex_.positions, rows)
    dens = facet_density(complex_.positions, rows, [mass.get(t, 0.0) for t in facets])
    row = {t: i for i, t in enumerate(facets)}
    cos_bound = np.cos(np.radians(angle))
    found = []
    for i, t in enumerate(facets):
        if not (dens.area[i] > 0 and dens.relative[i] < density):
            continue
        others = [[row[u] for u in complex_.edges[e] if u != t] for e in triangle_edges(t)]
        if any(not o for o in others) and all(abs(unit[i] @ unit[j]) < cos_bound for o in others for j in o):
            found.append(t)
    return found


def remove_caps(plan: SurfacePlan, angle: float = CAP_ANGLE, density: float = CAP_DENSITY) -> int:
    """Removes the caps of ``plan.complex`` in place (:func:`find_caps`),
    their mass handed to their corners; returns how many."""
    c = plan.complex
    return remove_facets(plan, find_caps(c, {t: plan.simplex_mass(t) for t in c.triangles}, angle, density))
