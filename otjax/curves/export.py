"""Jobs laid end to end as one flat host batch, and the kernel's outputs read back.

:func:`export_jobs` writes a list of :class:`~otjax.curves.stencils.Job` s
as a :class:`HostBatch`: every job's new triangles, local edges (numbered in
increasing key within the job), rows (the points of its region, then those
across its link that keep their edge) and fan, on concatenated arrays (the
per-job Python work is slicing only). :meth:`HostBatch.values` is what the
:data:`~otjax.curves.scoring.FIELDS` layout packs. :func:`read_costs` cuts
the kernel's outputs back into one :class:`CandidateCost` per job.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from otjax.batch.fields import Gather, Prefix
from otjax.batch.packing import choose_packing
from otjax.curves import scoring
from otjax.curves.location import MIN_PAIRS as LOCATE_MIN_PAIRS
from otjax.curves.location import locate_pairs
from otjax.curves.stencils import CandidateCost, CandidateStencil, Job, triangle_edges
from otjax.stencil import ragged_index

_NO_IDS = np.zeros(0, np.int64)


@dataclass
class HostBatch:
    """One flat batch on the host: candidates, rows, edges and triangles end
    to end (unpadded, ids of any width), and what reading the results needs.

    See :class:`otjax.curves.scoring.FlatBatch` for the fields shared with the
    kernel; the others: ``cands`` (the :class:`CandidateStencil` of each job,
    a sequence that makes each when first read), ``n_inside`` (``(J,)`` or
    ``None``: read from ``cands``),
    ``row_point`` (``(R,)`` point id of each row), ``row_tri`` (local triangle
    of a row located on the host, else ``-1``), ``row_start``,
    ``edge_start``, ``tri_start`` (``(J + 1,)`` offsets per job), ``before``
    (``(J,)``), ``seq`` (where each job stands in the job list a packed export
    was made from) and ``located_by_kernel`` (whether host location used the
    location kernel: one more compiled shape).
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
    seq: np.ndarray | None = None
    located_by_kernel: bool = False
    n_inside: np.ndarray | None = None

    @classmethod
    def empty(cls) -> HostBatch:
        return cls.without_triangles(_NO_IDS, np.zeros((0, 3), np.int64), _NO_IDS, np.zeros((0, 2, 2)),
                                     _NO_IDS, [])

    @classmethod
    def without_triangles(cls, row_point, row_cand, row_job, edge_xy, edge_job, cands, before=None,
                          row_tri=None) -> HostBatch:
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
            job_theta=np.zeros(nj), job_ears=np.full((nj, scoring.MAX_EARS), -1, np.int64),
            before=np.zeros(nj) if before is None else before)

    def need(self) -> int:
        """The smallest row capacity that fits this batch (:func:`scoring.capacity`)."""
        return scoring.capacity(len(self.row_point), len(self.edge_job), len(self.tri_edges),
                                len(self.job_theta))

    def values(self, points: np.ndarray, mass: np.ndarray) -> dict:
        """The batch as :data:`scoring.FIELDS` values, the rows' points and
        masses gathered from ``points (n, 2)`` and ``mass (n,)``."""
        return {
            "row_xy": Gather(points, self.row_point), "row_mass": Gather(mass, self.row_point),
            "row_job": self.row_job, "row_cand": self.row_cand, "row_locate": self.row_locate,
            "row_valid": Prefix(len(self.row_point), 1), "tri_xy": self.tri_xy.T, "tri_edges": self.tri_edges,
            "fan_key": self.fan_key, "fan_tri": self.fan_tri, "job_fan": self.job_fan,
            "job_apex": self.job_apex, "job_theta": self.job_theta, "job_ears": self.job_ears,
            "edge_xy": self.edge_xy, "edge_valid": Prefix(len(self.edge_job), 1), "edge_job": self.edge_job,
        }


