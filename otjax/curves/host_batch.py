"""The flat host batch: jobs end to end on concatenated arrays.

A :class:`HostBatch` holds candidates, rows, edges and triangles of many
jobs end to end (unpadded, ids of any width) and what reading the kernel's
results needs; :meth:`HostBatch.values` is what a
:class:`~otjax.curves.scoring.Layout`'s fields pack. :mod:`otjax.curves.export`
makes them from jobs, :mod:`otjax.curves.batches` from located candidates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from otjax.batch.fields import Gather, Prefix
from otjax.curves import scoring


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

    def need(self, layout: scoring.Layout) -> int:
        """The smallest row capacity that fits this batch in ``layout``
        (:func:`scoring.capacity`)."""
        return layout.capacity(len(self.row_point), len(self.edge_job), len(self.tri_edges),
                               len(self.job_theta))

    def values(self, points: np.ndarray, mass: np.ndarray) -> dict:
        """The batch as values of a :class:`scoring.Layout`'s fields, the rows'
        points and masses gathered from ``points (n, 2)`` and ``mass (n,)``."""
        return {
            "row_xy": Gather(points, self.row_point), "row_mass": Gather(mass, self.row_point),
            "row_job": self.row_job, "row_cand": self.row_cand, "row_locate": self.row_locate,
            "row_valid": Prefix(len(self.row_point), 1), "tri_xy": self.tri_xy.T, "tri_edges": self.tri_edges,
            "fan_key": self.fan_key, "fan_tri": self.fan_tri, "job_fan": self.job_fan,
            "job_apex": self.job_apex, "job_theta": self.job_theta, "job_ears": self.job_ears,
            "job_tri": self.tri_start,
            "edge_xy": self.edge_xy, "edge_valid": Prefix(len(self.edge_job), 1), "edge_job": self.edge_job,
        }
