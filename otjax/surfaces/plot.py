"""A matplotlib 3D view of a surface complex, for notebooks and pictures.

:func:`plot_complex` draws, on a 3D ``Axes``: input points (grey), facets
coloured by mass density, dangling edges, isolated vertices, optional plan
segments from each point to where its mass goes (a vertex: red, a facet
bin: green, as in the paper's figures) and optional highlighted edges.
Nothing here touches pyplot's global state unless no axes are given.
"""

from __future__ import annotations

import numpy as np


def plan_segments(plan) -> tuple[np.ndarray, np.ndarray]:
    """The entries of a transport plan as segments.

    Args:
      plan: a :class:`otjax.surfaces.plan.SurfacePlan` (read only).

    Returns:
      ``segments (S, 2, 3)`` from each point to the bin it sends mass to
      (one per plan entry) and ``to_vertex (S,)`` bool, True for vertex bins;
      vertices first, then facets, each in key order.
    """
    parts, kinds = [np.zeros((0, 2, 3))], [np.zeros(0, bool)]
    for v in sorted(plan.vertex_entries):
        e = plan.vertex_entries[v]
        target = np.broadcast_to(plan.complex.positions[v], (len(e.point), 3))
        parts.append(np.stack([plan.points[e.point], target], 1))
        kinds.append(np.ones(len(e.point), bool))
    for t in sorted(plan.facet_entries):
        e = plan.facet_entries[t]
        parts.append(np.stack([plan.points[e.point], plan.bin_positions(t)[e.bin]], 1))
        kinds.append(np.zeros(len(e.point), bool))
    return np.concatenate(parts), np.concatenate(kinds)


def _thin(n: int, most: int) -> np.ndarray:
    """Indices of at most ``most`` of ``n`` items, evenly spread (deterministic)."""
    return np.arange(n) if n <= most else np.unique(np.linspace(0, n - 1, most).round().astype(np.int64))


def plot_complex(vertices, triangles, edges=None, isolated=None, *, density=None, points=None, plan=None,
                 segments=None, highlight=None, ax=None, cmap: str = "viridis", max_segments: int = 3000):
    """Draws a complex on 3D axes.

    Args:
      vertices: ``(V, 3)``; triangles: ``(T, 3)``; edges: ``(E, 2)`` dangling
        edges or ``None``; isolated: ``(I,)`` or ``None``.
      density: ``(T,)`` facet colours (mass density), or ``None`` (one colour).
      points: ``(n, 3)`` input points, or ``None``.
      plan: a :class:`~otjax.surfaces.plan.SurfacePlan` whose entries are drawn
        as segments (:func:`plan_segments`), or ``None``.
      segments: ``(S, 2, 3)`` segments to draw instead of a plan's, or ``None``.
      highlight: ``(H, 2)`` edges drawn thick in red (creases, boundaries), or ``None``.
      ax: 3D axes to draw on; ``None`` makes a new pyplot figure (shows in notebooks).
      cmap: colour map of the densities.
      max_segments: at most this many plan segments are drawn, evenly spread.

    Returns:
      The axes.

    Example:
      >>> ax = plot_complex(np.eye(3), [[0, 1, 2]], density=[1.0])  # doctest: +SKIP
    """
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    if ax is None:
        import matplotlib.pyplot as plt

        ax = plt.figure(figsize=(6, 6)).add_subplot(projection="3d")
    vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    drawn = [vertices]
    if points is not None and len(points):
        points = np.asarray(points, np.float64).reshape(-1, 3)
        ax.scatter(*points.T, s=2, c="0.6", linewidths=0, depthshade=False, label="input points")
        drawn.append(points)
    if len(triangles):
        if density is not None and len(density):
            density = np.asarray(density, np.float64)
            colours = colormaps[cmap](Normalize(0.0, float(density.max()) or 1.0)(density))
        else:
            colours = "tab:blue"
        ax.add_collection3d(Poly3DCollection(vertices[triangles], facecolors=colours, edgecolors="0.2",
                                             linewidths=0.3, alpha=0.85, label="facets"))
    if segments is None and plan is not None:
        segments, to_vertex = plan_segments(plan)
    else:
        to_vertex = None
    if segments is not None and len(segments):
        keep = _thin(len(segments), max_segments)
        colour = "tab:green" if to_vertex is None else np.where(to_vertex[keep, None], [[0.84, 0.15, 0.16, 1]],
                                                                [[0.17, 0.63, 0.17, 1]])
        ax.add_collection3d(Line3DCollection(np.asarray(segments)[keep], colors=colour, linewidths=0.4,
                                             label="transport plan"))
    for rows, style in ((edges, {"colors": "0.1", "linewidths": 1.2, "label": "edges"}),
                        (highlight, {"colors": "tab:red", "linewidths": 2.5, "label": "highlighted edges"})):
        if rows is not None and len(rows):
            ax.add_collection3d(Line3DCollection(vertices[np.asarray(rows, np.int64).reshape(-1, 2)], **style))
    if isolated is not None and len(isolated):
        ax.scatter(*vertices[np.asarray(isolated, np.int64)].T, s=20, marker="s", c="tab:red", label="isolated")
    everything = np.concatenate(drawn)
    if len(everything):
        lo, hi = everything.min(0), everything.max(0)
        pad = 0.02 * float(np.max(hi - lo)) or 1.0
        for k, setter in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
            setter(lo[k] - pad, hi[k] + pad)
        ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * float(np.max(hi - lo)) or 1.0))
    return ax
