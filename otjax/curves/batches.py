"""Jobs and located candidates grouped into flat batches.

:func:`packed_batches` packs jobs into few kernel capacities, exported for
the kernel to locate; :func:`located_batches` and :func:`batch_of_located`
batch candidates whose rows are located already; :func:`located_jobs`
takes jobs out of a batch, located, as a batch of their own.
"""

from __future__ import annotations

import numpy as np

from otjax.batch.packing import choose_packing
from otjax.curves import scoring
from otjax.curves.export import Stencils, export_jobs
from otjax.curves.host_batch import HostBatch
from otjax.curves.stencils import CandidateStencil


def packed_batches(jobs, plan, layout: scoring.Layout, budget: int | None = None):
    """The jobs as batches packed into few capacities of ``layout``
    (:func:`~otjax.batch.packing.choose_packing`; ``budget`` rows a call,
    default the layout's), left for the kernel to locate; a generator (the
    jobs are listed at the first batch), each batch's ``seq`` saying where
    its jobs stand in ``jobs``."""
    jobs = list(jobs)
    packing = choose_packing([job.size() for job in jobs], budget or layout.budget, layout.capacity,
                             scoring.SHAPES.shape_for, scoring.MIN_ROWS)
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


def located_jobs(batch: HostBatch, jobs: np.ndarray) -> HostBatch:
    """The jobs ``jobs`` (increasing) of an exported ``batch``, every row of
    them located (:func:`~otjax.curves.host_location.keep_located`,
    :func:`~otjax.curves.host_location.locate_on_host`), as a batch of their own.

    A job's scores do not depend on the other jobs of its batch, so scoring
    these again alone gives what scoring the whole batch again would. The
    arrays are those :func:`batch_of_located` makes of the located
    candidates, cut out of the batch's at once; the candidates are made
    when read (:class:`~otjax.curves.export.Stencils`).
    """
    in_job = np.zeros(len(batch.row_start) - 1, bool)
    in_job[jobs] = True
    rows, edges = in_job[batch.row_job], in_job[batch.edge_job]
    n_rows, n_edges = np.diff(batch.row_start)[jobs], np.diff(batch.edge_start)[jobs]
    row_job = np.repeat(np.arange(len(jobs)), n_rows)
    edge_start = np.concatenate([[0], np.cumsum(n_edges)])
    row_cand = batch.row_cand[rows] + (edge_start[:-1] - batch.edge_start[jobs])[row_job][:, None]
    edge_job = np.repeat(np.arange(len(jobs)), n_edges)
    out = HostBatch.without_triangles(batch.row_point[rows], row_cand, row_job, batch.edge_xy[edges],
                                      edge_job, [None] * len(jobs), before=batch.before[jobs],
                                      row_tri=batch.row_tri[rows])
    out.n_inside = batch.n_inside[jobs]
    # The candidates read the new batch's arrays: made once it exists (the placeholders above only count).
    jobs_out = [batch.cands.jobs[j] for j in jobs.tolist()]
    out.cands = Stencils(jobs_out, out, batch.cands.edge_keys[edges], on_host=True)
    return out
