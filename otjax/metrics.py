"""Distances between a reconstruction and its ground truth.

This module measures curves; surfaces (Chamfer, Hausdorff, crease and
boundary errors of a complex) are measured by :mod:`otjax.metrics3d`.

Everything here is plain NumPy on segment sets, shaped ``(s, 2, d)`` (segment,
endpoint, coordinate; ``d = 2`` for curves). Lengths come back in the units of
the inputs: to report a percentage of the shape's size, divide by
``truth["diagonal"]`` from :mod:`otjax.datasets`.

Typical use, with ``vertices (k, 2)`` and ``edges (m, 2)`` from a reconstruction::

    out = edges_to_segments(vertices, edges)
    hausdorff(truth["segments"], out) / truth["diagonal"]     # worst deviation
    length_within(truth["segments"], out, tol)                # recall
    length_within(out, truth["segments"], tol)                # precision
    corner_errors(vertices, truth["corners"]).max()           # feature accuracy
"""

from __future__ import annotations

import numpy as np

# Upper bound on the entries of one (points x segments) block: about 8 MiB per float64 temporary.
_BLOCK = 1 << 20


def _as_points(p, name: str) -> np.ndarray:
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 2:
        raise ValueError(f"{name} must have shape (n, d), got {p.shape}")
    return p


def _as_segments(segs, name: str) -> np.ndarray:
    segs = np.asarray(segs, dtype=np.float64)
    if segs.size == 0:
        # An empty list of segments arrives as shape (0,); give it a usable shape.
        return segs.reshape(0, 2, segs.shape[-1] if segs.ndim == 3 else 2)
    if segs.ndim != 3 or segs.shape[1] != 2:
        raise ValueError(f"{name} must have shape (s, 2, d), got {segs.shape}")
    return segs


