"""Distances between a reconstructed surface and its ground truth.

An output is a complex: ``vertices (V, 3)``, ``triangles (T, 3)``, dangling
``edges (E, 2)`` and ``isolated (I,)`` vertices. A truth is any object with
``sample(n, rng) -> (n, 3)`` (uniform by area), ``distance(x) -> (m,)``
(exact) and ``diagonal`` (a :class:`otjax.datasets3d.SurfaceTruth`).
Lengths come back in the units of the input; divide by ``truth.diagonal``
for a share of the shape's size.

Typical use::

    d = surface_distances(r.vertices, r.triangles, r.edges, r.isolated, truth)
    d.chamfer / truth.diagonal, d.hausdorff / truth.diagonal
    crease_error(r.vertices, r.triangles, truth.creases).mean / truth.diagonal
    boundary_error(r.vertices, r.triangles, truth.boundaries).mean / truth.diagonal
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from otjax.metrics import point_segment_distance, sample_segments

#: Default sharpness above which an output edge is a crease: the usual
#: "feature angle" of mesh tools (docs/decisions.md#crease_angle).
CREASE_ANGLE = np.deg2rad(30.0)
#: Two triangles whose half planes around an edge are closer than this lie
#: over each other (a fold): a defect of the output, not a crease, however
#: sharp the turn (docs/decisions.md#folds).
FOLD_ANGLE = np.deg2rad(30.0)
#: Default sampling step of the output, as a share of the truth's diagonal.
STEP = 0.005
# Point-triangle pairs measured at once: about 8 MiB per (n, 3) float64 temporary.
_BLOCK = 1 << 18


def _points(x, name: str) -> np.ndarray:
    x = np.asarray(x, np.float64)
    if x.size == 0:
        return x.reshape(0, 3)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {x.shape}")
    return x


def _indices(x, width: int, n: int, name: str) -> np.ndarray:
    x = np.asarray([] if x is None else x)
    if x.size == 0:
        return np.zeros((0, width) if width else 0, np.int64)
    if x.dtype.kind not in "iu" or (x.ndim != 2 or x.shape[1] != width if width else x.ndim != 1):
        raise ValueError(f"{name} must be an integer array of shape {f'(m, {width})' if width else '(m,)'}")
    if x.min() < 0 or x.max() >= n:
        raise ValueError(f"{name} index out of range: indices must be in [0, {n}), got {x.min()}..{x.max()}")
    return x.astype(np.int64)


# ----------------------------------------------------------------- sampling


def triangle_samples(vertices, triangles, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points across triangles, with area weights.

    Each triangle is laid in its plane with its longest edge on the x axis
    and the opposite corner above it, cut into columns at most ``step`` wide
    (and at the corner's foot), and each column into equal rows at most
    ``step`` tall. Every cell is a trapezoid with vertical sides, represented
    by its centroid weighing its area. So every point of a triangle is
    within ``sqrt(2) step`` of a sample, a triangle's weights sum to its
    area, and a long thin triangle gets about ``length / step`` samples, not
    ``(length / step)^2``.

    Returns:
      ``points (N, 3)`` and ``weights (N,)``, the cells of each triangle
      contiguous and in triangle order.

    Example:
      >>> p, w = triangle_samples([[0, 0, 0], [2, 0, 0], [0, 1, 0]], [[0, 1, 2]], 1.0)
      >>> len(p), float(w.sum())
      (4, 1.0)
    """
    v = _points(vertices, "vertices")[_indices(triangles, 3, len(vertices), "triangles")]
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    edge = np.linalg.norm(v[:, [1, 2, 0]] - v, axis=2)  # edge i runs from corner i to corner i + 1
    i = edge.argmax(axis=1)
    v = v[np.arange(len(v))[:, None], (i[:, None] + np.arange(3)) % 3]  # longest edge: corner 0 to 1
    a, length = v[:, 0], edge.max(axis=1, initial=0.0)
    ex = (v[:, 1] - a) / np.where(length > 0, length, 1.0)[:, None]
    cx = np.einsum("td,td->t", v[:, 2] - a, ex)
    up = v[:, 2] - a - cx[:, None] * ex
    h = np.linalg.norm(up, axis=1)
    ey = up / np.where(h > 0, h, 1.0)[:, None]
    # Columns: n equal cuts plus the foot of the apex, so the top of each column is linear.
    n = np.maximum(1, np.ceil(length / step)).astype(np.int64)
    tri, k = _ragged(n + 1)
    cuts = np.concatenate([length[tri] * k / n[tri], cx])
    owner = np.concatenate([tri, np.arange(len(v))])
    order = np.lexsort((cuts, owner))
    cuts, owner = cuts[order], owner[order]
    col = np.flatnonzero((owner[1:] == owner[:-1]) & (cuts[1:] > cuts[:-1]))
    t, x0, x1 = owner[col], cuts[col], cuts[col + 1]

    def top(x):  # height of the triangle above x: a tent peaking at the apex's foot
        left = h[t] * x / np.where(cx[t] > 0, cx[t], 1.0)
        right = h[t] * (length[t] - x) / np.where(length[t] > cx[t], length[t] - cx[t], 1.0)
        return np.where(x <= cx[t], left, right)

    top0, top1 = top(x0), top(x1)
    m = np.maximum(1, np.ceil(np.maximum(top0, top1) / step)).astype(np.int64)
    c, row = _ragged(m)
    sa, sb, w = top0[c] / m[c], top1[c] / m[c], (x1 - x0)[c]
    area = 0.5 * w * (sa + sb)
    ab = np.where(sa + sb > 0, sa + sb, 1.0)
    x = x0[c] + w * (sa + 2 * sb) / (3 * ab)
    y = (row + 0.5) * (2.0 / 3.0) * (sa * sa + sa * sb + sb * sb) / ab
    tc = t[c]
    return a[tc] + x[:, None] * ex[tc] + y[:, None] * ey[tc], area


