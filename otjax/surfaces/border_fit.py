"""Open borders moved out to where the points end (not in the paper).

At an open border the transport cost settles vertices inside the shape: a
vertex's own bin takes the points nearest to it whatever their amount, so
a border vertex ends up short of the last points, by up to a few percent
of the diagonal at a few thousand points
(docs/benchmarks.md#surfaces-reconstruction). :func:`fit_border` moves
each *flat* border vertex (its facets' planes within ``flat_angle`` of one
another) within that plane, straight across its border, to where the
points of a strip beside it end: past the farthest by their mean spacing,
as the last of a uniform sample falls short of its end by about that. At
a convex corner of the border each of the vertex's two border edges moves
out so, and the vertex to where the two lines meet.
Vertices on creases and where a border meets a crease are left where they
are. The farthest point decides: give the points without their outliers.

A border edge is an edge of one facet. Where two facets on an edge lie
over each other (a fold, :func:`otjax.metrics3d.edge_sharpness`) the
doubled patch ends too, but inside a closed surface that end is no border:
folds are left alone.
Every decision is taken on the positions given; the vertices move
together. The rule uses lengths relative to the vertex's own border
edges, so scaling, rotating or translating the input moves the result
with it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from otjax.metrics3d import boundary_edges
from otjax.surfaces.fit_input import (VertexFit, checked, points_noise, unit_normals,
                                      vertex_facets, without_flattening)
from otjax.uniform_ends import uniform_end

#: Largest angle, in degrees, between two facets of a vertex that still
#: counts as flat (docs/decisions.md#border_fit).
FLAT_ANGLE = 45.0
#: Fewest points in a vertex's strip for it to move.
MIN_POINTS = 5
#: A ball around a vertex holding its whole strip (a side's: |(1/2, 1/10, 1)|,
#: a corner edge's: |(1, 1/10, 1)| < 1.42).
STRIP_RADIUS = 1.42
#: A flat border vertex of two border edges less than this many degrees apart,
#: its facets between them, is a corner: each edge moves out to its points'
#: end and the vertex to where they meet (docs/decisions.md#border_fit).
CORNER_ANGLE = 135.0
#: A corner's facets are flat within this many degrees (docs/decisions.md#border_fit).
CORNER_FLAT_ANGLE = 20.0


#: What :func:`fit_border` returns: the positions after the fit and the rows that moved.
BorderFit = VertexFit


def fit_border(vertices, triangles, points, flat_angle: float = FLAT_ANGLE,
               noise: float | None = None) -> BorderFit:
    """Moves the flat border vertices of a complex out to the end of the points.

    For a border vertex ``v`` with at least two border neighbours (the
    straightest pair of them is used) whose facets' normals are all within
    ``flat_angle`` of one another: ``N`` their mean normal, ``T`` the
    direction between the two neighbours in that plane, ``out`` the
    direction in the plane across ``T`` away from ``v``'s facets, and ``L``
    the shorter of its two border edges. The strip is the points ``p``
    with ``|(p - v).T| <= L/2``, ``|(p - v).N| <= L/10`` and
    ``|(p - v).out| <= L``; with at least :data:`MIN_POINTS` of them, ``v``
    moves along ``out`` to where their ``(p - v).out`` end
    (:func:`~otjax.uniform_ends.uniform_end`: past the largest by
    their mean spacing, or the quantile that stands for it in the points'
    ``noise``; outward, or inward where the points end before it; inward
    by at most ``L / 2``: the vertex stays where they end further in).
    A vertex of exactly two border edges less than :data:`CORNER_ANGLE`
    apart in that plane, its facets' centre between them and their normals
    within :data:`CORNER_FLAT_ANGLE` of one another, is a corner:
    each edge moves out across itself to where the points of the strip
    beside it end (``L/4 <= (p - v).e <= L`` along it, ``e`` its
    direction; ``|(p - v).N| <= L/10``; within ``L`` across) and the
    vertex to where the two lines meet, if that is at most ``L / 2`` away
    and has a point within ``L / 4`` (else, or where a strip has too few
    points, it moves as a side vertex).
    Moves that would flatten a triangle are undone
    (:func:`~otjax.surfaces.fit_input.without_flattening`).

    Args:
      vertices: ``(V, 3)`` vertex positions.
      triangles: ``(T, 3)`` int rows into ``vertices``.
      points: ``(n, 3)`` the points the complex was reconstructed from
        (without outliers: the farthest point of a strip decides).
      flat_angle: degrees, in ``(0, 90)``.
      noise: the points' standard deviation about their surface, if known
        (else :func:`~otjax.background.flat_noise` of ``points``).

    Returns:
      :class:`BorderFit`.

    Raises:
      ValueError: arrays of the wrong shape, non-finite values, indices out
        of range, ``flat_angle`` outside ``(0, 90)``.

    Example:
      >>> import numpy as np
      >>> g = np.linspace(0.0, 1.0, 41)
      >>> pts = np.c_[np.stack(np.meshgrid(g, g), -1).reshape(-1, 2), np.zeros(41 * 41)]
      >>> v = np.array([[0.1, 0.1, 0], [0.5, 0.1, 0], [0.9, 0.1, 0], [0.1, 0.5, 0], [0.5, 0.5, 0],
      ...               [0.9, 0.5, 0], [0.1, 0.9, 0], [0.5, 0.9, 0], [0.9, 0.9, 0]])
      >>> t = [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6], [4, 5, 8], [4, 8, 7]]
      >>> fit = fit_border(v, t, pts)
      >>> fit.moved.tolist()
      [0, 1, 2, 3, 5, 6, 7, 8]
      >>> off = fit.vertices[[0, 1, 4]] - [[0, 0, 0], [0.5, 0, 0], [0.5, 0.5, 0]]  # corner, side, centre
      >>> bool(np.abs(off).max() < 0.025 / 10)  # at the grid's sides, to a tenth of its step
      True
    """
    vertices, triangles, points = _checked(vertices, triangles, points, flat_angle)
    out = vertices.copy()
    if not len(triangles) or not len(points):
        return VertexFit(out, np.zeros(0, np.int64))
    neighbours: dict[int, list[int]] = {}
    for a, b in boundary_edges(triangles).tolist():
        neighbours.setdefault(a, []).append(b)
        neighbours.setdefault(b, []).append(a)
    normal = unit_normals(vertices, triangles)
    facets = vertex_facets(triangles)
    cos_flat = np.cos(np.radians(flat_angle))
    tree = cKDTree(points)
    noise = points_noise(points, noise)
    moved = []
    for v in sorted(neighbours):
        step = _step(v, neighbours[v], vertices, triangles, normal, facets.get(v, []), points, tree, cos_flat,
                     noise)
        if step is not None:
            out[v] = vertices[v] + step
            moved.append(v)
    return without_flattening(vertices, out, triangles, np.asarray(moved, np.int64))


def _step(v, neighbours, vertices, triangles, normal, facets, points, tree, cos_flat,
          noise: float) -> np.ndarray | None:
    """The move of border vertex ``v``, or ``None`` if it stays (not flat,
    fewer than two border neighbours, a degenerate facet or too few points)."""
    if len(neighbours) < 2 or not facets:
        return None
    n = normal[facets]
    if not np.all(np.linalg.norm(n, axis=1) > 0):
        return None
    n = n * np.where(n @ n[0] < 0, -1.0, 1.0)[:, None]  # facets carry no consistent orientation
    if np.any(n @ n.T < cos_flat):
        return None
    axis = n.mean(0)
    axis /= np.linalg.norm(axis)
    u, w = _straightest(v, neighbours, vertices)
    along = vertices[w] - vertices[u]
    along -= (along @ axis) * axis
    size = np.linalg.norm(along)
    if not size > 0:
        return None
    along /= size
    across = np.cross(axis, along)
    centre = vertices[triangles[facets]].mean(axis=(0, 1))
    if (centre - vertices[v]) @ across > 0:
        across = -across
    reach = min(np.linalg.norm(vertices[u] - vertices[v]), np.linalg.norm(vertices[w] - vertices[v]))
    d = points[tree.query_ball_point(vertices[v], STRIP_RADIUS * reach)] - vertices[v]
    if len(neighbours) == 2 and np.all(n @ n.T >= np.cos(np.radians(CORNER_FLAT_ANGLE))):
        step = _corner_step(vertices[[u, w]] - vertices[v], axis, centre - vertices[v], d, reach, noise)
        if step is not None:
            return step
    t, h, o = d @ along, d @ axis, d @ across
    strip = (np.abs(t) <= reach / 2) & (np.abs(h) <= reach / 10) & (np.abs(o) <= reach)
    if strip.sum() < MIN_POINTS:
        return None
    # Points ending over half an edge inside the vertex are not its
    # border's: around a vertex whose fan opens inwards (facets filtered or
    # folded away) the strip lies across the shape.
    end = uniform_end(o[strip], noise)
    return end * across if end >= -reach / 2 else None


def _corner_step(edges: np.ndarray, axis: np.ndarray, inside: np.ndarray, d: np.ndarray, reach: float,
                 noise: float) -> np.ndarray | None:
    """The move of a vertex at a convex corner of the border: its two border
    edges ``(2, 3)`` (from the vertex), in the plane across ``axis``, less
    than :data:`CORNER_ANGLE` apart with its facets' centre ``inside``
    between them. Each edge moves out across itself to where the points
    ``d (n, 3)`` (from the vertex) of a strip beside it end, and the vertex
    to where the two lines meet. ``None`` where the vertex is no such
    corner, a strip holds fewer than :data:`MIN_POINTS` points, the move
    exceeds ``reach / 2`` or no point lies within ``reach / 4`` of where
    it ends."""
    dirs = edges - np.outer(edges @ axis, axis)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    if dirs[0] @ dirs[1] <= np.cos(np.radians(CORNER_ANGLE)) or inside @ (dirs[0] + dirs[1]) <= 0:
        return None
    ends = []
    for i in (0, 1):
        across = np.cross(axis, dirs[i])
        if across @ dirs[1 - i] > 0:  # away from the other edge: out of the corner
            across = -across
        t, h, o = d @ dirs[i], d @ axis, d @ across
        strip = (t >= reach / 4) & (t <= reach) & (np.abs(h) <= reach / 10) & (np.abs(o) <= reach)
        if strip.sum() < MIN_POINTS:
            return None
        ends.append((across, uniform_end(o[strip], noise)))
    # x = a dirs[0] + b dirs[1] with x . across_i = end_i; dirs[i] . across_i = 0.
    (c0, e0), (c1, e1) = ends
    step = e1 / (dirs[0] @ c1) * dirs[0] + e0 / (dirs[1] @ c0) * dirs[1]
    # Where the two edges are no borders of the points (a fold covers the
    # true border beyond them) the lines meet out past the points.
    if np.linalg.norm(step) > reach / 2 or np.linalg.norm(d - step, axis=1).min() > reach / 4:
        return None
    return step


def _straightest(v: int, neighbours: list[int], vertices: np.ndarray) -> tuple[int, int]:
    """The two border neighbours of ``v`` whose edges from ``v`` are closest
    to opposite (ties: the first pair in increasing ids)."""
    nb = sorted(neighbours)
    d = vertices[nb] - vertices[v]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), np.finfo(np.float64).tiny)
    cos = d @ d.T
    i, j = np.triu_indices(len(nb), 1)
    k = int(np.argmin(cos[i, j]))
    return nb[i[k]], nb[j[k]]


def _checked(vertices, triangles, points, flat_angle):
    """The arrays as float64 / int64, checked (see :func:`fit_border`)."""
    if isinstance(flat_angle, bool) or not np.isscalar(flat_angle) or not 0 < float(flat_angle) < 90:
        raise ValueError(f"flat_angle must be a number of degrees in (0, 90), got {flat_angle!r}")
    return checked(vertices, triangles, points)
