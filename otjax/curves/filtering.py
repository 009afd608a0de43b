"""Filters on the solid edges of a finished reconstruction, beyond relevance.

Two tests, both decided by the data:

* :func:`above_background`: where the input holds uniform background noise
  (:mod:`otjax.background`), an edge is kept only if the band around it
  holds significantly more mass than that background puts there; likewise
  an isolated vertex and the disc around it. Without background every edge
  passes.
* :func:`redundant_edges`: noise can leave a thin triangle of solid edges
  where the shape has a single corner or a single line (one edge of the
  3-cycle carries points that the two others would hold almost as well),
  or a spur: a short edge from a junction to a free end, a few degrees off
  a branch that carries the same points. Such an edge is dropped when its
  points lie, on average, within a few noise widths of the other kept
  edges (docs/decisions.md#redundant_edges). A true triangle of the shape
  keeps its three edges and a true branch its edge: their points are far
  from the other edges.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from otjax.background import Background

# Kept when the band's mass is above BAND_RATIO x the background's expectation
# plus BAND_SIGMAS Poisson deviations of it.
BAND_RATIO = 2.0
BAND_SIGMAS = 3.0
# Band half-width in noise widths (the mass-weighted median RMS normal distance of the edges).
BAND_WIDTHS = 2.0
# A chord goes when its points' mean squared distance to the other edges is
# within this many times the mean squared distance of all kept points to their own edge.
CHORD_FACTOR = 8.0


def segment_sqdist(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(n,)`` squared distances of points ``p (n, 2)`` to the segment ``[a, b]``.

    Each row's value depends on that row alone (no BLAS product, whose
    rounding can depend on the row's place in the array), so a subset of
    the points gets bitwise the distances the whole array gets."""
    d = b - a
    dd = float(d @ d)
    along = (p[:, 0] - a[0]) * d[0] + (p[:, 1] - a[1]) * d[1]
    t = np.clip(along / dd, 0.0, 1.0) if dd > 0 else np.zeros(len(p))
    q = a + t[:, None] * d
    return ((p - q) ** 2).sum(1)


def noise_width(normal: np.ndarray, mass: np.ndarray) -> float:
    """Mass-weighted median over edges of the RMS normal distance ``sqrt(N_e / M_e)``."""
    ok = mass > 0
    if not ok.any():
        return 0.0
    rms = np.sqrt(normal[ok] / mass[ok])
    order = np.argsort(rms)
    cum = np.cumsum(mass[ok][order])
    return float(rms[order][np.searchsorted(cum, 0.5 * cum[-1])])