def _new_triangles(jobs: list[Job], xy: np.ndarray):
    """``(tris (T, 3), coords (T, 3, 2), tri_start (J + 1,))`` of the jobs,
    the moved vertex of a move at its new position."""
    n_tri = np.array([len(job.triangles) for job in jobs])
    tris = np.concatenate([job.triangles for job in jobs])
    coords = xy[tris]
    tri_start = np.concatenate([[0], np.cumsum(n_tri)])
    for j, job in enumerate(jobs):
        if job.moved is not None:
            s = slice(tri_start[j], tri_start[j + 1])
            coords[s] = np.where((job.triangles == job.plan.source)[..., None], job.moved, coords[s])
    return tris, coords, tri_start


class _Edges(NamedTuple):
    """The local edges of the jobs of a batch (see :func:`_local_edges`)."""

    code: np.ndarray
    keys: np.ndarray
    start: np.ndarray
    job: np.ndarray
    xy: np.ndarray
    of_triangle: np.ndarray


class _Rows(NamedTuple):
    """The rows of the jobs of a batch (see :func:`_rows`)."""

    point: np.ndarray
    job: np.ndarray
    cand: np.ndarray
    locate: np.ndarray
    start: np.ndarray
    n_inside: np.ndarray


class _Fans(NamedTuple):
    """The fans of the jobs of a batch (see :func:`_fans`)."""

    key: np.ndarray
    tri: np.ndarray
    job_fan: np.ndarray
    apex: np.ndarray
    theta: np.ndarray
    ears: np.ndarray
    few_ears: np.ndarray


