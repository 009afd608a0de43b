"""What changed since a collapse was scored, and re-scoring only that.

The :class:`ChangeLog` owns the versions: ``version[v]`` is bumped whenever a
change touches the region of ``v`` (the score table reads it to tell stale
scores; the region cache stamps with it), ``star_version[v]`` whenever the
star of ``v`` itself changes (collapse plans are stamped with it). For a
vertex whose star kept its triangles, it also remembers which link edges
saw their far side change, and which ring vertices moved.

A scored collapse whose source's star kept its triangles differs from a
fresh scoring on a few edges only; :class:`LinkRecord` keeps what is needed
to score just those again (:class:`LinkUpdates`), bit for bit the values of
a full scoring.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.curves.plan import Change
from otjax.curves.stencils import Job, Region, triangle_edges
from otjax.curves.triangulation import CollapsePlan, edge_key

# Link changes remembered per vertex; an older record counts as a change of
# the star (docs/decisions.md#link_log).
LINK_LOG = 64


class ChangeLog:
    """Per-vertex versions and the link changes since each star change.

    Args:
      n_vertices: vertex count of the triangulation (ids are never reused).
    """

    def __init__(self, n_vertices: int):
        self.version = [0] * n_vertices
        self.star_version = [0] * n_vertices
        self._star_changed_at: dict[int, int] = {}
        self._link_log: dict[int, list[tuple[int, frozenset, frozenset]]] = {}

    def record(self, change: Change) -> None:
        """Bumps the versions of what ``change`` touched and logs its link changes."""
        for v in change.ring + (change.source, change.target):
            self.star_version[v] += 1
        full = {*change.ring, change.source}
        # A move keeps every star's triangles: around its ring vertices, only
        # the moved vertex is logged (LinkUpdates.partial_job scores what it reaches).
        moved = frozenset((change.source,)) if change.moved else frozenset()
        for v in change.touched:
            self.version[v] += 1
            if v in change.links or (moved and v != change.source):
                log = self._link_log.setdefault(v, [])
                log.append((self.version[v], change.links.get(v, frozenset()), moved if v in full else frozenset()))
                if len(log) > LINK_LOG:
                    self._star_changed_at[v] = log.pop(0)[0]
            else:
                self._star_changed_at[v] = self.version[v]
                self._link_log.pop(v, None)

    def changes(self, v: int, since: int) -> tuple[set, set] | None:
        """``(link edge keys, moved ring vertices)`` changed around ``v``
        after version ``since``, or ``None`` if its triangles did."""
        if self._star_changed_at.get(v, -1) > since:
            return None
        keys: set = set()
        moved: set = set()
        for version, k, m in self._link_log.get(v, ()):
            if version > since:
                keys |= k
                moved |= m
        return keys, moved

    def changed_links(self, v: int, since: int) -> set | None:
        """Link edges of ``v``'s star whose far side changed after version
        ``since``; ``None`` if the star itself may have changed (its
        triangles, or the position of a ring vertex)."""
        changes = self.changes(v, since)
        return None if changes is None or changes[1] else changes[0]


class LinkRecord(NamedTuple):
    """What re-scoring a scored collapse needs when part of its stencil changed.

    A change next to the star of ``source`` (not in it) alters the points
    across some of its link edges and nothing else of its collapse stencils:
    their after-costs differ on those link edges only. Each link edge after
    the collapse holds the points of the changed region assigned to it
    (unchanged while the plan is) and the points across it that keep it.

    A move of a ring vertex ``m`` changes the new triangles at ``m`` and the
    points across the link edges next to it; every other new triangle keeps
    its shape, hence its points and their edges. Only the edges of the
    changed triangles (and of the changed link edges) are scored again, on
    the subsequence of the full stencil that can reach them
    (:meth:`LinkUpdates.partial_job`).

    Attributes:
      plan: the collapse plan scored.
      version: the source's version when scored (:class:`ChangeLog`).
      keys: ``(E, 2)`` the candidate's local edge keys.
      edge_cost: ``(E,)`` cost of each local edge after the collapse.
      link_edge: ``(n,)`` local index of link edge ``k`` (``(ring[k], ring[k+1])``).
      link_start: ``(n + 1,)`` offsets of each link edge's points in ``link_points``.
      link_points: points of the changed region assigned to each link edge,
        in stencil order.
      inside: ``(P,)`` the region's points when scored, in stencil order.
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
        segment sum does: the greedy makes the same choices (exact ties and
        rounding included) with or without updates.
        """
        return float(np.cumsum(self.edge_cost)[-1]) - before


class Partial(NamedTuple):
    """What :meth:`LinkUpdates.finish_partial` needs with a partial job's scores."""

    record: LinkRecord
    affected: np.ndarray
    changed_tri: np.ndarray
    inside: np.ndarray
    pos: np.ndarray
    fixed: np.ndarray
    take: np.ndarray


