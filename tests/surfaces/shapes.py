"""Surfaces with known geometry and the distances that judge a complex against them.

Samplers return noise-free points on a cube's surface, an open square patch
and two planes crossing at a line; each shape also gives the exact distance
from any point to its surface, so a kept facet's distance to the truth is
measured, not estimated. The distance from the truth to the facets is exact
too (point-to-triangle, brute force in chunks): coverage is the share of a
dense uniform sample of the true surface within a given distance of a facet.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np


class Shape(NamedTuple):
    """A sampler ``sample(n, rng) -> (n, 3)`` uniform on the surface by area,
    and ``distance(x) -> (m,)``, the exact distance of points ``(m, 3)`` to it."""

    sample: Callable[[int, np.random.Generator], np.ndarray]
    distance: Callable[[np.ndarray], np.ndarray]


def _cube_sample(n, rng):
    face = rng.integers(0, 6, n)
    uv = rng.random((n, 2))
    axis, side = face // 2, (face % 2).astype(float)
    out = np.empty((n, 3))
    for a in range(3):
        others = [b for b in range(3) if b != a]
        sel = axis == a
        out[sel, a] = side[sel]
        out[np.ix_(sel, others)] = uv[sel]
    return out


def _cube_distance(x):
    outside = np.linalg.norm(np.maximum(np.maximum(-x, x - 1.0), 0.0), axis=1)
    inside = np.minimum(x, 1.0 - x).min(axis=1)
    return np.where(np.all((x >= 0) & (x <= 1), axis=1), inside, outside)


def _square_sample(n, rng):
    return np.c_[rng.random((n, 2)), np.full(n, 0.5)]


def _square_distance(x):
    return np.linalg.norm(np.c_[np.maximum(np.maximum(-x[:, :2], x[:, :2] - 1.0), 0.0), x[:, 2] - 0.5], axis=1)


def _cross_sample(n, rng):
    h = n // 2
    a, b = rng.random((h, 2)), rng.random((n - h, 2))
    return np.r_[np.c_[a[:, 0], a[:, 1], np.full(h, 0.5)], np.c_[b[:, 0], np.full(n - h, 0.5), b[:, 1]]]


def _cross_distance(x):
    on_z = np.linalg.norm(np.c_[np.maximum(np.maximum(-x[:, :2], x[:, :2] - 1.0), 0.0), x[:, 2] - 0.5], axis=1)
    xz = x[:, [0, 2]]
    on_y = np.linalg.norm(np.c_[np.maximum(np.maximum(-xz, xz - 1.0), 0.0), x[:, 1] - 0.5], axis=1)
    return np.minimum(on_z, on_y)


#: The unit cube's surface (a closed surface with sharp edges).
CUBE = Shape(_cube_sample, _cube_distance)
#: The unit square at z = 0.5 (an open patch: its boundary must be kept).
SQUARE = Shape(_square_sample, _square_distance)
#: The unit squares at z = 0.5 and y = 0.5 (two planes crossing at a line).
CROSS = Shape(_cross_sample, _cross_distance)


def diagonal(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0)))


def triangle_samples(vertices: np.ndarray, triangles: np.ndarray, spacing: float) -> np.ndarray:
    """Points on every triangle: its corners, edge midpoints and a barycentric
    grid fine enough that no point of the triangle is farther than about
    ``spacing`` from a sample."""
    v = vertices[triangles]
    longest = np.max(np.linalg.norm(v - np.roll(v, 1, axis=1), axis=2), axis=1)
    out = [v.reshape(-1, 3)]
    for n in np.unique(np.maximum(1, np.ceil(longest / spacing)).astype(int)):
        tri = v[np.ceil(longest / spacing).clip(1).astype(int) == n]
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        w = np.c_[i[keep], j[keep]] / n
        out.append((tri[:, None, 0] + w[None, :, :1] * (tri[:, None, 1] - tri[:, None, 0])
                    + w[None, :, 1:] * (tri[:, None, 2] - tri[:, None, 0])).reshape(-1, 3))
    return np.concatenate(out)


def point_triangle_distance(x: np.ndarray, tri: np.ndarray, chunk: int = 1 << 22) -> np.ndarray:
    """``(m,)`` exact distance of each point ``(m, 3)`` to the nearest of the
    triangles ``(t, 3, 3)``: the closest point on each triangle (interior,
    edge or corner), brute force over pairs in chunks."""
    out = np.full(len(x), np.inf)
    if len(tri) == 0:
        return out
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    step = max(1, chunk // len(tri))
    for lo in range(0, len(x), step):
        p = x[lo:lo + step, None, :]
        best = np.minimum(np.minimum(_segment(p, a, b), _segment(p, b, c)), _segment(p, c, a))
        n = np.cross(b - a, c - a)
        nn = np.einsum("td,td->t", n, n)
        ok = nn > 0
        n_unit = n / np.sqrt(np.where(ok, nn, 1.0))[:, None]
        h = np.einsum("ptd,td->pt", p - a, n_unit)
        q = p - h[..., None] * n_unit
        inside = ok
        for u, v in ((a, b), (b, c), (c, a)):
            inside = inside & (np.einsum("ptd,td->pt", np.cross(v - u, q - u), n) >= 0)
        best = np.where(inside, np.minimum(best, np.abs(h)), best)
        out[lo:lo + step] = best.min(axis=1)
    return out


def _segment(p, u, v):
    d = v - u
    dd = np.einsum("td,td->t", d, d)
    t = np.clip(np.einsum("ptd,td->pt", p - u, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (u + t[..., None] * d), axis=2)


class Fit(NamedTuple):
    """How kept facets match a known surface (distances in units of ``D``).

    Attributes:
      coverage: share of the surface's area within ``within`` of a facet.
      to_surface: largest distance of a facet point to the surface.
      chamfer: symmetric Chamfer distance (mean of both one-sided means).
      hausdorff: the larger one-sided maximum.
    """

    coverage: float
    to_surface: float
    chamfer: float
    hausdorff: float


def fit(shape: Shape, vertices: np.ndarray, triangles: np.ndarray, d: float, within: float = 0.01,
        samples: int = 20000, seed: int = 0) -> Fit:
    """Measures triangles ``(T, 3)`` over ``vertices`` against ``shape``
    (``d``: the diagonal distances are divided by)."""
    truth = shape.sample(samples, np.random.default_rng(seed))
    tri = vertices[triangles]
    from_truth = point_triangle_distance(truth, tri) / d
    on_facets = triangle_samples(vertices, triangles, 0.002 * d)
    from_facets = shape.distance(on_facets) / d if len(on_facets) else np.zeros(1)
    return Fit(float(np.mean(from_truth <= within)), float(from_facets.max()),
               float(0.5 * (from_truth.mean() + from_facets.mean())),
               float(max(from_truth.max(), from_facets.max())))
