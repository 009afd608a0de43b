"""Candidate changes as export jobs: regions, collapse plans and their caches.

A *region* is what every change of the star of a vertex ``v`` shares: the
points in the star, the points across its link that are assigned to link
edges, and the cost of the star's edges (what any change of the star
replaces). A *job* is one candidate change written against its region: the
planned collapse (or move), the triangles that would replace the star, and
where known, the edge each point keeps. :mod:`otjax.curves.export` turns
jobs into flat batches for the scoring kernel.

Regions and collapse plans are read many times between two changes, so they
are cached here, stamped with the :class:`~otjax.curves.rescoring.ChangeLog`
versions of their vertices.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.curves.collapse import CollapsePlan, MovePlan, link_condition, plan_flips_from, plan_from_flips

_NO_IDS = np.zeros(0, np.int64)


class Region(NamedTuple):
    """What every change of the star of one vertex ``v`` shares.

    Attributes:
      ring: CCW one-ring of ``v``.
      star: triangle ids around ``v`` (``star[k] = (v, ring[k], ring[k+1])``).
      inside: ``(P,)`` ids of the points in the star.
      outside: ``(Q,)`` ids of the points of the faces across the link that
        are assigned to those link edges.
      outside_link: ``(Q,)`` the link edge ``k`` (``(ring[k], ring[k+1])``) of
        each point of ``outside``.
      before: cost of every edge of the star (spokes and link).
      outside_key: ``(Q,)`` int64 code ``min * V + max`` of the link edge of
        each point of ``outside`` (``V`` vertices in the triangulation).
    """

    ring: tuple[int, ...]
    star: tuple[int, ...]
    inside: np.ndarray
    outside: np.ndarray
    outside_link: np.ndarray
    before: float
    outside_key: np.ndarray


class Job(NamedTuple):
    """One candidate change, ready for export.

    Attributes:
      plan: the :class:`CollapsePlan` or :class:`MovePlan`.
      triangles: ``(T, 3)`` vertex ids of ``plan.new_triangles``: the
        plan's tuple of triples, or an int64 array.
      region: the :class:`Region` of ``plan.source`` (or its subsequence, for
        a partial update).
      moved: the new position of ``plan.source`` for a move, else ``None``.
      fixed_edge: ``(len(region.inside),)`` local edge each point keeps
        (``-1``: locate it), or ``None`` to locate them all.
    """

    plan: CollapsePlan | MovePlan
    triangles: np.ndarray
    region: Region
    moved: np.ndarray | None
    fixed_edge: np.ndarray | None

    def size(self) -> tuple[int, int, int]:
        """``(rows, edges, triangles)`` extents for packing; a triangulated
        disc of ``t`` triangles has at most ``2 t + 1`` edges."""
        return (len(self.region.inside) + len(self.region.outside), 2 * len(self.triangles) + 1,
                len(self.triangles))


class CandidateStencil(NamedTuple):
    """One candidate change (collapse or move), exported for scoring.

    Attributes:
      plan: the topological plan (flips + collapse, or a move).
      keys: ``(E, 2)`` global keys of the local edges after the change,
        sorted; row ``i`` is local edge ``i``.
      edges: ``(E, 2, 2)`` endpoint coordinates, lower id first.
      point_ids: ``(P,)`` global ids of the stencil's points: the
        ``n_inside`` points of the changed region first, then the points
        outside it that keep their (link) edge.
      n_inside: number of points of the changed region.
      before: cost of the region's edges before the change.
      moved: for a move, the new position of ``plan.source``; ``None`` for a
        collapse.
      cand: ``(P, 3)`` local candidate edges per point (see
        :class:`~otjax.stencil.EdgeStencil`), or ``None`` when the points are
        left to the scoring kernel to locate.
      triangle_of_point: ``(P,)`` index into ``plan.new_triangles`` for the
        points of the changed region, ``-1`` for the others; ``None`` with
        ``cand``.
    """

    plan: CollapsePlan | MovePlan
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


def triangle_edges(tris: np.ndarray) -> np.ndarray:
    """``(T, 3, 2)`` the edges of triangles ``(T, 3)``, each as ``(min, max)`` id."""
    return np.sort(np.stack([tris, tris[:, [1, 2, 0]]], -1), -1)


class PlanEntry(NamedTuple):
    """A cached collapse plan of a half-edge, valid while both star versions hold.

    Attributes:
      source_stamp, target_stamp: the star versions of its two ends it was made at.
      flips: its ``Flips``, or ``None`` when the collapse cannot be planned.
      plan: its ``CollapsePlan``, or ``None`` (no flips, or the link condition fails).
      new_triangles: ``plan.new_triangles`` (read once), or ``None`` with ``plan``.
    """

    source_stamp: int
    target_stamp: int
    flips: object
    plan: CollapsePlan | None
    new_triangles: tuple | None


def _plan_entry(tri, source: int, target: int, stamps: tuple[int, int], flips, old_plan=None,
                old_triangles=None) -> PlanEntry:
    """The cache entry of a half-edge whose flips are ``flips``, at the star
    versions ``stamps`` (see :meth:`StencilCache._plan_entries`).

    ``old_plan`` (and its ``old_triangles``) is the plan of the same flips
    at an older star of the target: kept, the same object (plans are
    compared by identity first), while the link condition holds.
    """
    if flips is None:
        return PlanEntry(*stamps, None, None, None)
    if old_plan is not None:
        if link_condition(tri, target, flips):
            return PlanEntry(*stamps, flips, old_plan, old_triangles)
        return PlanEntry(*stamps, flips, None, None)
    plan = plan_from_flips(tri, source, target, flips)
    # The triangles stay tuples: the export reads a batch's at once.
    return PlanEntry(*stamps, flips, plan, None if plan is None else plan.new_triangles)


class StencilCache:
    """Regions and collapse plans of the current state, and jobs built from them.

    Args:
      plan: the :class:`~otjax.curves.plan.TransportPlan` (read only).
      log: the :class:`~otjax.curves.rescoring.ChangeLog` whose versions
        stamp the cache entries.
      max_source_degree: half-edges leaving a vertex of higher degree are not
        candidates until its degree falls (docs/decisions.md#max_source_degree).
    """

    def __init__(self, plan, log, max_source_degree: int = 32):
        self.plan = plan
        self.log = log
        self.max_source_degree = max_source_degree
        self._regions: dict[int, tuple[int, Region]] = {}
        # {source: {target: PlanEntry}}
        self._plans: dict[int, dict[int, PlanEntry]] = {}

    def forget(self, v: int) -> None:
        """Drops the region and plans of a removed vertex (memory only:
        stamps tell stale entries)."""
        self._regions.pop(v, None)
        self._plans.pop(v, None)

    def changed_plans(self, change) -> list[int]:
        """The vertices of ``change.quiet`` that must be scored again after
        all: a collapse onto a neighbour whose star the change altered gained
        or lost the link condition, or has no plan at hand to tell."""
        tri = self.plan.tri
        changed_stars = {*change.ring, change.target}
        star_version = self.log.star_version
        woke = []
        for a in sorted(change.quiet):
            if not self.collapsible_source(a):
                continue
            plans = self._plans.get(a, {})
            for x in tri.star(a)[0]:
                if x not in changed_stars:
                    continue
                hit = plans.get(x)
                if hit is None or hit.source_stamp != star_version[a] or (
                        hit.flips is not None and (hit.plan is not None) != link_condition(tri, x, hit.flips)):
                    woke.append(a)
                    break
        return woke

    def collapse_plan(self, source: int, target: int) -> CollapsePlan | None:
        """The collapse plan of a half-edge, cached until the star of either end changes.

        Its flips depend on the source's star alone: a change of the
        target's star only asks for the link condition again.
        """
        return self._plan_entries(source, (target,))[0].plan

    def _plan_entries(self, source: int, targets) -> list[PlanEntry]:
        """The current :class:`PlanEntry` of the half-edge from ``source`` to
        each of ``targets``. The flips not at hand are
        planned together (:func:`~otjax.curves.collapse.plan_flips_from`)."""
        sv = self.log.star_version
        s_stamp = sv[source]
        plans = self._plans.get(source)
        if plans is None:
            plans = self._plans[source] = {}
        tri = self.plan.tri
        out: list = []
        missing: list[int] = []
        for target in targets:
            hit = plans.get(target)
            if hit is None or hit.source_stamp != s_stamp:
                missing.append(len(out))
                out.append(None)
                continue
            t_stamp = sv[target]
            if hit.target_stamp != t_stamp:
                hit = plans[target] = _plan_entry(tri, source, target, (s_stamp, t_stamp), hit.flips, hit.plan,
                                                  hit.new_triangles)
            out.append(hit)
        if missing:
            wanted = [targets[i] for i in missing]
            for i, target, flips in zip(missing, wanted, plan_flips_from(tri, source, wanted)):
                out[i] = plans[target] = _plan_entry(tri, source, target, (s_stamp, sv[target]), flips)
        return out

    def region(self, v: int) -> Region:
        """The :class:`Region` of ``v``, cached until a change touches it."""
        hit = self._regions.get(v)
        version = self.log.version[v]
        if hit is not None and hit[0] == version:
            return hit[1]
        plan = self.plan
        tri = plan.tri
        ring, star = tri.star(v)
        nv = len(tri.xy)
        face_pts, cost, tris, nbr = plan.face_pts, plan.edge_cost, tri.tri, tri.nbr
        before = 0.0
        across, counts, codes = [], [], []
        for a, b, f in zip(ring, ring[1:] + ring[:1], star):
            before += cost.get((v, a) if v < a else (a, v), 0.0) + cost.get((a, b) if a < b else (b, a), 0.0)
            g = nbr[f][tris[f].index(v)]
            pts = face_pts[g] if g >= 0 else _NO_IDS
            across.append(pts)
            counts.append(len(pts))
            codes.append(a * nv + b if a < b else b * nv + a)
        inside = np.concatenate([face_pts[f] for f in star])
        # Of the points across each link edge, those assigned to that edge
        # (edges compared by their code min * V + max). Link index and code
        # are repeated together: each NumPy call costs more than its rows here.
        ids = np.concatenate(across)
        link_code = np.repeat(np.array((range(len(ring)), codes), np.int64), counts, axis=1)
        keep = plan.pt_code[ids] == link_code[1]
        kept = link_code[:, keep]
        region = Region(ring, star, inside, ids[keep], kept[0], before, kept[1])
        self._regions[v] = (version, region)
        return region

    def collapsible_source(self, v: int) -> bool:
        """Whether half-edges leaving ``v`` are candidates: live, free, and
        of degree within :attr:`max_source_degree`."""
        tri = self.plan.tri
        return bool(tri.alive[v]) and not tri.pinned[v] and len(tri.star(v)[0]) <= self.max_source_degree

    def prefetch(self, half_edges) -> None:
        """Reads the regions and collapse plans of ``half_edges`` into the
        caches: host work to do while a kernel runs."""
        for u, w in half_edges:
            if self.collapsible_source(u):
                self.region(u)
                self.collapse_plan(u, w)

    def collapse_jobs(self, sources, targets: dict | None = None) -> list[Job]:
        """Jobs of the collapsible half-edges leaving ``sources``, in source
        then ring order (``targets``: optional ``{source: allowed targets}``)."""
        jobs = []
        for v in sources:
            if not self.collapsible_source(v):
                continue
            region = self.region(v)
            if targets is None:
                wanted = region.ring
            else:
                allowed = set(targets[v])
                wanted = [w for w in region.ring if w in allowed]
            for entry in self._plan_entries(v, wanted):
                if entry.plan is not None:
                    jobs.append(Job(entry.plan, entry.new_triangles, region, None, None))
        return jobs

    def move_jobs(self, moves):
        """Jobs of the ``(v, position)`` moves that keep the embedding
        (``position`` strictly inside the kernel of ``v``'s one-ring)."""
        tri = self.plan.tri
        for v, position in moves:
            position = np.asarray(position, np.float64)
            ring, star = tri.star(v)
            if not tri.in_kernel_at(ring, position):
                continue
            plan = MovePlan(v, ring, star)
            yield Job(plan, plan.new_triangles, self.region(v), position, None)
