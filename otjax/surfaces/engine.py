"""The surface engine: what the greedy loop (:mod:`otjax.decimation.loop`) calls.

:class:`SurfaceEngine` owns a :class:`~otjax.surfaces.plan.SurfacePlan` (and
through it the complex) and implements the loop's
:class:`~otjax.decimation.loop.Engine` protocol for half-edge collapses
(§4.2): scoring goes through :mod:`otjax.surfaces.collapse_scoring`;
:meth:`~SurfaceEngine.apply` collapses the complex, writes the winner's
local plan (solved again by HiGHS) over the closed star of the target, and
returns a :class:`SurfaceChange`. Calls run one way: nothing below calls
back up.

Vertex moves (§4.3) go through the same protocol as the curve engine's:
:meth:`~SurfaceEngine.propose_moves` makes each vertex's relocation
(:func:`otjax.surfaces.moves.propose_moves`: a few alternations of the
closed-form target, a move half way there and a re-solve of its closed star)
without changing anything, and :meth:`~SurfaceEngine.apply` of a
:class:`~otjax.surfaces.moves.StarMove` moves the vertex, writes its
star's plan and returns a :class:`SurfaceMove`. The loop
(:func:`otjax.decimation.relocation.relocate`) applies the moves that lower
the cost.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from typing import NamedTuple

import numpy as np

from otjax.lp.batched import NewtonOptions
from otjax.lp.exact import solve_member
from otjax.lp.problem import CONVERGED, lower_bound
from otjax.lp.solve import BATCH
from otjax.surfaces.collapse_scoring import (CollapseCandidate, ScoredCollapse, build_candidates,
                                             score_candidates)
from otjax.surfaces.complex import CollapseChange
from otjax.surfaces.moves import StarMove
from otjax.surfaces.moves import propose_moves as propose_star_moves
from otjax.surfaces.plan import SurfacePlan
from otjax.surfaces.relocation import DAMPING, ROUNDS
from otjax.surfaces.solvers import LocalSolver

#: Sources of higher degree are not drawn (sampling rejects slots past it);
#: the exhaustive queue still scores them.
DEGREE_BOUND = 32
#: Scored candidates kept at hand for :meth:`SurfaceEngine.take` (the latest
#: ones); an older winner is built again, which solves nothing.
HOT_CANDIDATES = 512


class SurfaceChange(NamedTuple):
    """What :meth:`SurfaceEngine.apply` did.

    Attributes:
      source, target: the collapsed half-edge.
      dirty: live vertices whose outgoing half-edges' scores are stale.
      ring: ``target`` and its neighbours after the collapse, increasing:
        the vertices the loop relocates after it (the paper relocates the
        vertex that remains; its neighbours' stars changed with it).
      delta: the change of the plan's total cost.
      collapse: the complex's :class:`~otjax.surfaces.complex.CollapseChange`.
    """

    source: int
    target: int
    dirty: frozenset
    ring: tuple[int, ...]
    delta: float
    collapse: CollapseChange


class SurfaceMove(NamedTuple):
    """What :meth:`SurfaceEngine.apply` did for a move.

    Attributes:
      vertex: the moved vertex.
      dirty: live vertices whose outgoing half-edges' scores are stale.
      delta: the change of the plan's total cost.
    """

    vertex: int
    dirty: frozenset
    delta: float


class Taken(NamedTuple):
    """A candidate taken to be applied: ``engine.apply(*taken)``."""

    candidate: CollapseCandidate


class SurfaceEngine:
    """A surface transport plan and the machinery that scores and applies collapses.

    Args:
      plan: the plan (owned and mutated from now on, with its complex).
      method: scoring solver: ``"auto"`` (JAX batches, HiGHS for members not
        certified) or ``"exact"`` (HiGHS).
      options: the JAX solver's settings.
      degree_bound: see :data:`DEGREE_BOUND`.
      relocation_rounds: alternations of a proposed move (:data:`~otjax.surfaces.relocation.ROUNDS`).
      damping: the fraction of the way to its target a move goes (the paper's half).

    ``"auto"`` needs JAX's float64 mode (``jax.enable_x64``).

    Example:
      >>> from tests.surfaces.complexes import sphere_complex  # doctest: +SKIP
      >>> from otjax.decimation import decimate  # doctest: +SKIP
      >>> engine = SurfaceEngine(plan, method="exact")  # doctest: +SKIP
      >>> stats = decimate(engine, 10, queue="multiple-choice")  # doctest: +SKIP
    """

    # Relocation calls propose only the vertices no earlier move can reach:
    # a proposal is a local LP, dropped ones would cost more than the calls
    # they save (docs/decisions.md#relocation_batch).
    speculate = 1

    def __init__(self, plan: SurfacePlan, *, method: str = "auto", options: NewtonOptions = NewtonOptions(),
                 degree_bound: int = DEGREE_BOUND, relocation_rounds: int = ROUNDS, damping: float = DAMPING):
        self.plan = plan
        self.method = method
        self.options = options
        self._versions = [0] * len(plan.complex.alive)
        self._degree_bound = degree_bound
        self._hot: OrderedDict = OrderedDict()  # (source, target) -> (version, CollapseCandidate)
        self._bins: dict = {}  # bins of facets that may appear, valid while no vertex moves
        self.counts = {"scored": 0, "updated": 0, "partial": 0, "refused": 0, "exact_resolves": 0,
                       "kernel_calls": 0, "moves_proposed": 0, "pruned": 0}
        self.seconds = {"export": 0.0, "score": 0.0, "propose_moves": 0.0}
        self._relocation_rounds = relocation_rounds
        self._damping = damping
        self._move_solver = LocalSolver("exact" if method == "exact" else "auto", options)
        self.sizes: list[tuple[int, int]] = []  # (points, bins) of every scored stencil, in order

    # ------------------------------------------------------------ the loop's view
    @property
    def versions(self) -> list[int]:
        """Per-vertex versions (read only): a score is stale once its source's moved on."""
        return self._versions

    @property
    def degree_bound(self) -> int:
        return self._degree_bound

    def live_sources(self) -> list[int]:
        """Live vertices, increasing (isolated ones too: they count, and have no half-edge)."""
        return np.flatnonzero(self.plan.complex.alive).tolist()

    def ring(self, v: int) -> tuple[int, ...]:
        """Neighbours of ``v``, increasing."""
        return self.plan.complex.neighbors(v)

    def free(self, v: int) -> bool:
        """Every live vertex may be a collapse target."""
        return bool(self.plan.complex.alive[v])

    def prefetch(self, half_edges) -> None:
        """Nothing to read ahead: a candidate is built when scored."""

    def stats(self) -> dict:
        """Counters (``scored``, ``updated``, ``partial``, ``kernel_calls``,
        ``refused``, ``exact_resolves``) and ``seconds`` (``export``, ``score``)."""
        return {**self.counts, "seconds": dict(self.seconds)}

    def score(self, sources, targets: dict | None = None, *, veto=None, keep: bool = True,
              while_waiting=None, cheapest_only: bool = False) -> list[tuple[tuple[int, int], float]]:
        """Scores the half-edges leaving ``sources`` (all, or ``targets[v]``);
        returns ``[(half-edge, delta)]`` of the admissible ones that
        ``veto(candidate, scored)`` (if given) accepts.

        With ``cheapest_only`` the caller wants the cheapest of them alone:
        candidates are solved in increasing order of a lower bound of their
        delta (:func:`~otjax.lp.problem.lower_bound` of the local LP, minus
        the cost it replaces), and those whose bound is not below the
        cheapest admissible delta found so far are left unscored (not
        returned). The cheapest is the same as with every candidate scored.
        ``while_waiting`` is not called: nothing is prefetched.
        """
        c = self.plan.complex
        keys = [(v, w) for v in sorted(sources) if c.alive[v]
                for w in (c.neighbors(v) if targets is None else targets[v]) if c.alive[w] and c.has_edge(v, w)]
        admissible = (lambda s: veto is None or veto(s.candidate, s))
        scored = self.score_half_edges(keys, cheapest_of=admissible if cheapest_only else None)
        out = []
        for key, s in zip(keys, scored):
            if s is None or not admissible(s):
                continue
            out.append((key, s.delta))
            if keep:
                self._keep(key, s.candidate)
        return out

    def score_half_edges(self, keys, cheapest_of=None) -> list[ScoredCollapse | None]:
        """``ScoredCollapse`` of each half-edge (``None``: refused), one solve
        for all; with ``cheapest_of`` (a filter of scored candidates), as
        :meth:`score`'s ``cheapest_only``, ``None`` also for those left unscored."""
        t0 = time.perf_counter()
        cands = build_candidates(self.plan, keys, self._bins)
        live = [c for c in cands if c is not None]
        t1 = time.perf_counter()
        if cheapest_of is None:
            scored = self._solve(live)
        else:
            scored = self._solve_cheapest(live, cheapest_of)
        self.seconds["export"] += t1 - t0
        self.seconds["score"] += time.perf_counter() - t1
        self.counts["refused"] += len(cands) - len(live)
        it = iter(scored)
        return [None if c is None else next(it) for c in cands]

    def _solve(self, cands: list[CollapseCandidate]) -> list[ScoredCollapse | None]:
        """Scores ``cands`` in one solve, counting."""
        scored, solved = score_candidates(cands, "exact" if self.method == "exact" else "auto", self.options)
        self.counts["scored"] += len(cands)
        self.counts["refused"] += sum(s is None for s in scored)
        self.counts["exact_resolves"] += solved.exact_resolves
        self.counts["kernel_calls"] += solved.batched_calls
        self.sizes.extend(c.stencil.lp.cost.shape for c in cands)
        return scored

    def _solve_cheapest(self, cands: list[CollapseCandidate], admissible) -> list[ScoredCollapse | None]:
        """Scores ``cands`` in increasing order of their bound until no bound
        is below the cheapest admissible delta; the others stay ``None``.
        HiGHS takes them one at a time, the batched solver a batch at a time."""
        bound = np.array([lower_bound(c.stencil.lp) - c.stencil.cost for c in cands])
        order = np.argsort(bound, kind="stable")
        step = 1 if self.method == "exact" else BATCH
        out: list[ScoredCollapse | None] = [None] * len(cands)
        best, solved = np.inf, 0
        for lo in range(0, len(order), step):
            group = [int(i) for i in order[lo:lo + step] if bound[i] < best]
            if not group:
                break
            solved += len(group)
            for i, s in zip(group, self._solve([cands[i] for i in group])):
                out[i] = s
                if s is not None and admissible(s):
                    best = min(best, s.delta)
        self.counts["pruned"] += len(cands) - solved
        return out

    def _keep(self, key, cand: CollapseCandidate) -> None:
        self._hot[key] = (self._versions[key[0]], cand)
        self._hot.move_to_end(key)
        while len(self._hot) > HOT_CANDIDATES:
            self._hot.popitem(last=False)

    def take(self, keys) -> list[Taken]:
        """The candidates of fresh half-edges ``keys`` (built again where not at hand)."""
        out: dict = {}
        for key in keys:
            h = self._hot.pop(key, None)
            if h is not None and h[0] == self._versions[key[0]]:
                out[key] = h[1]
        missing = [k for k in keys if k not in out]
        for key, cand in zip(missing, build_candidates(self.plan, missing, self._bins)):
            if cand is None:
                raise ValueError(f"the collapse {key} is not admissible")
            out[key] = cand
        return [Taken(out[k]) for k in keys]

    def apply(self, change: CollapseCandidate | StarMove) -> SurfaceChange | SurfaceMove:
        """Applies a taken collapse or a proposed move.

        A collapse: collapses the complex and writes the candidate's local
        plan, solved again by HiGHS (the exact optimum of the stencil), over
        the target's closed star; returns the :class:`SurfaceChange`. A
        move: moves the vertex and writes its star's solved plan; returns
        the :class:`SurfaceMove`.

        Raises:
          RuntimeError: HiGHS does not solve the stencil (not expected: a
            stencil with a vertex bin is always feasible).
        """
        if isinstance(change, StarMove):
            return self._apply_move(change)
        return self._apply_collapse(change)

    def _apply_collapse(self, candidate: CollapseCandidate) -> SurfaceChange:
        plan, c = self.plan, self.plan.complex
        s, t, st = candidate.source, candidate.target, candidate.stencil
        sol = solve_member(st.lp)
        if sol.status != CONVERGED:
            raise RuntimeError(f"HiGHS could not solve the collapse ({s}, {t}): status {sol.status}")
        written = plan.sparsified(st, sol.plan)
        change = c.collapse(s, t)
        for f in candidate.removed:
            plan.drop_facet(f)
        plan.vertex_entries.pop(s, None)
        plan.bins.update({f: b for f, b in candidate.new_bins.items() if f in c.triangles})
        plan.assign(st, written)
        dirty = self._bump(t, s)
        delta = float(np.sum(written * st.lp.cost)) - st.cost
        ring = tuple(sorted({t, *c.neighbors(t)}))
        return SurfaceChange(s, t, frozenset(dirty), ring, delta, change)

    def _apply_move(self, move: StarMove) -> SurfaceMove:
        v, st = move.vertex, move.stencil
        self.plan.complex.move(v, move.position)
        self.plan.assign(st, move.plan)
        self.forget_bins([v])
        delta = float(np.sum(move.plan * st.lp.cost)) - st.cost
        return SurfaceMove(v, frozenset(self._bump(v)), delta)

    def _bump(self, centre: int, source: int | None = None) -> set[int]:
        """Bumps the versions of every vertex whose half-edges' stencils a
        change on the closed star of ``centre`` (a collapse's target, a
        moved vertex) made stale, and ``source``'s; returns the live ones.

        The entries (and a move's position) changed on the closed star
        ``Z`` of ``centre``; a half-edge's stencil holds the vertices within
        one edge of its ends and their facets, so it changed if an end is
        within one edge of ``Z``: every half-edge leaving a vertex within
        two edges of ``Z`` is stale.
        """
        c = self.plan.complex
        near = {centre, *c.neighbors(centre)}
        for _ in range(2):
            near |= {w for v in near for w in c.neighbors(v)}
        for v in near | ({source} if source is not None else set()):
            self._versions[v] += 1
        return near

    # ------------------------------------------------------------ moves
    def movable(self, v: int) -> bool:
        """Every live vertex may move (a vertex whose star carries no mass has no target)."""
        return bool(self.plan.complex.alive[v])

    def propose_moves(self, vertices) -> list[tuple[int, float, tuple[StarMove]]]:
        """``[(vertex, delta, (move,))]``: the relocation of each vertex that
        lowers the cost (:func:`otjax.surfaces.moves.propose_moves`),
        made on the current state, nothing changed; ``apply(move)`` applies one."""
        t0 = time.perf_counter()
        moves = propose_star_moves(self.plan, vertices, self._move_solver, self._relocation_rounds,
                                   damping=self._damping)
        self.seconds["propose_moves"] += time.perf_counter() - t0
        self.counts["moves_proposed"] += sum(m is not None for m in moves)
        return [(m.vertex, m.delta, (m,)) for m in moves if m is not None]

    def forget_bins(self, vertices) -> None:
        """Drops cached bins of facets touching ``vertices`` (for a move)."""
        moved = set(vertices)
        self._bins = {f: b for f, b in self._bins.items() if moved.isdisjoint(f)}

    # ------------------------------------------------------------ research API
    def total_cost(self) -> float:
        """The plan's cost, recomputed from every entry."""
        return self.plan.total_cost()
