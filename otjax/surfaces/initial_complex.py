"""The initial simplicial complex (§4.1): Delaunay, relaxation, facets with mass.

A seeded random subset of the points is tetrahedralised together with the
eight corners of a box around the input (so that coplanar or collinear
subsets still have a well-defined 3D Delaunay triangulation; the corners
carry no points and lose their facets in the filter). Every point is sent to
its nearest vertex, the plan is relaxed over two-tetrahedra stencils (a facet,
the other facets of the tetrahedra on each side, their vertices), and the
facets that received mass make the complex. A vertex that carries mass
without a kept facet keeps one edge, to its nearest Delaunay neighbour on a
kept facet (docs/decisions.md#tethers): it may hold its points (the paper's
garbage collectors), but the decimation can collapse it like any other.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np
import scipy.spatial

from otjax.surfaces.bins import DEFAULT_DENSITY
from otjax.surfaces.complex import SimplicialComplex, Triangle
from otjax.surfaces.plan import BinSettings, SurfacePlan
from otjax.surfaces.relaxation import RelaxationStats, Solver, relax

#: Default fraction of the points that become Delaunay vertices (the paper
#: uses 10-20%; docs/decisions.md#initial_fraction).
FRACTION = 0.15
#: The box corners stand this far (in bbox diagonals) outside the input's box.
BOX_MARGIN = 0.25
#: Fewest bins on a facet in the initial relaxation (docs/decisions.md#initial_bins).
MIN_BINS = 1
#: ... and at least one bin per this length (in bbox diagonals) of its longest
#: edge. One bin puts the whole measure of a long sliver at its centroid,
#: a cheap place to send points beyond an open boundary; every facet that
#: reaches a box corner has an edge longer than the margin, so it gets two
#: bins at least, while facets along the surface keep one.
BIN_LENGTH = 0.25
#: Stretched Delaunay facets keep their mapped template bins (exact
#: capacities and centroids, cells not quite centroidal) instead of their own
#: Lloyd iterations, which cost most of the time of the bins; they are the
#: large facets across the volume that the filter drops
#: (docs/decisions.md#initial_bins).
MAX_STRETCH = float("inf")
_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])


class InitialComplex(NamedTuple):
    """The complex decimation starts from.

    Attributes:
      plan: the relaxed :class:`SurfacePlan` on the kept complex
        (``plan.complex``); vertex ids are rows of ``vertex_points``.
      vertex_points: ``(V,)`` int64 input point of each vertex id.
      delaunay_facets: facets of the tetrahedralisation (box corners excluded
        or not, all of them).
      relaxation: the :class:`RelaxationStats` of the relaxation.
      seconds: wall time of each step: ``delaunay``, ``bins`` (the plan on
        every Delaunay facet), ``relaxation``, ``filter``.
    """

    plan: SurfacePlan
    vertex_points: np.ndarray
    delaunay_facets: int
    relaxation: RelaxationStats
    seconds: dict


def sample_subset(n_points: int, fraction: float, seed: int) -> np.ndarray:
    """Sorted ids of ``max(4, round(fraction * n))`` distinct points."""
    k = min(n_points, max(4, int(round(fraction * n_points))))
    return np.sort(np.random.default_rng(seed).choice(n_points, size=k, replace=False))


def box_corners(points: np.ndarray, margin: float = BOX_MARGIN) -> np.ndarray:
    """``(8, 3)`` corners of the input's bounding box grown by ``margin`` diagonals."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = margin * float(np.linalg.norm(hi - lo))
    lo, hi = lo - pad, hi + pad
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def tetrahedra(vertices: np.ndarray) -> np.ndarray:
    """``(T, 4)`` int64 Delaunay tetrahedra of ``vertices`` ``(V, 3)``.

    Raises:
      ValueError: the vertices span no volume.
    """
    try:
        return scipy.spatial.Delaunay(vertices).simplices.astype(np.int64)
    except scipy.spatial.QhullError as err:
        raise ValueError(f"the 3D Delaunay triangulation failed: {str(err).splitlines()[0]}") from None


def tetrahedra_facets(tets: np.ndarray) -> np.ndarray:
    """``(F, 3)`` sorted unique facets of the tetrahedra."""
    faces = np.sort(tets[:, _FACES].reshape(-1, 3), axis=1)
    return np.unique(faces, axis=0)


def two_tetrahedra_rule(tets: np.ndarray):
    """The stencil rule of §4.1: a facet, every facet of the (one or two)
    tetrahedra it bounds, and their vertices."""
    faces = np.sort(tets[:, _FACES], axis=2)
    around: dict[Triangle, list[int]] = {}
    for t, four in enumerate(faces.tolist()):
        for f in four:
            around.setdefault(tuple(f), []).append(t)

    def rule(facet: Triangle):
        cells = around[facet]
        facets = sorted({tuple(f) for t in cells for f in faces[t].tolist()})
        return sorted({int(v) for t in cells for v in tets[t]}), facets

    return rule


