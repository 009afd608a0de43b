"""A transport plan onto a mesh of fixed connectivity, as flat arrays, and the
closed-star problems of many vertices cut out and written back at once.

Feature recovery (§5) never changes the mesh's connectivity, so its plan
needs none of :class:`~otjax.surfaces.plan.SurfacePlan`'s per-simplex
dictionaries: every bin has one global id (vertex ``v`` is bin ``v``, facet
bin ``b`` is bin ``V + b``), the bins of a facet are fixed barycentric
points of its sorted key (they follow its vertices), and the plan is three
arrays of entries ``(point, bin, mass)``.

The local problem of a vertex ``v`` is its closed star: the vertex bins of
``v`` and of its neighbours and the bins of the facets around ``v`` (the
stencil :func:`otjax.surfaces.relocation.relocate` re-solves). Vertices whose
closed stars share no vertex own disjoint sets of bins, so for such a set
(:func:`~otjax.surfaces.mesh_stencils.distance2_graph` colours them) each
bin has at most one owner, and cutting out, pricing and writing back all
their problems is a handful of NumPy operations over the entry arrays
(:meth:`StarPlan.cut`, :meth:`StarPlan.replace`). The mesh's stars and
facet rings as CSR rows are :mod:`otjax.surfaces.mesh_stencils`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.spatial

from otjax.surfaces.bins import facet_bins
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.mesh_stencils import Ragged, Stencils, distance2_graph, facet_rings
from otjax.surfaces.plan import ENTRY_FLOOR, Bins, BinSettings, Entries, SurfacePlan


class MeshBins(NamedTuple):
    """The facet bins of a mesh (sorted facet keys, lexicographic order).

    Attributes:
      keys: ``(T, 3)`` int64 facets, each row sorted; rows in lexicographic order.
      start: ``(T + 1,)`` int64 first bin of each facet; facet ``f`` owns bins
        ``start[f] .. start[f + 1] - 1``.
      barycentric: ``(NB, 3)`` float64 weights of each bin over its facet's key.
      capacity: ``(NB,)`` float64 share of its facet's measure (a facet's sum to 1).
      facet: ``(NB,)`` int64 facet of each bin.
    """

    keys: np.ndarray
    start: np.ndarray
    barycentric: np.ndarray
    capacity: np.ndarray
    facet: np.ndarray


class StarBatch(NamedTuple):
    """The local problems of ``B`` stencils with no vertex in common, padded.

    Local bins: the stencil's vertices (sorted, local simplices
    ``0 .. nv - 1``), then the bins of its facets (sorted keys; facet ``j``
    is local simplex ``nv + j``), as :meth:`SurfacePlan.stencil` orders
    them. Padding: point and bin id ``-1``, mass, cost and capacity 0.

    Attributes:
      centre: ``(B,)`` int64 the stencils' ids (rows of the :class:`Stencils` cut).
      point: ``(B, P)`` int64 global point ids of each problem's points.
      bin: ``(B, K)`` int64 global bin ids.
      mass: ``(B, P)`` float64 each point's partial mass on the star.
      cost: ``(B, P, K)`` float64 squared distances point to bin.
      capacity: ``(B, K)`` float64 facet-bin capacities (0 on vertex bins).
      simplex: ``(B, K)`` int32 local simplex of each bin.
      is_vertex: ``(B, K)`` bool.
      n_points, n_bins, n_simplices: ``(B,)`` int64 real sizes.
      current: ``(B,)`` float64 the plan's cost on the star now.
      lower: ``(B,)`` float64 ``sum_i m_i min_j C_ij``: no plan of the star costs less.
      free_best: ``(B, P)`` int64 each point's cheapest bin whose mass no
        uniformity constraint ties (a vertex bin or a facet's only bin), or
        ``-1`` where every cheapest bin is tied: a problem with no ``-1`` on
        its real points is solved by sending each point there (closed form).
    """

    centre: np.ndarray
    point: np.ndarray
    bin: np.ndarray
    mass: np.ndarray
    cost: np.ndarray
    capacity: np.ndarray
    simplex: np.ndarray
    is_vertex: np.ndarray
    n_points: np.ndarray
    n_bins: np.ndarray
    n_simplices: np.ndarray
    current: np.ndarray
    lower: np.ndarray
    free_best: np.ndarray

    @property
    def closed_form(self) -> np.ndarray:
        """``(B,)`` bool: problems whose optimum is each point on its free cheapest bin."""
        real = self.point >= 0
        return ~np.any(real & (self.free_best < 0), axis=1)


def width(n: int, smallest: int) -> int:
    """A padded axis length: the power of two ``>= max(n, smallest)``."""
    size = smallest
    while size < n:
        size *= 2
    return size


class StarPlan:
    """A sparse transport plan of weighted points onto a fixed mesh's bins.

    Args:
      positions: ``(V, 3)`` float64 vertex positions (copied; they move).
      triangles: ``(T, 3)`` int64 faces (any orientation; no repeated face).
      points: ``(N, 3)`` float64; masses: ``(N,)`` float64 positive.
      settings: :class:`BinSettings` of the facet bins (made once, at ``positions``).

    The plan starts with every point on its nearest vertex of a face (§3.3).

    Attributes:
      positions, points, masses, bins (:class:`MeshBins`), settings;
      entry_point, entry_bin, entry_mass: ``(E,)`` the plan's entries (global bin ids);
      closed_star: :class:`Ragged` sorted vertices of each vertex's closed star;
      star_facets: :class:`Ragged` sorted facets (rows of ``bins.keys``) around each vertex;
      stars: :class:`Stencils` the closed star of each vertex (row ``v``);
      rings: :class:`Stencils` the paper's stencil of each facet (row ``f``):
        it, the facets sharing an edge with it, and their vertices (§3.3);
      two: :func:`~otjax.surfaces.mesh_stencils.distance2_graph` of the mesh;
      reference_normals: ``(T, 3)`` ``(c1 - c0) x (c2 - c0)`` of each facet
        (corners in key order) at the given ``positions``: the orientation
        moves must keep (:func:`otjax.surfaces.star_passes.relocate_class`).
    """

    def __init__(self, positions: np.ndarray, triangles: np.ndarray, points: np.ndarray, masses: np.ndarray,
                 settings: BinSettings):
        self.positions = np.array(positions, np.float64)
        self.points = np.asarray(points, np.float64)
        self.masses = np.asarray(masses, np.float64)
        self.settings = settings
        nv = len(self.positions)
        keys = np.unique(np.sort(np.asarray(triangles, np.int64).reshape(-1, 3), axis=1), axis=0)
        s = settings
        made = facet_bins(self.positions, keys, density=s.density, min_bins=s.min_bins, max_bins=s.max_bins,
                          diagonal=s.diagonal, seed=s.seed, max_stretch=s.max_stretch, bin_length=s.bin_length)
        start = np.concatenate([[0], np.cumsum(made.count)]).astype(np.int64)
        self.bins = MeshBins(keys, start, made.barycentric, made.capacity,
                             np.repeat(np.arange(len(keys)), made.count))
        corner = keys.ravel()
        facet = np.repeat(np.arange(len(keys)), 3)
        order = np.lexsort((facet, corner))
        self.star_facets = Ragged(np.searchsorted(corner[order], np.arange(nv + 1)), facet[order])
        self.two = distance2_graph(keys, nv)
        pairs = np.unique(np.concatenate([np.c_[np.arange(nv), np.arange(nv)],
                                          np.c_[corner, keys[:, [1, 2, 0]].ravel()],
                                          np.c_[corner, keys[:, [2, 0, 1]].ravel()]]), axis=0)
        self.closed_star = Ragged(np.searchsorted(pairs[:, 0], np.arange(nv + 1)), pairs[:, 1])
        self.stars = Stencils(self.closed_star, self.star_facets)
        self.reference_normals = face_normals(self.positions[keys])
        self.rings = facet_rings(keys, nv)
        used = np.unique(keys)
        _, near = scipy.spatial.cKDTree(self.positions[used]).query(self.points)
        self.entry_point = np.arange(len(self.points), dtype=np.int64)
        self.entry_bin = used[near].astype(np.int64)
        self.entry_mass = self.masses.copy()

    # ------------------------------------------------------------ reading
    @property
    def n_vertices(self) -> int:
        return len(self.positions)

    def bin_positions(self, ids: np.ndarray) -> np.ndarray:
        """``(..., 3)`` positions of global bins ``ids`` (any shape; ``-1`` gives 0)."""
        ids = np.asarray(ids, np.int64)
        nv = self.n_vertices
        flat = ids.ravel()
        out = np.zeros((len(flat), 3))
        vertex = (flat >= 0) & (flat < nv)
        out[vertex] = self.positions[flat[vertex]]
        facet = flat >= nv
        b = flat[facet] - nv
        corners = self.positions[self.bins.keys[self.bins.facet[b]]]
        out[facet] = np.einsum("nk,nkd->nd", self.bins.barycentric[b], corners)
        return out.reshape(ids.shape + (3,))

    def entry_costs(self) -> np.ndarray:
        """``(E,)`` ``mass |point - bin|^2`` of every entry."""
        diff = self.points[self.entry_point] - self.bin_positions(self.entry_bin)
        return self.entry_mass * np.einsum("ed,ed->e", diff, diff)

    def total_cost(self) -> float:
        """The plan's cost, summed over every entry."""
        return float(np.sum(self.entry_costs()))

    def vertex_mass(self) -> np.ndarray:
        """``(V,)`` mass on each vertex bin."""
        nv = self.n_vertices
        on = self.entry_bin < nv
        return np.bincount(self.entry_bin[on], weights=self.entry_mass[on], minlength=nv)

    def facet_mass(self) -> np.ndarray:
        """``(T,)`` mass on each facet (rows of ``bins.keys``)."""
        nv = self.n_vertices
        on = self.entry_bin >= nv
        return np.bincount(self.bins.facet[self.entry_bin[on] - nv], weights=self.entry_mass[on],
                           minlength=len(self.bins.keys))

    def facet_rows(self, triangles: np.ndarray) -> np.ndarray:
        """``(T',)`` row of ``bins.keys`` of each face ``(T', 3)`` (any orientation)."""
        keys = self.bins.keys
        code = lambda k: (k[:, 0] * self.n_vertices + k[:, 1]) * self.n_vertices + k[:, 2]
        return np.searchsorted(code(keys), code(np.sort(np.asarray(triangles, np.int64), axis=1)))

    # -------------------------------------------------------- star problems
    def owners(self, stencils: Stencils) -> tuple[np.ndarray, np.ndarray]:
        """Which of ``stencils`` (no vertex in common) owns each global bin, and where.

        Returns ``(owner, column)``: ``owner`` ``(V + NB,)`` int64 the
        stencil's row (``-1``: none) and ``column`` the bin's local index.
        """
        nv = self.n_vertices
        nb = len(stencils.vertices.ptr) - 1
        verts, vrow = stencils.vertices.index, np.repeat(np.arange(nb), np.diff(stencils.vertices.ptr))
        vcol = np.arange(len(verts)) - stencils.vertices.ptr[vrow]
        facets, frow = stencils.facets.index, np.repeat(np.arange(nb), np.diff(stencils.facets.ptr))
        nverts = np.diff(stencils.vertices.ptr)
        nbins = self.bins.start[facets + 1] - self.bins.start[facets]
        # facet bins of each stencil, after its vertices, facet by facet
        brow = np.repeat(frow, nbins)
        within = np.arange(int(nbins.sum())) - np.repeat(np.cumsum(nbins) - nbins, nbins)
        gbin = nv + np.repeat(self.bins.start[facets], nbins) + within
        per_row = np.bincount(brow, minlength=nb)
        bcol = nverts[brow] + np.arange(len(brow)) - np.repeat(np.cumsum(per_row) - per_row, per_row)
        owner = np.full(nv + len(self.bins.capacity), -1, np.int64)
        column = np.zeros(len(owner), np.int64)
        owner[verts], column[verts] = vrow, vcol
        owner[gbin], column[gbin] = brow, bcol
        return owner, column

    def costs(self, stencils: Stencils) -> np.ndarray:
        """``(B,)`` the plan's cost on each of ``stencils`` (no vertex in common)."""
        owner = self.owners(stencils)[0]
        on = owner[self.entry_bin]
        sel = on >= 0
        diff = self.points[self.entry_point[sel]] - self.bin_positions(self.entry_bin[sel])
        cost = self.entry_mass[sel] * np.einsum("ed,ed->e", diff, diff)
        return np.bincount(on[sel], weights=cost, minlength=len(stencils.vertices.ptr) - 1)

    def cut(self, stencils: Stencils, rows: np.ndarray, min_points: int = 1, min_bins: int = 1) -> StarBatch:
        """The local problems of ``stencils`` ``rows`` ``(B,)``, which must have
        no vertex in common, padded to at least ``min_points`` x ``min_bins``."""
        centres = np.asarray(rows, np.int64)
        nb = len(centres)
        nv = self.n_vertices
        chosen = stencils.take(centres)
        owner, column = self.owners(chosen)
        verts, facets = chosen.vertices, chosen.facets
        n_vert = np.diff(verts.ptr)
        n_facet = np.diff(facets.ptr)
        fb = self.bins.start[facets.index + 1] - self.bins.start[facets.index]
        n_bins = n_vert + np.bincount(np.repeat(np.arange(nb), n_facet), weights=fb, minlength=nb).astype(np.int64)
        k = width(int(n_bins.max(initial=0)), min_bins)
        # bins: global id, local simplex, capacity, vertex flag
        gbin = np.flatnonzero(owner >= 0)
        row, col = owner[gbin], column[gbin]
        bins = np.full((nb, k), -1, np.int64)
        bins[row, col] = gbin
        simplex = np.zeros((nb, k), np.int32)
        is_vertex = np.zeros((nb, k), bool)
        capacity = np.zeros((nb, k))
        vertex = gbin < nv
        is_vertex[row[vertex], col[vertex]] = True
        simplex[row[vertex], col[vertex]] = col[vertex]
        fbin = gbin[~vertex] - nv
        frow = row[~vertex]
        # local facet j of a problem: the rank of its facet among the problem's sorted facets
        facet_rank = np.zeros(len(self.bins.keys), np.int64)
        facet_rank[facets.index] = np.arange(len(facets.index)) - np.repeat(facets.ptr[:-1], n_facet)
        simplex[frow, col[~vertex]] = n_vert[frow] + facet_rank[self.bins.facet[fbin]]
        capacity[frow, col[~vertex]] = self.bins.capacity[fbin]
        # the points on each star, with their partial masses
        on = owner[self.entry_bin]
        sel = np.flatnonzero(on >= 0)
        erow = on[sel]
        key = erow * len(self.points) + self.entry_point[sel]
        uniq, inverse = np.unique(key, return_inverse=True)
        urow = uniq // len(self.points)
        first = np.searchsorted(urow, np.arange(nb))
        prow = np.arange(len(uniq)) - first[urow]
        n_points = np.bincount(urow, minlength=nb)
        p = width(int(n_points.max(initial=0)), min_points)
        point = np.full((nb, p), -1, np.int64)
        point[urow, prow] = uniq % len(self.points)
        mass = np.zeros((nb, p))
        np.add.at(mass, (urow[inverse], prow[inverse]), self.entry_mass[sel])
        real_p = point >= 0
        real_k = bins >= 0
        diff = (np.where(real_p[..., None], self.points[np.maximum(point, 0)], 0.0)[:, :, None, :]
                - self.bin_positions(bins)[:, None, :, :])
        cost = np.einsum("bpkd,bpkd->bpk", diff, diff)
        cost *= real_p[:, :, None] & real_k[:, None, :]
        ecol = column[self.entry_bin[sel]]
        eprow = prow[inverse]
        current = np.bincount(erow, weights=self.entry_mass[sel] * cost[erow, eprow, ecol], minlength=nb)
        masked = np.where(real_k[:, None, :], cost, np.inf)
        cheapest = masked.min(axis=2)
        lower = np.sum(np.where(real_p, mass * np.where(real_p, cheapest, 0.0), 0.0), axis=1)
        # a bin is free when it is a vertex bin or its facet's only bin
        per_simplex = np.zeros((nb, int(simplex.max(initial=0)) + 1), np.int64)
        np.add.at(per_simplex, (np.repeat(np.arange(nb), k)[real_k.ravel()], simplex[real_k]), 1)
        free = real_k & (is_vertex | (np.take_along_axis(per_simplex, simplex.astype(np.int64), 1) == 1))
        free_cost = np.where(free[:, None, :], cost, np.inf)
        best = np.argmin(free_cost, axis=2)
        ok = np.take_along_axis(free_cost, best[..., None], 2)[..., 0] <= cheapest
        free_best = np.where(ok & real_p, best, -1)
        n_simplices = n_vert + n_facet
        return StarBatch(centres, point, bins, mass, cost, capacity, simplex, is_vertex, n_points, n_bins,
                         n_simplices, current, lower, free_best)

    def replace(self, batch: StarBatch, rows: np.ndarray, plans: np.ndarray) -> None:
        """Replaces the entries of the stars ``rows`` of ``batch`` by ``plans``
        ``(len(rows), P, K)``: feasible plans of those problems, already
        sparsified (:func:`sparsify`); the other stars' entries stay."""
        rows = np.asarray(rows, np.int64)
        if len(rows) == 0:
            return
        drop = np.zeros(self.n_vertices + len(self.bins.capacity), bool)
        ids = batch.bin[rows]
        drop[ids[ids >= 0]] = True
        keep = ~drop[self.entry_bin]
        r, i, j = np.nonzero(plans)
        self.entry_point = np.concatenate([self.entry_point[keep], batch.point[rows[r], i]])
        self.entry_bin = np.concatenate([self.entry_bin[keep], batch.bin[rows[r], j]])
        self.entry_mass = np.concatenate([self.entry_mass[keep], plans[r, i, j]])

    # ------------------------------------------------------------ targets
    def targets(self, centres: np.ndarray) -> np.ndarray:
        """``(B, 3)`` closed-form targets of ``centres`` (disjoint closed stars)
        with the plan fixed (§4.3), as
        :func:`otjax.surfaces.fixed_plan_cost.vertex_targets` (mass-weighted).

        Each simplex of ``v`` carrying mass (its vertex bin; each facet around
        it) gives ``v* = sum m a (p - r) / sum m a^2`` for entries whose bin is
        ``a v + r``; the target is their average weighted by the simplices'
        masses (the paper), or the current position when none carries mass.
        """
        centres = np.asarray(centres, np.int64)
        nv = self.n_vertices
        owner = self.owners(self.stars.take(centres))[0]
        on = owner[self.entry_bin]
        gb = self.entry_bin
        own = (on >= 0) & ((gb >= nv) | (gb == centres[np.maximum(on, 0)]))
        sel = np.flatnonzero(own)
        row, gb = on[sel], gb[sel]
        m, p = self.entry_mass[sel], self.points[self.entry_point[sel]]
        alpha = np.ones(len(sel))
        rest = np.zeros((len(sel), 3))
        facet = gb >= nv
        b = gb[facet] - nv
        f = self.bins.facet[b]
        corners = self.bins.keys[f]
        bary = self.bins.barycentric[b]
        same = corners == centres[row[facet]][:, None]
        alpha[facet] = np.sum(np.where(same, bary, 0.0), axis=1)
        rest[facet] = np.einsum("nk,nkd->nd", np.where(same, 0.0, bary), self.positions[corners])
        # one share per (problem, simplex): the vertex bin is simplex -1
        simplex = np.full(len(sel), -1, np.int64)
        simplex[facet] = f
        _, share = np.unique(np.c_[row, simplex], axis=0, return_inverse=True)
        share = share.ravel()
        n = int(share.max(initial=-1)) + 1
        num = np.stack([np.bincount(share, weights=m * alpha * (p[:, d] - rest[:, d]), minlength=n)
                        for d in range(3)], axis=1)
        den = np.bincount(share, weights=m * alpha * alpha, minlength=n)
        mass = np.bincount(share, weights=m, minlength=n)
        share_row = np.zeros(n, np.int64)
        share_row[share] = row
        curved = den > 0
        star = np.where(curved[:, None], num / np.where(curved, den, 1.0)[:, None], 0.0)
        weight = np.where(curved, mass, 0.0)
        top = np.stack([np.bincount(share_row, weights=weight * star[:, d], minlength=len(centres))
                        for d in range(3)], axis=1)
        total = np.bincount(share_row, weights=weight, minlength=len(centres))
        valid = total > 0
        return np.where(valid[:, None], top / np.where(valid, total, 1.0)[:, None], self.positions[centres])


def surface_plan(plan: StarPlan) -> SurfacePlan:
    """``plan`` as a :class:`SurfacePlan` over a :class:`SimplicialComplex`."""
    nv = plan.n_vertices
    keys = [tuple(map(int, k)) for k in plan.bins.keys.tolist()]
    start = plan.bins.start.tolist()
    bins = {k: Bins(plan.bins.barycentric[a:b], plan.bins.capacity[a:b])
            for k, a, b in zip(keys, start[:-1], start[1:])}
    simplex = np.where(plan.entry_bin < nv, plan.entry_bin,
                       nv + plan.bins.facet[np.maximum(plan.entry_bin - nv, 0)])
    order = np.argsort(simplex, kind="stable")
    s = simplex[order]
    cuts = np.flatnonzero(np.diff(s)) + 1
    vertex_entries, facet_entries = {}, {}
    for chunk in np.split(order, cuts):
        if not len(chunk):
            continue
        sid = int(simplex[chunk[0]])
        if sid < nv:
            vertex_entries[sid] = Entries(plan.entry_point[chunk], np.zeros(len(chunk), np.int64),
                                          plan.entry_mass[chunk])
        else:
            f = sid - nv
            within = plan.entry_bin[chunk] - nv - plan.bins.start[f]
            facet_entries[keys[f]] = Entries(plan.entry_point[chunk], within, plan.entry_mass[chunk])
    complex_ = SimplicialComplex(plan.positions.copy(), plan.bins.keys)
    return SurfacePlan.from_entries(complex_, plan.points, plan.masses, plan.settings, bins, vertex_entries,
                                    facet_entries)


def face_normals(corners: np.ndarray) -> np.ndarray:
    """``(F, 3)`` unnormalised normals ``(c1 - c0) x (c2 - c0)`` of triangles ``(F, 3, 3)``."""
    return np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


def sparsify(mass: np.ndarray, plans: np.ndarray) -> np.ndarray:
    """``plans`` ``(B, P, K)`` with entries under :data:`ENTRY_FLOOR` of their
    point's mass ``(B, P)`` dropped and each row rescaled to that mass
    (:meth:`SurfacePlan.sparsified`, batched)."""
    plans = np.where(plans > ENTRY_FLOOR * mass[..., None], plans, 0.0)
    rows = plans.sum(axis=-1)
    return plans * np.where(rows > 0, mass / np.where(rows > 0, rows, 1.0), 0.0)[..., None]
