"""Facet bins: the quadrature of the uniform measure on each triangle (§3.1).

The transport cost onto a facet is discretised by bins: the cells of a
centroidal Voronoi tessellation (CVT) of the triangle, each represented by
its centroid and given a capacity, the cell's share of the facet's area. A
vertex is a bin of its own with no capacity constraint, so it needs nothing
here. Centroids are stored as barycentric coordinates in their triangle:
bin positions are then linear in the vertex positions, which the relocation
step and gradients rely on (§4.3).

The number of bins of a facet follows its area measured against the squared
diagonal ``D`` of the input's bounding box, so it does not depend on units.
Each bin count has a CVT *template* on the equilateral triangle, mapped
affinely onto a facet. An affine map keeps area ratios and centroids, so the
mapped cells still partition the facet with exact capacities and centroids;
it only loses centroidality when it stretches. Facets whose map stretches
more than ``max_stretch`` are therefore tessellated on their own: a few Lloyd
iterations started from the mapped template, with the Voronoi cells clipped
exactly (no sampling), vectorised over facets with the same bin count.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# Measured reasons for these values: docs/decisions.md#facet_bins. A facet of
# n CVT bins keeps about 1 - 0.87 / n of its second moment (equilateral; more
# on skinny facets), which is what the bins lose of a transport cost.
#: Bins per squared bbox diagonal of facet area: the paper's 200 bins per unit
#: area with the points in a half-unit box (D^2 = 0.75).
DEFAULT_DENSITY = 150.0
#: Fewest bins on a facet, however small: three keep 70% of the facet's second
#: moment (one bin, at the centroid, keeps none).
DEFAULT_MIN_BINS = 3
#: Most bins on a facet, however large: bounds the size of a local LP (97% of
#: the second moment kept).
DEFAULT_MAX_BINS = 32
#: Largest singular-value ratio of the template's affine map that keeps it:
#: beyond it the mapped cells are measurably not the Voronoi cells of their
#: centroids (capacities off by more than ~5%).
DEFAULT_MAX_STRETCH = 1.2
#: Lloyd iterations at most on a stretched facet, started from its mapped
#: template; it stops when no generator moves 1% of a cell size sqrt(area / n).
LLOYD_ITERATIONS = 100
LLOYD_TOLERANCE = 1e-2
_TEMPLATE_ITERATIONS = 100
_TEMPLATE_TOLERANCE = 1e-6
_REFERENCE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, np.sqrt(3.0) / 2.0]])
_CHUNK_ENTRIES = 1 << 21  # polygon vertices held at once while clipping
_TEMPLATES: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}


class FacetBins(NamedTuple):
    """The bins of every facet, grouped by facet in increasing facet order.

    Attributes:
      facet: ``(N,)`` int64 row of ``triangles`` holding each bin.
      barycentric: ``(N, 3)`` float64 centroid of each bin, as weights of the
        facet's three vertices in the order of its ``triangles`` row.
      capacity: ``(N,)`` float64 share of the facet's measure the bin receives
        (cell area / facet area); the capacities of a facet sum to 1.
      count: ``(T,)`` int64 bins per facet; facet ``f`` owns rows
        ``cumsum(count)[f] - count[f]`` to ``cumsum(count)[f]``.
    """

    facet: np.ndarray
    barycentric: np.ndarray
    capacity: np.ndarray
    count: np.ndarray


class CvtCells(NamedTuple):
    """Voronoi cells of generators clipped to their triangles.

    Attributes:
      area: ``(F, n)`` float64 cell areas.
      centroid: ``(F, n, 2)`` float64 cell centroids (of an empty cell: its generator).
    """

    area: np.ndarray
    centroid: np.ndarray


def facet_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(T,)`` float64 areas of the triangles ``(T, 3)`` over ``vertices`` ``(V, 3)``."""
    v = np.asarray(vertices, np.float64)[np.asarray(triangles)]
    return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)


def bin_counts(areas: np.ndarray, diagonal: float, density: float = DEFAULT_DENSITY,
               min_bins: int = DEFAULT_MIN_BINS, max_bins: int = DEFAULT_MAX_BINS) -> np.ndarray:
    """``(T,)`` int64 bins per facet: ``density * area / diagonal**2``, rounded
    and clipped to ``[min_bins, max_bins]``.

    Example:
      >>> bin_counts(np.array([0.0, 0.01, 0.5]), diagonal=1.0).tolist()
      [3, 3, 32]
    """
    if not (diagonal > 0 and np.isfinite(diagonal)):
        raise ValueError(f"diagonal must be a positive length, got {diagonal}")
    if not 1 <= min_bins <= max_bins:
        raise ValueError(f"need 1 <= min_bins <= max_bins, got {min_bins}, {max_bins}")
    if not density >= 0:
        raise ValueError(f"density must be >= 0, got {density}")
    n = np.rint(density * np.asarray(areas, np.float64) / diagonal**2)
    return np.clip(n, min_bins, max_bins).astype(np.int64)


