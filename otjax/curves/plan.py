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

import itertools
from dataclasses import dataclass
from typing import NamedTuple

import jax
import numpy as np

from otjax.curves import scoring as _scoring
from otjax.curves.location import MIN_PAIRS as LOCATE_MIN_PAIRS
from otjax.curves.location import locate_pairs
from otjax.curves.predicates import orient_perturbed
from otjax.curves.triangulation import CollapsePlan, Triangulation, edge_key
from otjax.stencil import ragged_index

_NO_IDS = np.zeros(0, np.int64)
# Rows (point, candidate pairs) per kernel call in the decimation loop: large
# enough that the call overhead (~0.1 ms) is small against the work, small
# enough that the next chunk is exported while this one is scored. 2^15
# rather than 2^16: one compiled shape fewer below 200k points (50k: 19.6 ->
# 18.3 s, 200k: 44.0 -> 41.2 s; 1M unchanged, its stars need 2^16 alone).
ROW_BUDGET = 1 << 15
# What one more kernel call costs, in padded rows: a call's fixed cost
# (dispatch, reading results back, ~0.25 ms) over the cost of a row
# (~0.125 us): 4096 rows 0.76 ms, 8192 rows 1.27 ms, 32768 rows 4.34 ms.
CALL_ROWS = 1 << 11
# Jobs of at most 1/SMALL_JOB of the row budget are packed in export order
# (pack_next_fit): a batch then wastes less than 1/SMALL_JOB of its rows.
SMALL_JOB = 32
# Link changes remembered per vertex (see TransportPlan.changed_links); an
# older record is treated as a change of the star.
_LINK_LOG = 64


class CandidateStencil(NamedTuple):
    """One candidate change (collapse or relocation), exported for scoring.

    Attributes:
      plan: the topological plan (flips + collapse).
      keys: ``(E, 2)`` global keys of the local edges after the change,
        sorted; row ``i`` is local edge ``i``.
      edges: ``(E, 2, 2)`` endpoint coordinates, lower id first.
      point_ids: ``(P,)`` global ids of the stencil's points: the
        ``n_inside`` points of the changed region first, then the points
        outside it that keep their (link) edge.
      n_inside: number of points of the changed region.
      before: cost of the region's edges before the change.
      moved: for a relocation, the new position of ``plan.source`` (then
        ``plan.target == plan.source`` and the triangles are the star's own);
        ``None`` for a collapse.
      cand: ``(P, 3)`` local candidate edges per point (see
        :class:`~otjax.stencil.EdgeStencil`), or ``None`` when the points are
        left to the scoring kernel to locate (see :meth:`TransportPlan.export`).
      triangle_of_point: ``(P,)`` index into ``plan.new_triangles`` for the
        points of the changed region, ``-1`` for the others; ``None`` with
        ``cand``.
    """

    plan: CollapsePlan
    keys: np.ndarray
    edges: np.ndarray
    point_ids: np.ndarray
    n_inside: int
    before: float
    moved: np.ndarray | None = None
    cand: np.ndarray | None = None
    triangle_of_point: np.ndarray | None = None


class CandidateCost(NamedTuple):
    """The scored outcome of one candidate (host arrays, views into a batch).

    Attributes:
      delta: cost after the change minus ``before``.
      edge_cost, normal, tangential, vertex, edge_mass: ``(E,)`` per local
        edge, as in :class:`~otjax.curves.cost.StencilCost`.
      solid: ``(E,)`` bool.
      assignment: ``(P,)`` local edge of each point.
      triangle: ``(n_inside,)`` index into ``plan.new_triangles`` of the
        triangle holding each point of the changed region.
    """

    delta: float
    edge_cost: np.ndarray
    normal: np.ndarray
    tangential: np.ndarray
    vertex: np.ndarray
    edge_mass: np.ndarray
    solid: np.ndarray
    assignment: np.ndarray
    triangle: np.ndarray


class LinkRecord(NamedTuple):
    """What re-scoring a scored collapse needs when part of its stencil changed.

    A change next to the star of ``source`` (not in it) alters the points
    across some of its link edges and nothing else of its collapse stencils:
    their after-costs differ on those link edges only. Each link edge after
    the collapse holds the points of the changed region assigned to it
    (unchanged while the plan is) and the points across it that keep it.

    A move of a ring vertex ``m`` (relocation) changes the new triangles at
    ``m`` and the points across the link edges next to it; every other new
    triangle keeps its shape, hence its points and their edges. Only the
    edges of the changed triangles (and of the changed link edges) are
    scored again, on the subsequence of the full stencil that can reach
    them (see :meth:`TransportPlan.partial_job`).

    Attributes:
      plan: the collapse plan scored.
      version: the source's region version when scored (see
        :meth:`TransportPlan.changed_links`).
      keys: ``(E, 2)`` the candidate's local edge keys.
      edge_cost: ``(E,)`` cost of each local edge after the collapse.
      link_edge: ``(n,)`` local index of link edge ``k`` (``(ring[k], ring[k+1])``).
      link_start: ``(n + 1,)`` offsets of each link edge's points in ``link_points``.
      link_points: points of the changed region assigned to each link edge,
        in stencil order.
      inside: ``(P,)`` the region's points when scored, in stencil order
        (the region's own array, shared by the records of one source).
      triangle: ``(P,)`` int16 index into ``plan.new_triangles`` of the new
        triangle holding each point of ``inside``.
      edge: ``(P,)`` int16 local edge each point of ``inside`` goes to.
    """

    plan: CollapsePlan
    version: int
    keys: np.ndarray
    edge_cost: np.ndarray
    link_edge: np.ndarray
    link_start: np.ndarray
    link_points: np.ndarray
    inside: np.ndarray
    triangle: np.ndarray
    edge: np.ndarray

    def delta(self, before: float) -> float:
        """Cost increase of the collapse against the region's ``before``.

        The edge costs are added in local edge order, as the kernel's
        segment sum does: the greedy makes the same choices (exact ties
        and rounding included) with or without updates (tested).
        """
        return float(np.cumsum(self.edge_cost)[-1]) - before


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


def _triangle_edges(tris: np.ndarray) -> np.ndarray:
    """``(T, 3, 2)`` the edges of triangles ``(T, 3)``, each as ``(min, max)`` id."""
    return np.sort(np.stack([tris, tris[:, [1, 2, 0]]], -1), -1)


