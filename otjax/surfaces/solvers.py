"""The local LP solvers the surface steps call, behind one signature.

``solver(problems) -> [LocalSolution]``: the exact one solves each problem
with HiGHS; the batched one packs problems of similar sizes into padded
batches, solves each batch in one jitted call, and re-solves exactly every
member that did not converge within its step budget.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from otjax.lp.batched import NewtonOptions, solve_batched
from otjax.lp.exact import solve_member
from otjax.lp.problem import CONVERGED, LocalLP, group_by_class, member_plan, pack
from otjax.surfaces.relaxation import LocalSolution

#: Members per padded batch (bounds the memory of one call).
MAX_BATCH = 256


class SolverCounts(NamedTuple):
    """How many problems each path solved."""

    batched: int
    exact_fallback: int


def exact_solver(problems: Sequence[LocalLP]) -> list[LocalSolution]:
    """Every problem by HiGHS, one at a time."""
    return [LocalSolution(s.plan, s.cost, s.status) for s in map(solve_member, problems)]


class BatchedSolver:
    """Padded batches through :func:`otjax.lp.batched.solve_batched`, with an
    exact re-solve of the members that did not converge.

    Args:
      options: the batched solver's step budget and tolerances.
      dtype: float dtype of the batched computation.
    """

    def __init__(self, options: NewtonOptions = NewtonOptions(), dtype=np.float64):
        self.options = options
        self.dtype = dtype
        self.batched = 0
        self.exact_fallback = 0

    @property
    def counts(self) -> SolverCounts:
        return SolverCounts(self.batched, self.exact_fallback)

    def __call__(self, problems: Sequence[LocalLP]) -> list[LocalSolution]:
        out: list[LocalSolution | None] = [None] * len(problems)
        for ids in group_by_class(problems).values():
            for start in range(0, len(ids), MAX_BATCH):
                chunk = ids[start:start + MAX_BATCH]
                batch = pack([problems[i] for i in chunk], dtype=self.dtype)
                sol = solve_batched(batch, self.options, self.dtype)
                status = np.asarray(sol.status)
                cost = np.asarray(sol.cost)
                host = type(sol)(*(np.asarray(a) for a in sol))
                for b, i in enumerate(chunk):
                    if status[b] == CONVERGED:
                        out[i] = LocalSolution(member_plan(host, batch, b), float(cost[b]), CONVERGED)
                        self.batched += 1
                    else:
                        exact = solve_member(problems[i])
                        out[i] = LocalSolution(exact.plan, exact.cost, exact.status)
                        self.exact_fallback += 1
        return out  # type: ignore[return-value]