def facet_bins(vertices: np.ndarray, triangles: np.ndarray, density: float = DEFAULT_DENSITY,
               min_bins: int = DEFAULT_MIN_BINS, max_bins: int = DEFAULT_MAX_BINS,
               diagonal: float | None = None, seed: int = 0,
               max_stretch: float = DEFAULT_MAX_STRETCH, bin_length: float | None = None) -> FacetBins:
    """CVT bins of every triangle (§3.1), deterministic for a given ``seed``.

    Args:
      vertices: ``(V, 3)`` float64 positions.
      triangles: ``(T, 3)`` int rows of vertex ids.
      density: bins per ``diagonal**2`` of facet area.
      min_bins, max_bins: bounds on the bins of one facet.
      diagonal: the length the density refers to; default the bounding-box
        diagonal of ``vertices``. Pass the input points' diagonal so that bins
        do not change as the complex changes.
      seed: seeds the template CVTs (the only random step).
      max_stretch: facets whose template map stretches more get their own CVT.
      bin_length: if given, a facet also gets at least ``longest edge /
        (bin_length * diagonal)`` bins (rounded up; still at most
        ``max_bins``), so a long thin facet, small in area, does not have
        its measure summed up by one or two bins.

    Returns:
      :class:`FacetBins`.

    Example:
      >>> v = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
      >>> b = facet_bins(v, np.array([[0, 1, 2]]), min_bins=5, max_bins=5)
      >>> b.count.tolist(), round(float(b.capacity.sum()), 12)
      ([5], 1.0)
    """
    vertices = np.asarray(vertices, np.float64)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    if diagonal is None:
        diagonal = float(np.linalg.norm(np.ptp(vertices, axis=0))) if len(vertices) else 0.0
    corners = local_frames(vertices, triangles)
    count = bin_counts(_area2d(corners), diagonal, density, min_bins, max_bins)
    if bin_length is not None:
        if not bin_length > 0:
            raise ValueError(f"bin_length must be > 0, got {bin_length}")
        longest = np.max(np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2), axis=1)
        by_length = np.ceil(longest / (bin_length * diagonal) - 1e-9).astype(np.int64)
        count = np.maximum(count, np.minimum(by_length, max_bins))
    start = np.cumsum(count) - count
    total = int(count.sum())
    bary = np.empty((total, 3))
    cap = np.empty(total)
    templates = cvt_templates(np.unique(count).tolist(), seed)
    for n, template in templates.items():
        fs = np.flatnonzero(count == n)
        rows = start[fs][:, None] + np.arange(n)
        b, c = _bins_of_size(corners[fs], template, max_stretch, diagonal)
        bary[rows] = b
        cap[rows] = c
    return FacetBins(np.repeat(np.arange(len(triangles)), count), bary, cap, count)


def bin_positions(vertices: np.ndarray, triangles: np.ndarray, bins: FacetBins) -> np.ndarray:
    """``(N, 3)`` float64 bin centroids: barycentric weights times facet vertices."""
    corners = np.asarray(vertices, np.float64)[np.asarray(triangles)[bins.facet]]
    return np.einsum("nk,nkd->nd", bins.barycentric, corners)


