"""Jobs laid end to end as one flat host batch.

:func:`export_jobs` writes a list of :class:`~otjax.curves.stencils.Job` s
as a :class:`~otjax.curves.host_batch.HostBatch`: every job's new triangles,
local edges (numbered in increasing key within the job), rows (the points of
its region, then those across its link that keep their edge) and fan, on
concatenated arrays (the per-job Python work is slicing only).
:class:`Stencils` are the batch's candidates, each made when first read.
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import chain
from typing import NamedTuple

import numpy as np

from otjax.curves import scoring
from otjax.curves.host_batch import HostBatch
from otjax.curves.host_location import locate_on_host
from otjax.curves.stencils import CandidateStencil, Job


# The (job, a, b) edge code of _local_edges must not wrap.
_CODE_MAX = np.iinfo(np.int64).max


def _offsets(counts: np.ndarray) -> np.ndarray:
    """``(len(counts) + 1,)`` int64 offsets of runs of ``counts`` laid end to end."""
    out = np.zeros(len(counts) + 1, np.int64)
    np.cumsum(counts, out=out[1:])
    return out


class _PerJob(NamedTuple):
    """What the export reads of each job of a batch, in one pass over them.

    Attributes:
      n_tri, n_flip, n_in, n_out: ``(J,)`` int64 new triangles, flipped-out
        ears, region points and points across the link.
      before: ``(J,)`` cost of each job's region before the change.
      moved: the jobs that are moves.
      fixed: the jobs with rows fixed to an edge (partial updates).
    """

    n_tri: np.ndarray
    n_flip: np.ndarray
    n_in: np.ndarray
    n_out: np.ndarray
    before: np.ndarray
    moved: list[int]
    fixed: list[int]


def _per_job(jobs: list[Job]) -> _PerJob:
    """The :class:`_PerJob` of ``jobs``: one Python loop over them rather
    than one per count (on ~60 small jobs a batch, the loops cost, not the
    arrays)."""
    counts: list[int] = []
    before, moved, fixed = [], [], []
    for j, job in enumerate(jobs):
        region = job.region
        counts += (len(job.triangles), len(job.plan.flipped_out), len(region.inside), len(region.outside))
        before.append(region.before)
        if job.moved is not None:
            moved.append(j)
        if job.fixed_edge is not None:
            fixed.append(j)
    table = np.fromiter(counts, np.int64, len(counts)).reshape(-1, 4)
    # n_in becomes a batch field: its own buffer, not a view holding the table (held_bytes counts buffers).
    return _PerJob(table[:, 0], table[:, 1], table[:, 2].copy(), table[:, 3], np.array(before), moved, fixed)


def _new_triangles(jobs: list[Job], per_job: _PerJob, xy: np.ndarray):
    """``(tris (T, 3), coords (T, 3, 2), tri_start (J + 1,))`` of the jobs,
    the moved vertex of a move at its new position."""
    # One pass over every job's triples (tuples mostly): a conversion per job costs more.
    flat = chain.from_iterable(chain.from_iterable(job.triangles for job in jobs))
    tris = np.fromiter(flat, np.int64, 3 * int(per_job.n_tri.sum())).reshape(-1, 3)
    coords = xy[tris]
    tri_start = _offsets(per_job.n_tri)
    for j in per_job.moved:
        job = jobs[j]
        s = slice(tri_start[j], tri_start[j + 1])
        coords[s] = np.where((tris[s] == job.plan.source)[..., None], job.moved, coords[s])
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


def _local_edges(jobs: list[Job], per_job: _PerJob, tris: np.ndarray, xy: np.ndarray) -> _Edges:
    """Local edges of every job.

    Keys are coded job-major, so ``np.unique`` numbers every job's edges
    contiguously and in increasing key order within the job: the flat number
    of an edge is its job's offset plus its local one.
    """
    nv = len(xy)
    nj = len(jobs)
    if nj * nv * nv > _CODE_MAX:  # the (job, a, b) code below must not wrap
        raise ValueError(f"{nj} jobs over {nv} vertices overflow the int64 edge code; use fewer initial vertices")
    tri_job = np.repeat(np.arange(nj), per_job.n_tri)
    nxt = tris[:, [1, 2, 0]]  # edge k of a triangle: (tris[k], nxt[k]), as in triangle_edges
    code = ((tri_job[:, None] * nv + np.minimum(tris, nxt)) * nv + np.maximum(tris, nxt)).ravel()
    ucode, inv = np.unique(code, return_inverse=True)
    edge_job = ucode // (nv * nv)
    edge_start = np.searchsorted(edge_job, np.arange(nj + 1))
    ukeys = np.stack([(ucode // nv) % nv, ucode % nv], 1)
    tri_edges = np.sort(inv.reshape(-1, 3), 1)
    edge_xy = xy[ukeys]
    for j in per_job.moved:
        job = jobs[j]
        es = slice(edge_start[j], edge_start[j + 1])
        edge_xy[es] = np.where((ukeys[es] == job.plan.source)[..., None], job.moved, edge_xy[es])
    return _Edges(ucode, ukeys, edge_start, edge_job, edge_xy, tri_edges)


def _rows(jobs: list[Job], per_job: _PerJob, ucode: np.ndarray, edge_start: np.ndarray, nv: int) -> _Rows:
    """Rows of every job: the points of its region, then the points across
    its link that keep their link edge (their candidate: that edge); rows
    whose edge is known (a partial update) are fixed to it.
    """
    nj = len(jobs)
    n_rows = per_job.n_in + per_job.n_out
    row_start = _offsets(n_rows)
    row_point = np.concatenate([a for job in jobs for a in (job.region.inside, job.region.outside)])
    row_point = row_point.astype(np.int64, copy=False)
    row_job = np.repeat(np.arange(nj), n_rows)
    row_cand = np.zeros((len(row_point), 3), np.int64)
    # Each job's region rows are located, the rows across its link are not.
    runs = np.stack([per_job.n_in, per_job.n_out], 1).ravel()
    row_locate = np.repeat(np.tile(np.array([True, False]), nj), runs)
    out_rows = np.flatnonzero(~row_locate)
    if len(out_rows):
        # The (job, a, b) code of _local_edges: job * V^2 + the region's link key.
        lk = row_job[out_rows] * (nv * nv) + np.concatenate([job.region.outside_key for job in jobs])
        row_cand[out_rows] = np.searchsorted(ucode, lk)[:, None]
    for j in per_job.fixed:
        fixed_edge = jobs[j].fixed_edge
        k = np.flatnonzero(fixed_edge >= 0)
        row_cand[row_start[j] + k] = (edge_start[j] + fixed_edge[k])[:, None]
        row_locate[row_start[j] + k] = False
    return _Rows(row_point, row_job, row_cand, row_locate, row_start, per_job.n_in)


def _fans(per_job: _PerJob, coords: np.ndarray, tri_start: np.ndarray) -> _Fans:
    """The new triangles of a job are its flipped-out ears, then a fan around
    one apex (the target, or the moved vertex), CCW: the fan keys the kernel
    searches and the ears it tests first (up to :data:`scoring.MAX_EARS`).
    """
    nj = len(per_job.n_tri)
    n_flip = per_job.n_flip
    fan_start = tri_start[:-1] + n_flip
    n_fan = per_job.n_tri - n_flip
    job_fan = _offsets(n_fan)
    fan_job = np.repeat(np.arange(nj), n_fan)
    fan_tri = np.arange(len(fan_job)) + (fan_start - job_fan[:-1])[fan_job]
    apex = coords[fan_start, 0]  # (J, 2): fan triangles are (apex, a, b)
    # The first spoke of each job, then the first spoke of each fan triangle: one pseudo-angle call.
    d = np.concatenate([coords[fan_start, 1] - apex, coords[fan_tri, 1] - apex[fan_job]])
    angle = scoring.pseudo_angle(d[:, 0], d[:, 1])
    theta = angle[:nj].copy()  # a batch field: its own buffer (see _per_job)
    phi = np.mod(angle[nj:] - theta[fan_job], 4.0)
    phi[job_fan[:-1]] = 0.0
    slot = np.arange(scoring.MAX_EARS)
    ears = np.where(slot < n_flip[:, None], tri_start[:-1, None] + slot, -1)
    return _Fans(fan_job * 8.0 + phi, fan_tri, job_fan, apex, theta, ears)


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

    def plans(self) -> list:
        """The plan of each job (without making their stencils)."""
        return [job.plan for job in self.jobs]

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


def export_jobs(jobs: list[Job], plan, on_host: bool) -> HostBatch:
    """The flat :class:`HostBatch` of ``jobs``.

    Args:
      jobs: the jobs, against the current state of ``plan``.
      plan: the :class:`~otjax.curves.plan.TransportPlan` (read only).
      on_host: locate every point here (exactly); otherwise the kernel
        locates them.
    """
    if not jobs:
        return HostBatch.empty()
    xy, points, point_rows = plan.tri.xy, plan.points, plan.point_rows
    nv = len(xy)
    per_job = _per_job(jobs)
    tris, coords, tri_start = _new_triangles(jobs, per_job, xy)
    edges = _local_edges(jobs, per_job, tris, xy)
    rows = _rows(jobs, per_job, edges.code, edges.start, nv)
    fans = _fans(per_job, coords, tri_start)
    batch = HostBatch(
        cands=(), row_point=rows.point, row_job=rows.job, row_cand=rows.cand, row_locate=rows.locate,
        row_tri=np.full(len(rows.point), -1, np.int64), row_start=rows.start, edge_start=edges.start,
        tri_start=tri_start, edge_xy=edges.xy, edge_job=edges.job,
        tri_xy=np.ascontiguousarray(coords.reshape(-1, 6).T), tri_edges=edges.of_triangle, fan_key=fans.key,
        fan_tri=fans.tri, job_fan=fans.job_fan, job_apex=fans.apex, job_theta=fans.theta, job_ears=fans.ears,
        before=per_job.before, n_inside=rows.n_inside)
    if on_host:
        locate_on_host(batch, np.arange(len(jobs)), points, point_rows)
    batch.cands = Stencils(jobs, batch, edges.keys, on_host)
    return batch
