"""The local LP solvers the surface steps call, behind one signature.

``solver(problems) -> [LocalSolution]`` over :func:`otjax.lp.solve.solve_members`:
``"exact"`` solves each problem with HiGHS; ``"batched"``/``"auto"`` pack
problems of similar sizes into padded batches solved in one jitted call each,
``"auto"`` re-solving exactly every member the batched solver did not certify.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from otjax.lp.batched import NewtonOptions
from otjax.lp.exact import solve_member
from otjax.lp.problem import LocalLP
from otjax.lp.solve import solve_members
from otjax.surfaces.relaxation import LocalSolution


class LocalSolver:
    """A :data:`~otjax.surfaces.relaxation.Solver` that counts its work.

    Args:
      method: ``"exact"``, ``"batched"`` or ``"auto"`` (:func:`solve_members`).
      options, dtype: the batched solver's settings.

    Attributes:
      solved: problems solved so far.
      exact_resolves: of those, re-solved by HiGHS after the batched solver.
      closed_form: of those (``"exact"``), solved in closed form without HiGHS.
    """

    def __init__(self, method: str = "exact", options: NewtonOptions = NewtonOptions(), dtype=np.float64):
        self.method = method
        self.options = options
        self.dtype = dtype
        self.solved = 0
        self.exact_resolves = 0
        self.closed_form = 0

    def __call__(self, problems: Sequence[LocalLP]) -> list[LocalSolution]:
        if self.method == "exact":
            # One member at a time either way: no padding into a batch and out again.
            solutions = [solve_member(lp) for lp in problems]
            self.solved += len(problems)
            self.closed_form += sum(s.closed_form for s in solutions)
            return [LocalSolution(s.plan, s.cost, s.status) for s in solutions]
        result = solve_members(problems, self.method, self.options, self.dtype)
        self.solved += len(problems)
        self.exact_resolves += result.exact_resolves
        return [LocalSolution(s.plan, s.cost, s.status) for s in result.solutions]


def exact_solver(problems: Sequence[LocalLP]) -> list[LocalSolution]:
    """Every problem by HiGHS, one at a time."""
    return LocalSolver("exact")(problems)


def default_solver() -> str:
    """The local LP method when none is asked for: ``"exact"`` (HiGHS) on a
    CPU backend, where it solves the local problems of every surface step
    several times faster than the batched solver, ``"auto"`` on an
    accelerator (docs/decisions.md#feature_recovery_batches,
    docs/decisions.md#member_batches)."""
    return "exact" if jax.default_backend() == "cpu" else "auto"