def local_frames(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(T, 3, 2)`` float64 corners of each triangle in an isometric 2D frame
    of its plane (first corner at the origin, second on the x axis)."""
    v = np.asarray(vertices, np.float64)[triangles]
    a, b = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    la = np.linalg.norm(a, axis=1)
    e1 = a / np.where(la > 0, la, 1.0)[:, None]
    bx = np.einsum("td,td->t", b, e1)
    by = np.linalg.norm(b - bx[:, None] * e1, axis=1)
    out = np.zeros((len(v), 3, 2))
    out[:, 1, 0] = la
    out[:, 2, 0] = bx
    out[:, 2, 1] = by
    return out


def stretch(corners: np.ndarray) -> np.ndarray:
    """``(F,)`` singular-value ratio of the affine map from the equilateral
    triangle onto each triangle ``(F, 3, 2)`` (1 for equilateral, inf if flat)."""
    ref = np.stack([_REFERENCE[1] - _REFERENCE[0], _REFERENCE[2] - _REFERENCE[0]], axis=1)
    m = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2) @ np.linalg.inv(ref)
    s = np.linalg.svd(m, compute_uv=False)
    with np.errstate(divide="ignore"):
        return np.where(s[:, 1] > 0, s[:, 0] / np.where(s[:, 1] > 0, s[:, 1], 1.0), np.inf)


def voronoi_cells(corners: np.ndarray, generators: np.ndarray) -> CvtCells:
    """Exact Voronoi cells of ``generators`` ``(F, n, 2)`` clipped to the
    triangles ``corners`` ``(F, 3, 2)``: each cell is its triangle cut by the
    ``n - 1`` bisector half-planes, vectorised over every cell at once."""
    f, n, _ = generators.shape
    area = np.empty((f, n))
    centroid = np.empty((f, n, 2))
    step = max(1, _CHUNK_ENTRIES // (n * (n + 2)))
    for lo in range(0, f, step):
        a, c = _cells(corners[lo:lo + step], generators[lo:lo + step])
        area[lo:lo + step], centroid[lo:lo + step] = a, c
    return CvtCells(area, centroid)


def lloyd(corners: np.ndarray, generators: np.ndarray, max_iterations: int = LLOYD_ITERATIONS,
          tolerance: float = LLOYD_TOLERANCE) -> np.ndarray:
    """Lloyd iterations: every generator moves to the centroid of its cell,
    per triangle until none moves more than ``tolerance * sqrt(area / n)``.
    Centroids of cells lie in the triangle, so generators never leave it.

    Args:
      corners: ``(F, 3, 2)`` triangles of positive area.
      generators: ``(F, n, 2)`` distinct start points inside them.

    Returns:
      ``(F, n, 2)`` float64 generators.
    """
    g = np.array(generators, np.float64)
    n = g.shape[1]
    scale = tolerance * np.sqrt(np.abs(_area2d(corners)) / n)
    active = np.arange(len(g))
    for _ in range(max_iterations):
        if len(active) == 0:
            break
        cells = voronoi_cells(corners[active], g[active])
        moved = np.max(np.linalg.norm(cells.centroid - g[active], axis=2), axis=1)
        g[active] = cells.centroid
        active = active[moved > scale[active]]
    return g


def cvt_templates(counts, seed: int = 0) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """CVTs of the equilateral triangle for each bin count in ``counts``:
    ``{n: (barycentric (n, 3), capacity (n,))}`` of the cells, read-only.

    Each starts at points drawn from ``default_rng([seed, n])``, so a template
    does not depend on which others are built with it. The missing ones are
    built in one batch (generators of smaller counts padded with far-away
    points, whose cells are empty and cut nothing) and cached per process.
    """
    missing = sorted({int(n) for n in counts} - {k[0] for k in _TEMPLATES if k[1] == seed})
    if missing:
        width = missing[-1]
        far = _REFERENCE.mean(axis=0) + 1e3 * np.stack([np.cos(np.arange(width)), np.sin(np.arange(width))], 1)
        gens = np.repeat(far[None], len(missing), axis=0)
        for i, n in enumerate(missing):
            gens[i, :n] = np.random.default_rng([seed, n]).dirichlet(np.ones(3), size=n) @ _REFERENCE
        corners = np.repeat(_REFERENCE[None], len(missing), axis=0)
        g = lloyd(corners, gens, _TEMPLATE_ITERATIONS, _TEMPLATE_TOLERANCE)
        cells = voronoi_cells(corners, g)
        bary = barycentric(corners, cells.centroid)
        for i, n in enumerate(missing):
            b, c = bary[i, :n].copy(), cells.area[i, :n] / cells.area[i, :n].sum()
            b.flags.writeable = c.flags.writeable = False
            _TEMPLATES[n, seed] = (b, c)
    return {int(n): _TEMPLATES[int(n), seed] for n in counts}


def barycentric(corners: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(F, n, 3)`` barycentric coordinates of ``points`` ``(F, n, 2)`` in ``corners`` ``(F, 3, 2)``."""
    m = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)
    rhs = (points - corners[:, None, 0]).transpose(0, 2, 1)
    lam = np.linalg.solve(m, rhs).transpose(0, 2, 1)
    return np.concatenate([1.0 - lam.sum(axis=2, keepdims=True), lam], axis=2)


# ----------------------------------------------------------------- internals
def _area2d(corners: np.ndarray) -> np.ndarray:
    d1, d2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    return 0.5 * (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])