def point_segment_distance(p, segs) -> np.ndarray:
    """Distance from each point to the nearest point of a union of segments.

    Args:
      p: ``(n, d)`` points.
      segs: ``(s, 2, d)`` segments; a segment whose endpoints coincide is a point.

    Returns:
      ``(n,)`` float64 distances; ``inf`` everywhere when ``s == 0``.

    Points are processed in blocks so that memory stays bounded by about
    ``2**20`` point-segment pairs whatever ``n * s`` is.

    Example:
      >>> point_segment_distance([[0.5, 2.0], [3.0, 0.0]], [[[0, 0], [1, 0]]])
      array([2., 2.])
    """
    p = _as_points(p, "p")
    segs = _as_segments(segs, "segs")
    if len(segs) == 0:
        return np.full(len(p), np.inf)
    if segs.shape[2] != p.shape[1]:
        raise ValueError(f"points are {p.shape[1]}-D but segments are {segs.shape[2]}-D")
    a = segs[:, 0]
    ab = segs[:, 1] - a
    len2 = np.einsum("sd,sd->s", ab, ab)
    # Degenerate segments project everything onto their first endpoint (t = 0), without dividing by 0.
    inv_len2 = np.divide(1.0, len2, out=np.zeros_like(len2), where=len2 > 0)
    out = np.empty(len(p))
    chunk = max(1, _BLOCK // len(segs))
    for lo in range(0, len(p), chunk):
        ap = p[lo : lo + chunk, None, :] - a[None]  # (c, s, d)
        t = np.clip(np.einsum("csd,sd->cs", ap, ab) * inv_len2, 0.0, 1.0)
        off = ap - t[..., None] * ab[None]
        out[lo : lo + chunk] = np.sqrt(np.einsum("csd,csd->cs", off, off).min(axis=1))
    return out


def corner_errors(vertices, corners) -> np.ndarray:
    """Distance from each true corner to the nearest output vertex.

    Args:
      vertices: ``(k, d)`` output vertices.
      corners: ``(c, d)`` true corners (or any feature points: ends, junctions).

    Returns:
      ``(c,)`` float64; ``inf`` for every corner when there are no vertices.

    Example:
      >>> corner_errors([[0.0, 0.0], [1.0, 0.1]], [[1.0, 0.0]])
      array([0.1])
    """
    corners = np.asarray(corners, dtype=np.float64)
    vertices = np.asarray(vertices, dtype=np.float64)
    if corners.size == 0:
        return np.zeros(0)
    corners = _as_points(corners, "corners")
    if vertices.size == 0:
        return np.full(len(corners), np.inf)
    vertices = _as_points(vertices, "vertices")
    # A vertex is a degenerate segment: reuse the blocked distance.
    return point_segment_distance(corners, np.stack([vertices, vertices], axis=1))


def sample_segments(segs, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Points along segments, at most ``step`` apart, with arc-length weights.

    Each segment of length ``L`` is cut into ``k = max(1, ceil(L / step))``
    equal pieces and represented by their midpoints, each weighing ``L / k``.
    So every point of the segments is within ``step / 2`` of a sample, and the
    weights of one segment sum to its length exactly.

    Args:
      segs: ``(s, 2, d)`` segments.
      step: positive spacing.

    Returns:
      ``points (N, d)`` and ``weights (N,)``; a degenerate segment gives one
      sample (its endpoint) of weight 0.

    Example:
      >>> pts, w = sample_segments([[[0.0, 0.0], [1.0, 0.0]]], 0.5)
      >>> pts[:, 0], w
      (array([0.25, 0.75]), array([0.5, 0.5]))
    """
    segs = _as_segments(segs, "segs")
    if not step > 0:
        raise ValueError(f"step must be > 0, got {step}")
    length = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    k = np.maximum(1, np.ceil(length / step)).astype(np.int64)
    owner = np.repeat(np.arange(len(segs)), k)
    # Index of each piece within its segment: 0..k-1, built without a Python loop.
    first = np.cumsum(k) - k
    piece = np.arange(k.sum()) - np.repeat(first, k)
    t = ((piece + 0.5) / k[owner])[:, None]
    points = segs[owner, 0] * (1 - t) + segs[owner, 1] * t
    return points, (length / k)[owner]


def _default_step(*segment_sets: np.ndarray) -> float:
    """``1e-3`` times the diagonal of the bounding box of all the segments."""
    allpts = np.concatenate([s.reshape(-1, s.shape[-1]) for s in segment_sets])
    diag = float(np.linalg.norm(allpts.max(0) - allpts.min(0))) if len(allpts) else 0.0
    # All segments collapsed to one point: every length is 0, any positive step samples them exactly.
    return 1e-3 * diag if diag > 0 else 1.0


def hausdorff(segs_a, segs_b, step: float | None = None) -> float:
    """Symmetric Hausdorff distance between two segment sets.

    Each side is sampled with :func:`sample_segments` and the exact distance
    from every sample to the other side is taken. The distance to a set is
    1-Lipschitz and every point is within ``step / 2`` of a sample, so the
    result ``h`` satisfies ``H - step / 2 <= h <= H`` for the true distance ``H``.

    Args:
      segs_a: ``(s, 2, d)`` segments.
      segs_b: ``(t, 2, d)`` segments.
      step: sampling step; default ``1e-3`` times the diagonal of the bounding
        box of both sets together.

    Returns:
      The distance as a float; ``0.0`` if both sets are empty, ``inf`` if only one is.

    Example:
      >>> hausdorff([[[0, 0], [1, 0]]], [[[0, 0.5], [1, 0.5]]])
      0.5
    """
    a = _as_segments(segs_a, "segs_a")
    b = _as_segments(segs_b, "segs_b")
    if len(a) == 0 or len(b) == 0:
        return 0.0 if len(a) == len(b) else float("inf")
    step = _default_step(a, b) if step is None else step
    pa, _ = sample_segments(a, step)
    pb, _ = sample_segments(b, step)
    return float(max(point_segment_distance(pa, b).max(), point_segment_distance(pb, a).max()))


def length_within(segs_a, segs_b, tol: float, step: float | None = None) -> float:
    """Fraction of the length of A that lies within ``tol`` of B.

    With A the truth and B the output edges this is a recall; swapped, a precision.
    A is sampled with :func:`sample_segments`; each sample's piece counts as
    within when its midpoint is. Each place where A enters or leaves the
    ``tol``-neighbourhood of B can thus misplace at most ``step / 2`` of length.

    Args:
      segs_a: ``(s, 2, d)`` segments whose length is measured.
      segs_b: ``(t, 2, d)`` reference segments.
      tol: distance threshold (inclusive), ``>= 0``.
      step: sampling step; default as in :func:`hausdorff`.

    Returns:
      A float in ``[0, 1]``; ``0.0`` when A has no length.

    Example:
      >>> round(length_within([[[0, 0], [2, 0]]], [[[1, -1], [1, 1]]], tol=0.5), 6)
      0.5
    """
    a = _as_segments(segs_a, "segs_a")
    b = _as_segments(segs_b, "segs_b")
    if not tol >= 0:
        raise ValueError(f"tol must be >= 0, got {tol}")
    if len(a) == 0:
        return 0.0
    step = _default_step(a, b) if step is None else step
    pts, w = sample_segments(a, step)
    total = w.sum()
    if total == 0:
        return 0.0
    return float(w[point_segment_distance(pts, b) <= tol].sum() / total)


def edges_to_segments(vertices, edges) -> np.ndarray:
    """The segments ``(m, 2, d)`` of a graph given by vertices and index pairs.

    Args:
      vertices: ``(k, d)`` positions.
      edges: ``(m, 2)`` integer indices into ``vertices``.

    Example:
      >>> edges_to_segments([[0, 0], [1, 0], [1, 1]], [[0, 1], [1, 2]]).shape
      (2, 2, 2)
    """
    vertices = _as_points(vertices, "vertices")
    edges = np.asarray(edges)
    if edges.size == 0:
        return np.zeros((0, 2, vertices.shape[1]))
    if edges.ndim != 2 or edges.shape[1] != 2 or not np.issubdtype(edges.dtype, np.integer):
        raise ValueError(f"edges must be an (m, 2) integer array, got {edges.dtype} {edges.shape}")
    if edges.min() < 0 or edges.max() >= len(vertices):
        raise ValueError(f"edge indices must lie in [0, {len(vertices)}), got [{edges.min()}, {edges.max()}]")
    return vertices[edges]
