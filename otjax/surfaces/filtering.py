"""Facet filtering by mass density (Digne et al. 2014, §4.4).

When decimation ends, noise and outliers leave facets that carry a little
mass. The paper sorts the facets by *mass density*, the mass transported
onto a facet divided by its area, and lets the user pick a threshold. Here
the threshold is relative, so it means the same at any scale:

* ``relative density = density / mean density``, where the mean density is
  the total mass of the facets over their total area (facets of zero area
  left out of both). A facet as dense as the surface on average has relative
  density 1; a uniformly sampled surface has all its facets near 1, and a
  facet made by noise or outliers far below.
* A facet is kept when its relative density is ``>= threshold`` and its
  mass is positive. ``threshold = 0`` keeps every facet that carries mass
  (the paper's unfiltered output); a higher threshold keeps a subset.

Scaling the points by any factor and the masses by another changes neither
the relative densities nor the kept set: they are computed on coordinates
and masses scaled by powers of two (exact), then divided.

What goes with a dropped facet (:func:`filter_facets`): its edges, unless a
kept facet or the complex's own dangling edges hold them; its vertices,
unless a kept facet or dangling edge holds them, or they carry mass of
their own (``vertex_mass > 0``: they become isolated vertices, as the
transport still puts mass there). Isolated vertices and dangling edges of
the input are kept as they are.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class FacetDensity(NamedTuple):
    """Mass densities of the facets of a complex.

    Attributes:
      area: ``(T,)`` facet areas, input units.
      density: ``(T,)`` ``mass / area`` in input units (0 where the area is 0).
      reference: the mean density (see the module doc), input units.
      relative: ``(T,)`` ``density / reference``, scale-free (0 when the
        reference is 0: no facet carries mass).
      order: ``(T,)`` int64 facets by decreasing relative density (ties by index).
      sorted: ``(T,)`` relative densities in that order: the thresholds at
        which the kept set changes, for a slider.
    """

    area: np.ndarray
    density: np.ndarray
    reference: float
    relative: np.ndarray
    order: np.ndarray
    sorted: np.ndarray


def _power_of_two_frame(vertices: np.ndarray) -> tuple[np.ndarray, int]:
    """``(q, e)``: vertices translated to their box's centre and scaled by ``2^-e``
    so that the largest coordinate is below 1 (areas scale by exactly ``4^-e``)."""
    if not len(vertices):
        return vertices, 0
    q = vertices - (vertices.min(0) / 2 + vertices.max(0) / 2)
    big = float(np.abs(q).max())
    e = int(np.frexp(big)[1]) if big > 0 else 0
    return np.ldexp(q, -e), e


def facet_density(vertices, triangles, triangle_mass) -> FacetDensity:
    """The :class:`FacetDensity` of triangles ``(T, 3)`` over ``vertices (V, 3)``
    carrying ``triangle_mass (T,)`` (finite, ``>= 0``).

    Example:
      >>> d = facet_density([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 2, 3]], [1.0, 3.0])
      >>> d.relative.tolist(), d.order.tolist()
      ([0.5, 1.5], [1, 0])
    """
    vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    mass = np.asarray(triangle_mass, np.float64).reshape(-1)
    if len(mass) != len(triangles):
        raise ValueError(f"triangle_mass must have shape ({len(triangles)},), got {mass.shape}")
    q, e = _power_of_two_frame(vertices)
    t = q[triangles]
    area_q = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    big = float(mass.max(initial=0.0))
    m = np.ldexp(mass, -int(np.frexp(big)[1])) if big > 0 else mass
    real = area_q > 0
    ref_q = m[real].sum() / area_q[real].sum() if real.any() else 0.0
    dens_q = np.where(real, m / np.where(real, area_q, 1.0), 0.0)
    relative = dens_q / ref_q if ref_q > 0 else np.zeros(len(mass))
    with np.errstate(over="ignore", under="ignore"):  # absurd units: the user-unit values saturate
        area = np.ldexp(area_q, 2 * e)
        density = np.where(real, mass / np.where(area > 0, area, 1.0), 0.0)
        reference = float(mass[real].sum() / area[real].sum()) if real.any() and area[real].sum() > 0 else 0.0
    order = np.lexsort((np.arange(len(relative)), -relative))
    return FacetDensity(area, density, reference, relative, order, relative[order])


def check_threshold(threshold) -> float:
    """A relative density threshold: a finite number ``>= 0``."""
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.integer, np.floating)) \
            or not np.isfinite(threshold) or threshold < 0:
        raise ValueError(f"threshold must be a finite number >= 0 (a multiple of the mean density), got {threshold!r}")
    return float(threshold)


def keep_facets(relative, threshold: float) -> np.ndarray:
    """``(T,)`` bool: facets whose ``relative`` density is positive and ``>= threshold``."""
    relative = np.asarray(relative, np.float64)
    return (relative > 0) & (relative >= check_threshold(threshold))


class FilteredComplex(NamedTuple):
    """A complex after facet filtering, vertices renumbered compactly.

    Attributes:
      vertices: ``(V', 3)`` kept vertices, in their original order.
      triangles: ``(T', 3)`` kept facets.
      edges: ``(E, 2)`` the input's dangling edges, renumbered.
      isolated: ``(I',)`` isolated vertices: the input's, then those that
        lost all their facets but carry mass, in vertex order.
      triangle_keep: ``(T,)`` bool, which input facets are kept.
      vertex_index: ``(V,)`` int64 new index of each input vertex, ``-1`` if dropped.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    edges: np.ndarray
    isolated: np.ndarray
    triangle_keep: np.ndarray
    vertex_index: np.ndarray


def filter_facets(vertices, triangles, triangle_mass, threshold: float, edges=None, isolated=None,
                  vertex_mass=None) -> FilteredComplex:
    """Drops the facets below a relative density ``threshold`` (module doc).

    Args:
      vertices, triangles, triangle_mass: the complex and the mass on each facet.
      threshold: relative density, a multiple of the mean density, ``>= 0``.
      edges: ``(E, 2)`` dangling edges (kept), or ``None``.
      isolated: ``(I,)`` isolated vertices (kept), or ``None``.
      vertex_mass: ``(V,)`` mass on each vertex, or ``None`` (unknown: a
        vertex that loses all its facets is dropped).

    Example:
      >>> f = filter_facets(np.eye(4, 3), [[0, 1, 2], [1, 2, 3]], [1.0, 0.01], 0.5)
      >>> f.triangles.tolist(), f.vertex_index.tolist()
      ([[0, 1, 2]], [0, 1, 2, -1])
    """
    vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    edges = np.zeros((0, 2), np.int64) if edges is None else np.asarray(edges, np.int64).reshape(-1, 2)
    isolated = np.zeros(0, np.int64) if isolated is None else np.asarray(isolated, np.int64).reshape(-1)
    keep = keep_facets(facet_density(vertices, triangles, triangle_mass).relative, threshold)
    used = np.zeros(len(vertices), bool)
    used[triangles[keep].ravel()] = True
    used[edges.ravel()] = True
    held = used.copy()
    held[isolated] = True
    # Vertices that lost every facet but still receive mass stay, as isolated vertices.
    orphan = ~held & (np.asarray(vertex_mass, np.float64) > 0) if vertex_mass is not None else np.zeros_like(held)
    orphan[~np.isin(np.arange(len(vertices)), triangles.ravel())] = False
    held |= orphan
    index = np.full(len(vertices), -1, np.int64)
    index[held] = np.arange(int(held.sum()))
    new_isolated = np.concatenate([index[isolated], index[np.flatnonzero(orphan)]])
    return FilteredComplex(vertices[held], index[triangles[keep]].reshape(-1, 3), index[edges].reshape(-1, 2),
                           new_isolated, keep, index)
