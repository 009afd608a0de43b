"""The initial Delaunay triangulation, point location and the embedding check (host, exact).

Functions of a :class:`~otjax.curves.triangulation.Triangulation`, read only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import Delaunay, cKDTree

from otjax.predicates import in_triangle_perturbed, orient

N_CORNERS = 4


class InitialTriangles(NamedTuple):
    """An exact Delaunay triangulation as arrays.

    Attributes:
      alive: ``(V,)`` bool, the vertices that made it in.
      triangles: ``(T, 3)`` int64 CCW vertex ids.
      neighbours: ``(T, 3)`` int64 triangle across the edge opposite each
        corner (``-1``: the outer boundary).
    """

    alive: np.ndarray
    triangles: np.ndarray
    neighbours: np.ndarray


def delaunay(xy: np.ndarray, pinned: np.ndarray, use: np.ndarray) -> InitialTriangles:
    """Delaunay of the vertices ``xy[use]``; drops vertices Qhull mishandles.

    Qhull works in floating point: with near-duplicate or near-collinear
    input it may skip a vertex or emit a flat triangle. Every triangle is
    re-checked with the exact predicate; offending vertices (never ``pinned``
    ones) are taken out (their points are still transported, only not as
    vertices) and the triangulation is rebuilt, so the result is always a
    valid embedding.
    """
    # Qhull's tolerances are relative to the coordinates' magnitude: feed
    # it centred, unit-scale copies (the exact checks use the originals).
    lo, hi = xy.min(0), xy.max(0)
    scaled = (xy - (lo + hi) / 2) / np.max(hi - lo)
    for _ in range(64):
        ids = np.nonzero(use)[0]
        dt = Delaunay(scaled[ids])
        simp = ids[dt.simplices]
        nbr = dt.neighbors.copy()
        s = orient(xy[simp[:, 0]], xy[simp[:, 1]], xy[simp[:, 2]])
        flip = s < 0
        simp[flip] = simp[flip][:, [0, 2, 1]]
        nbr[flip] = nbr[flip][:, [0, 2, 1]]
        bad = s == 0
        # Qhull's orientation is arbitrary, hence the re-orientation above;
        # but on near-degenerate input two of its triangles can overlap,
        # which shows as a directed edge used twice once all are CCW.
        directed = np.stack([simp, simp[:, [1, 2, 0]]], -1).reshape(-1, 2)
        _, first, count = np.unique(directed, axis=0, return_inverse=True, return_counts=True)
        bad |= (count[first.ravel()] > 1).reshape(-1, 3).any(1)
        used = np.zeros(len(xy), bool)
        used[simp.ravel()] = True
        missing = use & ~used
        if not bad.any() and not missing.any():
            break
        drop = np.zeros(len(xy), bool)
        drop[simp[bad].ravel()] = True
        drop |= missing
        drop &= ~pinned
        if not drop.any():  # a flat triangle made of corners only: impossible
            raise RuntimeError("could not build an embedded initial triangulation")
        use = use & ~drop
    else:
        raise RuntimeError("could not build an embedded initial triangulation")
    return InitialTriangles(use.copy(), simp, nbr)


def locate_in(tri, points: np.ndarray, faces: list[int]) -> np.ndarray:
    """Which of ``faces`` holds each (symbolically perturbed) point.

    Args:
      points: ``(n, 2)`` query points, all inside the union of ``faces``.
      faces: candidate triangle ids.

    Returns:
      ``(n,)`` int64 triangle ids.

    Raises:
      RuntimeError: a point lies in none of the faces (caller's bug).
    """
    if len(points) == 0:
        return np.zeros(0, np.int64)
    corners = tri.xy[np.array([tri.tri[f] for f in faces])]  # (F, 3, 2)
    inside = in_triangle_perturbed(corners[None], points[:, None, :])  # (n, F)
    hit = inside.argmax(1)
    if not inside[np.arange(len(points)), hit].all():
        raise RuntimeError("point location failed: a point lies outside the region")
    return np.asarray(faces, np.int64)[hit]


# The stars of this many nearest vertices are tried for a point before the
# test against every triangle.
NEAREST_STARS = 8


def _star_guess(tri, points: np.ndarray, vertex: np.ndarray) -> np.ndarray:
    """Per point, a triangle of the star of ``vertex (n,)`` that holds it
    (exact, perturbed test), or ``-1``.

    Everything is arrays: no LAPACK call, whose threads fight the kernels'
    for the cores (Qhull's own location computes a LAPACK transform per
    triangle).
    """
    tris = tri.triangles()
    fid = np.asarray(tri.triangle_ids(), np.int64)
    corner = tris.ravel()
    order = np.argsort(corner, kind="stable")
    row_of = np.repeat(np.arange(len(tris)), 3)[order]
    start = np.searchsorted(corner[order], np.arange(len(tri.xy) + 1))
    count = start[vertex + 1] - start[vertex]
    point_of = np.repeat(np.arange(len(points)), count)
    slot = np.arange(len(point_of)) - np.repeat(np.cumsum(count) - count, count)
    row = row_of[start[vertex][point_of] + slot]
    hit = in_triangle_perturbed(tri.xy[tris[row]], points[point_of])
    out = np.full(len(points), -1, np.int64)
    # Reversed, so that the first hit of a point is the one that stays.
    out[point_of[hit][::-1]] = fid[row[hit]][::-1]
    return out


def locate(tri, points: np.ndarray) -> np.ndarray:
    """Triangle holding each perturbed point, over the whole triangulation.

    Each point is tested against the star of its nearest vertex (a k-d
    tree query and one vectorised exact test), which almost always holds
    it; the points left, against the stars of their next nearest vertices,
    up to :data:`NEAREST_STARS`; whatever is still left, against every
    triangle in chunks: simple, exact and slow, which is fine because it
    is rare and the collapse loop never calls it (it relocates locally).
    The holding triangle is unique (symbolic perturbation), so the order
    of the tests does not change the answer.

    Args:
      points: ``(n, 2)`` points inside the pinned box.

    Returns:
      ``(n,)`` int64 triangle ids.
    """
    points = np.asarray(points, np.float64).reshape(-1, 2)
    if not len(points):
        return np.zeros(0, np.int64)
    live = np.unique(tri.triangles().ravel())
    tree = cKDTree(tri.xy[live])
    _, nearest = tree.query(points)
    out = _star_guess(tri, points, live[nearest])
    rest = np.flatnonzero(out < 0)
    if len(rest):
        k = min(NEAREST_STARS, len(live))
        _, near = tree.query(points[rest], k=k)
        for rank in range(1, k):
            out[rest] = _star_guess(tri, points[rest], live[near[:, rank]])
            found = out[rest] >= 0
            rest, near = rest[~found], near[~found]
            if not len(rest):
                break
    if len(rest):
        ids = tri.triangle_ids()
        chunk = max(1, 2_000_000 // max(len(ids), 1))
        for s in range(0, len(rest), chunk):
            sel = rest[s:s + chunk]
            out[sel] = locate_in(tri, points[sel], ids)
    return out


def check(tri) -> None:
    """Raises ``AssertionError`` unless the structure is a valid embedding.

    Checks: every triangle strictly CCW (exact); no directed edge in two
    triangles (no overlap); neighbour links symmetric
    and consistent; every interior edge in two triangles, boundary edges
    only between corners; Euler characteristic of a disk; all live
    vertices referenced and strictly inside the pinned box.
    """
    t = tri.triangles()
    xy = tri.xy
    assert (orient(xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]) > 0).all(), "non-CCW triangle"
    for f, (tv, nv) in enumerate(zip(tri.tri, tri.nbr)):
        if tv is None:
            continue
        assert len(set(tv)) == 3, "repeated vertex in triangle"
        for k in range(3):
            g = nv[k]
            u, w = tv[(k + 1) % 3], tv[(k + 2) % 3]
            if g < 0:
                assert tri.pinned[u] and tri.pinned[w], "boundary edge not between corners"
                continue
            assert tri.tri[g] is not None, "link to a freed triangle"
            assert f in tri.nbr[g], "asymmetric neighbour link"
            assert {u, w} <= set(tri.tri[g]), "neighbour does not share the edge"
    directed = t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert len(np.unique(directed, axis=0)) == len(directed), "two triangles overlap (fold-over)"
    e = directed.copy()
    e.sort(axis=1)
    _, count = np.unique(e, axis=0, return_counts=True)
    assert count.max() <= 2, "edge in more than two triangles"
    n_boundary = int((count == 1).sum())
    assert n_boundary == N_CORNERS, f"boundary has {n_boundary} edges"
    used = np.unique(t)
    assert np.array_equal(used, np.nonzero(tri.alive)[0]), "live vertex set mismatch"
    assert len(used) - len(count) + len(t) == 1, "Euler characteristic of a disk violated"
    lo, hi = xy[tri.pinned].min(0), xy[tri.pinned].max(0)
    inner = xy[tri.alive & ~tri.pinned]
    assert ((inner > lo) & (inner < hi)).all(), "vertex outside the pinned box"
