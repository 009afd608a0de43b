"""The scoring kernel's outputs read back, one cost per job.

:func:`cut_outputs` cuts the padded outputs to a batch's real jobs, edges
and rows; :func:`read_costs` reads them into one
:class:`~otjax.curves.stencils.CandidateCost` per job (a :class:`Costs`,
each made when first read); :func:`held_bytes` is what keeping a batch and
its costs holds.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from otjax.curves import scoring
from otjax.curves.host_batch import HostBatch
from otjax.curves.stencils import CandidateCost


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
