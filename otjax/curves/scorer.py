"""Scoring flat batches with the fused kernel: dispatch, collect, pipelined runs.

The :class:`Scorer` owns the :class:`~otjax.batch.pipeline.KernelPipeline`
of :func:`otjax.curves.scoring.score_packed` and the points it gathers rows
from. It neither builds batches (:mod:`otjax.curves.export` does) nor keeps
results: it turns a :class:`~otjax.curves.host_batch.HostBatch` into candidate
costs, locating on the host the rows the kernel's filter was unsure of.
"""

from __future__ import annotations

import numpy as np

from otjax.batch.pipeline import Handle, KernelPipeline, pipelined
from otjax.curves import scoring
from otjax.curves.batches import located_jobs
from otjax.curves.host_batch import HostBatch
from otjax.curves.host_location import keep_located, locate_on_host
from otjax.curves.kernel_outputs import cut_outputs, read_costs
from otjax.curves.stencils import CandidateCost

# While the kernel keeps leaving rows unlocated (exactly collinear input
# without the kernel's exact stage), batches are located on the host before
# their call instead of scored twice;
# every PROBE-th such batch is left to the kernel to see whether that still
# holds (docs/decisions.md#host_first).
PROBE = 8
# Host location of a whole batch tests its pairs on the host below this many
# (above, the location kernel): the batches of a small run hold ~900 rows
# (docs/decisions.md#host_first).
HOST_FIRST_MIN_PAIRS = 1 << 12
# Whether the kernel locates the rows its first tests leave (filter unsure,
# or in an ear beyond the retry round) in an exact round
# (scoring._locate_exactly): no score depends on it; off, every such row is
# left to the host (tests turn it off to exercise that path).
EXACT_IN_KERNEL = True