class LinkPart(NamedTuple):
    """One changed link edge to score again: its points and its place."""

    item: int
    local_edge: int
    key: np.ndarray
    points: tuple[np.ndarray, np.ndarray]


class LinkUpdates:
    """Builds and finishes the updates of :class:`LinkRecord` s.

    Args:
      plan: the :class:`~otjax.curves.plan.TransportPlan` (read only).
      log: the :class:`ChangeLog`.
      stencils: the :class:`~otjax.curves.stencils.StencilCache`.
    """

    def __init__(self, plan, log: ChangeLog, stencils):
        self.plan = plan
        self.log = log
        self.stencils = stencils
        self._slot: np.ndarray | None = None  # scratch of _positions

    def record_changes(self, rec: LinkRecord) -> tuple[set, set] | None:
        """What changed since ``rec`` was scored: ``(link edge keys, moved
        ring vertices)``, or ``None`` if it must be scored again in full:
        its source's star changed, its target moved, or the plan of its
        half-edge changed."""
        changes = self.log.changes(rec.plan.source, rec.version)
        if changes is None or rec.plan.target in changes[1]:
            return None
        if self.stencils.collapse_plan(rec.plan.source, rec.plan.target) != rec.plan:
            return None
        return changes

    def record(self, cand, scored) -> LinkRecord:
        """The :class:`LinkRecord` of a scored collapse, valid at the current state."""
        n = cand.n_inside
        inside = self.stencils.region(cand.plan.source).inside
        if len(inside) != n:
            raise RuntimeError("the region changed since the candidate was exported")
        if len(cand.keys) > np.iinfo(np.int16).max:  # local triangles <= local edges: both fit int16
            raise ValueError(f"a stencil of {len(cand.keys)} local edges overflows the int16 record; "
                             "lower max_source_degree")
        return self._record(cand.plan, cand.keys, np.asarray(scored.edge_cost, np.float64), inside,
                            scored.triangle[:n].astype(np.int16), scored.assignment[:n].astype(np.int16))

    def _record(self, plan: CollapsePlan, keys, edge_cost, inside, triangle, edge) -> LinkRecord:
        ring = np.asarray(plan.ring, np.int64)
        nxt = np.asarray(plan.ring[1:] + plan.ring[:1], np.int64)
        nv = len(self.plan.tri.xy)
        code = keys[:, 0] * nv + keys[:, 1]  # keys are sorted
        link_edge = np.searchsorted(code, np.minimum(ring, nxt) * nv + np.maximum(ring, nxt))
        which = np.full(len(code), -1, np.int64)
        which[link_edge] = np.arange(len(ring))
        k = which[edge]
        on_link = np.flatnonzero(k >= 0)
        order = on_link[np.argsort(k[on_link], kind="stable")]
        start = np.searchsorted(k[order], np.arange(len(ring) + 1))
        return LinkRecord(plan, self.log.version[plan.source], keys, edge_cost, link_edge, start,
                          inside[order], inside, triangle, edge)

    def _affected(self, rec: LinkRecord, region: Region, changed: set, moved: set, changed_tri):
        """Local edges a partial update must score again: those of the
        changed triangles and the changed link edges."""
        tri = self.plan.tri
        tris = np.asarray(rec.plan.new_triangles, np.int64)
        nv = len(tri.xy)
        code = rec.keys[:, 0] * nv + rec.keys[:, 1]
        e = triangle_edges(tris[changed_tri]).reshape(-1, 2)
        affected = np.zeros(len(code), bool)
        affected[np.searchsorted(code, e[:, 0] * nv + e[:, 1])] = True
        ring, star, v = region.ring, region.star, rec.plan.source
        n = len(ring)
        for k in range(n):
            f = star[k]
            g = tri.nbr[f][tri.tri[f].index(v)]
            if (g >= 0 and any(x in moved for x in tri.tri[g])) or edge_key(ring[k], ring[(k + 1) % n]) in changed:
                affected[rec.link_edge[k]] = True
        return affected

    def partial_job(self, rec: LinkRecord, changed: set, moved: set) -> tuple[Job, Partial] | None:
        """The part of ``rec``'s collapse that ring moves (and link changes)
        since it was scored reach, as an export job, or ``None`` if that is
        all of it.

        The job's rows are the subsequence of the full stencil's rows (same
        order) that can reach an affected edge: points not known to lie in an
        unchanged new triangle (located by the kernel: they lie in a changed
        one), points of unchanged triangles recorded on an affected edge
        (fixed to it), and the points across affected link edges. An edge
        whose points come in another order than when scored (a move rebuilds
        the point lists of its faces) is affected too: its sum would round
        otherwise. Each affected edge thus gets the points a full scoring
        would give it, in the same order, and the kernel's costs for it are
        the full scoring's, bit for bit.
        """
        plan = rec.plan
        region = self.stencils.region(plan.source)
        tris = np.asarray(plan.new_triangles, np.int64)
        mv = np.fromiter(moved, np.int64, len(moved))
        changed_tri = np.isin(tris, mv).any(1)
        if changed_tri.all():
            return None
        affected = self._affected(rec, region, changed, moved, changed_tri)
        inside = region.inside
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
        take_out = affected[rec.link_edge][region.outside_link]
        sub = Region(region.ring, region.star, inside[take], region.outside[take_out],
                     region.outside_link[take_out], region.before, region.outside_key[take_out])
        return Job(plan, tris, sub, None, fixed_edge[take]), Partial(rec, affected, changed_tri, inside, pos,
                                                                      fixed, take)

    def finish_partial(self, pending: Partial, cand, scored) -> tuple[LinkRecord, float]:
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
        return new, new.delta(self.stencils.region(rec.plan.source).before)

    def _positions(self, old: np.ndarray, new: np.ndarray) -> np.ndarray:
        """Index of each of ``new`` in ``old`` (ids of points), ``-1`` if absent."""
        n = len(self.plan.points)
        if self._slot is None or len(self._slot) != n:
            self._slot = np.full(n, -1, np.int64)
        slot = self._slot
        slot[old] = np.arange(len(old))
        out = slot[new]
        slot[old] = -1
        return out

    def link_parts(self, items) -> list[LinkPart]:
        """The changed link edges of ``items``, ``(record, changed keys)``
        pairs: each edge's points (those of the changed region recorded on
        it, then those across it that keep it) and where its cost goes."""
        parts = []
        for i, (rec, changed) in enumerate(items):
            region = self.stencils.region(rec.plan.source)
            ring = region.ring
            n = len(ring)
            for k in range(n):
                if edge_key(ring[k], ring[(k + 1) % n]) not in changed:
                    continue
                pts = (rec.link_points[rec.link_start[k]: rec.link_start[k + 1]],
                       region.outside[region.outside_link == k])
                parts.append(LinkPart(i, int(rec.link_edge[k]), rec.keys[rec.link_edge[k]], pts))
        return parts

    def finish_links(self, items, parts: list[LinkPart], costs: np.ndarray) -> list[tuple[LinkRecord, float]]:
        """``[(record, delta)]``: each record of ``items`` brought up to date
        with the ``costs (len(parts),)`` of its changed link edges, and the
        collapse's cost increase (the values of a full re-scoring, since each
        edge gets the same points in the same order)."""
        new_cost = [rec.edge_cost.copy() for rec, _ in items]
        for part, c in zip(parts, costs.tolist()):
            new_cost[part.item][part.local_edge] = c
        out = []
        for (rec, _), cost in zip(items, new_cost):
            v = rec.plan.source
            rec = rec._replace(version=self.log.version[v], edge_cost=cost)
            out.append((rec, rec.delta(self.stencils.region(v).before)))
        return out


