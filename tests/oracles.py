"""Plain-Python reference implementations (slow, loop-based, obviously correct).

Written from de Goes et al. 2011, Sec. 2.2-2.3, independently of the JAX
kernels in :mod:`otjax.curves.cost`. All costs are squared W2 costs.
"""

from __future__ import annotations

import math


def oracle_segment_sqdist(p, a, b) -> float:
    """Squared distance from point ``p`` to segment ``[a, b]`` (2-sequences).

    Endpoint regions are decided by signs of dot products and the interior
    distance is ``cross^2 / |b - a|^2``: the rounding convention the kernels
    share, so that exact ties (lattice data) are ties here too.
    """
    dx, dy = b[0] - a[0], b[1] - a[1]
    if (p[0] - a[0]) * dx + (p[1] - a[1]) * dy <= 0:
        return (p[0] - a[0]) ** 2 + (p[1] - a[1]) ** 2
    if (p[0] - b[0]) * dx + (p[1] - b[1]) * dy >= 0:
        return (p[0] - b[0]) ** 2 + (p[1] - b[1]) ** 2
    cross = dx * (p[1] - a[1]) - dy * (p[0] - a[0])
    return cross**2 / (dx * dx + dy * dy)


def oracle_edge_cost(a, b, pts, masses) -> tuple[float, float, float]:
    """Costs of the points ``pts`` (masses ``masses``) assigned to edge ``[a, b]``.

    Returns:
      ``(N, T, V)``: normal (Eq. 3) and tangential (Eq. 4) cost of keeping the
      points on the edge, and cost of sending each to its nearer endpoint
      (Eq. 2). ``N = T = 0`` on a zero-length edge.
    """
    a = [float(a[0]), float(a[1])]
    b = [float(b[0]), float(b[1])]
    pts = [[float(p[0]), float(p[1])] for p in pts]
    masses = [float(m) for m in masses]
    total = sum(masses)
    vertex = 0.0
    for p, m in zip(pts, masses):
        da = (p[0] - a[0]) ** 2 + (p[1] - a[1]) ** 2
        db = (p[0] - b[0]) ** 2 + (p[1] - b[1]) ** 2
        vertex += m * min(da, db)
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    if length == 0 or total == 0:
        return 0.0, 0.0, vertex
    ux, uy = (b[0] - a[0]) / length, (b[1] - a[1]) / length

    normal = 0.0
    projected = []  # (coordinate along the supporting line, mass)
    for p, m in zip(pts, masses):
        rx, ry = p[0] - a[0], p[1] - a[1]
        along = rx * ux + ry * uy
        foot = (a[0] + along * ux, a[1] + along * uy)  # projection on the line
        normal += m * ((p[0] - foot[0]) ** 2 + (p[1] - foot[1]) ** 2)
        projected.append((along, m))

    # Bins of length L m_i / M_e laid end to end in the order of the projections.
    tangential = 0.0
    bin_start = 0.0
    for along, m in sorted(projected, key=lambda q: q[0]):
        bin_len = length * m / total
        centre = bin_start + bin_len / 2
        tangential += m * (bin_len**2 / 12 + (along - centre) ** 2)
        bin_start += bin_len
    return normal, tangential, vertex


def oracle_stencil_cost(edges, edge_mask, points, mass, point_mask, cand) -> dict:
    """Transport cost of ONE unbatched (possibly padded) stencil.

    Each real point goes to the nearest of its candidate edges (exact ties: the
    earliest entry); each edge then keeps its points (solid) if that is
    strictly cheaper than sending them to the endpoints, else it is a ghost.

    Returns:
      dict with ``total``, and per edge ``edge_cost``, ``normal``,
      ``tangential``, ``vertex``, ``edge_mass``, ``solid``; ``assignment`` per
      point (``-1`` for padding).
    """
    n_edges, n_points = len(edge_mask), len(point_mask)
    assignment = [-1] * n_points
    for i in range(n_points):
        if not point_mask[i]:
            continue
        best, best_d = None, math.inf
        for e in cand[i]:
            d = oracle_segment_sqdist(points[i], edges[e][0], edges[e][1])
            if d < best_d:
                best, best_d = int(e), d
        assignment[i] = best

    out = {k: [0.0] * n_edges for k in ("edge_cost", "normal", "tangential", "vertex", "edge_mass")}
    out["solid"] = [False] * n_edges
    for e in range(n_edges):
        if not edge_mask[e]:
            continue
        mine = [i for i in range(n_points) if assignment[i] == e]
        pts = [points[i] for i in mine]
        ms = [float(mass[i]) for i in mine]
        n, t, v = oracle_edge_cost(edges[e][0], edges[e][1], pts, ms)
        length = math.hypot(edges[e][1][0] - edges[e][0][0], edges[e][1][1] - edges[e][0][1])
        solid = sum(ms) > 0 and length > 0 and n + t < v
        out["normal"][e], out["tangential"][e], out["vertex"][e] = n, t, v
        out["edge_mass"][e] = sum(ms)
        out["solid"][e] = solid
        out["edge_cost"][e] = n + t if solid else v
    out["total"] = sum(out["edge_cost"])
    out["assignment"] = assignment
    return out