class Scorer:
    """Runs the scoring kernel on host batches.

    Args:
      points: ``(n, 2)`` float64 input points.
      mass: ``(n,)`` float64 masses.
      dtype: float dtype of the cost arithmetic (location is float64 whatever
        this is).
      n_vertices: vertices of the initial triangulation (default ``n``).

    Its calls are shaped by :attr:`layout` (:func:`~otjax.curves.scoring.layout_for`)
    and filled to its ``budget`` rows.

    Which rows the kernel locates changes no score: a located row is the
    exact perturbed location wherever it is found.
    """

    def __init__(self, points: np.ndarray, mass: np.ndarray, dtype=np.float64, n_vertices: int | None = None):
        self.points = points
        self.mass = mass
        self.point_rows = np.ascontiguousarray(points.T)
        self.layout = scoring.layout_for(len(points), n_vertices or len(points))
        self.pipeline = KernelPipeline(self.layout.fields, scoring.score_packed, scoring.SHAPES, dtype,
                                       static={"edges_per_row": self.layout.edges_per_row,
                                               "exact": EXACT_IN_KERNEL})
        self.location_kernel_used = False
        # Locate batches on the host before their call (see PROBE).
        self.host_first = False
        self._host_batches = 0

    @property
    def calls(self) -> int:
        """Kernel calls made."""
        return self.pipeline.calls

    @property
    def compiled_shapes(self) -> int:
        """Distinct kernel shapes used: scoring kernel and location kernel."""
        return len(self.pipeline.shapes_seen) + int(self.location_kernel_used)

    def note(self, batch: HostBatch) -> None:
        """Counts the location kernel if ``batch``'s export used it."""
        self.location_kernel_used |= batch.located_by_kernel

    def dispatch(self, batch: HostBatch) -> Handle | None:
        """Pads and dispatches ``batch``; does not wait (``None`` if empty).

        With :attr:`host_first` on, the rows left for the kernel to locate
        are located here first, except in every :data:`PROBE`-th batch.
        """
        if not batch.cands:
            self.note(batch)
            return None
        if self.host_first and batch.row_locate.any():
            self._host_batches += 1
            if self._host_batches % PROBE:
                locate_on_host(batch, np.arange(len(batch.row_start) - 1), self.points, self.point_rows,
                               HOST_FIRST_MIN_PAIRS)
        self.note(batch)
        return self.pipeline.dispatch(batch.values(self.points, self.mass), batch.need(self.layout))

    def _wait(self, batch: HostBatch, handle: Handle) -> tuple:
        return cut_outputs(batch, self.pipeline.wait(handle))

    def collect(self, batch: HostBatch, handle: Handle | None) -> tuple[np.ndarray, list[CandidateCost]]:
        """``(delta, costs)`` of a dispatched batch (waits for its kernel).

        Jobs with a row the kernel could not locate (an orientation its
        adaptive stages cannot decide; while :data:`EXACT_IN_KERNEL` is
        off, every row its first tests leave) keep the rows it located,
        have the others located on the host, and are scored again in a
        batch of their own. Whether
        such rows turned up (in a batch the kernel located rows of) sets
        :attr:`host_first`.
        """
        if handle is None:
            return np.zeros(0), []
        outputs = self._wait(batch, handle)
        bad = np.flatnonzero(outputs.unresolved)
        if batch.row_locate.any():  # the kernel located rows: did its filter settle them all?
            self.host_first = len(bad) > 0
        if not len(bad):
            return read_costs(batch, outputs)
        # The kernel costs an unlocated row on the edges of flat triangle 0
        # (a placeholder): their job is scored again too.
        if len(batch.tri_edges):
            bad = np.union1d(bad, batch.edge_job[batch.tri_edges[0]])
        keep_located(batch, bad, outputs.located)
        locate_on_host(batch, bad, self.points, self.point_rows)
        self.note(batch)
        again = located_jobs(batch, bad)
        delta, costs = read_costs(batch, outputs)
        delta_again, costs_again = read_costs(again, self._wait(again, self.dispatch(again)))
        delta[bad] = delta_again
        for j, c in zip(bad.tolist(), costs_again):
            costs[j] = c
        return delta, costs

    def score_batches(self, batches) -> tuple[list, np.ndarray, list[CandidateCost]]:
        """Scores an iterable of batches, each dispatched before the last
        one is collected.

        Returns:
          ``(cands, delta, costs)`` over all batches, in the order of the
          jobs they were exported from (batches packed out of order carry
          ``seq``), else in batch order.
        """
        cands, deltas, costs, seqs = [], [np.zeros(0)], [], [np.zeros(0, np.int64)]

        def read(batch, handle):
            d, c = self.collect(batch, handle)
            deltas.append(d)
            costs.extend(c)
            seqs.append(len(cands) + np.arange(len(batch.cands)) if batch.seq is None else batch.seq)
            cands.extend(batch.cands)

        pipelined(batches, self.dispatch, read, in_flight=1)
        delta = np.concatenate(deltas)
        order = np.argsort(np.concatenate(seqs), kind="stable")
        return [cands[i] for i in order], delta[order], [costs[i] for i in order]

    def edge_costs(self, parts, edge_xy: np.ndarray, budget: int | None = None) -> np.ndarray:
        """Costs of edges given with their points.

        Args:
          parts: per edge, a tuple of point-id arrays (concatenated in order).
          edge_xy: ``(m, 2, 2)`` endpoints of each edge, lower id first.
          budget: rows per call (whole edges per batch, within the shapes the
            decimation loop uses anyway; default the layout's budget); each
            batch is dispatched before the last is read.

        Returns:
          ``(m, 6)`` the kernel's per-edge fields (:data:`scoring.EDGE_FIELDS`).
        """
        budget = budget or self.layout.budget
        counts = np.fromiter((sum(map(len, p)) for p in parts), np.int64, len(parts))

        def batches():
            first = 0
            while first < len(parts):
                rows = np.cumsum(counts[first:])
                last = first + max(1, int(np.searchsorted(rows, budget, side="right")))
                last = min(last, first + budget // self.layout.edges_per_row - 1)
                ids = np.concatenate([a for p in parts[first:last] for a in p]).astype(np.int64)
                edge_of_row = np.repeat(np.arange(last - first), counts[first:last])
                yield HostBatch.without_triangles(
                    ids, np.repeat(edge_of_row[:, None], 3, 1), np.zeros(len(ids), np.int64),
                    edge_xy[first:last], np.zeros(last - first, np.int64), [None])
                first = last

        out = [np.zeros((0, 6))]
        pipelined(batches(), self.dispatch, lambda batch, handle: out.append(self._wait(batch, handle).per_edge),
                  in_flight=1)
        return np.concatenate(out)