def pack_first_fit(sizes, budget: int) -> list[list[int]]:
    """Groups jobs into kernel batches, first fit by decreasing rows.

    The kernel's cost is per padded row (a padding row costs ~80% of a real
    one, measured), so the batches should fill their capacity. Cut in
    export order, a long list of stars of a few thousand rows each left a
    quarter of each 32k-row batch empty; sorted by size and placed first
    fit, the small candidates fill the gaps the large ones leave (50k
    points, last 40 collapses: 28.9M padded rows -> 26.0M, 926 -> 839 calls).

    Args:
      sizes: ``(rows, edges, triangles)`` of each job.
      budget: row capacity of a batch (a capacity class); a job that needs
        more opens a batch of its own capacity, which smaller jobs then fill.

    Returns:
      Batches as lists of job indices, each in increasing order; every job
      in exactly one. A batch holds jobs while :func:`scoring.capacity` of
      its totals stays within its limit (the larger of ``budget`` and its
      first job's own capacity), and a job goes to the first batch with room.
    """
    order = sorted(range(len(sizes)), key=lambda i: -sizes[i][0])
    bins: list[list] = []  # [members, rows, edges, triangles, limit]
    for i in order:
        r, e, t = sizes[i]
        for b in bins:
            # Rows bind first: skip the capacity call for batches without room.
            if b[1] + r <= b[4] and _scoring.capacity(b[1] + r, b[2] + e, b[3] + t, len(b[0]) + 1) <= b[4]:
                b[0].append(i)
                b[1] += r
                b[2] += e
                b[3] += t
                break
        else:
            bins.append([[i], r, e, t, max(budget, _scoring.capacity(r, e, t, 1))])
    return [sorted(b[0]) for b in bins]


def pack_next_fit(sizes, budget: int) -> list[list[int]]:
    """Groups jobs into kernel batches in their order, each batch closed when
    the next job does not fit it (limits as in :func:`pack_first_fit`).

    For many small jobs (a parallel round re-scores thousands of
    candidates of a few dozen rows): a batch then wastes less than one job,
    and first fit would test every job against every batch.
    """
    batches: list[list[int]] = []
    rows = edges = tris = limit = 0
    for i, (r, e, t) in enumerate(sizes):
        alone = _scoring.capacity(r, e, t, 1)
        if not batches or _scoring.capacity(rows + r, edges + e, tris + t, len(batches[-1]) + 1) > max(limit, alone):
            batches.append([])
            rows = edges = tris = 0
            limit = budget
        batches[-1].append(i)
        rows, edges, tris, limit = rows + r, edges + e, tris + t, max(limit, alone)
    return batches


