"""Local stencil relaxation of a transport plan (§3.3, Algorithm 2).

Starting from any feasible plan, each facet's stencil (the facet, its
neighbours, their vertices) is cut out with the partial masses its points
have there, solved as a small LP, and written back if its cost did not rise;
sweeps repeat until one lowers the total cost by less than a relative
``tolerance``. Stencils that share no vertex share no simplex, so a sweep is
split into rounds of vertex-disjoint stencils and each round is one batched
solver call; rounds run in order, so each sees the plan the earlier ones left
(the sequential sweep's Gauss-Seidel character is kept between rounds).
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import numpy as np

from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, LocalLP
from otjax.surfaces.complex import SimplicialComplex, Triangle
from otjax.surfaces.plan import SurfacePlan

#: Relative decrease of the total cost over a sweep below which relaxation
#: stops (the paper's threshold).
TOLERANCE = 1e-5
MAX_SWEEPS = 10
#: A local solution replaces the plan only if it lowers the stencil's cost by
#: more than this fraction: an equal-cost rewrite gains nothing and would
#: mark the neighbours for another solve.
GAIN = 1e-12


class LocalSolution(NamedTuple):
    """A solved member: ``plan`` ``(P, K)`` feasible, its ``cost``, its ``status``."""

    plan: np.ndarray
    cost: float
    status: int


#: ``solve(problems) -> solutions``, one per problem, in order.
Solver = Callable[[Sequence[LocalLP]], Sequence[LocalSolution]]
#: ``stencil_of(facet) -> (vertices, facets)``: the simplices of a facet's stencil.
StencilRule = Callable[[Triangle], tuple[Sequence[int], Sequence[Triangle]]]


class RelaxationStats(NamedTuple):
    """What a relaxation did.

    Attributes:
      costs: total cost before the first sweep and after each sweep.
      solves: local LPs solved.
      accepted: solutions written back (cost not higher than before).
      rounds: solver calls (rounds of vertex-disjoint stencils).
      unconverged: solutions whose status was not converged (kept only if
        they still lowered the cost: every returned plan is feasible).
    """

    costs: tuple[float, ...]
    solves: int
    accepted: int
    rounds: int
    unconverged: int

    @property
    def sweeps(self) -> int:
        return len(self.costs) - 1


def facet_ring(complex_: SimplicialComplex) -> StencilRule:
    """The paper's stencil of a facet: it, the facets sharing an edge with it,
    and their vertices."""

    def rule(facet: Triangle):
        facets = (facet,) + complex_.triangle_neighbors(facet)
        return sorted({v for t in facets for v in t}), facets

    return rule


def rounds_of(stencils: Sequence[Sequence[int]]) -> list[list[int]]:
    """Splits stencils (given by their vertex sets) into rounds of
    vertex-disjoint ones, first fit in the given order.

    Example:
      >>> rounds_of([[0, 1], [1, 2], [3], [2, 3]])
      [[0, 2], [1], [3]]
    """
    busy: dict[int, set[int]] = {}
    rounds: list[list[int]] = []
    for i, verts in enumerate(stencils):
        taken = set().union(*(busy.get(v, ()) for v in verts))
        r = 0
        while r in taken:
            r += 1
        if r == len(rounds):
            rounds.append([])
        rounds[r].append(i)
        for v in verts:
            busy.setdefault(v, set()).add(r)
    return rounds


def relax(plan: SurfacePlan, solve: Solver, stencil_of: StencilRule | None = None, *,
          centres: Sequence[Triangle] | None = None, tolerance: float = TOLERANCE,
          max_sweeps: int = MAX_SWEEPS, seed: int = 0) -> RelaxationStats:
    """Relaxes ``plan`` in place by sweeps of local solves (Algorithm 2).

    Args:
      plan: the plan to improve; only its entries change.
      solve: the local LP solver (:data:`Solver`); its plans must be feasible.
      stencil_of: the stencil of a centre facet; default :func:`facet_ring`.
      centres: the facets whose stencils are swept; default every facet.
      tolerance: stop when a sweep lowers the cost by less than this fraction.
      max_sweeps: at most this many sweeps.
      seed: seeds the order of the stencils within each sweep.

    Returns:
      :class:`RelaxationStats`. The total cost never rises: a local solution
      is written back only if it costs less than what it replaces. Stencils
      whose simplices did not change since their last solve are skipped.
    """
    rule = stencil_of or facet_ring(plan.complex)
    centres = sorted(plan.complex.triangles) if centres is None else list(centres)
    simplices = [rule(c) for c in centres]
    rng = np.random.default_rng(seed)
    total = plan.total_cost()
    costs = [total]
    solves = accepted = n_rounds = unconverged = 0
    # A stencil's LP depends only on the entries of its simplices: one whose
    # simplices did not change since it was last solved would give the same
    # answer again, so it is skipped (exactly).
    changed_at: dict = {}
    solved_at = np.full(len(centres), -1)
    clock = 0
    for _ in range(max_sweeps):
        order = [i for i in rng.permutation(len(centres))
                 if solved_at[i] < 0 or _last_change(changed_at, simplices[i]) > solved_at[i]]
        for members in rounds_of([simplices[i][0] for i in order]):
            clock += 1
            ids = [order[i] for i in members]
            solved_at[ids] = clock
            cut = [plan.stencil(*simplices[i]) for i in ids]
            cut = [s for s in cut if len(s.points)]
            if not cut:
                continue
            solutions = solve([s.lp for s in cut])
            n_rounds += 1
            solves += len(cut)
            for stencil, sol in zip(cut, solutions):
                if sol.status not in (CONVERGED, ITERATION_LIMIT):
                    continue
                unconverged += sol.status != CONVERGED
                written = plan.sparsified(stencil, sol.plan)
                if float(np.sum(written * stencil.lp.cost)) < stencil.cost * (1.0 - GAIN):
                    plan.assign(stencil, written)
                    accepted += 1
                    for key in stencil.vertices + stencil.facets:
                        changed_at[key] = clock
        previous, total = total, plan.total_cost()
        costs.append(total)
        if previous - total <= tolerance * previous:
            break
    return RelaxationStats(tuple(costs), solves, accepted, n_rounds, unconverged)


def _last_change(changed_at: dict, stencil) -> int:
    vertices, facets = stencil
    return max((changed_at.get(k, -1) for k in (*vertices, *facets)), default=-1)