def initial_complex(points: np.ndarray, masses: np.ndarray, solve: Solver, *, fraction: float = FRACTION,
                    settings: BinSettings | None = None, seed: int = 0, tolerance: float = 1e-5,
                    max_sweeps: int = 10) -> InitialComplex:
    """Builds the initial complex of §4.1 from weighted points ``(N, 3)``.

    Args:
      points, masses: the input (in a normalised frame: see :mod:`otjax.frame`).
      solve: the local LP solver of the relaxation.
      fraction: share of the points that become vertices.
      settings: bin settings; default :func:`initial_settings`.
      seed: seeds the subset, the bins' templates and the sweep order.
      tolerance, max_sweeps: the relaxation's stop (:func:`relax`).

    Returns:
      :class:`InitialComplex`. Its plan transports every point's mass onto
      the kept simplices with the relaxed cost.
    """
    points = np.asarray(points, np.float64)
    masses = np.asarray(masses, np.float64)
    clock = [time.perf_counter()]
    seconds = {}

    def lap(name):
        clock.append(time.perf_counter())
        seconds[name] = clock[-1] - clock[-2]

    subset = sample_subset(len(points), fraction, seed)
    vertices = np.vstack([points[subset], box_corners(points)])
    tets = tetrahedra(vertices)
    facets = tetrahedra_facets(tets)
    lap("delaunay")
    if settings is None:
        settings = initial_settings(points, seed)
    full = SimplicialComplex(vertices, facets)
    plan = SurfacePlan(full, points, masses, settings)
    lap("bins")
    stats = relax(plan, solve, two_tetrahedra_rule(tets), tolerance=tolerance, max_sweeps=max_sweeps, seed=seed)
    lap("relaxation")
    kept = _kept(plan, vertices, subset)
    lap("filter")
    return InitialComplex(kept[0], kept[1], len(facets), stats, seconds)


def initial_settings(points: np.ndarray, seed: int = 0, density: float = DEFAULT_DENSITY) -> BinSettings:
    """The bin settings of the initial relaxation (and of the facets the
    decimation makes): the input's diagonal, ``density`` bins per squared
    diagonal of facet area, at least :data:`MIN_BINS` bins on a facet and one
    per :data:`BIN_LENGTH` of its longest edge, and every facet's bins mapped
    from the template (:data:`MAX_STRETCH`)."""
    return BinSettings(diagonal=float(np.linalg.norm(np.ptp(points, axis=0))), density=density,
                       min_bins=MIN_BINS, seed=seed, max_stretch=MAX_STRETCH, bin_length=BIN_LENGTH)


def _tethers(full: SimplicialComplex, vertices: np.ndarray, loose, used: set, on_facets: set) -> list:
    """``[(v, w)]``: a Delaunay edge of ``full`` from each vertex ``v`` of
    ``loose`` (kept for its own mass, on no kept facet) to its nearest
    neighbour ``w`` in ``used``, on a kept facet if one is (ties: the lower
    id). Without an edge such a vertex has no half-edge, so the decimation
    could never remove it and it would hold a place of the vertex budget
    to the end."""
    out = []
    for v in loose:
        near = [w for w in full.neighbors(v) if w in used]
        best = [w for w in near if w in on_facets] or near
        if best:
            d = np.linalg.norm(vertices[best] - vertices[v], axis=1)
            out.append((v, best[int(np.argmin(d))]))
    return out


def _kept(plan: SurfacePlan, vertices: np.ndarray, subset: np.ndarray) -> tuple[SurfacePlan, np.ndarray]:
    """The plan moved onto the complex of the facets that carry mass and
    the vertices that carry mass or belong to such a facet (renumbered),
    with the tethers of :func:`_tethers`."""
    facets = sorted(plan.facet_entries)
    on_facets = {v for t in facets for v in t}
    used = sorted(on_facets | set(plan.vertex_entries))
    row = {v: i for i, v in enumerate(used)}
    tethers = _tethers(plan.complex, vertices, [v for v in used if v not in on_facets], set(used), on_facets)
    complex_ = SimplicialComplex(vertices[used], np.array([[row[v] for v in t] for t in facets],
                                                          np.int64).reshape(-1, 3),
                                 np.array([[row[a], row[b]] for a, b in tethers], np.int64).reshape(-1, 2))
    new = SurfacePlan.from_entries(
        complex_, plan.points, plan.masses, plan.settings,
        bins={tuple(row[v] for v in t): plan.bins[t] for t in facets},
        vertex_entries={row[v]: e for v, e in plan.vertex_entries.items()},
        facet_entries={tuple(row[v] for v in t): plan.facet_entries[t] for t in facets},
    )
    ids = np.concatenate([subset, np.full(8, -1)])[used]
    return new, ids.astype(np.int64)
