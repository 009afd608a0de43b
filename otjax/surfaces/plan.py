"""The transport plan of points onto a simplicial complex's bins (§3), as state.

The plan is sparse: each simplex keeps the entries ``(point, bin, mass)``
transported onto it. A vertex is one bin; a facet owns the CVT bins of
:mod:`otjax.surfaces.bins`, stored in barycentric coordinates of its sorted
key so that bin positions follow the vertices when they move. The plan owns
the assignments and the bins; the complex owns topology and positions.

Local work goes through a :class:`Stencil`: the points transported (wholly or
partly) onto a set of simplices, with the partial masses they have there, as
one :class:`~otjax.lp.problem.LocalLP` over the stencil's bins. A solved
stencil is written back with :meth:`SurfacePlan.assign`, which replaces the
entries of exactly those simplices; nothing else changes.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import NamedTuple

import numpy as np
import scipy.sparse
import scipy.spatial

from otjax.lp.problem import LocalLP
from otjax.surfaces.bins import (
    DEFAULT_DENSITY,
    DEFAULT_MAX_BINS,
    DEFAULT_MAX_STRETCH,
    DEFAULT_MIN_BINS,
    facet_bins,
)
from otjax.surfaces.complex import SimplicialComplex, Triangle, triangle_key

#: Plan entries below this fraction of their point's mass on a stencil are
#: dropped when a solved stencil is written back (the batched solver's plans
#: are dense with exponentially small entries); the rest of the row is scaled
#: so the point's mass is conserved exactly.
ENTRY_FLOOR = 1e-12


class Entries(NamedTuple):
    """The plan entries of one simplex.

    Attributes:
      point: ``(n,)`` int64 input point ids.
      bin: ``(n,)`` int64 bin of the simplex (0 for a vertex).
      mass: ``(n,)`` float64 transported mass, ``> 0``.
    """

    point: np.ndarray
    bin: np.ndarray
    mass: np.ndarray


class Bins(NamedTuple):
    """The bins of one facet: ``barycentric`` ``(n, 3)`` in the order of the
    facet's sorted key, ``capacity`` ``(n,)`` summing to 1."""

    barycentric: np.ndarray
    capacity: np.ndarray


class BinSettings(NamedTuple):
    """How facet bins are made (:func:`otjax.surfaces.bins.facet_bins`);
    ``diagonal`` is the input's bounding-box diagonal the density refers to."""

    diagonal: float
    density: float = DEFAULT_DENSITY
    min_bins: int = DEFAULT_MIN_BINS
    max_bins: int = DEFAULT_MAX_BINS
    seed: int = 0
    max_stretch: float = DEFAULT_MAX_STRETCH
    bin_length: float | None = None


class Stencil(NamedTuple):
    """A local transport problem cut out of the plan.

    Attributes:
      lp: the :class:`LocalLP` over the stencil's points and bins (costs in
        the plan's units).
      points: ``(P,)`` int64 global ids of the LP's points.
      vertices: the stencil's vertex ids; local simplex ``s < len(vertices)``.
      facets: the stencil's facet keys; local simplex ``len(vertices) + f``.
      bin_of: ``(K,)`` int64 bin index within its simplex of each LP bin.
      cost: the current plan's cost of these partial masses on these simplices.
    """

    lp: LocalLP
    points: np.ndarray
    vertices: tuple[int, ...]
    facets: tuple[Triangle, ...]
    bin_of: np.ndarray
    cost: float


