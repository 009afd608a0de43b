"""Vertex relocation: the closed form of de Goes et al. 2011 §3.3.

It only proposes positions; :meth:`otjax.curves.engine.CurveEngine.relocate`
applies a move only when it keeps the triangulation embedded (the new
position is inside the kernel of the one-ring) and lowers the exact
transport cost computed by the batched kernel after reassigning the points
of the star. The paper moves unconditionally (inside the kernel); otjax also
asks for a decrease, because the closed form minimises only the normal part
for a frozen assignment and can, rarely, raise the total.
"""

from __future__ import annotations

import numpy as np

from otjax.curves.plan import TransportPlan


def optimal_position(plan: TransportPlan, v: int) -> np.ndarray | None:
    """Closed-form position of ``v`` minimising the normal part of its cost.

    With the assignment frozen, the points sent to ``v`` itself (``S_v``, from
    its ghost edges) and those on its solid edges ``(v, b)`` (``S_(v,b)``,
    with ``q_i = (1 - l_i) v + l_i b`` the projection on the supporting line)
    give the quadratic ``sum_Sv m |p - v|^2 + sum m |p - q|^2``, minimised by::

        v* = (sum_Sv m p + sum m (1 - l)(p - l b)) / (M_v + sum m (1 - l)^2)

    Args:
      plan: current transport plan.
      v: an interior (non-pinned, live) vertex.

    Returns:
      ``(2,)`` position, or ``None`` if no point is transported to ``v``'s
      edges or to ``v`` (nothing pins it down).
    """
    tri = plan.tri
    _, star = tri.star(v)
    ids = np.concatenate([plan.face_pts[f] for f in star])
    if not len(ids):
        return None
    keys = np.take(plan.pt_edge, ids, axis=0)
    touch = (keys[:, 0] == v) | (keys[:, 1] == v)
    ids, keys = ids[touch], keys[touch]
    if not len(ids):
        return None
    other = np.where(keys[:, 0] == v, keys[:, 1], keys[:, 0])
    solid = plan.solid_of(keys)
    p, m = np.take(plan.points, ids, axis=0), plan.mass[ids]
    x, b = tri.xy[v], tri.xy[other]
    d = b - x
    lam = np.einsum("ij,ij->i", p - x, d) / np.einsum("ij,ij->i", d, d)
    # Ghost edges send each point to its nearer end: only those nearer v count.
    to_v = ~solid & (np.einsum("ij,ij->i", p - x, p - x) <= np.einsum("ij,ij->i", p - b, p - b))
    w_num = np.where(solid, m * (1 - lam), np.where(to_v, m, 0.0))
    num = np.where(solid[:, None], w_num[:, None] * (p - lam[:, None] * b), w_num[:, None] * p).sum(0)
    den = np.where(solid, m * (1 - lam) ** 2, np.where(to_v, m, 0.0)).sum()
    if not den > 0:
        return None
    return num / den