def _local_edges(jobs: list[Job], tris: np.ndarray, tri_start: np.ndarray, xy: np.ndarray) -> _Edges:
    """Local edges of every job.

    Keys are coded job-major, so ``np.unique`` numbers every job's edges
    contiguously and in increasing key order within the job: the flat number
    of an edge is its job's offset plus its local one.
    """
    nv = len(xy)
    nj = len(jobs)
    if nj * nv * nv > np.iinfo(np.int64).max:  # the (job, a, b) code below must not wrap
        raise ValueError(f"{nj} jobs over {nv} vertices overflow the int64 edge code; use fewer initial vertices")
    tri_job = np.repeat(np.arange(nj), np.diff(tri_start))
    e = triangle_edges(tris)  # (T, 3, 2)
    code = (np.repeat(tri_job, 3) * nv + e[..., 0].ravel()) * nv + e[..., 1].ravel()
    ucode, inv = np.unique(code, return_inverse=True)
    edge_job = ucode // (nv * nv)
    edge_start = np.searchsorted(edge_job, np.arange(nj + 1))
    ukeys = np.stack([(ucode // nv) % nv, ucode % nv], 1)
    tri_edges = np.sort(inv.reshape(-1, 3), 1)
    edge_xy = xy[ukeys]
    for j, job in enumerate(jobs):
        if job.moved is not None:
            es = slice(edge_start[j], edge_start[j + 1])
            edge_xy[es] = np.where((ukeys[es] == job.plan.source)[..., None], job.moved, edge_xy[es])
    return _Edges(ucode, ukeys, edge_start, edge_job, edge_xy, tri_edges)


def _rows(jobs: list[Job], ucode: np.ndarray, edge_start: np.ndarray, nv: int) -> _Rows:
    """Rows of every job: the points of its region, then the points across
    its link that keep their link edge (their candidate: that edge); rows
    whose edge is known (a partial update) are fixed to it.
    """
    nj = len(jobs)
    n_in = np.array([len(job.region.inside) for job in jobs])
    n_out = np.array([len(job.region.outside) for job in jobs])
    n_rows = n_in + n_out
    row_start = np.concatenate([[0], np.cumsum(n_rows)])
    parts = []
    for job in jobs:
        parts += [job.region.inside, job.region.outside]
    row_point = np.concatenate(parts).astype(np.int64)
    row_job = np.repeat(np.arange(nj), n_rows)
    row_cand = np.zeros((len(row_point), 3), np.int64)
    row_locate = np.ones(len(row_point), bool)
    if n_out.sum():
        out_job, k = ragged_index(n_out)
        out_rows = row_start[out_job] + n_in[out_job] + k
        # The (job, a, b) code of _local_edges: job * V^2 + the region's link key.
        lk = out_job * (nv * nv) + np.concatenate([job.region.outside_key for job in jobs])
        row_cand[out_rows] = np.searchsorted(ucode, lk)[:, None]
        row_locate[out_rows] = False
    for j, job in enumerate(jobs):
        if job.fixed_edge is not None:
            k = np.flatnonzero(job.fixed_edge >= 0)
            row_cand[row_start[j] + k] = (edge_start[j] + job.fixed_edge[k])[:, None]
            row_locate[row_start[j] + k] = False
    return _Rows(row_point, row_job, row_cand, row_locate, row_start, n_in)


def _fans(jobs: list[Job], coords: np.ndarray, tri_start: np.ndarray) -> _Fans:
    """The new triangles of a job are its flipped-out ears, then a fan around
    one apex (the target, or the moved vertex), CCW: the fan keys the kernel
    searches and the ears it tests.
    ``few_ears``: whether a job's ears fit the kernel's :data:`scoring.MAX_EARS`.
    """
    nj = len(jobs)
    n_tri = np.diff(tri_start)
    n_flip = np.fromiter((len(job.plan.flipped_out) for job in jobs), np.int64, nj)
    fan_start = tri_start[:-1] + n_flip
    n_fan = n_tri - n_flip
    job_fan = np.concatenate([[0], np.cumsum(n_fan)])
    fan_job, k = ragged_index(n_fan)
    fan_tri = fan_start[fan_job] + k
    apex = coords[fan_start, 0]  # (J, 2): fan triangles are (apex, a, b)
    d = coords[fan_start, 1] - apex
    theta = scoring.pseudo_angle(d[:, 0], d[:, 1])
    d = coords[fan_tri, 1] - apex[fan_job]
    phi = np.mod(scoring.pseudo_angle(d[:, 0], d[:, 1]) - theta[fan_job], 4.0)
    phi[job_fan[:-1]] = 0.0
    ears = np.full((nj, scoring.MAX_EARS), -1, np.int64)
    few = n_flip <= scoring.MAX_EARS
    ej, k = ragged_index(np.where(few, n_flip, 0))
    ears[ej, k] = tri_start[ej] + k
    return _Fans(fan_job * 8.0 + phi, fan_tri, job_fan, apex, theta, ears, few)


class Stencils(Sequence):
    """The :class:`CandidateStencil` s of an exported batch, each made when
    first read: a scoring reads a few of them (the winner, large stencils),
    not all.

    It holds the batch's arrays, not the batch (which holds it): no
    reference cycle, so a dropped batch is freed at once.

    Args:
      jobs: the batch's jobs.
      batch: the :class:`HostBatch` exported from them.
      edge_keys: ``(E, 2)`` the batch's flat edge keys.
      on_host: whether the batch was located on the host (the stencils then
        carry their candidate edges and triangles).
    """

    def __init__(self, jobs: list[Job], batch: HostBatch, edge_keys: np.ndarray, on_host: bool):
        self.jobs = jobs
        self.edge_keys = edge_keys
        self.edge_xy, self.row_point, self.before = batch.edge_xy, batch.row_point, batch.before
        self.edge_start, self.row_start, self.n_inside = batch.edge_start, batch.row_start, batch.n_inside
        self.located = (batch.row_cand, batch.row_tri) if on_host else None
        self._made: list = [None] * len(jobs)

    def __len__(self) -> int:
        return len(self.jobs)

    def plan(self, j: int):
        """The plan of job ``j`` (without making its stencil)."""
        return self.jobs[j].plan

    def __getitem__(self, j):
        if isinstance(j, slice):
            return [self[i] for i in range(*j.indices(len(self)))]
        c = self._made[j]
        if c is None:
            job = self.jobs[j]
            es = slice(self.edge_start[j], self.edge_start[j + 1])
            rs = slice(self.row_start[j], self.row_start[j + 1])
            cand = tri = None
            if self.located is not None:
                cand = self.located[0][rs] - self.edge_start[j]
                tri = self.located[1][rs]
            c = self._made[j] = CandidateStencil(job.plan, self.edge_keys[es], self.edge_xy[es], self.row_point[rs],
                                                 int(self.n_inside[j]), float(self.before[j]), job.moved, cand, tri)
        return c


class Costs(Sequence):
    """The :class:`CandidateCost` s of a scored batch, each made when first
    read; an entry may be replaced (a job scored again).

    Args:
      delta: ``(J,)`` cost increase of each job.
      fields: the six ``(E,)`` per-edge fields of :class:`CandidateCost`.
      assignment: ``(R,)`` local edge of each row.
      triangle: ``(R,)`` local new triangle of each row.
      edge_start, row_start: ``(J + 1,)`` offsets.
      n_inside: ``(J,)`` rows of each job's changed region.
    """

    def __init__(self, delta, fields, assignment, triangle, edge_start, row_start, n_inside):
        self.delta = delta
        self.fields = fields
        self.assignment = assignment
        self.triangle = triangle
        self.edge_start = edge_start
        self.row_start = row_start
        self.n_inside = n_inside
        self._made: list = [None] * len(delta)

    def __len__(self) -> int:
        return len(self._made)

    def __getitem__(self, j):
        if isinstance(j, slice):
            return [self[i] for i in range(*j.indices(len(self)))]
        c = self._made[j]
        if c is None:
            es = slice(self.edge_start[j], self.edge_start[j + 1])
            r0 = self.row_start[j]
            c = self._made[j] = CandidateCost(float(self.delta[j]), *(f[es] for f in self.fields),
                                              self.assignment[r0:self.row_start[j + 1]],
                                              self.triangle[r0:r0 + self.n_inside[j]])
        return c

    def __setitem__(self, j: int, cost: CandidateCost) -> None:
        self._made[j] = cost


def held_bytes(batch: HostBatch, costs: Costs) -> int:
    """Bytes of the arrays that keeping ``batch`` and its ``costs`` holds
    (each underlying buffer once)."""
    arrays = [v for v in vars(batch).values() if isinstance(v, np.ndarray)]
    arrays += [*costs.fields, costs.assignment, costs.triangle]
    owners = {}
    for a in arrays:
        while isinstance(a.base, np.ndarray):
            a = a.base
        owners[id(a)] = a.nbytes
    return sum(owners.values())


def export_jobs(jobs: list[Job], plan, on_host: bool) -> HostBatch:
    """The flat :class:`HostBatch` of ``jobs``.

    Args:
      jobs: the jobs, against the current state of ``plan``.
      plan: the :class:`~otjax.curves.plan.TransportPlan` (read only).
      on_host: locate every point here (exactly); otherwise only the points
        of jobs with more ears than the kernel tests.
    """
    if not jobs:
        return HostBatch.empty()
    xy, points, point_rows = plan.tri.xy, plan.points, plan.point_rows
    nv = len(xy)
    tris, coords, tri_start = _new_triangles(jobs, xy)
    edges = _local_edges(jobs, tris, tri_start, xy)
    rows = _rows(jobs, edges.code, edges.start, nv)
    fans = _fans(jobs, coords, tri_start)
    batch = HostBatch(
        cands=(), row_point=rows.point, row_job=rows.job, row_cand=rows.cand, row_locate=rows.locate,
        row_tri=np.full(len(rows.point), -1, np.int64), row_start=rows.start, edge_start=edges.start,
        tri_start=tri_start, edge_xy=edges.xy, edge_job=edges.job,
        tri_xy=np.ascontiguousarray(coords.reshape(-1, 6).T), tri_edges=edges.of_triangle, fan_key=fans.key,
        fan_tri=fans.tri, job_fan=fans.job_fan, job_apex=fans.apex, job_theta=fans.theta, job_ears=fans.ears,
        before=np.array([job.region.before for job in jobs]), n_inside=rows.n_inside)
    if on_host:
        locate_on_host(batch, np.arange(len(jobs)), points, point_rows)
    elif not fans.few_ears.all():
        locate_on_host(batch, np.flatnonzero(~fans.few_ears), points, point_rows)
    batch.cands = Stencils(jobs, batch, edges.keys, on_host)
    return batch


def locate_on_host(batch: HostBatch, jobs: np.ndarray, points: np.ndarray, point_rows: np.ndarray) -> None:
    """Locates the region points of ``jobs`` exactly, on the host.

    Sets their ``row_cand`` and ``row_tri`` and clears ``row_locate``.

    A guess first: the angular sector around the fan apex that the point
    falls in (one ``searchsorted`` for all jobs). The exact test confirms
    each guess; points it rejects (in an ear, near a sector boundary, on the
    apex) are tested against every new triangle of their job. So the answer
    is the exact perturbed location in every case, at about one tested pair
    per point instead of ``deg - 2``.
    """
    in_job = np.zeros(len(batch.row_start) - 1, bool)
    in_job[jobs] = True
    rows = np.flatnonzero(batch.row_locate & in_job[batch.row_job])
    if not len(rows):
        return
    inside = batch.row_point[rows]
    pt_job = batch.row_job[rows]
    tri_start = batch.tri_start
    n_tri = np.diff(tri_start)
    d = np.take(points, inside, axis=0) - batch.job_apex[pt_job]
    phi = np.mod(scoring.pseudo_angle(d[:, 0], d[:, 1]) - batch.job_theta[pt_job], 4.0)
    lo, hi = batch.job_fan[pt_job], batch.job_fan[pt_job + 1] - 1
    g = np.clip(np.searchsorted(batch.fan_key, pt_job * 8.0 + phi, side="right") - 1, lo, hi)
    guess = batch.fan_tri[g]
    ok = locate_pairs(batch.tri_xy[:, guess], point_rows[:, inside])
    batch.located_by_kernel |= len(inside) >= LOCATE_MIN_PAIRS
    found = np.where(ok, guess, -1)
    rest = np.flatnonzero(~ok)
    if len(rest):
        job = pt_job[rest]
        pair_pt, k = ragged_index(n_tri[job])
        pair_tri = tri_start[job][pair_pt] + k
        hold = locate_pairs(batch.tri_xy[:, pair_tri], point_rows[:, inside[rest[pair_pt]]])
        batch.located_by_kernel |= len(pair_pt) >= LOCATE_MIN_PAIRS
        hit = np.flatnonzero(hold)
        # The perturbed location is a partition: exactly one triangle each.
        if len(hit) != len(rest) or np.any(pair_pt[hit] != np.arange(len(rest))):
            raise RuntimeError("a point of the star is not covered exactly once after the change")
        found[rest] = pair_tri[hit]
    batch.row_cand[rows] = batch.tri_edges[found]
    batch.row_tri[rows] = found - tri_start[pt_job]
    batch.row_locate[rows] = False


def keep_located(batch: HostBatch, jobs: np.ndarray, located: np.ndarray) -> None:
    """Takes the kernel's locations of the rows of ``jobs`` it located.

    The kernel locates a row only where its filter is sure, so those are
    the exact perturbed locations: only the other rows of ``jobs`` are left
    for :func:`locate_on_host`. Sets their ``row_cand`` and ``row_tri`` and
    clears ``row_locate``.

    Args:
      batch: the batch the kernel scored.
      jobs: ``(k,)`` job indices.
      located: ``(R,)`` the kernel's flat triangle of each row (``-1``: not located).
    """
    in_job = np.zeros(len(batch.row_start) - 1, bool)
    in_job[jobs] = True
    rows = np.flatnonzero(batch.row_locate & in_job[batch.row_job] & (located >= 0))
    found = located[rows]
    batch.row_cand[rows] = batch.tri_edges[found]
    batch.row_tri[rows] = found - batch.tri_start[batch.row_job[rows]]
    batch.row_locate[rows] = False


def located_jobs(batch: HostBatch, jobs: np.ndarray) -> HostBatch:
    """The jobs ``jobs`` of ``batch``, every row of them located
    (:func:`keep_located`, :func:`locate_on_host`), as a batch of their own.

    A job's scores do not depend on the other jobs of its batch, so scoring
    these again alone gives what scoring the whole batch again would.
    """
    cands = []
    for j in jobs.tolist():
        c = batch.cands[j]
        rs = slice(batch.row_start[j], batch.row_start[j + 1])
        cands.append(c._replace(cand=batch.row_cand[rs] - batch.edge_start[j], triangle_of_point=batch.row_tri[rs]))
    return batch_of_located(cands)


def packed_batches(jobs, plan, budget: int = scoring.ROW_BUDGET):
    """The jobs as batches packed into few capacities
    (:func:`~otjax.batch.packing.choose_packing`), left for the kernel to
    locate; a generator (the jobs are listed at the first batch), each
    batch's ``seq`` saying where its jobs stand in ``jobs``."""
    jobs = list(jobs)
    packing = choose_packing([job.size() for job in jobs], budget, scoring.capacity, scoring.SHAPES.shape_for,
                             scoring.MIN_ROWS)
    for members in packing:
        batch = export_jobs([jobs[i] for i in members], plan, on_host=False)
        batch.seq = np.asarray(members, np.int64)
        yield batch


def located_batches(cands: list[CandidateStencil], budget: int = scoring.ROW_BUDGET):
    """Located candidates in batches of about ``budget`` rows, in order."""
    run, used = [], 0
    for c in cands:
        if run and used + len(c.point_ids) > budget:
            yield batch_of_located(run)
            run, used = [], 0
        run.append(c)
        used += len(c.point_ids)
    if run:
        yield batch_of_located(run)


def batch_of_located(cands: list[CandidateStencil]) -> HostBatch:
    """A flat batch of located candidates (from an ``on_host`` export)."""
    if any(c.cand is None for c in cands):
        raise ValueError("candidates exported for the kernel to locate are scored as the batch they came in")
    n_edges = np.array([len(c.keys) for c in cands], np.int64)
    edge_start = np.concatenate([[0], np.cumsum(n_edges)])
    n_rows = np.array([len(c.point_ids) for c in cands], np.int64)
    row_job = np.repeat(np.arange(len(cands)), n_rows)
    return HostBatch.without_triangles(
        np.concatenate([c.point_ids for c in cands]),
        np.concatenate([c.cand for c in cands]) + edge_start[row_job][:, None], row_job,
        np.concatenate([c.edges for c in cands]), np.repeat(np.arange(len(cands)), n_edges), cands,
        before=np.array([c.before for c in cands]),
        row_tri=np.concatenate([c.triangle_of_point for c in cands]))


def cut_outputs(batch: HostBatch, outputs: scoring.Scores) -> scoring.Scores:
    """The kernel's host outputs cut to the batch's real jobs, edges and rows."""
    nj, ne, nr = len(batch.row_start) - 1, len(batch.edge_job), len(batch.row_point)
    return scoring.Scores(outputs.total[:nj], outputs.per_edge[:ne], outputs.assignment[:nr],
                          outputs.located[:nr], outputs.unresolved[:nj])


def read_costs(batch: HostBatch, outputs: scoring.Scores) -> tuple[np.ndarray, Costs]:
    """``(delta (J,), costs)``: each job's cost increase and its
    :class:`CandidateCost` (in a :class:`Costs`), from the :func:`cut_outputs`
    of its scoring."""
    per_edge, assignment, located = outputs.per_edge, outputs.assignment, outputs.located
    delta = outputs.total - batch.before
    # Local numbering: flat edges minus the job's offset, likewise triangles.
    assignment = assignment - batch.edge_start[batch.row_job]
    triangle = np.where(batch.row_locate, located - batch.tri_start[batch.row_job], batch.row_tri)
    fields = [per_edge[:, i] for i in range(6)]
    fields[5] = fields[5] > 0
    n_inside = batch.n_inside
    if n_inside is None:
        n_inside = np.fromiter((c.n_inside for c in batch.cands), np.int64, len(batch.cands))
    return delta, Costs(delta, fields, assignment, triangle, batch.edge_start, batch.row_start, n_inside)
