"""The transport plan from input points to a triangulation: state only.

Assignment rule (de Goes et al. 2011, §2.3, made exact): every point belongs to
the triangle that holds it (symbolic perturbation, see
:mod:`otjax.predicates`) and is sent to the nearest of that triangle's three
edges. For a point inside a triangle, every other edge of the triangulation
is at least as far as the triangle's boundary, so this *is* the paper's
"closest edge" rule; the triangle only decides exact ties, and ties between
its own edges go to the smaller edge key ``(min id, max id)``. The rule makes
the plan local: a collapse changes the assignment of the points in the star
of the removed vertex and nothing else, so the cost change of a candidate is
computed exactly from its stencil.

Each edge then takes the cheaper of keeping its points (normal + tangential
cost) or sending each to its nearer endpoint. Costs are squared W2 (mass x
squared length): the greedy order is the same as for W2 itself, and squared
costs add. The per-edge costs come from the scoring kernel; the plan stores
them (:meth:`TransportPlan.set_edge_costs`) and never runs a kernel itself.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.curves.triangulation import Triangulation, edge_key
from otjax.predicates import orient_perturbed


class Change(NamedTuple):
    """What one applied change (a collapse or a vertex move) did.

    Attributes:
      source: the removed vertex (collapse) or the moved one.
      target: the vertex ``source`` merged into; ``source`` for a move.
      ring: the one-ring of ``source`` before the change.
      moved: whether the change was a move.
      touched: vertices whose region (star, the faces across its link, their
        points or the costs of its star's edges) changed; a superset of those
        whose collapse stencils changed (paper, Fig. 6).
      links: for the vertices of ``touched`` whose star kept its triangles and
        only saw the far side of some link edges change, those edge keys.
      dirty: the live, free vertices of ``touched``: every half-edge leaving one
        of them must be scored again.
      quiet: vertices next to the changed region (its faces across their
        link) left out of ``touched``: every link edge they share with it kept
        its points and its cost, so nothing of their region changed. Their
        collapses onto a vertex whose star changed may still have gained or
        lost the link condition (the engine checks).
    """

    source: int
    target: int
    ring: tuple[int, ...]
    moved: bool
    touched: frozenset
    links: dict
    dirty: frozenset
    quiet: frozenset = frozenset()

    def woken(self, vertices, free) -> Change:
        """This change with ``vertices`` (of :attr:`quiet`) moved to
        :attr:`touched` (their stars kept their triangles and no link edge
        changed: :attr:`links` of none), and to :attr:`dirty` where ``free(v)``."""
        vertices = frozenset(vertices)
        if not vertices:
            return self
        return self._replace(touched=self.touched | vertices, dirty=self.dirty | {v for v in vertices if free(v)},
                             links={**self.links, **{v: frozenset() for v in vertices}},
                             quiet=self.quiet - vertices)


def segment_sqdist_np(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared point-segment distance with the kernel's exact tie rule.

    NumPy twin of :func:`otjax.curves.cost.segment_sqdist` (same branch tests
    on signs, same interior formula), for host-side assignments. Shapes
    broadcast over ``(..., 2)``.
    """
    d = b - a
    pa, pb = p - a, p - b
    along = np.sum(pa * d, -1)
    den = np.sum(d * d, -1)
    cross = d[..., 0] * pa[..., 1] - d[..., 1] * pa[..., 0]
    interior = np.divide(cross**2, den, out=np.zeros_like(cross), where=den > 0)
    return np.where(along <= 0, np.sum(pa * pa, -1),
                    np.where(np.sum(pb * d, -1) >= 0, np.sum(pb * pb, -1), interior))


def locate_points(tri: Triangulation, points: np.ndarray) -> np.ndarray:
    """``(n,)`` the triangle of each point: exact, fast for points on vertices."""
    out = np.full(len(points), -1, np.int64)
    # Points on a vertex: the perturbed point lies in the triangle whose
    # corner wedge at that vertex contains direction (1, eps).
    t = tri.triangles()
    fid = np.asarray(tri.triangle_ids(), np.int64)
    xy = tri.xy
    vert_face = np.full(len(xy), -1, np.int64)
    for k in range(3):
        v, a, b = t[:, k], t[:, (k + 1) % 3], t[:, (k + 2) % 3]
        ok = (orient_perturbed(xy[v], xy[a], xy[v]) > 0) & (orient_perturbed(xy[b], xy[v], xy[v]) > 0)
        vert_face[v[ok]] = fid[ok]
    # Which points sit exactly on a live vertex: match coordinates by a
    # sort (complex numbers order lexicographically; -0.0 == 0.0).
    live = np.nonzero(tri.alive)[0]
    vkey = xy[live, 0] + 1j * xy[live, 1]
    order = np.argsort(vkey, kind="stable")
    vkey = vkey[order]
    pkey = points[:, 0] + 1j * points[:, 1]
    pos = np.minimum(np.searchsorted(vkey, pkey), len(vkey) - 1)
    on_vertex = vkey[pos] == pkey
    out[on_vertex] = vert_face[live[order[pos[on_vertex]]]]
    rest = np.flatnonzero(out < 0)
    if len(rest):
        out[rest] = tri.locate(points[rest])
    return out


class TransportPlan:
    """Points, their triangles and edges, and the per-edge costs.

    The constructor locates every point and assigns it to the nearest edge
    of its triangle (host work, exact); the edge costs start empty and are
    set by whoever runs the kernel (:meth:`set_edge_costs`, see
    :class:`otjax.curves.engine.CurveEngine`).

    Args:
      tri: the triangulation (owned and mutated by this plan).
      points: ``(n, 2)`` float64 input points.
      mass: ``(n,)`` float64 non-negative masses.

    Attributes:
      pt_face: ``(n,)`` triangle id of each point.
      face_pts: per triangle id, the ids of its points (increasing).
      pt_edge: ``(n, 2)`` edge key each point is assigned to.
      pt_code: ``(n,)`` int64 code ``min * V + max`` of ``pt_edge`` (``V``
        vertices in the triangulation): one gather where regions compare
        edges.
      edge_cost, edge_solid: per edge key holding points, its cost and
        whether it keeps its points (solid) or sends them to its ends (ghost).
      edge_normal: per edge key holding points, the normal part ``N`` of
        its points (squared distances to its supporting line), solid or not.
    """

    def __init__(self, tri: Triangulation, points: np.ndarray, mass: np.ndarray):
        self.tri = tri
        self.points = np.asarray(points, np.float64)
        self.mass = np.asarray(mass, np.float64)
        self.point_rows = np.ascontiguousarray(self.points.T)  # (2, n): gathers stay contiguous
        self.pt_face = locate_points(tri, self.points)
        self.face_pts: list[np.ndarray] = [np.zeros(0, np.int64)] * len(tri.tri)
        order = np.argsort(self.pt_face, kind="stable")
        faces, starts = np.unique(self.pt_face[order], return_index=True)
        for f, chunk in zip(faces, np.split(order, starts[1:])):
            self.face_pts[int(f)] = chunk
        self.pt_edge = self._nearest_edges(np.arange(len(self.points)))
        self.pt_code = self.pt_edge[:, 0] * len(tri.xy) + self.pt_edge[:, 1]
        self.edge_cost: dict[tuple[int, int], float] = {}
        self.edge_solid: dict[tuple[int, int], bool] = {}
        self.edge_normal: dict[tuple[int, int], float] = {}

    def _nearest_edges(self, ids: np.ndarray) -> np.ndarray:
        """``(len(ids), 2)`` edge keys: nearest edge of each point's triangle."""
        tri = self.tri
        faces, inv = np.unique(self.pt_face[ids], return_inverse=True)
        t = np.array([tri.tri[f] for f in faces], np.int64).reshape(-1, 3)[inv.ravel()]
        keys = np.stack([np.sort(t[:, [k, (k + 1) % 3]], 1) for k in range(3)], 1)  # (n, 3, 2)
        # Order each point's three edges by key so that argmin's first-hit rule
        # breaks exact ties towards the smaller key, as the kernel does.
        kid = keys[..., 0] * len(tri.xy) + keys[..., 1]
        order = np.argsort(kid, 1)
        keys = np.take_along_axis(keys, order[..., None], 1)
        p = self.points[ids][:, None, :]
        d = segment_sqdist_np(p, tri.xy[keys[..., 0]], tri.xy[keys[..., 1]])
        return keys[np.arange(len(ids)), d.argmin(1)]

    def points_by_edge(self) -> tuple[np.ndarray, list[tuple[np.ndarray]]]:
        """``(keys (m, 2), parts)``: every edge holding points, in increasing
        key, and ``parts[i] = (ids,)`` its points in increasing id."""
        keys = self.pt_edge[:, 0] * len(self.tri.xy) + self.pt_edge[:, 1]
        order = np.argsort(keys, kind="stable")
        _uniq, starts = np.unique(keys[order], return_index=True)
        return self.pt_edge[order[starts]], [(p,) for p in np.split(order, starts[1:])]

    def set_edge_costs(self, keys: np.ndarray, per_edge: np.ndarray) -> None:
        """Stores the kernel's per-edge fields ``per_edge (m, 6)``
        (:data:`otjax.curves.scoring.EDGE_FIELDS`) for the edges ``keys (m, 2)``."""
        for (u, v), c, n, solid in zip(keys.tolist(), per_edge[:, 0].tolist(), per_edge[:, 1].tolist(),
                                       (per_edge[:, 5] > 0).tolist()):
            self.edge_cost[(u, v)] = c
            self.edge_normal[(u, v)] = n
            self.edge_solid[(u, v)] = solid

    def solid_of(self, keys: np.ndarray) -> np.ndarray:
        """``(n,)`` bool: whether each edge key of ``keys (n, 2)`` is solid."""
        keys = np.asarray(keys, np.int64).reshape(-1, 2)
        if not len(keys):
            return np.zeros(0, bool)
        nv = len(self.tri.xy)
        # Each distinct key once (points share few edges); 1D: 10x faster than axis=0.
        uniq, inv = np.unique(keys[:, 0] * nv + keys[:, 1], return_inverse=True)
        get = self.edge_solid.get
        flags = np.fromiter((get((int(c // nv), int(c % nv)), False) for c in uniq), bool, len(uniq))
        return flags[inv.ravel()]

    def total_cost(self) -> float:
        """Squared W2 cost of the current plan (sum of the edge costs)."""
        return float(sum(self.edge_cost.values()))

    def normal_of(self, keys) -> float:
        """Sum of the normal parts :attr:`edge_normal` over the edge ``keys``."""
        get = self.edge_normal.get
        return float(sum(get(k, 0.0) for k in map(tuple, np.asarray(keys).reshape(-1, 2).tolist())))

    def apply(self, cand, scored) -> Change:
        """Performs a scored change (collapse or move) and updates the plan.

        Args:
          cand: the :class:`~otjax.curves.stencils.CandidateStencil`,
            exported against the current state.
          scored: its :class:`~otjax.curves.stencils.CandidateCost`.

        Returns:
          The :class:`Change`: what it touched, for whoever keeps versions.
        """
        plan = cand.plan
        tri = self.tri
        if cand.moved is None:
            new_ids = np.asarray(tri.collapse(plan), np.int64)
            for a in plan.ring:
                k = edge_key(plan.source, a)
                self.edge_cost.pop(k, None)
                self.edge_normal.pop(k, None)
                self.edge_solid.pop(k, None)
        else:
            v = plan.source
            if tuple(tri.star(v)[1]) != plan.star:
                raise ValueError("stale relocation: the star has changed")
            tri.move(v, cand.moved)
            new_ids = np.asarray(plan.star, np.int64)
        kept = self._reassign(cand, scored, new_ids)
        return self._change(cand, new_ids, kept)

    def _reassign(self, cand, scored, new_ids: np.ndarray) -> set:
        plan = cand.plan
        inside = cand.point_ids[:cand.n_inside]
        fid = new_ids[scored.triangle]
        self.pt_face[inside] = fid
        for f in plan.star:
            self.face_pts[f] = np.zeros(0, np.int64)
        order = np.argsort(fid, kind="stable")
        if len(inside):
            uf, st = np.unique(fid[order], return_index=True)
            for f, chunk in zip(uf, np.split(inside[order], st[1:])):
                self.face_pts[int(f)] = chunk
        self.pt_edge[cand.point_ids] = np.take(cand.keys, scored.assignment, axis=0)
        codes = cand.keys[:, 0] * len(self.tri.xy) + cand.keys[:, 1]
        old_code = self.pt_code[cand.point_ids]
        new_code = np.take(codes, scored.assignment)
        self.pt_code[cand.point_ids] = new_code
        switched = old_code != new_code
        # An edge whose points and cost are what they were changed nothing
        # for the stars on its far side (Change.quiet); an edge missing from
        # the table carried no point, at cost 0.
        reassigned = set(old_code[switched].tolist()) | set(new_code[switched].tolist())
        kept = set()
        get = self.edge_cost.get
        for k, code, c, n, solid in zip(map(tuple, cand.keys.tolist()), codes.tolist(), scored.edge_cost.tolist(),
                                        scored.normal.tolist(), scored.solid.tolist()):
            if code not in reassigned and get(k, 0.0) == c:
                kept.add(k)
            self.edge_cost[k] = c
            self.edge_normal[k] = n
            self.edge_solid[k] = solid
        return kept

    def _change(self, cand, new_ids: np.ndarray, kept: set) -> Change:
        """The vertices of the new triangles and of the triangles next to
        them: every vertex whose star, faces across its link, their points
        or its star's edge costs changed. The far vertex of a face across
        the region's boundary keeps its star: at most the points across that
        link edge and its cost changed (``links``); where neither did on any
        of the edges ``kept`` it shares with the region, it is quiet."""
        plan = cand.plan
        tri = self.tri
        full = {*plan.ring, plan.source}
        links: dict[int, set] = {}
        far: set = set()
        new_set = set(new_ids.tolist())
        for f in new_set:
            tf = tri.tri[f]
            for g in tri.nbr[f]:
                if g >= 0 and g not in new_set:
                    tg = tri.tri[g]
                    a = next(u for u in tg if u not in tf)
                    if a not in full:
                        far.add(a)
                        x, y = (u for u in tg if u != a)
                        key = edge_key(x, y)
                        if key not in kept:
                            links.setdefault(a, set()).add(key)
        touched = full | set(links)
        moved = cand.moved is not None
        if not moved:
            touched.discard(plan.source)  # removed by the collapse
        dirty = frozenset(v for v in touched if tri.alive[v] and not tri.pinned[v])
        return Change(plan.source, plan.target, plan.ring, moved, frozenset(touched),
                      {v: frozenset(k) for v, k in links.items()}, dirty, frozenset(far - touched))