def _ragged(count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(owner, k)``: ``k = 0 .. count[i] - 1`` for each ``i``, owners in order."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)


class ComplexSamples(NamedTuple):
    """Weighted samples of a complex: ``points (N, 3)``, ``weights (N,)``."""

    points: np.ndarray
    weights: np.ndarray


def complex_samples(vertices, triangles, edges=None, isolated=None, *, step: float) -> ComplexSamples:
    """Samples of every simplex of a complex, weighted by their measure.

    Triangles by :func:`triangle_samples`. A dangling edge counts as a
    strip of width ``step`` (samples of :func:`otjax.metrics.sample_segments`
    weighing ``length share * step``) and an isolated vertex as a
    ``step`` x ``step`` square, so a spurious edge or vertex weighs like a
    patch of surface as thin as the sampling, neither free nor dominant.
    """
    vertices = _points(vertices, "vertices")
    p, w = triangle_samples(vertices, triangles, step)
    e = _indices(edges, 2, len(vertices), "edges")
    q, u = sample_segments(vertices[e], step) if len(e) else (np.zeros((0, 3)), np.zeros(0))
    iso = vertices[_indices(isolated, 0, len(vertices), "isolated")]
    return ComplexSamples(np.concatenate([p, q, iso]),
                          np.concatenate([w, u * step, np.full(len(iso), step * step)]))


# ----------------------------------------------------------------- distance


def _pair_distance(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``(n,)`` exact distance of points ``p (n, 3)`` to triangles ``t (n, 3, 3)``, row by row:
    the projection on the plane when it falls inside, else the nearest edge."""
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    best = np.full(len(p), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        d = v - u
        dd = np.einsum("nd,nd->n", d, d)
        s = np.clip(np.einsum("nd,nd->n", p - u, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
        off = p - u - s[:, None] * d
        best = np.minimum(best, np.einsum("nd,nd->n", off, off))
    n = np.cross(b - a, c - a)
    nn = np.einsum("nd,nd->n", n, n)
    h = np.einsum("nd,nd->n", p - a, n)
    q = p - (h / np.where(nn > 0, nn, 1.0))[:, None] * n
    inside = nn > 0
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("nd,nd->n", np.cross(v - u, q - u), n) >= 0
    plane = h * h / np.where(nn > 0, nn, 1.0)
    return np.sqrt(np.where(inside, np.minimum(best, plane), best))


def point_triangle_distance(points, tris) -> np.ndarray:
    """``(n,)`` exact distance of each point ``(n, 3)`` to the nearest of the triangles ``(t, 3, 3)``.

    Only the triangles that can be nearest are measured: the nearest of a
    few samples of the triangles bounds the answer from above, and a
    triangle whose bounding box is farther than that cannot beat it.

    Returns:
      ``(n,)`` float64; ``inf`` everywhere when ``t == 0``.

    Example:
      >>> point_triangle_distance([[0.2, 0.2, 1.0]], [[[0, 0, 0], [1, 0, 0], [0, 1, 0]]])
      array([1.])
    """
    points = _points(points, "points")
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    if len(tris) == 0 or len(points) == 0:
        return np.full(len(points), np.inf)
    lo, hi = tris.min(axis=1), tris.max(axis=1)
    span = float(np.linalg.norm(hi.max(0) - lo.min(0)))
    flat = tris.reshape(-1, 3)
    samples, _ = triangle_samples(flat, np.arange(len(flat)).reshape(-1, 3), span / 32 or 1.0)
    upper, _ = cKDTree(np.concatenate([flat, samples])).query(points)
    out = np.empty(len(points))
    chunk = max(1, _BLOCK // len(tris))
    for s in range(0, len(points), chunk):
        p, up = points[s:s + chunk], upper[s:s + chunk]
        gap = np.maximum(np.maximum(lo[None] - p[:, None], p[:, None] - hi[None]), 0.0)  # (c, t, 3)
        # With slack: the bound is often attained exactly (a vertex nearest to both), up to rounding.
        pt, tri = np.nonzero(np.einsum("ctd,ctd->ct", gap, gap) <= ((1 + 1e-9) * up * up)[:, None])
        d = np.full(len(p), np.inf)
        for b in range(0, len(pt), _BLOCK):  # the pairs in blocks: memory stays bounded
            np.minimum.at(d, pt[b:b + _BLOCK], _pair_distance(p[pt[b:b + _BLOCK]], tris[tri[b:b + _BLOCK]]))
        out[s:s + chunk] = d
    return out


def distance_to_complex(points, vertices, triangles, edges=None, isolated=None) -> np.ndarray:
    """``(n,)`` distance of each point to the nearest triangle, dangling edge or
    isolated vertex of a complex; ``inf`` when the complex is empty."""
    points = _points(points, "points")
    vertices = _points(vertices, "vertices")
    d = point_triangle_distance(points, vertices[_indices(triangles, 3, len(vertices), "triangles")])
    e = _indices(edges, 2, len(vertices), "edges")
    iso = _indices(isolated, 0, len(vertices), "isolated")
    segs = np.concatenate([vertices[e], np.stack([vertices[iso], vertices[iso]], 1)])
    if len(segs):
        d = np.minimum(d, point_segment_distance(points, segs))
    return d


class SurfaceDistances(NamedTuple):
    """Distances between an output and a truth, in input units.

    Attributes:
      chamfer: ``(to_truth_mean + from_truth_mean) / 2``.
      hausdorff: ``max(to_truth_max, from_truth_max)``.
      to_truth_mean, to_truth_max: output to truth, weighted by the output's
        measure (:func:`complex_samples`).
      from_truth_mean, from_truth_max: truth to output, over samples uniform
        by area on the truth.
    """

    chamfer: float
    hausdorff: float
    to_truth_mean: float
    to_truth_max: float
    from_truth_mean: float
    from_truth_max: float


def surface_distances(vertices, triangles, edges=None, isolated=None, *, truth, samples: int = 20000,
                      step: float | None = None, seed: int = 0) -> SurfaceDistances:
    """Symmetric Chamfer and Hausdorff distances between a complex and a truth.

    The output is sampled by :func:`complex_samples` at ``step`` and each
    sample measured with the truth's exact distance; the truth is sampled
    ``samples`` times uniformly by area (seeded) and each sample measured
    exactly against the complex (:func:`distance_to_complex`). The output's
    maximum is within ``sqrt(2) step`` of the true one-sided Hausdorff distance
    (distances are 1-Lipschitz); the truth side's mean is a Monte Carlo
    estimate and its maximum a lower bound.

    Args:
      vertices, triangles, edges, isolated: the complex (edges and isolated may be ``None``).
      truth: see the module doc.
      samples: number of truth samples.
      step: output sampling step; default :data:`STEP` times ``truth.diagonal``.
      seed: seed of the truth samples.

    Returns:
      :class:`SurfaceDistances`; every field ``inf`` when the complex is empty.
    """
    step = STEP * truth.diagonal if step is None else float(step)
    out = complex_samples(vertices, triangles, edges, isolated, step=step)
    if not len(out.points):
        return SurfaceDistances(*[float("inf")] * 6)
    to_truth = truth.distance(out.points)
    total = out.weights.sum()
    to_mean = float(out.weights @ to_truth / total) if total > 0 else float(to_truth.mean())
    ref = truth.sample(samples, np.random.default_rng(seed))
    from_truth = distance_to_complex(ref, vertices, triangles, edges, isolated)
    to_max, from_mean, from_max = float(to_truth.max()), float(from_truth.mean()), float(from_truth.max())
    return SurfaceDistances(0.5 * (to_mean + from_mean), max(to_max, from_max), to_mean, to_max, from_mean,
                            from_max)


def chamfer(vertices, triangles, edges=None, isolated=None, *, truth, **options) -> float:
    """:attr:`SurfaceDistances.chamfer` of :func:`surface_distances`."""
    return surface_distances(vertices, triangles, edges, isolated, truth=truth, **options).chamfer


def hausdorff(vertices, triangles, edges=None, isolated=None, *, truth, **options) -> float:
    """:attr:`SurfaceDistances.hausdorff` of :func:`surface_distances`."""
    return surface_distances(vertices, triangles, edges, isolated, truth=truth, **options).hausdorff


# ----------------------------------------------------------------- features


class EdgeSharpness(NamedTuple):
    """The edges of a set of triangles and how sharp each is.

    Attributes:
      edges: ``(E, 2)`` int64, each row increasing, rows sorted.
      n_triangles: ``(E,)`` triangles on each edge.
      layers: ``(E,)`` sheets on each edge: its triangles grouped by folds
        (half planes less than :data:`FOLD_ANGLE` apart, chained), those
        without a half plane (degenerate) left out; 1 on an edge of one
        triangle. An edge of one layer is a boundary edge
        (:func:`boundary_error`): a patch doubled by a fold ends there.
      angle: ``(E,)`` radians in ``[0, pi - FOLD_ANGLE]``: over pairs of
        triangles on the edge that do not fold (their half planes at least
        :data:`FOLD_ANGLE` apart), the largest ``pi - `` the angle between
        their half planes (0 for flat, ``pi / 2`` for a cube's edge); 0 on
        boundary edges, between degenerate triangles and where every pair folds.
    """

    edges: np.ndarray
    n_triangles: np.ndarray
    layers: np.ndarray
    angle: np.ndarray


def edge_sharpness(vertices, triangles) -> EdgeSharpness:
    """The :class:`EdgeSharpness` of the edges of ``triangles (T, 3)`` over ``vertices (V, 3)``.

    Orientation-free: a complex's triangles carry no consistent orientation.
    """
    vertices = _points(vertices, "vertices")
    tri = np.sort(_indices(triangles, 3, len(vertices), "triangles"), axis=1)
    rows = np.concatenate([tri[:, [0, 1, 2]], tri[:, [0, 2, 1]], tri[:, [1, 2, 0]]])  # (a, b, opposite)
    rows = rows[np.lexsort((rows[:, 2], rows[:, 1], rows[:, 0]))]
    a, b = vertices[rows[:, 0]], vertices[rows[:, 1]]
    d = b - a
    w = vertices[rows[:, 2]] - a
    dd = np.einsum("nd,nd->n", d, d)
    w = w - (np.einsum("nd,nd->n", w, d) / np.where(dd > 0, dd, 1.0))[:, None] * d  # across the edge
    ok = np.linalg.norm(w, axis=1) > 0
    new = np.r_[len(rows) > 0, np.any(rows[1:, :2] != rows[:-1, :2], axis=1)]
    start = np.flatnonzero(new[:len(rows)])
    count = np.diff(np.r_[start, len(rows)])
    angle = np.zeros(len(start))
    layers = np.ones(len(start), np.int64)
    for e in np.flatnonzero(count > 1):
        i = np.arange(start[e], start[e] + count[e])
        i = i[ok[i]]
        layers[e] = len(i)
        if len(i) < 2:
            continue
        x, y = np.triu_indices(len(i), 1)
        u, v = w[i[x]], w[i[y]]
        between = np.arctan2(np.linalg.norm(np.cross(u, v), axis=1), np.einsum("nd,nd->n", u, v))
        folded = between < FOLD_ANGLE
        layers[e] = _components(len(i), x[folded], y[folded])
        between = between[~folded]
        angle[e] = np.pi - between.min() if len(between) else 0.0
    return EdgeSharpness(rows[start, :2], count, layers, angle)


def _components(n: int, x: np.ndarray, y: np.ndarray) -> int:
    """Connected components of ``n`` nodes joined by the pairs ``(x[k], y[k])``."""
    label = np.arange(n)
    for a, b in zip(x.tolist(), y.tolist()):
        la, lb = label[a], label[b]
        if la != lb:
            label[label == lb] = la
    return len(np.unique(label))


def boundary_edges(triangles) -> np.ndarray:
    """``(b, 2)`` edges on exactly one of ``triangles (T, 3)``, rows increasing and sorted."""
    tri = np.sort(np.asarray(triangles, np.int64).reshape(-1, 3), axis=1)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [0, 2]], tri[:, [1, 2]]])
    keys, count = np.unique(e, axis=0, return_counts=True)
    return keys[count == 1].reshape(-1, 2)


class FeatureError(NamedTuple):
    """Distance from a true feature to the output's feature edges.

    Attributes:
      mean: length-weighted mean over the true feature's samples.
      max: largest over them.
      n_edges: output edges the feature was measured against.
    """

    mean: float
    max: float
    n_edges: int


def _feature_error(vertices, edges: np.ndarray, truth_segments, step: float | None) -> FeatureError:
    segs = np.asarray(truth_segments, np.float64).reshape(-1, 2, 3)
    if not len(segs):
        return FeatureError(0.0, 0.0, len(edges))
    if step is None:
        span = np.concatenate([segs.reshape(-1, 3), vertices])
        step = 1e-3 * float(np.linalg.norm(span.max(0) - span.min(0))) or 1.0
    pts, w = sample_segments(segs, step)
    if not len(edges):
        return FeatureError(float("inf"), float("inf"), 0)
    d = point_segment_distance(pts, vertices[edges])
    return FeatureError(float(w @ d / w.sum()) if w.sum() > 0 else float(d.mean()), float(d.max()), len(edges))


def crease_error(vertices, triangles, creases, angle: float = CREASE_ANGLE, step: float | None = None) -> FeatureError:
    """How far the true creases are from the output's sharp edges.

    The true creases ``(c, 2, 3)`` are sampled every ``step`` (default 1e-3
    of the diagonal of everything's bounding box); each sample's distance is
    to the nearest output edge sharper than ``angle`` (:func:`edge_sharpness`;
    edges of two or more triangles only, dangling edges have no angle).

    Returns:
      :class:`FeatureError`; ``inf`` when the output has no sharp edge and
      the truth has creases, ``0`` when the truth has none.

    Example:
      >>> from otjax.datasets3d import cube_truth
      >>> t = cube_truth()
      >>> crease_error(t.mesh.vertices, t.mesh.triangles, t.creases).max
      0.0
    """
    vertices = _points(vertices, "vertices")
    s = edge_sharpness(vertices, triangles)
    return _feature_error(vertices, s.edges[(s.n_triangles > 1) & (s.angle > angle)], creases, step)


def boundary_error(vertices, triangles, boundaries, step: float | None = None) -> FeatureError:
    """How far the true boundaries ``(b, 2, 3)`` are from the output's boundary
    edges, sampled as in :func:`crease_error`.

    A boundary edge is an edge of one layer (:class:`EdgeSharpness`): on a
    mesh without folds, an edge of one triangle (:func:`boundary_edges`);
    where two triangles on an edge lie over each other, the doubled patch
    also ends there (docs/decisions.md#folds).
    """
    vertices = _points(vertices, "vertices")
    s = edge_sharpness(vertices, triangles)
    return _feature_error(vertices, s.edges[s.layers == 1], boundaries, step)
