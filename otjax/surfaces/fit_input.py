"""What the fitting steps of a finished complex share: their checked input
(:func:`checked`), unit facet normals, each vertex's facets and the guard
against flattened triangles (:func:`without_flattening`)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.background import NOISE_NEIGHBOURS, flat_noise
from otjax.surfaces.relocation import MIN_ASPECT, aspect
from otjax.surfaces.star_plan import face_normals

#: An edge a fit shortens to less than this fraction of its length closes:
#: one of the moves is undone (docs/decisions.md#feature_fit).
CLOSED = 0.1


def checked(vertices, triangles, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(vertices (V, 3) float64, triangles (T, 3) int64, points (n, 3) float64)``.

    Raises:
      ValueError: arrays of the wrong shape, non-finite values, indices out of range.
    """
    vertices = np.asarray(vertices, np.float64)
    points = np.asarray(points, np.float64)
    triangles = np.asarray(triangles)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.isfinite(vertices).all():
        raise ValueError(f"vertices must be a finite (V, 3) array, got shape {vertices.shape}")
    if points.ndim != 2 or points.shape[1] != 3 or not np.isfinite(points).all():
        raise ValueError(f"points must be a finite (n, 3) array, got shape {points.shape}")
    if len(triangles) == 0:
        triangles = np.zeros((0, 3), np.int64)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
        raise ValueError(f"triangles must be an integer (T, 3) array, got shape {triangles.shape}")
    if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(vertices)):
        raise ValueError(f"triangles index vertices 0..{len(vertices) - 1}, got {triangles.min()}..{triangles.max()}")
    return vertices, triangles.astype(np.int64), points


def unit_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """``(T, 3)`` unit normals of ``triangles``; zero rows for degenerate ones."""
    normal = face_normals(vertices[triangles])
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)


def vertex_facets(triangles: np.ndarray) -> dict[int, list[int]]:
    """Each vertex's rows of ``triangles``, increasing (vertices of none absent)."""
    facets: dict[int, list[int]] = {}
    for f, row in enumerate(triangles.tolist()):
        for v in row:
            facets.setdefault(v, []).append(f)
    return facets


def points_noise(points: np.ndarray, noise: float | None = None) -> float:
    """``noise`` if given, else the points' standard deviation about their
    surface (:func:`otjax.background.flat_noise`; 0 for too few points)."""
    if noise is not None:
        return float(noise)
    return flat_noise(points) if len(points) > NOISE_NEIGHBOURS else 0.0


class VertexFit(NamedTuple):
    """What a fit of a complex's vertices to the points returns
    (:func:`~otjax.surfaces.crease_fit.fit_creases`, :func:`~otjax.surfaces.border_fit.fit_border`).

    Attributes:
      vertices: ``(V, 3)`` float64 the positions after the fit.
      moved: ``(m,)`` int64 rows of ``vertices`` that moved, increasing.
    """

    vertices: np.ndarray
    moved: np.ndarray


def without_flattening(before: np.ndarray, after: np.ndarray, triangles: np.ndarray,
                       moved: np.ndarray) -> VertexFit:
    """``after`` and ``moved`` with the fewest moves undone that flatten a
    triangle or close one of its edges.

    A triangle flatter than :data:`~otjax.surfaces.relocation.MIN_ASPECT`
    at the ``after`` positions and flatter than at ``before`` (``(V, 3)``
    each) puts back the one of its ``moved`` vertices that moved least
    (several vertices of one triangle can each move well and flatten it
    together, as three on one crease line would); an edge shortened to less
    than :data:`CLOSED` times its length puts back the one of its moved ends
    that moved least (two vertices sent to one crease end would make it
    twice). Repeated until none does.
    """
    after, moved = after.copy(), np.asarray(moved, np.int64)
    old = aspect(before[triangles])
    edges = np.unique(np.sort(triangles[:, [[0, 1], [1, 2], [0, 2]]].reshape(-1, 2), axis=1), axis=0)
    old_length = np.linalg.norm(np.diff(before[edges], axis=1)[:, 0], axis=1)
    step = np.linalg.norm(after - before, axis=1)
    while len(moved):
        new = aspect(after[triangles])
        closed = np.linalg.norm(np.diff(after[edges], axis=1)[:, 0], axis=1) < CLOSED * old_length
        groups = [row for row in triangles[(new < MIN_ASPECT) & (new < old)]] + list(edges[closed])
        back = []
        for row in groups:
            mine = row[np.isin(row, moved)]
            if len(mine):
                back.append(mine[np.argmin(step[mine])])
        if not back:
            break
        back = np.unique(back)
        after[back] = before[back]
        moved = np.setdiff1d(moved, back)
    return VertexFit(after, moved)