class Split(NamedTuple):
    """The half-edges of some sources, by how they are brought up to date
    (see :meth:`LinkRecords.split`)."""

    full: dict
    updates: list
    partial: list


class LinkRecords:
    """The :class:`LinkRecord` of each collapse scored in full or updated,
    by source then target, and what each needs now.

    Args:
      links: the :class:`LinkUpdates` that reads what changed.
    """

    def __init__(self, links: LinkUpdates):
        self.links = links
        self._by_source: dict[int, dict[int, LinkRecord]] = {}

    def put(self, key: tuple[int, int], rec: LinkRecord) -> None:
        """Records half-edge ``key``'s scoring (replacing an older one)."""
        self._by_source.setdefault(key[0], {})[key[1]] = rec

    def drop(self, source: int) -> None:
        """Forgets the records of the half-edges leaving ``source``."""
        self._by_source.pop(source, None)

    def split(self, sources) -> Split:
        """The half-edges leaving ``sources``: to score in full (``full``,
        ``{source: targets}``), ``(record, changed links)`` of those only
        their link changed (``updates``), and ``(job, pending)`` of those a
        ring move changed in part (``partial``). Their records are dropped."""
        tri = self.links.plan.tri
        full: dict[int, list[int]] = {}
        updates, partial = [], []
        for v in sources:
            recs = self._by_source.pop(v, {})
            if not tri.alive[v] or tri.pinned[v]:
                continue
            for w in tri.star(v)[0]:
                rec = recs.get(w)
                changes = None if rec is None else self.links.record_changes(rec)
                if changes is not None and changes[1]:
                    part = self.links.partial_job(rec, *changes)
                    if part is not None:
                        partial.append(part)
                        continue
                elif changes is not None:
                    updates.append((rec, changes[0]))
                    continue
                full.setdefault(v, []).append(w)
        return Split(full, updates, partial)