class SurfacePlan:
    """A sparse transport plan from weighted points onto a complex's bins.

    Args:
      complex_: the :class:`SimplicialComplex` (positions and topology).
      points: ``(N, 3)`` float64 input points.
      masses: ``(N,)`` float64 positive masses.
      settings: :class:`BinSettings` for facet bins.

    The initial plan sends every point to its nearest live vertex (§3.3),
    which is feasible since vertex bins take any amount.
    """

    def __init__(self, complex_: SimplicialComplex, points: np.ndarray, masses: np.ndarray,
                 settings: BinSettings):
        self.complex = complex_
        self.points = np.asarray(points, np.float64)
        self.masses = np.asarray(masses, np.float64)
        self.settings = settings
        self.bins: dict[Triangle, Bins] = {}
        self.vertex_entries: dict[int, Entries] = {}
        self.facet_entries: dict[Triangle, Entries] = {}
        self.ensure_bins(complex_.triangles)
        self._nearest_vertex()

    @classmethod
    def from_entries(cls, complex_: SimplicialComplex, points: np.ndarray, masses: np.ndarray,
                     settings: BinSettings, bins: dict, vertex_entries: dict, facet_entries: dict) -> SurfacePlan:
        """A plan with the given bins and entries (no nearest-vertex start);
        facets of ``complex_`` without bins get them made."""
        plan = cls.__new__(cls)
        plan.complex = complex_
        plan.points = np.asarray(points, np.float64)
        plan.masses = np.asarray(masses, np.float64)
        plan.settings = settings
        plan.bins = dict(bins)
        plan.vertex_entries = dict(vertex_entries)
        plan.facet_entries = dict(facet_entries)
        plan.ensure_bins(complex_.triangles)
        return plan

    # ------------------------------------------------------------- bins
    def ensure_bins(self, facets: Iterable[Triangle]) -> None:
        """Makes the bins of the given facets that have none yet (in one call)."""
        self.bins.update(self.make_bins(t for t in facets if t not in self.bins))

    def make_bins(self, facets: Iterable[Triangle]) -> dict:
        """``{facet: Bins}`` of the given facets by the plan's settings, in one
        :func:`facet_bins` call, at the current vertex positions; the plan is not changed."""
        todo = sorted(set(facets))
        if not todo:
            return {}
        s = self.settings
        made = facet_bins(self.complex.positions, np.array(todo, np.int64), density=s.density,
                          min_bins=s.min_bins, max_bins=s.max_bins, diagonal=s.diagonal, seed=s.seed,
                          max_stretch=s.max_stretch, bin_length=s.bin_length)
        stops = np.cumsum(made.count)
        return {t: Bins(made.barycentric[stop - n:stop], made.capacity[stop - n:stop])
                for t, stop, n in zip(todo, stops.tolist(), made.count.tolist())}

    def bin_positions(self, facet: Triangle) -> np.ndarray:
        """``(n, 3)`` positions of a facet's bins at the current vertex positions."""
        return self.bins[facet].barycentric @ self.complex.positions[list(facet)]

    # ------------------------------------------------------------ state
    def _nearest_vertex(self) -> None:
        alive = np.flatnonzero(self.complex.alive)
        tree = scipy.spatial.cKDTree(self.complex.positions[alive])
        _, near = tree.query(self.points)
        owner = alive[near]
        order = np.argsort(owner, kind="stable")
        bounds = np.flatnonzero(np.diff(owner[order])) + 1
        for chunk in np.split(order, bounds):
            if len(chunk):
                self.vertex_entries[int(owner[chunk[0]])] = Entries(
                    chunk.astype(np.int64), np.zeros(len(chunk), np.int64), self.masses[chunk].copy())

    def entries(self, simplex) -> Entries | None:
        """The entries of a vertex id or a facet key (None if it carries nothing)."""
        if isinstance(simplex, tuple):
            return self.facet_entries.get(simplex)
        return self.vertex_entries.get(int(simplex))

    def simplex_mass(self, simplex) -> float:
        """Mass transported onto a vertex or a facet."""
        e = self.entries(simplex)
        return 0.0 if e is None else float(e.mass.sum())

    def simplex_cost(self, simplex) -> float:
        """``sum m |p - b|^2`` of a vertex's or a facet's entries."""
        e = self.entries(simplex)
        if e is None:
            return 0.0
        if isinstance(simplex, tuple):
            b = self.bin_positions(simplex)[e.bin]
        else:
            b = self.complex.positions[int(simplex)]
        return float(np.sum(e.mass * np.sum((self.points[e.point] - b) ** 2, axis=-1)))

    def total_cost(self) -> float:
        """The plan's cost, recomputed from every entry."""
        return (sum(self.simplex_cost(v) for v in self.vertex_entries)
                + sum(self.simplex_cost(t) for t in self.facet_entries))

    def point_mass(self) -> np.ndarray:
        """``(N,)`` mass each point has on the complex (equals ``masses``)."""
        out = np.zeros(len(self.points))
        for e in list(self.vertex_entries.values()) + list(self.facet_entries.values()):
            np.add.at(out, e.point, e.mass)
        return out

    def matrix(self) -> tuple[scipy.sparse.csr_matrix, list]:
        """The plan as a sparse ``(N, M)`` matrix over an enumeration of bins.

        Returns the matrix and the list of ``(simplex, bin)`` of each column.
        """
        columns, rows, cols, vals = [], [], [], []
        for simplex in sorted(self.vertex_entries) + sorted(self.facet_entries):
            e = self.entries(simplex)
            n = len(self.bins[simplex].capacity) if isinstance(simplex, tuple) else 1
            base = len(columns)
            columns.extend((simplex, j) for j in range(n))
            rows.append(e.point)
            cols.append(base + e.bin)
            vals.append(e.mass)
        cat = (lambda xs, dt: np.concatenate(xs) if xs else np.zeros(0, dt))
        shape = (len(self.points), len(columns))
        m = scipy.sparse.csr_matrix((cat(vals, float), (cat(rows, np.int64), cat(cols, np.int64))), shape=shape)
        return m, columns

    # ---------------------------------------------------------- stencils
    def stencil(self, vertices: Sequence[int], facets: Sequence[Triangle]) -> Stencil:
        """The local problem of the points on these simplices (partial masses).

        Every listed simplex's bins are in the LP, whether or not it carries
        mass now; facets get their bins made if they have none. The current
        cost is read off the LP's own cost matrix at the current entries, so
        it is the same sum the solved plan is compared with.
        """
        vertices = tuple(sorted(int(v) for v in vertices))
        facets = tuple(sorted(triangle_key(*t) for t in facets))
        self.ensure_bins(facets)
        counts = [1] * len(vertices) + [len(self.bins[t].capacity) for t in facets]
        offsets = np.concatenate([[0], np.cumsum(counts)])
        parts = [(s, e) for s, e in enumerate(map(self.entries, vertices + facets)) if e is not None]
        if parts:
            pts = np.concatenate([e.point for _, e in parts])
            mass = np.concatenate([e.mass for _, e in parts])
            col = np.concatenate([offsets[s] + e.bin for s, e in parts])
            points, inverse = np.unique(pts, return_inverse=True)
            partial = np.bincount(inverse, weights=mass, minlength=len(points))
        else:
            points, partial, inverse = np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
            mass, col = np.zeros(0), np.zeros(0, np.int64)
        pos = [self.complex.positions[list(vertices)]] + [self.bin_positions(t) for t in facets]
        bins = np.concatenate(pos) if pos else np.zeros((0, 3))
        simplex = np.repeat(np.arange(len(counts)), counts)
        bin_of = np.arange(int(offsets[-1]), dtype=np.int64) - offsets[simplex]
        capacity = np.concatenate([np.zeros(len(vertices))] + [self.bins[t].capacity for t in facets])
        diff = self.points[points][:, None, :] - bins[None, :, :]
        cost_matrix = np.einsum("pkd,pkd->pk", diff, diff)
        lp = LocalLP(cost_matrix, partial, capacity, simplex, simplex < len(vertices))
        cost = float(np.sum(mass * cost_matrix[inverse, col]))
        return Stencil(lp, points, vertices, facets, bin_of, cost)

    @staticmethod
    def sparsified(stencil: Stencil, plan: np.ndarray) -> np.ndarray:
        """``plan`` ``(P, K)`` with entries under :data:`ENTRY_FLOOR` of their
        point's partial mass dropped and each row rescaled to that mass."""
        mass = stencil.lp.mass
        plan = np.where(plan > ENTRY_FLOOR * mass[:, None], plan, 0.0)
        rows = plan.sum(axis=1)
        return plan * np.where(rows > 0, mass / np.where(rows > 0, rows, 1.0), 0.0)[:, None]

    def assign(self, stencil: Stencil, plan: np.ndarray) -> None:
        """Replaces the entries of the stencil's simplices by ``plan`` ``(P, K)``.

        ``plan`` must be a feasible plan of ``stencil.lp`` (rows summing to the
        partial masses); it is :meth:`sparsified` first, so every point's mass
        stays exact.
        """
        plan = self.sparsified(stencil, plan)
        p_idx, k_idx = np.nonzero(plan)
        owner = stencil.lp.simplex[k_idx]
        simplices = list(stencil.vertices) + list(stencil.facets)
        for s, key in enumerate(simplices):
            sel = owner == s
            table = self.facet_entries if isinstance(key, tuple) else self.vertex_entries
            if not np.any(sel):
                table.pop(key, None)
                continue
            table[key] = Entries(stencil.points[p_idx[sel]], stencil.bin_of[k_idx[sel]], plan[p_idx[sel], k_idx[sel]])

    def move_entries(self, source, target) -> None:
        """Adds the entries of simplex ``source`` to ``target`` (vertices only:
        a vertex bin is a single bin) and removes ``source``'s."""
        moved = self.vertex_entries.pop(int(source), None)
        if moved is None:
            return
        old = self.vertex_entries.get(int(target))
        if old is not None:
            moved = Entries(*(np.concatenate([a, b]) for a, b in zip(old, moved)))
        self.vertex_entries[int(target)] = moved

    def drop_facet(self, facet: Triangle) -> Entries | None:
        """Removes a facet's entries and bins; returns the entries it had."""
        self.bins.pop(facet, None)
        return self.facet_entries.pop(facet, None)