class TransportPlan:
    """Points, their triangles and edges, and cached per-edge costs.

    Args:
      tri: the triangulation (owned and mutated by this plan).
      points: ``(n, 2)`` float64 input points.
      mass: ``(n,)`` float64 non-negative masses.
      dtype: float dtype of the cost arithmetic (float64 for exact greedy
        order); point location is float64 whatever this is.
      max_source_degree: half-edges leaving a vertex of higher degree are not
        candidates until its degree falls (see :meth:`candidates`).
    """

    def __init__(self, tri: Triangulation, points: np.ndarray, mass: np.ndarray,
                 dtype=np.float64, max_source_degree: int = 32):
        self.tri = tri
        self.points = np.asarray(points, np.float64)
        self.mass = np.asarray(mass, np.float64)
        self._point_rows = np.ascontiguousarray(self.points.T)  # (2, n): gathers stay contiguous
        self.dtype = dtype
        self.n_kernel_calls = 0
        self.location_kernel_used = False
        self.shapes_seen: set[int] = set()  # row capacities of the scoring kernel
        # Input buffers of finished kernel calls, by capacity (PackedBuffers).
        self._buffers: dict[int, list[PackedBuffers]] = {}
        self.max_source_degree = max_source_degree
        # Collapse plans depend only on the stars of their two ends: cache
        # them, stamped with per-vertex versions bumped when a star changes.
        self._star_version = [0] * len(tri.xy)
        # Regions (see _region) likewise, stamped with a version bumped for
        # every vertex a change makes dirty (a superset of those whose region
        # it touches: see apply).
        self._region_version = [0] * len(tri.xy)
        self._regions: dict[int, tuple] = {}
        # What each change did to the vertices it made dirty (see
        # changed_links): the region version of the last change of the star
        # itself, and since then the link edges whose far side changed.
        self._star_changed_at: dict[int, int] = {}
        self._link_log: dict[int, list[tuple[int, frozenset, frozenset]]] = {}
        self._slot: np.ndarray | None = None  # scratch of _positions
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
    def _score_all_edges(self) -> None:
        """Computes the cost of every edge that holds points, in batches."""
        keys = self.pt_edge[:, 0] * len(self.tri.xy) + self.pt_edge[:, 1]
        order = np.argsort(keys, kind="stable")
        _uniq, starts = np.unique(keys[order], return_index=True)
        ends = self.pt_edge[order[starts]]  # (n_edges, 2)
        per_edge = self._edge_costs([(p,) for p in np.split(order, starts[1:])], ends)
        for (u, v), c, solid in zip(ends.tolist(), per_edge[:, 0].tolist(), (per_edge[:, 5] > 0).tolist()):
            self.edge_cost[(u, v)] = c
            self.edge_solid[(u, v)] = solid

    @property
    def compiled_shapes(self) -> int:
        """Distinct kernel shapes this plan has used: scoring kernel and location kernel."""
        return len(self.shapes_seen) + int(self.location_kernel_used)

    def solid_of(self, keys: np.ndarray) -> np.ndarray:
        """``(n,)`` bool: whether each edge key of ``keys (n, 2)`` is solid.

        Looks each distinct key up once (points share few edges).
        """
        keys = np.asarray(keys, np.int64).reshape(-1, 2)
        if not len(keys):
            return np.zeros(0, bool)
        nv = len(self.tri.xy)
        uniq, inv = np.unique(keys[:, 0] * nv + keys[:, 1], return_inverse=True)  # 1D: 10x faster than axis=0
        get = self.edge_solid.get
        flags = np.fromiter((get((int(c // nv), int(c % nv)), False) for c in uniq), bool, len(uniq))
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

        Cached until a change makes ``v`` dirty. Returns ``(ring, star, inside, outside, outside_link, before)``: the
        points in the star; the points of the faces across the link edges that
        are assigned to those edges, with the link edge index ``k`` (edge
        ``(ring[k], ring[k+1])``) of each; and the cost of every edge of the
        star (spokes and link), which is what any change of the star replaces.
        """
        hit = self._regions.get(v)
        if hit is not None and hit[0] == self._region_version[v]:
            return hit[1]
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
        nxt = np.asarray(ring[1:] + ring[:1], np.int64)
        lo, hi = np.minimum(r, nxt), np.maximum(r, nxt)
        e = np.take(self.pt_edge, ids, axis=0)
        keep = (e[:, 0] == lo[link]) & (e[:, 1] == hi[link])
        region = ring, star, inside, ids[keep], link[keep], before
        self._regions[v] = (self._region_version[v], region)
        return region

    def changed_links(self, v: int, since: int) -> set | None:
        """Link edges of ``v``'s star whose far side changed after region
        version ``since``; ``None`` if the star itself may have changed
        (its triangles, or the position of a ring vertex)."""
        changes = self._changes(v, since)
        return None if changes is None or changes[1] else changes[0]

    def _changes(self, v: int, since: int) -> tuple[set, set] | None:
        """``(link edge keys, moved ring vertices)`` changed around ``v``
        after region version ``since``, or ``None`` if its triangles did."""
        if self._star_changed_at.get(v, -1) > since:
            return None
        keys: set = set()
        moved: set = set()
        for version, k, m in self._link_log.get(v, ()):
            if version > since:
                keys |= k
                moved |= m
        return keys, moved

    def record_changes(self, rec: LinkRecord) -> tuple[set, set] | None:
        """What changed since ``rec`` was scored: ``(link edge keys, moved
        ring vertices)``, or ``None`` if it must be scored again in full:
        its source's star changed, its target moved, or the plan of its
        half-edge changed (the target's star changed how the collapse is
        made)."""
        changes = self._changes(rec.plan.source, rec.version)
        if changes is None or rec.plan.target in changes[1]:
            return None
        if self._plan(rec.plan.source, rec.plan.target) != rec.plan:
            return None
        return changes

    def link_record(self, cand: CandidateStencil, scored: CandidateCost) -> LinkRecord:
        """The :class:`LinkRecord` of a scored collapse, valid at the current state."""
        n = cand.n_inside
        inside = self._region(cand.plan.source)[2]
        if len(inside) != n:
            raise RuntimeError("the region changed since the candidate was exported")
        return self._record(cand.plan, cand.keys, np.asarray(scored.edge_cost, np.float64), inside,
                            scored.triangle[:n].astype(np.int16), scored.assignment[:n].astype(np.int16))

    def _record(self, plan: CollapsePlan, keys, edge_cost, inside, triangle, edge) -> LinkRecord:
        ring = np.asarray(plan.ring, np.int64)
        nxt = np.asarray(plan.ring[1:] + plan.ring[:1], np.int64)
        nv = len(self.tri.xy)
        code = keys[:, 0] * nv + keys[:, 1]  # keys are sorted
        link_edge = np.searchsorted(code, np.minimum(ring, nxt) * nv + np.maximum(ring, nxt))
        which = np.full(len(code), -1, np.int64)
        which[link_edge] = np.arange(len(ring))
        k = which[edge]
        on_link = np.flatnonzero(k >= 0)
        order = on_link[np.argsort(k[on_link], kind="stable")]
        start = np.searchsorted(k[order], np.arange(len(ring) + 1))
        return LinkRecord(plan, self._region_version[plan.source], keys, edge_cost, link_edge, start,
                          inside[order], inside, triangle, edge)

    def partial_job(self, rec: LinkRecord, changed: set, moved: set):
        """The part of ``rec``'s collapse that ring moves (and link changes)
        since it was scored reach, as an export job, or ``None`` if that is
        all of it.

        Affected: the local edges of the new triangles with a moved vertex,
        and the link edges whose far side changed (listed in ``changed``,
        or across a face with a moved vertex). The job's rows are the
        subsequence of the full stencil's rows (same order) that can reach
        an affected edge: points not known to lie in an unchanged new
        triangle (located by the kernel: they lie in a changed one), points
        of unchanged triangles recorded on an affected edge (fixed to it),
        and the points across affected link edges. An edge whose points
        come in another order than when scored (a move rebuilds the point
        lists of its faces) is affected too: its sum would round otherwise. Each affected edge thus
        gets the points a full scoring would give it, in the same order,
        and the kernel's costs for it are the full scoring's, bit for bit.

        Returns:
          ``(job, pending)``: the job for :meth:`exports` (``extra``) and
          what :meth:`finish_partial` needs with its scores.
        """
        plan = rec.plan
        v = plan.source
        tri = self.tri
        ring, star, inside, outside, outside_link, before = self._region(v)
        tris = np.asarray(plan.new_triangles, np.int64)
        mv = np.fromiter(moved, np.int64, len(moved))
        changed_tri = np.isin(tris, mv).any(1)
        if changed_tri.all():
            return None
        nv = len(tri.xy)
        code = rec.keys[:, 0] * nv + rec.keys[:, 1]
        e = _triangle_edges(tris[changed_tri]).reshape(-1, 2)
        affected = np.zeros(len(code), bool)
        affected[np.searchsorted(code, e[:, 0] * nv + e[:, 1])] = True
        n = len(ring)
        for k in range(n):
            f = star[k]
            g = tri.nbr[f][tri.tri[f].index(v)]
            if (g >= 0 and any(x in moved for x in tri.tri[g])) or edge_key(ring[k], ring[(k + 1) % n]) in changed:
                affected[rec.link_edge[k]] = True
        pos = self._positions(rec.inside, inside)
        known = pos >= 0
        old_tri = np.where(known, rec.triangle[np.maximum(pos, 0)], 0)
        fixed = known & ~changed_tri[old_tri]
        fixed_edge = np.where(fixed, rec.edge[np.maximum(pos, 0)], -1)
        # The move re-sorted the points of its faces: an edge whose points
        # now come in another order sums them in another order. Scored again.
        rows = np.flatnonzero(fixed)
        order = rows[np.argsort(fixed_edge[rows], kind="stable")]
        e, p = fixed_edge[order], pos[order]
        affected[e[1:][(e[1:] == e[:-1]) & (p[1:] < p[:-1])]] = True
        take = ~fixed | affected[np.maximum(fixed_edge, 0)]
        take_out = affected[rec.link_edge][outside_link]
        region = (ring, star, inside[take], outside[take_out], outside_link[take_out], before)
        job = (plan, tris, region, None, fixed_edge[take])
        return job, (rec, affected, changed_tri, inside, pos, fixed, take)

    def finish_partial(self, pending, cand: CandidateStencil, scored: CandidateCost) -> tuple[LinkRecord, float]:
        """The record and cost increase of a collapse scored by :meth:`partial_job`."""
        rec, affected, changed_tri, inside, pos, fixed, take = pending
        edge_cost = rec.edge_cost.copy()
        edge_cost[affected] = scored.edge_cost[affected]
        p = np.maximum(pos, 0)
        triangle = np.where(fixed, rec.triangle[p], -1).astype(np.int16)
        edge = np.where(fixed, rec.edge[p], -1).astype(np.int16)
        located = np.flatnonzero(take & ~fixed)
        sub = (np.cumsum(take) - 1)[located]
        triangle[located] = scored.triangle[sub]
        edge[located] = scored.assignment[sub]
        if not changed_tri[triangle[located]].all():
            raise RuntimeError("a point outside the changed triangles was located by a partial update")
        new = self._record(rec.plan, rec.keys, edge_cost, inside, triangle, edge)
        return new, new.delta(self._region(rec.plan.source)[5])

    def _positions(self, old: np.ndarray, new: np.ndarray) -> np.ndarray:
        """Index of each of ``new`` in ``old`` (ids of points), ``-1`` if absent."""
        if self._slot is None or len(self._slot) != len(self.points):
            self._slot = np.full(len(self.points), -1, np.int64)
        slot = self._slot
        slot[old] = np.arange(len(old))
        out = slot[new]
        slot[old] = -1
        return out

    def link_updates(self, items, budget: int = ROW_BUDGET):
        """Re-scores collapses whose link changed: the changed link edges only.

        Args:
          items: ``(record, changed)`` pairs: a :class:`LinkRecord` and the
            keys of its changed link edges (from :meth:`record_changes`).

        Returns:
          ``[(record, delta)]``: each record brought up to date, and the
          collapse's cost increase: the values of a full re-scoring, since
          each edge gets the same points in the same order.
        """
        parts, edges, where = [], [], []
        for i, (rec, changed) in enumerate(items):
            region = self._region(rec.plan.source)
            ring = region[0]
            n = len(ring)
            for k in range(n):
                if edge_key(ring[k], ring[(k + 1) % n]) not in changed:
                    continue
                parts.append((rec.link_points[rec.link_start[k]: rec.link_start[k + 1]],
                              region[3][region[4] == k]))
                edges.append(rec.keys[rec.link_edge[k]])
                where.append((i, rec.link_edge[k]))
        costs = self._edge_costs(parts, np.asarray(edges, np.int64).reshape(-1, 2), budget)[:, 0]
        new_cost = [rec.edge_cost.copy() for rec, _ in items]
        for (i, e), c in zip(where, costs.tolist()):
            new_cost[i][e] = c
        out = []
        for (rec, _), cost in zip(items, new_cost):
            v = rec.plan.source
            rec = rec._replace(version=self._region_version[v], edge_cost=cost)
            out.append((rec, rec.delta(self._region(v)[5])))
        return out

    def _edge_costs(self, parts, keys: np.ndarray, budget: int = ROW_BUDGET) -> np.ndarray:
        """Costs of the edges ``keys (n, 2)``, edge ``i`` holding the points
        of ``parts[i]`` (id arrays, concatenated in order).

        Whole edges per batch, about ``budget`` rows each (within the
        capacities the decimation loop uses anyway: no shape of their own),
        each batch dispatched before the last is read.

        Returns:
          ``(n, 6)`` the kernel's per-edge fields (``scoring.EDGE_FIELDS``).
        """
        counts = np.fromiter((sum(map(len, p)) for p in parts), np.int64, len(parts))
        xy = self.tri.xy

        def batches():
            first = 0
            while first < len(parts):
                rows = np.cumsum(counts[first:])
                last = first + max(1, int(np.searchsorted(rows, budget, side="right")))
                last = min(last, first + budget // _scoring.EDGES_PER_ROW - 1)
                ids = np.concatenate([a for p in parts[first:last] for a in p]).astype(np.int64)
                edge_of_row = np.repeat(np.arange(last - first), counts[first:last])
                yield _Flat.without_triangles(
                    ids, np.repeat(edge_of_row[:, None], 3, 1), np.zeros(len(ids), np.int64),
                    xy[keys[first:last]], np.zeros(last - first, np.int64), [None])
                first = last

        out, pending = [np.zeros((0, 6))], None
        for flat in batches():
            handle = self.dispatch(flat)
            if pending is not None:
                out.append(self._host(*pending)[1])
            pending = flat, handle
        if pending is not None:
            out.append(self._host(*pending)[1])
        return np.concatenate(out)

    def prefetch(self, half_edges) -> None:
        """Reads the regions and collapse plans of ``half_edges`` into their
        caches, where they stay valid until a change touches them: host work
        to do while a kernel runs."""
        for u, w in half_edges:
            if self._collapsible_source(u):
                self._region(u)
                self._plan(u, w)

    def exports(self, sources, targets: dict | None = None, budget: int = ROW_BUDGET, extra=()):
        """Yields :meth:`export` batches of the half-edges leaving ``sources``.

        Candidates are packed into batches of row capacity ``budget`` (a
        capacity class; a candidate that needs more gets its own capacity,
        filled by smaller ones) by :func:`pack_first_fit`: the kernel's cost
        is per padded row, and full batches keep padding small (cut by
        sources, half the rows were padding) and the shapes few. Sizes come
        from the cached regions and plans; the export itself is a
        generator, so that the next batch is exported while the kernel
        scores the last. Each batch's ``seq`` says where its candidates
        stand in source then ring order. ``extra``: more jobs, after those
        (:meth:`partial_job`).
        """
        # Lazy: the jobs are listed at the first batch (timed as export).
        jobs = itertools.chain((job for v in sources for job in self._collapse_jobs([v], targets)), extra)
        return self._batches(jobs, budget)

    def relocation_exports(self, moves, budget: int = ROW_BUDGET):
        """:meth:`exports` for the moves of :meth:`relocation_candidates`."""
        return self._batches(self._relocation_jobs(moves), budget)

    def _batches(self, jobs_iter, budget: int):
        jobs = list(jobs_iter)
        # Edges of a triangulated disc of t triangles: at most 2 t + 1.
        sizes = [(len(job[2][2]) + len(job[2][3]), 2 * len(job[1]) + 1, len(job[1])) for job in jobs]
        # Jobs that are small against a batch fill it in any order; first fit
        # pays for large ones (it is quadratic in the batches).
        small = not sizes or max(x[0] for x in sizes) <= budget // SMALL_JOB
        packing = (pack_next_fit if small else pack_first_fit)(sizes, budget)
        # A batch of 4-16k rows pads to the budget's shape (see _shape_for):
        # a few calls of the smallest shape may cost less (and run side by
        # side). The packing with the fewer padded rows (a call counted as
        # CALL_ROWS more) is kept.
        if _scoring.MIN_ROWS < budget and sum(x[0] for x in sizes) <= 2 * budget:
            other = pack_first_fit(sizes, _scoring.MIN_ROWS)
            if self._padded_rows(other, sizes) < self._padded_rows(packing, sizes):
                packing = other
        for members in packing:
            flat = self._export([jobs[i] for i in members], on_host=False)
            flat.seq = np.asarray(members, np.int64)
            yield flat

    def _padded_rows(self, packing, sizes) -> int:
        """Rows the kernel calls of ``packing`` would pad to, plus
        :data:`CALL_ROWS` per call."""
        total = 0
        for members in packing:
            r, e, t = (sum(sizes[i][k] for i in members) for k in range(3))
            total += self._shape_for(_scoring.capacity(r, e, t, len(members))) + CALL_ROWS
        return total

    def _collapsible_source(self, v: int) -> bool:
        """Whether half-edges leaving ``v`` are candidates: live, free, and
        of degree within the kernel's bound."""
        tri = self.tri
        return bool(tri.alive[v]) and not tri.pinned[v] and len(tri.star(v)[0]) <= self.max_source_degree

    def _collapse_jobs(self, sources, targets):
        jobs = []
        for v in sources:
            if not self._collapsible_source(v):
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
                    jobs.append((plan, np.asarray(plan.new_triangles, np.int64), region, None, None))
        return jobs

    def export(self, sources, targets: dict | None = None) -> _Flat:
        """Exports the half-edges leaving ``sources`` as one flat batch, unlocated.

        What :meth:`candidates` does, except that the points of each changed
        region are left for the scoring kernel to locate (see
        :mod:`otjax.curves.scoring`): the decimation loop's fast path. Pass
        the result to :meth:`dispatch`; its candidates are ``.cands``.
        """
        return self._export(self._collapse_jobs(sources, targets), on_host=False)

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
          Candidates in order of ``sources`` then ring order, every point
          located (``cand`` and ``triangle_of_point`` set); half-edges that
          cannot be collapsed are left out.
        """
        return self._export(self._collapse_jobs(sources, targets), on_host=True).cands

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
          One located candidate per move whose ``position`` lies strictly
          inside the kernel of the one-ring of ``v`` (the only moves that
          keep the embedding); the others are left out.
        """
        return self._export(list(self._relocation_jobs(moves)), on_host=True).cands

    def _relocation_jobs(self, moves):
        tri = self.tri
        for v, position in moves:
            position = np.asarray(position, np.float64)
            ring, star = tri.star(v)
            if not tri.in_kernel_at(ring, position):
                continue
            n = len(ring)
            tris = np.array([[v, ring[k], ring[(k + 1) % n]] for k in range(n)], np.int64)
            plan = CollapsePlan(v, v, tuple(ring), tuple(star), (), (), tuple(map(tuple, tris.tolist())))
            yield plan, tris, self._region(v), position, None

    def relocation_candidate(self, v: int, position) -> CandidateStencil | None:
        """The stencil of moving ``v`` to ``position``, or ``None`` if that
        would fold a triangle over (see :meth:`relocation_candidates`)."""
        out = self.relocation_candidates([(v, position)])
        return out[0] if out else None

    def _export(self, jobs, on_host: bool) -> _Flat:
        """Builds the flat batch of ``(plan, triangles, region, moved)`` jobs.

        Everything is done on concatenated arrays over all jobs (edge keys,
        flat numbering, fans); the per-job Python work is slicing only.
        ``on_host``: locate every point here (exactly); otherwise only the
        points of jobs with more ears than the kernel tests.
        """
        if not jobs:
            return _Flat.empty()
        xy = self.tri.xy
        nv = len(xy)
        nj = len(jobs)
        n_tri = np.array([len(job[1]) for job in jobs])
        tris = np.concatenate([job[1] for job in jobs])  # (T, 3)
        tri_job = np.repeat(np.arange(nj), n_tri)
        coords = xy[tris]  # (T, 3, 2)
        tri_start = np.concatenate([[0], np.cumsum(n_tri)])
        for j, (plan, t, _region, moved, _fixed) in enumerate(jobs):
            if moved is not None:
                s = slice(tri_start[j], tri_start[j + 1])
                coords[s] = np.where((t == plan.source)[..., None], moved, coords[s])
        coords_rows = np.ascontiguousarray(coords.reshape(-1, 6).T)  # (6, T)

        # Local edges: keys coded job-major, so np.unique numbers every job's
        # edges contiguously and in increasing key order within the job:
        # the flat number of an edge is its job's offset plus its local one.
        e = _triangle_edges(tris)  # (T, 3, 2)
        code = (np.repeat(tri_job, 3) * nv + e[..., 0].ravel()) * nv + e[..., 1].ravel()
        ucode, inv = np.unique(code, return_inverse=True)
        edge_job = ucode // (nv * nv)
        edge_start = np.searchsorted(edge_job, np.arange(nj + 1))
        ukeys = np.stack([(ucode // nv) % nv, ucode % nv], 1)
        tri_edges = np.sort(inv.reshape(-1, 3), 1)
        edge_xy = xy[ukeys]
        for j, (plan, _t, _region, moved, _fixed) in enumerate(jobs):
            if moved is not None:
                es = slice(edge_start[j], edge_start[j + 1])
                edge_xy[es] = np.where((ukeys[es] == plan.source)[..., None], moved, edge_xy[es])

        # Rows: per job, the points of the region, then the points across its
        # link that keep their link edge.
        n_in = np.array([len(job[2][2]) for job in jobs])
        n_out = np.array([len(job[2][3]) for job in jobs])
        n_rows = n_in + n_out
        row_start = np.concatenate([[0], np.cumsum(n_rows)])
        parts = []
        for job in jobs:
            parts += [job[2][2], job[2][3]]
        row_point = np.concatenate(parts).astype(np.int64)
        row_job = np.repeat(np.arange(nj), n_rows)
        row_cand = np.zeros((len(row_point), 3), np.int64)
        row_locate = np.ones(len(row_point), bool)
        if n_out.sum():
            out_job, k = ragged_index(n_out)
            out_rows = row_start[out_job] + n_in[out_job] + k
            ring_arr = [np.asarray(job[2][0], np.int64) for job in jobs]
            a = np.concatenate([r[job[2][4]] for r, job in zip(ring_arr, jobs)])
            b = np.concatenate([r[(job[2][4] + 1) % len(r)] for r, job in zip(ring_arr, jobs)])
            lk = (out_job * nv + np.minimum(a, b)) * nv + np.maximum(a, b)
            row_cand[out_rows] = np.searchsorted(ucode, lk)[:, None]
            row_locate[out_rows] = False
        # Rows of the region whose edge is known (partial_job): fixed to it.
        for j, job in enumerate(jobs):
            if job[4] is not None:
                k = np.flatnonzero(job[4] >= 0)
                row_cand[row_start[j] + k] = (edge_start[j] + job[4][k])[:, None]
                row_locate[row_start[j] + k] = False

        # Fans: the new triangles of a job are its flipped-out ears, then a
        # fan around one apex (the target, or the moved vertex), CCW.
        n_flip = np.fromiter((len(job[0].flipped_out) for job in jobs), np.int64, nj)
        fan_start = tri_start[:-1] + n_flip
        n_fan = n_tri - n_flip
        job_fan = np.concatenate([[0], np.cumsum(n_fan)])
        fan_job, k = ragged_index(n_fan)
        fan_tri = fan_start[fan_job] + k
        apex = coords[fan_start, 0]  # (J, 2): fan triangles are (apex, a, b)
        d = coords[fan_start, 1] - apex
        theta = _scoring.pseudo_angle(d[:, 0], d[:, 1])
        d = coords[fan_tri, 1] - apex[fan_job]
        phi = np.mod(_scoring.pseudo_angle(d[:, 0], d[:, 1]) - theta[fan_job], 4.0)
        phi[job_fan[:-1]] = 0.0
        ears = np.full((nj, _scoring.MAX_EARS), -1, np.int64)
        few = n_flip <= _scoring.MAX_EARS
        ej, k = ragged_index(np.where(few, n_flip, 0))
        ears[ej, k] = tri_start[ej] + k

        flat = _Flat(
            cands=[], row_point=row_point, row_job=row_job, row_cand=row_cand, row_locate=row_locate,
            row_tri=np.full(len(row_point), -1, np.int64), row_start=row_start, edge_start=edge_start,
            tri_start=tri_start, edge_xy=edge_xy, edge_job=edge_job, tri_xy=coords_rows, tri_edges=tri_edges,
            fan_key=fan_job * 8.0 + phi, fan_tri=fan_tri, job_fan=job_fan, job_apex=apex, job_theta=theta,
            job_ears=ears, before=np.array([job[2][5] for job in jobs]))
        if on_host:
            self._locate_on_host(flat, np.arange(nj))
        elif not few.all():
            self._locate_on_host(flat, np.flatnonzero(~few))

        for j, (plan, _t, _region, moved, _fixed) in enumerate(jobs):
            es = slice(edge_start[j], edge_start[j + 1])
            rs = slice(row_start[j], row_start[j + 1])
            cand = tri = None
            if on_host:
                cand = row_cand[rs] - edge_start[j]
                tri = flat.row_tri[rs]
            flat.cands.append(CandidateStencil(plan, ukeys[es], edge_xy[es], row_point[rs], int(n_in[j]),
                                               float(flat.before[j]), moved, cand, tri))
        return flat

    def _locate_on_host(self, flat: _Flat, jobs: np.ndarray) -> None:
        """Locates the region points of ``jobs`` exactly, on the host.

        Sets their ``row_cand`` and ``row_tri`` and clears ``row_locate``.

        A guess first: the angular sector around the fan apex that the point
        falls in (one ``searchsorted`` for all jobs). The exact test confirms
        each guess; points it rejects (in an ear, near a sector boundary, on
        the apex) are tested against every new triangle of their job. So the
        answer is the exact perturbed location in every case, at about one
        tested pair per point instead of ``deg - 2``.
        """
        in_job = np.zeros(len(flat.row_start) - 1, bool)
        in_job[jobs] = True
        rows = np.flatnonzero(flat.row_locate & in_job[flat.row_job])
        if not len(rows):
            return
        inside = flat.row_point[rows]
        pt_job = flat.row_job[rows]
        tri_start = flat.tri_start
        n_tri = np.diff(tri_start)
        d = np.take(self.points, inside, axis=0) - flat.job_apex[pt_job]
        phi = np.mod(_scoring.pseudo_angle(d[:, 0], d[:, 1]) - flat.job_theta[pt_job], 4.0)
        lo, hi = flat.job_fan[pt_job], flat.job_fan[pt_job + 1] - 1
        g = np.clip(np.searchsorted(flat.fan_key, pt_job * 8.0 + phi, side="right") - 1, lo, hi)
        guess = flat.fan_tri[g]
        ok = locate_pairs(flat.tri_xy[:, guess], self._point_rows[:, inside])
        self.location_kernel_used |= len(inside) >= LOCATE_MIN_PAIRS
        found = np.where(ok, guess, -1)
        rest = np.flatnonzero(~ok)
        if len(rest):
            job = pt_job[rest]
            pair_pt, k = ragged_index(n_tri[job])
            pair_tri = tri_start[job][pair_pt] + k
            hold = locate_pairs(flat.tri_xy[:, pair_tri], self._point_rows[:, inside[rest[pair_pt]]])
            self.location_kernel_used |= len(pair_pt) >= LOCATE_MIN_PAIRS
            hit = np.flatnonzero(hold)
            # The perturbed location is a partition: exactly one triangle each.
            if len(hit) != len(rest) or np.any(pair_pt[hit] != np.arange(len(rest))):
                raise RuntimeError("a point of the star is not covered exactly once after the change")
            found[rest] = pair_tri[hit]
        flat.row_cand[rows] = flat.tri_edges[found]
        flat.row_tri[rows] = found - tri_start[pt_job]
        flat.row_locate[rows] = False

    def _flat_of(self, cands: list[CandidateStencil]) -> _Flat:
        """A flat batch of located candidates (from :meth:`candidates` and kin)."""
        if any(c.cand is None for c in cands):
            raise ValueError("candidates from export() are scored through dispatch(export)")
        n_edges = np.array([len(c.keys) for c in cands], np.int64)
        edge_start = np.concatenate([[0], np.cumsum(n_edges)])
        n_rows = np.array([len(c.point_ids) for c in cands], np.int64)
        row_job = np.repeat(np.arange(len(cands)), n_rows)
        return _Flat.without_triangles(
            np.concatenate([c.point_ids for c in cands]),
            np.concatenate([c.cand for c in cands]) + edge_start[row_job][:, None], row_job,
            np.concatenate([c.edges for c in cands]), np.repeat(np.arange(len(cands)), n_edges), cands,
            before=np.array([c.before for c in cands]),
            row_tri=np.concatenate([c.triangle_of_point for c in cands]))

    def dispatch(self, flat: _Flat):
        """Pads ``flat`` and dispatches the scoring kernel; does not wait.

        The kernel runs while the caller goes on (in the decimation loop,
        exports the next chunk: on two cores the host and XLA work side by
        side). :meth:`collect` gathers the results.
        """
        if not flat.cands:
            return None
        r = self._shape_for(flat.capacity())
        free = self._buffers.get(r)
        buffers = free.pop() if free else PackedBuffers(r)
        floats, ints = flat.packed(self.points, self.mass, r, out=buffers)
        self.shapes_seen.add(r)
        self.n_kernel_calls += 1
        with jax.enable_x64(True):
            return _scoring.score_packed(floats, ints, rows=r, dtype=self.dtype), buffers

    @staticmethod
    def _shape_for(need: int) -> int:
        """Row capacity a batch that needs ``need`` rows is scored at.

        At or below the budget, two shapes only: ``MIN_ROWS`` and
        ``ROW_BUDGET``. Each shape costs ~1 s of compilation (two cores
        busy); batches between the two are packed into ``MIN_ROWS`` calls
        where their candidates allow (:meth:`_batches`), and the few that
        do not pad to the budget (50k points: the 8192-row shape compiled
        mid-run cost more than the padding it saved). Larger batches, a
        star's candidates each, come by the thousand late in a large run:
        their own capacity class pays.
        """
        if need <= _scoring.MIN_ROWS:
            return _scoring.MIN_ROWS
        return ROW_BUDGET if need <= ROW_BUDGET else need

    def _host(self, flat: _Flat, pending):
        """The kernel's outputs as host arrays, cut to the batch's real jobs,
        edges and rows (waits for the kernel, then takes its input buffers
        back for reuse)."""
        outputs, buffers = pending
        total, per_edge, assignment, located, unresolved = jax.device_get(outputs)
        self._buffers.setdefault(buffers.r, []).append(buffers)
        nj, ne, nr = len(flat.row_start) - 1, len(flat.edge_job), len(flat.row_point)
        return total[:nj], per_edge[:ne], assignment[:nr], located[:nr], unresolved[:nj]

    def _run(self, flat: _Flat):
        """Dispatches ``flat`` and waits: :meth:`_host` of its outputs."""
        return self._host(flat, self.dispatch(flat))

    def collect(self, flat: _Flat, pending) -> tuple[np.ndarray, list[CandidateCost]]:
        """Results of :meth:`dispatch`: see :meth:`score`.

        Jobs with a point the kernel could not locate (its filter unsure:
        points on or within rounding of an edge, frequent on exactly
        collinear input) are located on the host and scored again.
        """
        if pending is None:
            return np.zeros(0), []
        total, per_edge, assignment, located, unresolved = self._host(flat, pending)
        bad = np.flatnonzero(unresolved)
        if len(bad):
            self._locate_on_host(flat, bad)
            total, per_edge, assignment, located, _ = self._run(flat)
        delta = total - flat.before
        # Local numbering: flat edges minus the job's offset, likewise triangles.
        assignment = assignment - flat.edge_start[flat.row_job]
        triangle = np.where(flat.row_locate, located - flat.tri_start[flat.row_job], flat.row_tri)
        fields = [per_edge[:, i] for i in range(6)]
        fields[5] = fields[5] > 0
        out = []
        for j, c in enumerate(flat.cands):
            es = slice(flat.edge_start[j], flat.edge_start[j + 1])
            r0 = flat.row_start[j]
            rs = slice(r0, flat.row_start[j + 1])
            out.append(CandidateCost(float(delta[j]), *(f[es] for f in fields), assignment[rs],
                                     triangle[r0:r0 + c.n_inside]))
        return delta, out

    def score(self, cands: list[CandidateStencil]) -> tuple[np.ndarray, list[CandidateCost]]:
        """Cost increase ``delta`` of each located candidate, batched.

        Candidates are scored in batches of about :data:`ROW_BUDGET` rows,
        one kernel call each (see :meth:`score_batches`).

        Returns:
          ``(delta (len(cands),), costs)``; ``costs[i]`` is the
          :class:`CandidateCost` of candidate ``i``, to pass to :meth:`apply`.
        """
        chunks, run, used = [], [], 0
        for c in cands:
            if run and used + len(c.point_ids) > ROW_BUDGET:
                chunks.append(run)
                run, used = [], 0
            run.append(c)
            used += len(c.point_ids)
        if run:
            chunks.append(run)
        _, delta, costs = self.score_batches(self._flat_of(chunk) for chunk in chunks)
        return delta, costs

    def score_batches(self, flats) -> tuple[list[CandidateStencil], np.ndarray, list[CandidateCost]]:
        """Scores an iterable of batches (e.g. :meth:`exports`), pipelined:
        each batch is dispatched before the last one is collected.

        Returns:
          ``(cands, delta, costs)`` over all batches, in the order of the
          jobs they were exported from (batches packed out of order, see
          :func:`pack_first_fit`, are put back in it), else in batch order.
        """
        cands, deltas, costs, seqs = [], [np.zeros(0)], [], [_NO_IDS]
        pending = None

        def read(flat, handle):
            d, c = self.collect(flat, handle)
            deltas.append(d)
            costs.extend(c)
            seqs.append(len(cands) + np.arange(len(flat.cands)) if flat.seq is None else flat.seq)
            cands.extend(flat.cands)

        for flat in flats:
            handle = self.dispatch(flat)
            if pending is not None:
                read(*pending)
            pending = (flat, handle)
        if pending is not None:
            read(*pending)
        delta = np.concatenate(deltas)
        order = np.argsort(np.concatenate(seqs), kind="stable")
        return [cands[i] for i in order], delta[order], [costs[i] for i in order]

    # ------------------------------------------------------------- mutation
    def apply(self, cand: CandidateStencil, scored: CandidateCost) -> set[int]:
        """Performs a scored change (collapse or relocation) and updates the plan.

        Args:
          cand: the candidate (exported against the current state).
          scored: its :class:`CandidateCost` from :meth:`score` or
            :meth:`collect`.

        Returns:
          The *dirty* vertices: every half-edge leaving one of them has a
          stencil that overlaps the change and must be re-scored (paper,
          Fig. 6: the modified one-ring and its flap vertices).
        """
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
        for k, c, solid in zip(map(tuple, cand.keys.tolist()), scored.edge_cost.tolist(), scored.solid.tolist()):
            self.edge_cost[k] = c
            self.edge_solid[k] = solid
        # The vertices of the new triangles and of the triangles next to them:
        # every vertex whose star, faces across its link, their points or the
        # costs of its star's edges have changed.
        # The far vertex of a face across the region's boundary keeps its
        # star: only the points across that link edge changed (logged for
        # changed_links).
        full = {*plan.ring, plan.source}
        links: dict[int, set] = {}
        new_set = set(new_ids.tolist())
        for f in new_set:
            tf = tri.tri[f]
            for g in tri.nbr[f]:
                if g >= 0 and g not in new_set:
                    tg = tri.tri[g]
                    a = next(u for u in tg if u not in tf)
                    if a not in full:
                        x, y = (u for u in tg if u != a)
                        links.setdefault(a, set()).add(edge_key(x, y))
        dirty = full | set(links)
        # A move keeps every star's triangles: around its ring vertices, only
        # the moved vertex is logged (partial_job scores what it reaches).
        moved = frozenset((plan.source,)) if cand.moved is not None else frozenset()
        if cand.moved is None:
            dirty.discard(plan.source)  # removed by the collapse
        for v in dirty:
            self._region_version[v] += 1
            if v in links or (moved and v != plan.source):
                log = self._link_log.setdefault(v, [])
                log.append((self._region_version[v], frozenset(links.get(v, ())), moved if v in full else frozenset()))
                if len(log) > _LINK_LOG:
                    self._star_changed_at[v] = log.pop(0)[0]
            else:
                self._star_changed_at[v] = self._region_version[v]
                self._link_log.pop(v, None)
        self._regions.pop(plan.source, None)
        return {v for v in dirty if tri.alive[v] and not tri.pinned[v]}


@dataclass
class _Flat:
    """Host side of one flat batch: the candidates, their rows, edges and
    triangles end to end (unpadded), and what reading the results needs.

    See :class:`otjax.curves.scoring.FlatBatch` for the fields shared with
    the kernel; the others: ``row_tri`` (local triangle of a row located on
    the host, else ``-1``), ``row_start``, ``edge_start``, ``tri_start``
    (``(J + 1,)`` offsets per job) and ``before`` (``(J,)``). Unpadded and
    with ids of any width: :meth:`packed` pads and narrows them. ``seq``:
    where each job stands in the list a packed export was made from.
    """

    cands: list
    row_point: np.ndarray
    row_job: np.ndarray
    row_cand: np.ndarray
    row_locate: np.ndarray
    row_tri: np.ndarray
    row_start: np.ndarray
    edge_start: np.ndarray
    tri_start: np.ndarray
    edge_xy: np.ndarray
    edge_job: np.ndarray
    tri_xy: np.ndarray
    tri_edges: np.ndarray
    fan_key: np.ndarray
    fan_tri: np.ndarray
    job_fan: np.ndarray
    job_apex: np.ndarray
    job_theta: np.ndarray
    job_ears: np.ndarray
    before: np.ndarray
    seq: np.ndarray | None = None  # position of each job in the export's job list (see _batches)

    @classmethod
    def empty(cls) -> _Flat:
        return cls.without_triangles(_NO_IDS, np.zeros((0, 3), np.int64), _NO_IDS, np.zeros((0, 2, 2)),
                                     _NO_IDS, [])

    @classmethod
    def without_triangles(cls, row_point, row_cand, row_job, edge_xy, edge_job, cands, before=None,
                          row_tri=None) -> _Flat:
        """A batch whose every row comes with its candidate edges."""
        nj = len(cands)
        n = len(row_point)
        return cls(
            cands=cands, row_point=row_point, row_job=row_job, row_cand=row_cand,
            row_locate=np.zeros(n, bool), row_tri=np.full(n, -1, np.int64) if row_tri is None else row_tri,
            row_start=np.searchsorted(row_job, np.arange(nj + 1)),
            edge_start=np.searchsorted(edge_job, np.arange(nj + 1)), tri_start=np.zeros(nj + 1, np.int64),
            edge_xy=edge_xy, edge_job=edge_job, tri_xy=np.zeros((6, 0)), tri_edges=np.zeros((0, 3), np.int64),
            fan_key=np.zeros(0), fan_tri=_NO_IDS, job_fan=np.zeros(nj + 1, np.int64), job_apex=np.zeros((nj, 2)),
            job_theta=np.zeros(nj), job_ears=np.full((nj, _scoring.MAX_EARS), -1, np.int64),
            before=np.zeros(nj) if before is None else before)

    def capacity(self) -> int:
        """The smallest row capacity that fits this batch (:func:`scoring.capacity`)."""
        return _scoring.capacity(len(self.row_point), len(self.edge_job), len(self.tri_edges),
                                 len(self.job_theta))

    def packed(self, points: np.ndarray, mass: np.ndarray, r: int,
               out: PackedBuffers | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The kernel's input ``(floats, ints)`` at row capacity ``r`` (a
        capacity class, at least :meth:`capacity`), packed by :func:`scoring.layout`.

        Args:
          points, mass: the plan's ``(n, 2)`` points and ``(n,)`` masses,
            gathered here by row (cheaper than a kernel shape per ``n``).
          out: buffers of capacity ``r`` to fill in place (see
            :class:`PackedBuffers`); fresh ones by default.
        """
        if out is None:
            out = PackedBuffers(r)
        out.fill(self, points, mass)
        return out.floats, out.ints


def _aligned_zeros(n: int, dtype) -> np.ndarray:
    """``np.zeros(n, dtype)`` whose data starts on a 64-byte boundary.

    XLA:CPU takes such a NumPy argument of a jitted call without a copy; an
    unaligned one (``np.zeros`` of a few MB lands 16 bytes past a page) is
    copied into fresh memory on every call: 1.8 ms for 6 MB, against 12 us
    aligned (measured).
    """
    dtype = np.dtype(dtype)
    raw = np.zeros(n * dtype.itemsize + 64, np.uint8)
    start = (-raw.ctypes.data) % 64
    return raw[start: start + n * dtype.itemsize].view(dtype)


class PackedBuffers:
    """The two input buffers of one kernel call at row capacity ``r``, for reuse.

    :meth:`fill` writes a batch and resets only what the previous batch
    wrote beyond it, so the buffers always hold exactly what freshly zeroed
    ones filled with the batch would: no zeroing of megabytes per call, and
    no page faults on new memory. The kernel reads the buffers in place (see
    :func:`_aligned_zeros`): they must not be filled again before the call
    that used them has returned its results (:class:`TransportPlan` hands
    them out from a pool and takes them back once the results are read).
    """

    def __init__(self, r: int):
        self.r = r
        where = _scoring.layout(r)
        self.floats = _aligned_zeros(where["_sizes"][0], np.float64)
        self.ints = _aligned_zeros(where["_sizes"][1], np.int32)
        self.v = {}
        for name, place in where.items():
            if name != "_sizes":
                is_float, offset, shape = place
                buf = self.floats if is_float else self.ints
                self.v[name] = buf[offset: offset + int(np.prod(shape))].reshape(shape)
        self.pad_job = r // _scoring.JOBS_PER_ROW - 1
        v = self.v
        v["row_job"][:] = self.pad_job
        v["edge_job"][:] = self.pad_job
        v["fan_key"][:] = np.inf
        v["job_ears"][:] = -1
        self.used = (0, 0, 0, 0, 0)  # rows, edges, triangles, fan keys, jobs

    def __reduce__(self):
        # A copy (copy.deepcopy of a plan, pickling) is a fresh set: copied
        # field views would no longer be views of the copied buffers, nor
        # aligned.
        return PackedBuffers, (self.r,)

    def fill(self, flat: _Flat, points: np.ndarray, mass: np.ndarray) -> None:
        """Writes ``flat`` (padded to ``r``) with its rows' points and masses."""
        v = self.v
        nr, ne, nt = len(flat.row_point), len(flat.edge_job), len(flat.tri_edges)
        nf, nj = len(flat.fan_key), len(flat.job_theta)
        if flat.capacity() > self.r:
            raise ValueError(f"batch needs capacity {flat.capacity()}, buffers have {self.r}")
        r0, e0, t0, f0, j0 = self.used
        # What the previous batch wrote past this one goes back to padding.
        if r0 > nr:
            for name in ("row_xy", "row_mass", "row_cand", "row_locate", "row_valid"):
                v[name][nr:r0] = 0
            v["row_job"][nr:r0] = self.pad_job
        if e0 > ne:
            v["edge_xy"][ne:e0] = 0
            v["edge_valid"][ne:e0] = 0
            v["edge_job"][ne:e0] = self.pad_job
        if t0 > nt:
            v["tri_xy"][:, nt:t0] = 0
            v["tri_edges"][nt:t0] = 0
        if f0 > nf:
            v["fan_key"][nf:f0] = np.inf
            v["fan_tri"][nf:f0] = 0
        if j0 > nj:
            v["job_apex"][nj:j0] = 0
            v["job_theta"][nj:j0] = 0
            v["job_ears"][nj:j0] = -1
        self.used = (nr, ne, nt, nf, nj)
        # mode="clip" lets take write straight into ``out`` (ids are valid).
        np.take(points, flat.row_point, axis=0, out=v["row_xy"][:nr], mode="clip")
        np.take(mass, flat.row_point, out=v["row_mass"][:nr], mode="clip")
        v["row_job"][:nr] = flat.row_job
        v["row_cand"][:nr] = flat.row_cand
        v["row_locate"][:nr] = flat.row_locate
        v["row_valid"][:nr] = 1
        v["tri_xy"][:, :nt] = flat.tri_xy
        v["tri_edges"][:nt] = flat.tri_edges
        v["fan_key"][:nf] = flat.fan_key
        v["fan_tri"][:nf] = flat.fan_tri
        v["job_fan"][: nj + 1] = flat.job_fan
        v["job_fan"][nj + 1:] = nf
        v["job_apex"][:nj] = flat.job_apex
        v["job_theta"][:nj] = flat.job_theta
        v["job_ears"][:nj] = flat.job_ears
        v["edge_xy"][:ne] = flat.edge_xy
        v["edge_valid"][:ne] = 1
        v["edge_job"][:ne] = flat.edge_job
