"""The curve engine: what the greedy loop calls, over one transport plan.

:class:`CurveEngine` owns the pieces of a 2D decimation and calls them one
way: the loop (:mod:`otjax.decimation.loop`) asks it to score half-edges,
take scored ones, apply them and relocate vertices; the engine calls the
stencil cache, :mod:`~otjax.curves.export` and :mod:`~otjax.curves.batches`
(jobs -> flat batches), the :class:`~otjax.curves.scorer.Scorer` (kernel),
reads the results, and applies changes to the
:class:`~otjax.curves.plan.TransportPlan`, whose
:class:`~otjax.curves.plan.Change` it hands to the
:class:`~otjax.curves.rescoring.ChangeLog` and returns. Nothing below it
calls back up.

It also serves research code (the notebooks): export candidates, score
them, apply one.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import numpy as np

from otjax.batch.pipeline import pipelined
from otjax.curves.batches import located_batches, packed_batches
from otjax.curves.export import Stencils, export_jobs
from otjax.curves.host_batch import HostBatch
from otjax.curves.hot_stencils import HotEntry, HotStencils
from otjax.curves.kernel_outputs import held_bytes
from otjax.curves.plan import Change, TransportPlan
from otjax.curves.relocation import optimal_position
from otjax.curves.rescoring import ChangeLog, LinkRecords, LinkUpdates
from otjax.curves.scorer import Scorer
from otjax.curves.stencils import CandidateCost, CandidateStencil, StencilCache
from otjax.curves.triangulation import Triangulation

# Collapses whose stencil has fewer rows are scored again in full rather than
# updated on their link (docs/decisions.md#update_min_rows).
UPDATE_MIN_ROWS = 512
# A relocation call proposes at least this many waiting vertices, near ones
# included: a closed-form proposal costs less than a kernel call
# (docs/decisions.md#relocation_batch).
SPECULATE = 8


class Scored(NamedTuple):
    """A scored candidate, ready for :meth:`CurveEngine.apply`."""

    candidate: CandidateStencil
    cost: CandidateCost


class CurveEngine:
    """A transport plan and the machinery that scores and applies its changes.

    Args:
      tri: the triangulation (owned and mutated from now on).
      points: ``(n, 2)`` float64 input points.
      mass: ``(n,)`` float64 non-negative masses.
      dtype: float dtype of the cost arithmetic (float64 for the exact
        greedy order); point location is float64 whatever this is.
      max_source_degree: see :class:`~otjax.curves.stencils.StencilCache`.
      incremental: bring the scores of collapses whose star kept its
        triangles up to date on the changed edges only (same scores, fewer
        scored rows), when the loop re-scores everything a change made dirty;
        and leave the vertices across the changed region whose link edges
        kept their points and costs unscored (``Change.quiet``: the loop
        enters their scores again as they were).
      update_min_rows: stencils below this many rows are scored again in
        full instead (docs/decisions.md#update_min_rows).

    Needs JAX's float64 mode (``jax.enable_x64``) for every call that scores.

    Example:
      >>> import jax, numpy as np
      >>> p = np.random.default_rng(0).random((40, 2))
      >>> with jax.enable_x64(True):
      ...     engine = CurveEngine(Triangulation(p), p, np.ones(40))
      ...     delta, costs = engine.score_candidates(engine.candidates(range(len(p))))
      >>> len(delta) > 0
      True
    """

    speculate = SPECULATE

    def __init__(self, tri: Triangulation, points: np.ndarray, mass: np.ndarray, *, dtype=np.float64,
                 max_source_degree: int = 32, incremental: bool = True, update_min_rows: int = UPDATE_MIN_ROWS):
        self.plan = TransportPlan(tri, points, mass)
        self.log = ChangeLog(len(tri.xy))
        self.stencils = StencilCache(self.plan, self.log, max_source_degree)
        self.scorer = Scorer(self.plan.points, self.plan.mass, dtype, tri.n_vertices)
        self.links = LinkUpdates(self.plan, self.log, self.stencils)
        self.records = LinkRecords(self.links)
        self.hot = HotStencils()
        self.incremental = incremental
        self.update_min_rows = update_min_rows
        self.counts = {"scored": 0, "updated": 0, "partial": 0}
        self.seconds = {"export": 0.0, "score": 0.0}
        self._partial: dict = {}  # key -> Partial, within one score call
        keys, parts = self.plan.points_by_edge()
        self.plan.set_edge_costs(keys, self.scorer.edge_costs(parts, tri.xy[keys]))

    # ------------------------------------------------------------ the loop's view
    @property
    def versions(self) -> list[int]:
        """Per-vertex versions (read only): a score is stale once its source's moved on."""
        return self.log.version

    @property
    def degree_bound(self) -> int:
        """Sources of higher degree are not candidates (sampling draws below it)."""
        return self.stencils.max_source_degree

    def live_sources(self) -> list[int]:
        """Vertices that may still be removed, increasing."""
        tri = self.plan.tri
        return np.nonzero(tri.alive & ~tri.pinned)[0].tolist()

    def ring(self, v: int) -> tuple[int, ...]:
        """CCW one-ring of a live free vertex."""
        return self.plan.tri.star(v)[0]

    def free(self, v: int) -> bool:
        """Whether ``v`` may be a collapse target (not a pinned corner)."""
        return not self.plan.tri.pinned[v]

    def prefetch(self, half_edges) -> None:
        """Reads the regions and plans of ``half_edges`` into the caches."""
        self.stencils.prefetch(half_edges)

    def stats(self) -> dict:
        """Counters: ``scored``, ``updated``, ``partial``, ``kernel_calls``, and
        ``seconds`` (``export``, ``score``)."""
        return {**self.counts, "kernel_calls": self.scorer.calls, "seconds": dict(self.seconds)}

    def score(self, sources, targets: dict | None = None, *, veto=None, keep: bool = True,
              while_waiting=None, cheapest_only: bool = False) -> list[tuple[tuple[int, int], float]]:
        """Scores the half-edges leaving ``sources``, batch by batch.

        Args:
          sources: vertex ids (scored in increasing order).
          targets: optional ``{source: targets}``; ``None`` scores every
            half-edge of each source, and then (``incremental``, no veto)
            collapses scored before whose star kept its triangles are
            updated on what changed instead of scored again.
          veto: optional ``(candidate, cost) -> bool``; rejected candidates
            are left out.
          keep: keep the stencils at hand for :meth:`take`.
          while_waiting: host work to run once every batch is dispatched.
          cheapest_only: accepted for the loop's protocol; every candidate
            is scored (one kernel call scores a batch whatever its order).

        Returns:
          ``[(half-edge, delta)]`` of the admissible candidates.
        """
        sources = sorted(sources)
        full, updates, partial = sources, [], []
        tracking = self.incremental and veto is None and targets is None
        if tracking:
            t0 = time.perf_counter()
            targets, updates, partial = self.records.split(sources)
            self.seconds["export"] += time.perf_counter() - t0
            full = sorted(targets)
        self._partial = {(job.plan.source, job.plan.target): pending for job, pending in partial}
        entered: list = []

        def settle(batch, handle):
            self._settle(batch, handle, entered, veto, keep, tracking)

        batches = self._timed(self.exports(full, targets, extra=[job for job, _ in partial]))
        pipelined(batches, self._dispatch, settle, while_waiting=while_waiting)
        if updates:
            t0 = time.perf_counter()
            parts = self.links.link_parts(updates)
            keys = np.asarray([p.key for p in parts], np.int64).reshape(-1, 2)
            costs = self.scorer.edge_costs([p.points for p in parts], self.plan.tri.xy[keys])[:, 0]
            for rec, delta in self.links.finish_links(updates, parts, costs):
                key = (rec.plan.source, rec.plan.target)
                self.records.put(key, rec)
                entered.append((key, delta))
            self.seconds["score"] += time.perf_counter() - t0
            self.counts["updated"] += len(updates)
        return entered

    def _timed(self, batches):
        """``batches``, the time to make each counted as export."""
        it = iter(batches)
        while True:
            t0 = time.perf_counter()
            batch = next(it, None)
            if batch is None:
                return
            self.seconds["export"] += time.perf_counter() - t0
            yield batch

    def _dispatch(self, batch: HostBatch):
        t0 = time.perf_counter()
        handle = self.scorer.dispatch(batch)
        self.seconds["score"] += time.perf_counter() - t0
        return handle

    def _collect(self, batch: HostBatch, handle) -> tuple[np.ndarray, list[CandidateCost]]:
        t0 = time.perf_counter()
        delta, costs = self.scorer.collect(batch, handle)
        self.seconds["score"] += time.perf_counter() - t0
        self.counts["scored"] += len(costs)
        return delta, costs

    def _settle(self, batch, handle, entered: list, veto, keep: bool, tracking: bool) -> None:
        """Reads a dispatched batch into ``entered`` (and records, hot stencils)."""
        kept: list = []
        call = self.hot.new_call()
        deltas, costs = self._collect(batch, handle)
        cands, version, partial = batch.cands, self.log.version, self._partial
        rows = np.diff(batch.row_start).tolist()
        plans = cands.plans() if isinstance(cands, Stencils) else [c.plan for c in cands]
        # Stencils and costs are made only where read: most are never taken.
        for j, (plan, d, n) in enumerate(zip(plans, deltas.tolist(), rows)):
            key = (plan.source, plan.target)
            part = partial.pop(key, None) if partial else None
            if part is not None:  # scored in part: not a whole stencil, never kept
                rec, delta = self.links.finish_partial(part, cands[j], costs[j])
                self.records.put(key, rec)
                entered.append((key, delta))
                self.counts["partial"] += 1
                continue
            if veto is not None and not veto(cands[j], costs[j]):
                continue
            delta = d
            if tracking and n >= self.update_min_rows:
                rec = self.links.record(cands[j], costs[j])
                self.records.put(key, rec)
                delta = rec.delta(float(batch.before[j]))
            entered.append((key, delta))
            if keep:
                kept.append((key, HotEntry(cands, costs, j, plan, version[key[0]], call)))
        if kept:
            self.hot.keep(call, held_bytes(batch, costs), kept)

    def take(self, keys) -> list[Scored]:
        """The scored candidates of fresh half-edges ``keys``, exporting again
        those not at hand (the same stencil: nothing around it changed)."""
        out: dict = {}
        again: dict[int, list[int]] = {}
        version = self.log.version
        for key in keys:
            h = self.hot.pop(key)
            # The plan too: a change of the target's star alone can change it.
            if h is not None and h.version == version[key[0]] and self.stencils.collapse_plan(*key) == h.plan:
                out[key] = Scored(h.stencils[h.index], h.costs[h.index])
            else:
                again.setdefault(key[0], []).append(key[1])
            self.records.drop(key[0])
        if again:
            t0 = time.perf_counter()
            batch = self.export(sorted(again), again)
            self.seconds["export"] += time.perf_counter() - t0
            handle = self._dispatch(batch)
            for c, r in zip(batch.cands, self._collect(batch, handle)[1]):
                out[(c.plan.source, c.plan.target)] = Scored(c, r)
        return [out[key] for key in keys]

    def apply(self, candidate: CandidateStencil, cost: CandidateCost) -> Change:
        """Applies a scored change to the plan and logs it; returns the :class:`Change`."""
        change = self.plan.apply(candidate, cost)
        if change.quiet:
            # Without incremental re-scoring the coarser rule holds: every
            # vertex across the changed region is scored again.
            woken = self.stencils.changed_plans(change) if self.incremental else change.quiet
            change = change.woken(woken, self.movable)
        self.log.record(change)
        self.stencils.forget(change.source)
        for v in change.touched | {change.source}:  # their stencils are stale now
            self.hot.forget(v)
        return change

    def movable(self, v: int) -> bool:
        """Whether ``v`` may be moved (live, not a pinned corner)."""
        tri = self.plan.tri
        return bool(tri.alive[v]) and not tri.pinned[v]

    def propose_moves(self, vertices) -> list[tuple[int, float, Scored]]:
        """``[(vertex, delta, scored)]``: each vertex's closed-form position
        (:func:`~otjax.curves.relocation.optimal_position`), where it moves
        the vertex and keeps the embedding, scored in one batched call."""
        tri = self.plan.tri
        moves = [(v, pos) for v, pos in ((v, optimal_position(self.plan, v)) for v in vertices)
                 if pos is not None and np.all(np.isfinite(pos)) and np.any(pos != tri.xy[v])]
        cands, delta, costs = self.score_batches(self.relocation_exports(moves))
        return [(c.plan.source, float(d), Scored(c, r)) for c, d, r in zip(cands, delta, costs)]

    # ------------------------------------------------------------ research API
    def total_cost(self) -> float:
        """Squared W2 cost of the current plan."""
        return self.plan.total_cost()

    @property
    def compiled_shapes(self) -> int:
        """Distinct kernel shapes used (scoring and location kernels)."""
        return self.scorer.compiled_shapes

    def exports(self, sources, targets: dict | None = None, budget: int | None = None, extra=()):
        """:func:`~otjax.curves.batches.packed_batches` of the half-edges
        leaving ``sources`` (then the jobs ``extra``), ``budget`` rows a call
        (default: the budget of the scorer's layout)."""
        def jobs():  # listed at the first batch: the time it takes counts as the batches'
            yield from self.stencils.collapse_jobs(sources, targets)
            yield from extra

        return packed_batches(jobs(), self.plan, self.scorer.layout, budget)

    def relocation_exports(self, moves, budget: int | None = None):
        """:meth:`exports` for ``(v, position)`` moves (those that keep the embedding)."""
        return packed_batches(self.stencils.move_jobs(moves), self.plan, self.scorer.layout, budget)

    def export(self, sources, targets: dict | None = None) -> HostBatch:
        """The half-edges leaving ``sources`` as one flat batch, left for the kernel to locate."""
        return export_jobs(self.stencils.collapse_jobs(sources, targets), self.plan, on_host=False)

    def candidates(self, sources, targets: dict | None = None) -> list[CandidateStencil]:
        """Located collapse stencils of the half-edges leaving ``sources``
        (dead, pinned and high-degree sources skipped), in source then ring
        order; half-edges that cannot be collapsed are left out."""
        batch = export_jobs(self.stencils.collapse_jobs(sources, targets), self.plan, on_host=True)
        self.scorer.note(batch)
        return list(batch.cands)

    def candidate(self, source: int, target: int) -> CandidateStencil | None:
        """The stencil of collapsing ``source`` onto ``target``, or ``None``."""
        out = self.candidates([source], {source: [target]})
        return out[0] if out else None

    def relocation_candidates(self, moves) -> list[CandidateStencil]:
        """Located stencils of the ``(v, position)`` moves that keep the embedding."""
        batch = export_jobs(list(self.stencils.move_jobs(moves)), self.plan, on_host=True)
        self.scorer.note(batch)
        return list(batch.cands)

    def relocation_candidate(self, v: int, position) -> CandidateStencil | None:
        """The stencil of moving ``v`` to ``position``, or ``None`` if it would fold a triangle."""
        out = self.relocation_candidates([(v, position)])
        return out[0] if out else None

    def score_candidates(self, cands: list[CandidateStencil]) -> tuple[np.ndarray, list[CandidateCost]]:
        """``(delta, costs)`` of located candidates, in batches of about the
        scorer's layout's budget of rows."""
        _, delta, costs = self.score_batches(located_batches(cands, self.scorer.layout.budget))
        return delta, costs

    def score_batches(self, batches):
        """``(cands, delta, costs)`` of exported batches (see :meth:`Scorer.score_batches`)."""
        return self.scorer.score_batches(batches)
