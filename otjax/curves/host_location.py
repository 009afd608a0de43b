"""Exact point location on the host, for the rows of a flat batch.

The kernel locates the rows of a batch where its filter or its adaptive
stages are sure (:func:`keep_located` takes those); :func:`locate_on_host`
locates the others exactly, or every row of a batch exported to be scored
on its candidates alone.
"""

from __future__ import annotations

import numpy as np

from otjax.curves import scoring
from otjax.curves.host_batch import HostBatch
from otjax.curves.location import MIN_PAIRS as LOCATE_MIN_PAIRS
from otjax.curves.location import locate_pairs
from otjax.stencil import ragged_index


def locate_on_host(batch: HostBatch, jobs: np.ndarray, points: np.ndarray, point_rows: np.ndarray,
                   min_pairs: int = LOCATE_MIN_PAIRS) -> None:
    """Locates the region points of ``jobs`` exactly, on the host.

    Sets their ``row_cand`` and ``row_tri`` and clears ``row_locate``;
    ``min_pairs`` is :func:`~otjax.curves.location.locate_pairs`'s (the
    locations do not depend on it).

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
    # np.take: half the time of [:, idx] on these (6, N) and (2, N) gathers.
    ok = locate_pairs(np.take(batch.tri_xy, guess, axis=1), np.take(point_rows, inside, axis=1), min_pairs)
    batch.located_by_kernel |= len(inside) >= min_pairs
    found = np.where(ok, guess, -1)
    rest = np.flatnonzero(~ok)
    if len(rest):
        job = pt_job[rest]
        pair_pt, k = ragged_index(n_tri[job])
        pair_tri = tri_start[job][pair_pt] + k
        q = np.take(point_rows, inside[rest[pair_pt]], axis=1)
        hold = locate_pairs(np.take(batch.tri_xy, pair_tri, axis=1), q, min_pairs)
        batch.located_by_kernel |= len(pair_pt) >= min_pairs
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
