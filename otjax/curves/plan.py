"""The transport plan from input points to a triangulation, kept up to date.

Assignment rule (de Goes et al. 2011, §2.3, made exact): every point belongs to
the triangle that holds it (symbolic perturbation, see
:mod:`otjax.curves.predicates`) and is sent to the nearest of that triangle's
three edges. For a point inside a triangle, every other edge of the
triangulation is at least as far as the triangle's boundary, so this *is* the
paper's "closest edge" rule; the triangle only decides exact ties, and ties
between its own edges go to the smaller edge key ``(min id, max id)``. The
rule makes the plan local: a collapse changes the assignment of the points in
the star of the removed vertex and nothing else, so the cost change of a
candidate is computed exactly from its stencil.

Each edge then takes the cheaper of keeping its points (normal + tangential
cost) or sending each to its nearer endpoint; the per-edge costs come from the
JAX kernel and are cached here. Costs are squared W2 (mass x squared length):
the greedy order is the same as for W2 itself, and squared costs add.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import numpy as np

from otjax.curves import cost as _cost
from otjax.curves.predicates import in_triangle_perturbed, orient_perturbed
from otjax.curves.triangulation import CollapsePlan, Triangulation, edge_key
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils


class CandidateStencil(NamedTuple):
    """One candidate collapse, exported for scoring.

    Attributes:
      plan: the topological plan (flips + collapse).
      keys: ``(E, 2)`` global keys of the local edges after the collapse,
        sorted; row ``i`` is local edge ``i``.
      edges: ``(E, 2, 2)`` endpoint coordinates, lower id first.
      point_ids: ``(P,)`` global ids of the stencil's points.
      cand: ``(P, 3)`` local candidate edges per point (see ``EdgeStencil``).
      triangle_of_point: ``(P,)`` index into ``plan.new_triangles`` for points
        of the changed region, ``-1`` for points outside it whose edge is fixed.
      before: cost of the region's edges before the collapse.
    """

    plan: CollapsePlan
    keys: np.ndarray
    edges: np.ndarray
    point_ids: np.ndarray
    cand: np.ndarray
    triangle_of_point: np.ndarray
    before: float


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


class TransportPlan:
    """Points, their triangles and edges, and cached per-edge costs.

    Args:
      tri: the triangulation (owned and mutated by this plan).
      points: ``(n, 2)`` float64 input points.
      mass: ``(n,)`` float64 non-negative masses.
      buckets: padding capacities for stencil batches.
      dtype: float dtype for the cost kernel (float64 for exact greedy order).
    """

    def __init__(self, tri: Triangulation, points: np.ndarray, mass: np.ndarray,
                 buckets: Buckets | None = None, dtype=np.float64):
        self.tri = tri
        self.points = np.asarray(points, np.float64)
        self.mass = np.asarray(mass, np.float64)
        self.buckets = buckets if buckets is not None else Buckets()
        self.dtype = dtype
        self.n_kernel_calls = 0
        self.pt_face = self._initial_location()
        self.face_pts: list[np.ndarray] = [np.zeros(0, np.int64)] * len(tri.tri)
        order = np.argsort(self.pt_face, kind="stable")
        faces, starts = np.unique(self.pt_face[order], return_index=True)
        for f, chunk in zip(faces, np.split(order, starts[1:])):
            self.face_pts[int(f)] = chunk
        self.pt_edge = self._nearest_edges(np.arange(len(self.points)))
        self.edge_cost: dict[tuple[int, int], float] = {}
        self.edge_solid: dict[tuple[int, int], bool] = {}
        self._score_all_edges()

    # ------------------------------------------------------------ location
    def _initial_location(self) -> np.ndarray:
        """Triangle of each point; exact, fast for points sitting on vertices."""
        tri = self.tri
        pts = self.points
        out = np.full(len(pts), -1, np.int64)
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
        live = np.nonzero(tri.alive)[0]
        lookup = {tuple(xy[v]): int(vert_face[v]) for v in live}
        rest = []
        for i, p in enumerate(pts):
            f = lookup.get((p[0], p[1]))
            if f is None:
                rest.append(i)
            else:
                out[i] = f
        if rest:
            rest = np.asarray(rest)
            out[rest] = tri.locate(pts[rest])
        return out

    def _nearest_edges(self, ids: np.ndarray) -> np.ndarray:
        """``(len(ids), 2)`` edge keys: nearest edge of each point's triangle."""
        tri = self.tri
        t = np.array([tri.tri[f] for f in self.pt_face[ids]], np.int64).reshape(-1, 3)
        keys = np.stack([np.sort(t[:, [k, (k + 1) % 3]], 1) for k in range(3)], 1)  # (n, 3, 2)
        # Order each point's three edges by key so that argmin's first-hit rule
        # breaks exact ties towards the smaller key, as the kernel does.
        kid = keys[..., 0] * len(tri.xy) + keys[..., 1]
        order = np.argsort(kid, 1)
        keys = np.take_along_axis(keys, order[..., None], 1)
        p = self.points[ids][:, None, :]
        d = segment_sqdist_np(p, tri.xy[keys[..., 0]], tri.xy[keys[..., 1]])
        return keys[np.arange(len(ids)), d.argmin(1)]

    # -------------------------------------------------------------- scoring
    def evaluate(self, batch: EdgeStencil):
        """Runs the batched cost kernel; returns a NumPy ``StencilCost``."""
        self.n_kernel_calls += 1
        with jax.enable_x64(self.dtype == np.float64):
            out = _cost.batched_stencil_cost(batch)
            return jax.device_get(out)

    def _score_all_edges(self) -> None:
        """Computes the cost of every edge that holds points, in batches."""
        keys = self.pt_edge[:, 0] * len(self.tri.xy) + self.pt_edge[:, 1]
        order = np.argsort(keys, kind="stable")
        _uniq, starts = np.unique(keys[order], return_index=True)
        groups = np.split(order, starts[1:])
        xy = self.tri.xy
        chunk = self.buckets.max_batch
        for s in range(0, len(groups), chunk):
            stencils, ekeys = [], []
            for g in groups[s:s + chunk]:
                u, v = self.pt_edge[g[0]]
                stencils.append((xy[[u, v]][None], self.points[g], self.mass[g],
                                 np.zeros((len(g), 3), np.int32)))
                ekeys.append((int(u), int(v)))
            res = self.evaluate(pack_edge_stencils(stencils, self.buckets, self.dtype))
            for i, k in enumerate(ekeys):
                self.edge_cost[k] = float(res.edge_cost[i, 0])
                self.edge_solid[k] = bool(res.solid[i, 0])

    def total_cost(self) -> float:
        """Squared W2 cost of the current plan (sum of cached edge costs)."""
        return float(sum(self.edge_cost.values()))

    # ------------------------------------------------------------ stencils
    def candidate(self, source: int, target: int) -> CandidateStencil | None:
        """Exports the stencil of collapsing ``source`` onto ``target``.

        Returns ``None`` when the half-edge cannot be made collapsible.
        """
        plan = self.tri.plan_collapse(source, target)
        if plan is None:
            return None
        tri, xy = self.tri, self.tri.xy
        new = np.asarray(plan.new_triangles, np.int64)  # (T, 3)
        local: dict[tuple[int, int], int] = {}
        tedges = []
        for t in plan.new_triangles:
            row = []
            for k in range(3):
                u, w = t[k], t[(k + 1) % 3]
                row.append(local.setdefault((u, w) if u < w else (w, u), len(local)))
            tedges.append(row)
        # Local edge indices in increasing key order: ties then go to the
        # smaller key, as in the from-scratch rule.
        keys = np.array(sorted(local), np.int64)
        rank = {k: i for i, k in enumerate(map(tuple, keys.tolist()))}
        remap = np.empty(len(local), np.int32)
        for k, i in local.items():
            remap[i] = rank[k]
        local = rank
        tcand = np.sort(remap[np.asarray(tedges)], 1).astype(np.int32)

        inside = np.concatenate([self.face_pts[f] for f in plan.star])
        if len(inside):
            hold = in_triangle_perturbed(xy[new][None], self.points[inside][:, None, :])
            t_of_p = hold.argmax(1)
            if not hold[np.arange(len(inside)), t_of_p].all():
                raise RuntimeError("a point of the star is not covered after the collapse")
        else:
            t_of_p = np.zeros(0, np.int64)

        ring, n = plan.ring, len(plan.ring)
        outside_ids, outside_cand = [], []
        before = 0.0
        for k in range(n):
            a, b = ring[k], ring[(k + 1) % n]
            before += self.edge_cost.get(edge_key(plan.source, a), 0.0)
            lk = edge_key(a, b)
            before += self.edge_cost.get(lk, 0.0)
            f = plan.star[k]
            g = tri.nbr[f][tri.tri[f].index(plan.source)]
            if g >= 0:
                ids = self.face_pts[g]
                if len(ids):
                    sel = ids[(self.pt_edge[ids, 0] == lk[0]) & (self.pt_edge[ids, 1] == lk[1])]
                    outside_ids.append(sel)
                    outside_cand.append(np.full((len(sel), 3), local[lk], np.int32))
        point_ids = np.concatenate([inside] + outside_ids).astype(np.int64)
        cand = np.concatenate([tcand[t_of_p]] + outside_cand).reshape(-1, 3).astype(np.int32)
        tp = np.concatenate([t_of_p, np.full(len(point_ids) - len(inside), -1)]).astype(np.int64)
        return CandidateStencil(plan, keys, xy[keys], point_ids, cand, tp, before)

    def pack(self, cands: list[CandidateStencil]) -> EdgeStencil:
        """Pads candidate stencils into one batch (see :class:`Buckets`)."""
        return pack_edge_stencils(
            [(c.edges, self.points[c.point_ids], self.mass[c.point_ids], c.cand) for c in cands],
            self.buckets, self.dtype)

    def score(self, cands: list[CandidateStencil]) -> tuple[np.ndarray, list[tuple[object, int]]]:
        """Cost increase ``delta`` of each candidate, batched.

        Candidates are scored in as few kernel calls as the bucket capacities
        allow (one, for the dirty region of a single collapse).

        Returns:
          ``(delta (len(cands),), rows)``; ``rows[i] = (result, r)`` locates
          candidate ``i`` in a kernel result, to pass to :meth:`apply`.
        """
        deltas, rows = [], []
        step = self.buckets.max_batch
        for s in range(0, len(cands), step):
            chunk = cands[s:s + step]
            res = self.evaluate(self.pack(chunk))
            deltas.append(np.asarray(res.total[: len(chunk)]) - np.array([c.before for c in chunk]))
            rows += [(res, r) for r in range(len(chunk))]
        return (np.concatenate(deltas) if deltas else np.zeros(0)), rows

    # ------------------------------------------------------------- mutation
    def apply(self, cand: CandidateStencil, scored: tuple[object, int]) -> set[int]:
        """Performs a scored collapse and updates points, edges and costs.

        Args:
          cand: the candidate (exported against the current state).
          scored: its ``(result, row)`` from :meth:`score`.

        Returns:
          The *dirty* vertices: every half-edge leaving one of them has a
          stencil that overlaps the change and must be re-scored (paper,
          Fig. 6: the modified one-ring and its flap vertices).
        """
        res, row = scored
        plan = cand.plan
        new_ids = np.asarray(self.tri.collapse(plan), np.int64)
        n_in = int((cand.triangle_of_point >= 0).sum())
        inside = cand.point_ids[:n_in]
        fid = new_ids[cand.triangle_of_point[:n_in]]
        self.pt_face[inside] = fid
        for f in plan.star:
            self.face_pts[f] = np.zeros(0, np.int64)
        order = np.argsort(fid, kind="stable")
        if n_in:
            uf, st = np.unique(fid[order], return_index=True)
            for f, chunk in zip(uf, np.split(inside[order], st[1:])):
                self.face_pts[int(f)] = chunk
        assign = np.asarray(res.assignment[row, : len(cand.point_ids)])
        self.pt_edge[cand.point_ids] = cand.keys[assign]
        for a in plan.ring:
            k = edge_key(plan.source, a)
            self.edge_cost.pop(k, None)
            self.edge_solid.pop(k, None)
        for i, (a, b) in enumerate(cand.keys):
            k = (int(a), int(b))
            self.edge_cost[k] = float(res.edge_cost[row, i])
            self.edge_solid[k] = bool(res.solid[row, i])
        dirty = set(plan.ring)
        dirty.add(plan.target)
        tri = self.tri
        for f in new_ids:
            for g in tri.nbr[f]:
                if g >= 0:
                    dirty.update(tri.tri[g])
        return {v for v in dirty if not tri.pinned[v]}