def _bins_of_size(corners, template, max_stretch, diagonal):
    """Bins of facets that all get the template's count ``n``:
    ``(barycentric (F, n, 3), capacity (F, n))``."""
    tb, tc = template
    n = len(tc)
    bary = np.broadcast_to(tb, (len(corners), n, 3)).copy()
    cap = np.broadcast_to(tc, (len(corners), n)).copy()
    if n == 1:
        return bary, cap
    # A flat facet keeps the template: no metric to be centroidal in.
    own = np.flatnonzero((stretch(corners) > max_stretch) & (_area2d(corners) > 1e-14 * diagonal**2))
    if len(own):
        c = corners[own]
        g = lloyd(c, np.einsum("fnk,fkd->fnd", bary[own], c))
        cells = voronoi_cells(c, g)
        bary[own] = barycentric(c, cells.centroid)
        cap[own] = cells.area / cells.area.sum(axis=1, keepdims=True)
    return bary, cap


def _cells(corners: np.ndarray, gens: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    f, n, _ = gens.shape
    b = f * n
    # Cells rarely have more than eight sides: the width grows when one does.
    poly = np.zeros((b, min(n + 2, 8), 2))
    poly[:, :3] = np.repeat(corners, n, axis=0)
    cnt = np.full(b, 3)
    own = gens.reshape(b, 2)
    dist = np.linalg.norm(gens[:, None, :, :] - gens[:, :, None, :], axis=3)
    order = np.argsort(dist, axis=2, kind="stable")[:, :, 1:].reshape(b, n - 1)
    near = np.take_along_axis(dist.reshape(b, n), order, axis=1)
    other_of = np.repeat(np.arange(f) * n, n)[:, None] + order  # rows of `own`
    todo = np.arange(b)
    # Cell i is cut by bisectors in order of distance; once it lies within
    # half the distance to its next generator, no later bisector cuts it.
    for k in range(n - 1):
        p, c = poly[todo], cnt[todo]
        if k > 0:
            valid, _ = _next_index(c, p.shape[1])
            reach = np.where(valid, np.linalg.norm(p - own[todo, None], axis=2), 0.0).max(axis=1)
            keep = 0.5 * near[todo, k] <= reach
            todo, p, c = todo[keep], p[keep], c[keep]
            if len(todo) == 0:
                break
        mine, other = own[todo], own[other_of[todo, k]]
        offset = 0.5 * (np.einsum("bd,bd->b", other, other) - np.einsum("bd,bd->b", mine, mine))
        p, c = _clip(p, c, other - mine, offset)
        if p.shape[1] > poly.shape[1]:
            poly = np.concatenate([poly, np.zeros((b, p.shape[1] - poly.shape[1], 2))], axis=1)
        poly[todo, : p.shape[1]] = p
        cnt[todo] = c
    area, centroid = _polygon_moments(poly, cnt)
    empty = area <= 0
    centroid[empty] = own[empty]
    return area.reshape(f, n), centroid.reshape(f, n, 2)


def _next_index(cnt: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray]:
    k = np.arange(width)[None, :]
    return k < cnt[:, None], np.where(k + 1 < cnt[:, None], k + 1, 0)


def _clip(poly, cnt, normal, offset):
    """Convex polygons ``(B, K, 2)`` (``cnt`` vertices each) cut to ``normal . x <= offset``."""
    bsz, width, _ = poly.shape
    valid, nxt = _next_index(cnt, width)
    nxt_poly = np.take_along_axis(poly, nxt[..., None], axis=1)
    s = np.einsum("bkd,bd->bk", poly, normal) - offset[:, None]
    s_next = np.take_along_axis(s, nxt, axis=1)
    inside = s <= 0
    crosses = valid & (inside != (s_next <= 0))
    t = np.where(crosses, s / np.where(crosses, s - s_next, 1.0), 0.0)
    cand = np.stack([poly, poly + t[..., None] * (nxt_poly - poly)], axis=2).reshape(bsz, 2 * width, 2)
    keep = np.stack([valid & inside, crosses], axis=2).reshape(bsz, 2 * width)
    new_cnt = keep.sum(axis=1)
    # Rounding can add a vertex beyond the convex bound: grow, never truncate.
    out = np.zeros((bsz, max(width, int(new_cnt.max(initial=0))), 2))
    rows, cols = np.nonzero(keep)
    out[rows, (np.cumsum(keep, axis=1) - 1)[rows, cols]] = cand[rows, cols]
    return out, new_cnt


def _polygon_moments(poly: np.ndarray, cnt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    valid, nxt = _next_index(cnt, poly.shape[1])
    q = np.take_along_axis(poly, nxt[..., None], axis=1)
    cross = np.where(valid, poly[..., 0] * q[..., 1] - poly[..., 1] * q[..., 0], 0.0)
    area = 0.5 * cross.sum(axis=1)
    safe = np.where(area > 0, area, 1.0)
    centroid = np.einsum("bk,bkd->bd", cross, poly + q) / (6.0 * safe[:, None])
    return area, centroid
