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
from otjax.curves.location import MIN_PAIRS as LOCATE_MIN_PAIRS
from otjax.curves.location import locate_pairs
from otjax.curves.predicates import orient_perturbed
from otjax.curves.triangulation import CollapsePlan, Triangulation, edge_key
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils, pack_ragged, ragged_index

_NO_IDS = np.zeros(0, np.int64)


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
      before: cost of the region's edges before the change.
      moved: for a relocation, the new position of ``plan.source`` (then
        ``plan.target == plan.source`` and the triangles are the star's own);
        ``None`` for a collapse.
    """

    plan: CollapsePlan
    keys: np.ndarray
    edges: np.ndarray
    point_ids: np.ndarray
    cand: np.ndarray
    triangle_of_point: np.ndarray
    before: float
    moved: np.ndarray | None = None


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
      max_source_degree: half-edges leaving a vertex of higher degree are not
        candidates until its degree falls (see :meth:`candidates`).
    """

    def __init__(self, tri: Triangulation, points: np.ndarray, mass: np.ndarray,
                 buckets: Buckets | None = None, dtype=np.float64, max_source_degree: int = 32):
        self.tri = tri
        self.points = np.asarray(points, np.float64)
        self.mass = np.asarray(mass, np.float64)
        self._point_rows = np.ascontiguousarray(self.points.T)  # (2, n): gathers stay contiguous
        # Local edge counts hardly vary: start the edge capacity where most
        # runs end, which saves the recompiles of growing it.
        self.buckets = buckets if buckets is not None else Buckets(min_edges=64)
        self.dtype = dtype
        self.n_kernel_calls = 0
        self.location_kernel_used = False
        self.max_source_degree = max_source_degree
        # Collapse plans depend only on the stars of their two ends: cache
        # them, stamped with per-vertex versions bumped when a star changes.
        self._star_version = [0] * len(tri.xy)
        self._plans: dict[tuple[int, int], tuple] = {}
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
        # Which points sit exactly on a live vertex: match coordinates by a
        # sort (complex numbers order lexicographically; -0.0 == 0.0).
        live = np.nonzero(tri.alive)[0]
        vkey = xy[live, 0] + 1j * xy[live, 1]
        order = np.argsort(vkey, kind="stable")
        vkey = vkey[order]
        pkey = pts[:, 0] + 1j * pts[:, 1]
        pos = np.minimum(np.searchsorted(vkey, pkey), len(vkey) - 1)
        on_vertex = vkey[pos] == pkey
        out[on_vertex] = vert_face[live[order[pos[on_vertex]]]]
        rest = np.flatnonzero(out < 0)
        if len(rest):
            out[rest] = tri.locate(pts[rest])
        return out

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

    # -------------------------------------------------------------- scoring
    def evaluate(self, batch: EdgeStencil):
        """Runs the batched cost kernel; returns a NumPy ``StencilCost``."""
        self.n_kernel_calls += 1
        with jax.enable_x64(self.dtype == np.float64):
            return _cost.batched_stencil_cost_host(batch)

    def _score_all_edges(self) -> None:
        """Computes the cost of every edge that holds points, in batches."""
        keys = self.pt_edge[:, 0] * len(self.tri.xy) + self.pt_edge[:, 1]
        order = np.argsort(keys, kind="stable")
        _uniq, starts = np.unique(keys[order], return_index=True)
        groups = np.split(order, starts[1:])
        xy = self.tri.xy
        for batch in self.buckets.batches([len(g) for g in groups]):
            stencils, ekeys = [], []
            for g in (groups[i] for i in batch):
                u, v = self.pt_edge[g[0]]
                stencils.append((xy[[u, v]][None], self.points[g], self.mass[g],
                                 np.zeros((len(g), 3), np.int32)))
                ekeys.append((int(u), int(v)))
            res = self.evaluate(pack_edge_stencils(stencils, self.buckets, self.dtype))
            for i, k in enumerate(ekeys):
                self.edge_cost[k] = float(res.edge_cost[i, 0])
                self.edge_solid[k] = bool(res.solid[i, 0])

    @property
    def compiled_shapes(self) -> int:
        """Distinct kernel shapes this plan has used: cost kernel and location kernel."""
        return len(self.buckets.shapes_seen) + int(self.location_kernel_used)

    def solid_of(self, keys: np.ndarray) -> np.ndarray:
        """``(n,)`` bool: whether each edge key of ``keys (n, 2)`` is solid.

        Looks each distinct key up once (points share few edges).
        """
        keys = np.asarray(keys, np.int64).reshape(-1, 2)
        if not len(keys):
            return np.zeros(0, bool)
        uniq, inv = np.unique(keys, axis=0, return_inverse=True)
        get = self.edge_solid.get
        flags = np.fromiter((get((int(a), int(b)), False) for a, b in uniq), bool, len(uniq))
        return flags[inv.ravel()]

    def total_cost(self) -> float:
        """Squared W2 cost of the current plan (sum of cached edge costs)."""
        return float(sum(self.edge_cost.values()))

    # ------------------------------------------------------------ stencils
    def _plan(self, source: int, target: int) -> CollapsePlan | None:
        """Collapse plan, cached until the star of either end changes."""
        key = (source, target)
        stamp = (self._star_version[source], self._star_version[target])
        hit = self._plans.get(key)
        if hit is not None and hit[0] == stamp:
            return hit[1]
        plan = self.tri.plan_collapse(source, target)
        self._plans[key] = (stamp, plan)
        return plan

    def _region(self, v: int):
        """What every change of the star of ``v`` shares (see :meth:`candidates`).

        Returns ``(ring, star, inside, outside, outside_link, before)``: the
        points in the star; the points of the faces across the link edges that
        are assigned to those edges, with the link edge index ``k`` (edge
        ``(ring[k], ring[k+1])``) of each; and the cost of every edge of the
        star (spokes and link), which is what any change of the star replaces.
        """
        tri = self.tri
        ring, star = tri.star(v)
        n = len(ring)
        face_pts = self.face_pts
        inside = np.concatenate([face_pts[f] for f in star])
        cost = self.edge_cost
        before = 0.0
        across = []
        for k in range(n):
            a, b = ring[k], ring[(k + 1) % n]
            before += cost.get((v, a) if v < a else (a, v), 0.0) + cost.get((a, b) if a < b else (b, a), 0.0)
            f = star[k]
            g = tri.nbr[f][tri.tri[f].index(v)]
            across.append(face_pts[g] if g >= 0 else _NO_IDS)
        # Of the points across each link edge, those assigned to that edge.
        counts = np.fromiter(map(len, across), np.int64, n)
        ids = np.concatenate(across)
        link = np.repeat(np.arange(n), counts)
        r = np.asarray(ring, np.int64)
        lo, hi = np.minimum(r, np.roll(r, -1)), np.maximum(r, np.roll(r, -1))
        e = self.pt_edge[ids]
        keep = (e[:, 0] == lo[link]) & (e[:, 1] == hi[link])
        return ring, star, inside, ids[keep], link[keep], before

    def source_chunks(self, sources, budget: int):
        """Splits ``sources`` into runs whose export stays under ``budget``.

        The export of the half-edges leaving ``v`` tests each point of the
        star against each new triangle of each candidate: about
        ``deg^2 * points`` (point, triangle) pairs, each ~100 bytes. This
        bounds them per run (a single source may exceed it alone).

        Yields:
          Lists of vertex ids, in the order given.
        """
        tri = self.tri
        run, used = [], 0
        for v in sources:
            if not tri.alive[v] or tri.pinned[v]:
                continue
            ring, star = tri.star(v)
            work = len(ring) ** 2 * (1 + sum(len(self.face_pts[f]) for f in star))
            if run and used + work > budget:
                yield run
                run, used = [], 0
            run.append(v)
            used += work
        if run:
            yield run

    def candidates(self, sources, targets: dict | None = None) -> list[CandidateStencil]:
        """Exports the collapse stencils of every half-edge leaving ``sources``.

        The work shared by the half-edges of one source (its star, the points
        around it, the cost being replaced) is done once per source, and the
        exact point location of all candidates is one vectorised predicate
        call, because per-call overhead, not arithmetic, dominates at these
        sizes.

        Sources of degree above ``max_source_degree`` are skipped for now.
        Delaunay triangulations of clean data have such hubs (a far vertex
        fanned to a long run of collinear points: degree 192 on the
        junctions example); each of their half-edges costs a flip plan
        quadratic in the degree and a stencil holding the whole run, and the
        hub is re-scored after every collapse in its ring. Its neighbours
        collapse first, and its half-edges join the queue once its degree is
        back under the bound (the hub is then dirty, so it is re-scored).

        Args:
          sources: vertex ids; dead and pinned ones are skipped.
          targets: optional ``{source: iterable of targets}`` restricting the
            half-edges (default: every neighbour).

        Returns:
          Candidates in order of ``sources`` then ring order; half-edges that
          cannot be collapsed are left out.
        """
        tri = self.tri
        jobs = []
        for v in sources:
            if not tri.alive[v] or tri.pinned[v]:
                continue
            if len(tri.star(v)[0]) > self.max_source_degree:
                continue
            region = self._region(v)
            ring = region[0]
            if targets is None:
                wanted = ring
            else:
                allowed = set(targets[v])
                wanted = [w for w in ring if w in allowed]
            for w in wanted:
                plan = self._plan(v, w)
                if plan is not None:
                    jobs.append((plan, np.asarray(plan.new_triangles, np.int64), region, None))
        return self._export(jobs)

    def candidate(self, source: int, target: int) -> CandidateStencil | None:
        """Exports the stencil of collapsing ``source`` onto ``target``.

        Returns ``None`` when the half-edge cannot be made collapsible.
        """
        out = self.candidates([source], {source: [target]})
        return out[0] if out else None

    def relocation_candidates(self, moves) -> list[CandidateStencil]:
        """Exports the stencils of moving vertices, all in one batched export.

        Args:
          moves: ``(v, position)`` pairs, each judged against the current
            state (moves of neighbouring vertices interact; the caller applies
            non-overlapping ones).

        Returns:
          One candidate per move whose ``position`` lies strictly inside the
          kernel of the one-ring of ``v`` (the only moves that keep the
          embedding); the others are left out.
        """
        tri = self.tri
        jobs = []
        for v, position in moves:
            position = np.asarray(position, np.float64)
            ring, star = tri.star(v)
            if not tri.in_kernel_at(ring, position):
                continue
            n = len(ring)
            tris = np.array([[v, ring[k], ring[(k + 1) % n]] for k in range(n)], np.int64)
            plan = CollapsePlan(v, v, tuple(ring), tuple(star), (), (), tuple(map(tuple, tris.tolist())))
            jobs.append((plan, tris, self._region(v), position))
        return self._export(jobs)

    def relocation_candidate(self, v: int, position) -> CandidateStencil | None:
        """The stencil of moving ``v`` to ``position``, or ``None`` if that
        would fold a triangle over (see :meth:`relocation_candidates`)."""
        out = self.relocation_candidates([(v, position)])
        return out[0] if out else None

    def _export(self, jobs) -> list[CandidateStencil]:
        """Builds the stencils of ``(plan, triangles, region, moved)`` jobs.

        Everything is done on concatenated arrays over all jobs (edge keys,
        local numbering, exact point location); the per-job Python work is
        slicing only.
        """
        if not jobs:
            return []
        xy = self.tri.xy
        nv = len(xy)
        nj = len(jobs)
        n_tri = np.array([len(job[1]) for job in jobs])
        tris = np.concatenate([job[1] for job in jobs])  # (sum T, 3)
        tri_job = np.repeat(np.arange(nj), n_tri)
        coords = xy[tris]  # (sum T, 3, 2)
        for j, (plan, t, _region, moved) in enumerate(jobs):
            if moved is not None:
                s = slice(int(n_tri[:j].sum()), int(n_tri[: j + 1].sum()))
                coords[s] = np.where((t == plan.source)[..., None], moved, coords[s])
        tri_start = np.concatenate([[0], np.cumsum(n_tri)])
        coords_rows = np.ascontiguousarray(coords.reshape(-1, 6).T)  # (6, sum T)

        # Local edges: keys coded job-major, so np.unique numbers every job's
        # edges contiguously and in increasing key order within the job.
        e = np.sort(np.stack([tris, tris[:, [1, 2, 0]]], -1), -1)  # (sum T, 3, 2)
        code = (np.repeat(tri_job, 3) * nv + e[..., 0].ravel()) * nv + e[..., 1].ravel()
        ucode, inv = np.unique(code, return_inverse=True)
        ujob = ucode // (nv * nv)
        edge_start = np.searchsorted(ujob, np.arange(nj + 1))
        ukeys = np.stack([(ucode // nv) % nv, ucode % nv], 1)
        tcand = np.sort(inv.reshape(-1, 3) - edge_start[tri_job][:, None], 1).astype(np.int32)

        # Exact location of every inside point among its job's new triangles:
        # one row per (point, triangle) pair, one predicate call in total.
        n_in = np.array([len(job[2][2]) for job in jobs])
        inside = np.concatenate([job[2][2] for job in jobs]).astype(np.int64)
        pt_job = np.repeat(np.arange(nj), n_in)
        t_global = self._locate_inside(jobs, coords, coords_rows, tri_start, n_tri, inside, pt_job)
        t_local = t_global - tri_start[pt_job]
        in_cand = tcand[t_global]

        # Points outside the region keep their (link) edge: look its key up.
        n_out = np.array([len(job[2][3]) for job in jobs])
        outside = np.concatenate([job[2][3] for job in jobs]).astype(np.int64)
        if len(outside):
            out_job = np.repeat(np.arange(nj), n_out)
            ring_arr = [np.asarray(job[2][0], np.int64) for job in jobs]
            link = np.concatenate([job[2][4] for job in jobs])
            a = np.concatenate([r[job[2][4]] for r, job in zip(ring_arr, jobs)])
            b = np.concatenate([r[(job[2][4] + 1) % len(r)] for r, job in zip(ring_arr, jobs)])
            del link
            lk = (out_job * nv + np.minimum(a, b)) * nv + np.maximum(a, b)
            out_local = (np.searchsorted(ucode, lk) - edge_start[out_job]).astype(np.int32)
            out_cand = np.repeat(out_local[:, None], 3, 1)
        else:
            out_cand = np.zeros((0, 3), np.int32)

        in_start = np.concatenate([[0], np.cumsum(n_in)])
        out_start = np.concatenate([[0], np.cumsum(n_out)])
        edges_all = xy[ukeys]
        out = []
        for j, (plan, _t, region, moved) in enumerate(jobs):
            es = slice(edge_start[j], edge_start[j + 1])
            si = slice(in_start[j], in_start[j + 1])
            so = slice(out_start[j], out_start[j + 1])
            keys = ukeys[es]
            edges = edges_all[es]
            if moved is not None:
                edges = np.where((keys == plan.source)[..., None], moved, edges)
            out.append(CandidateStencil(
                plan, keys, edges,
                np.concatenate([inside[si], outside[so]]),
                np.concatenate([in_cand[si], out_cand[so]]),
                np.concatenate([t_local[si], np.full(n_out[j], -1, np.int64)]),
                region[5], moved))
        return out

    def _locate_inside(self, jobs, coords, coords_rows, tri_start, n_tri, inside, pt_job) -> np.ndarray:
        """Index (into the jobs' concatenated triangles) of the new triangle holding each inside point.

        A guess first: the new triangles of a job are some flipped-out ears
        followed by a fan around one apex (the collapse target, or the moved
        vertex), CCW, so the fan triangle of a point is the angular sector
        around the apex it falls in: one ``searchsorted`` for all jobs. The
        exact test confirms each guess; points it rejects (in an ear, near a
        sector boundary, on the apex) are tested against every new triangle
        of their job, as before the guess. So the answer is the exact
        perturbed location in every case, at about one tested pair per point
        instead of ``deg - 2``.
        """
        out = np.full(len(inside), -1, np.int64)
        if not len(inside):
            return out
        nj = len(jobs)
        n_flip = np.fromiter((len(job[0].flipped_out) for job in jobs), np.int64, nj)
        fan_start = tri_start[:-1] + n_flip
        n_fan = n_tri - n_flip
        fan_off = np.concatenate([[0], np.cumsum(n_fan)])
        fan_job, k = ragged_index(n_fan)
        fans = fan_start[fan_job] + k
        apex = coords[fan_start, 0]  # (nj, 2): fan triangles are (apex, a, b)
        first = coords[fan_start, 1] - apex
        theta0 = np.arctan2(first[:, 1], first[:, 0])
        d = coords[fans, 1] - apex[fan_job]
        phi = np.mod(np.arctan2(d[:, 1], d[:, 0]) - theta0[fan_job], 2 * np.pi)
        phi[fan_off[:-1]] = 0.0
        d = self.points[inside] - apex[pt_job]
        phi_p = np.mod(np.arctan2(d[:, 1], d[:, 0]) - theta0[pt_job], 2 * np.pi)
        # Sector boundaries of all jobs in one sorted array (8 > 2 pi apart).
        g = np.searchsorted(fan_job * 8.0 + phi, pt_job * 8.0 + phi_p, side="right") - 1
        guess = fans[np.clip(g, fan_off[pt_job], fan_off[pt_job + 1] - 1)]
        ok = locate_pairs(coords_rows[:, guess], self._point_rows[:, inside])
        self.location_kernel_used |= len(inside) >= LOCATE_MIN_PAIRS
        out[ok] = guess[ok]
        rest = np.flatnonzero(~ok)
        if len(rest):
            job = pt_job[rest]
            pair_pt, k = ragged_index(n_tri[job])
            pair_tri = tri_start[job][pair_pt] + k
            hold = locate_pairs(coords_rows[:, pair_tri], self._point_rows[:, inside[rest[pair_pt]]])
            self.location_kernel_used |= len(pair_pt) >= LOCATE_MIN_PAIRS
            hit = np.flatnonzero(hold)
            # The perturbed location is a partition: exactly one triangle each.
            if len(hit) != len(rest) or np.any(pair_pt[hit] != np.arange(len(rest))):
                raise RuntimeError("a point of the star is not covered exactly once after the change")
            out[rest] = pair_tri[hit]
        return out

    def pack(self, cands: list[CandidateStencil]) -> EdgeStencil:
        """Pads candidate stencils into one batch (see :class:`Buckets`).

        The points and masses of all candidates are gathered in one go.
        """
        ids = np.concatenate([c.point_ids for c in cands])
        return pack_ragged(np.concatenate([c.edges for c in cands]), [len(c.keys) for c in cands],
                           self.points[ids], self.mass[ids], np.concatenate([c.cand for c in cands]),
                           [len(c.point_ids) for c in cands], self.buckets, self.dtype)

    def dispatch(self, cands: list[CandidateStencil]) -> list:
        """Packs and dispatches the batches of ``cands``; does not wait.

        The kernel of one batch runs while the next is packed (and, in the
        decimation loop, while the next chunk is exported): on two cores the
        host and XLA work side by side. :meth:`collect` gathers the results.
        """
        if not cands:
            return []
        # Grow first: every batch then has the same edge capacity.
        self.buckets.grow(max(len(c.keys) for c in cands))
        pending = []
        for batch in self.buckets.batches([len(c.point_ids) for c in cands]):
            packed = self.pack([cands[i] for i in batch])
            self.n_kernel_calls += 1
            with jax.enable_x64(self.dtype == np.float64):
                pending.append((batch, _cost.batched_stencil_cost_async(packed)))
        return pending

    def collect(self, cands: list[CandidateStencil], pending: list) -> tuple[np.ndarray, list]:
        """Results of :meth:`dispatch`: see :meth:`score`."""
        delta = np.zeros(len(cands))
        rows: list = [None] * len(cands)
        for batch, handle in pending:
            res = _cost.stencil_cost_to_host(handle)
            delta[batch] = np.asarray(res.total[: len(batch)]) - np.array([cands[i].before for i in batch])
            for r, i in enumerate(batch):
                rows[i] = (res, r)
        return delta, rows

    def score(self, cands: list[CandidateStencil]) -> tuple[np.ndarray, list[tuple[object, int]]]:
        """Cost increase ``delta`` of each candidate, batched.

        Candidates are scored in as few kernel calls as the bucket capacities
        allow (see :meth:`Buckets.batches`).

        Returns:
          ``(delta (len(cands),), rows)``; ``rows[i] = (result, r)`` locates
          candidate ``i`` in a kernel result, to pass to :meth:`apply`.
        """
        return self.collect(cands, self.dispatch(cands))

    # ------------------------------------------------------------- mutation
    def apply(self, cand: CandidateStencil, scored: tuple[object, int]) -> set[int]:
        """Performs a scored change (collapse or relocation) and updates the plan.

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
        tri = self.tri
        if cand.moved is None:
            new_ids = np.asarray(tri.collapse(plan), np.int64)
            for a in plan.ring:
                k = edge_key(plan.source, a)
                self.edge_cost.pop(k, None)
                self.edge_solid.pop(k, None)
        else:
            v = plan.source
            if tuple(tri.star(v)[1]) != plan.star:
                raise ValueError("stale relocation: the star has changed")
            tri.move(v, cand.moved)
            new_ids = np.asarray(plan.star, np.int64)
        for v in plan.ring + (plan.source, plan.target):
            self._star_version[v] += 1
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
        for i, (a, b) in enumerate(cand.keys):
            k = (int(a), int(b))
            self.edge_cost[k] = float(res.edge_cost[row, i])
            self.edge_solid[k] = bool(res.solid[row, i])
        dirty = set(plan.ring)
        dirty.add(plan.target)
        for f in new_ids:
            for g in tri.nbr[f]:
                if g >= 0:
                    dirty.update(tri.tri[g])
        return {v for v in dirty if tri.alive[v] and not tri.pinned[v]}