def above_background(segments: np.ndarray, isolated: np.ndarray, points: np.ndarray, mass: np.ndarray,
                     background: Background, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Which edges and isolated vertices stand out of the background noise.

    Args:
      segments: ``(m, 2, 2)`` kept edges' endpoints.
      isolated: ``(k, 2)`` isolated vertices.
      points, mass: ``(n, 2)``, ``(n,)`` the input points and their masses.
      background: its :class:`~otjax.background.Background` estimate.
      width: half-width of the band around an edge (radius of the disc
        around a vertex), input units.

    Returns:
      ``(edge_kept (m,), vertex_kept (k,))`` bool; all True when no
      background was found.
    """
    edge_kept = np.ones(len(segments), bool)
    vertex_kept = np.ones(len(isolated), bool)
    if not background.found or not width > 0:
        return edge_kept, vertex_kept
    unit = float(mass.mean())  # the background is counted in points, the bands in mass
    tree = cKDTree(points)

    def significant(band_mass: float, area: float) -> bool:
        expected = background.density * area * unit
        return band_mass > BAND_RATIO * expected + BAND_SIGMAS * np.sqrt(expected * unit)

    for i, (a, b) in enumerate(segments):
        length = float(np.linalg.norm(b - a))
        near = np.asarray(tree.query_ball_point(0.5 * (a + b), 0.5 * length + width), np.int64)
        inside = near[segment_sqdist(points[near], a, b) <= width**2] if len(near) else near
        edge_kept[i] = significant(float(mass[inside].sum()), 2 * width * length + np.pi * width**2)
    for i, v in enumerate(isolated):
        near = np.asarray(tree.query_ball_point(v, width), np.int64)
        vertex_kept[i] = significant(float(mass[near].sum()), np.pi * width**2)
    return edge_kept, vertex_kept


def _triangles(keys: list[tuple[int, int]]) -> list[tuple[int, int, int]]:
    """3-cycles of the graph ``keys`` (each once, as indices into ``keys``)."""
    index = {k: i for i, k in enumerate(keys)}
    nbr: dict[int, set] = {}
    for a, b in keys:
        nbr.setdefault(a, set()).add(b)
        nbr.setdefault(b, set()).add(a)
    out = []
    for a, b in keys:
        for c in sorted(nbr[a] & nbr[b]):
            if c > max(a, b):
                out.append((index[(a, b)], index[tuple(sorted((a, c)))], index[tuple(sorted((b, c)))]))
    return out


def _spurs(keys: list[tuple[int, int]], xy: np.ndarray) -> list[int]:
    """Spurs of the graph ``keys`` (as indices into ``keys``): edges from a
    junction (a vertex of degree 3 or more) to a free end (degree 1) that
    is nearer the junction than any other vertex of the graph. A free end
    near another vertex closes, all but one edge, a thin triangle at a
    corner of the shape, and marks that corner."""
    degree: dict[int, int] = {}
    for a, b in keys:
        degree[a] = degree.get(a, 0) + 1
        degree[b] = degree.get(b, 0) + 1
    ids = np.array(sorted(degree))
    out = []
    for i, (a, b) in enumerate(keys):
        end, junction = (a, b) if degree[a] == 1 else (b, a)
        if degree[end] != 1 or degree[junction] < 3:
            continue
        d2 = ((xy[ids] - xy[end]) ** 2).sum(1)
        d2[ids == end] = np.inf
        if ids[np.argmin(d2)] == junction:
            out.append(i)
    return out


def redundant_edges(keys: list[tuple[int, int]], xy: np.ndarray, edge_points: list[np.ndarray],
                    points: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Which kept edges survive the removal of redundant chords and spurs.

    The candidates are the edges of 3-cycles and the spurs (an edge from a
    junction, of degree 3 or more, to a free end nearer the junction than
    any other vertex). A candidate is redundant when its points lie, on
    average, within a few noise widths of the other kept edges.

    Args:
      keys: ``m`` kept edges as ``(u, v)`` vertex ids into ``xy``.
      xy: ``(V, 2)`` vertex positions.
      edge_points: per edge, the ids of the points it carries.
      points, mass: ``(n, 2)``, ``(n,)`` the points and the masses transported.

    Returns:
      ``(m,)`` bool, False for the dropped edges. One edge goes at a time,
      the most redundant first, until no candidate is redundant.
    """
    kept = np.ones(len(keys), bool)
    seg = np.array([[xy[a], xy[b]] for a, b in keys]).reshape(-1, 2, 2)
    own = [segment_sqdist(points[ids], *seg[i]) for i, ids in enumerate(edge_points)]
    weight = [mass[ids] for ids in edge_points]
    total = sum(float(w.sum()) for w in weight)
    if not total > 0:
        return kept
    noise2 = sum(float(w @ d) for w, d in zip(weight, own)) / total
    # Per candidate, its points' squared distance to the nearest other
    # kept edge and which edge that is. Edges only go, so a dropped edge
    # changes the rows whose nearest it was and nothing else.
    nearest: dict[int, _Nearest] = {}
    while True:
        alive = [int(i) for i in np.flatnonzero(kept)]
        live_keys = [keys[i] for i in alive]
        candidates = {alive[j] for cyc in _triangles(live_keys) for j in cyc}
        candidates |= {alive[j] for j in _spurs(live_keys, xy)}
        if not candidates:
            return kept
        best, best_score = -1, np.inf
        for e in sorted(candidates):
            w = weight[e]
            if not w.sum() > 0:
                score = 0.0
            else:
                if e not in nearest:
                    nearest[e] = _nearest_other(points[edge_points[e]], seg, e, alive)
                score = float(w @ nearest[e].d2) / float(w.sum())
            if score < best_score:
                best, best_score = e, score
        if best_score > CHORD_FACTOR * noise2:
            return kept
        kept[best] = False
        alive.remove(best)
        nearest.pop(best, None)
        for e, near in nearest.items():
            stale = np.flatnonzero(near.edge == best)
            if len(stale):
                fresh = _nearest_other(points[edge_points[e][stale]], seg, e, alive)
                near.d2[stale], near.edge[stale] = fresh.d2, fresh.edge


class _Nearest(NamedTuple):
    """Per point: squared distance to the nearest other kept edge, and that edge."""

    d2: np.ndarray
    edge: np.ndarray


def _nearest_other(p: np.ndarray, seg: np.ndarray, e: int, alive: list[int]) -> _Nearest:
    """:class:`_Nearest` of the points ``p`` among the ``alive`` edges but ``e``."""
    others = [i for i in alive if i != e]
    if not others:
        return _Nearest(np.full(len(p), np.inf), np.full(len(p), -1, np.int64))
    d2 = np.array([segment_sqdist(p, *seg[i]) for i in others]).reshape(len(others), len(p))
    k = d2.argmin(0)
    return _Nearest(d2[k, np.arange(len(p))], np.asarray(others, np.int64)[k])
