"""One entry point over both solvers: the batched one, with HiGHS behind it.

``method="auto"`` runs the batched solver and re-solves with HiGHS every
member it did not certify (status :data:`ITERATION_LIMIT` or :data:`FAILED`),
so every returned plan is optimal within the batched solver's tolerance or
exactly. The count of re-solved members is returned: a rising count says
the step budget no longer fits the problems.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import numpy as np

from otjax.lp.batched import NewtonOptions, solve_batched
from otjax.lp.exact import MemberSolution, closed_form_solution, solve_exact
from otjax.lp.problem import (FAILED, ITERATION_LIMIT, LocalLP, LPSolution, TransportLP, check_local,
                              group_by_class, member_plan, pack)

METHODS = ("auto", "batched", "exact")


class SolveResult(NamedTuple):
    """What :func:`solve` returns.

    Attributes:
      solution: the :class:`LPSolution` (NumPy arrays), padded like the problem.
      exact_resolves: members the batched solver left uncertified and HiGHS
        solved again (``method="auto"``; 0 otherwise).
    """

    solution: LPSolution
    exact_resolves: int


class MembersResult(NamedTuple):
    """What :func:`solve_members` returns.

    Attributes:
      solutions: one :class:`~otjax.lp.exact.MemberSolution` per problem, in order, unpadded.
      exact_resolves: members re-solved by HiGHS, as in :class:`SolveResult`.
    """

    solutions: list[MemberSolution]
    exact_resolves: int


def solve(problem: TransportLP, method: str = "auto", options: NewtonOptions = NewtonOptions(),
          dtype=np.float64, time_limit: float | None = None) -> SolveResult:
    """Solves a padded batch of local transport LPs.

    Args:
      problem: the padded batch.
      method: ``"batched"`` (JAX, a fixed step budget, a status per member),
        ``"exact"`` (HiGHS, one member at a time) or ``"auto"`` (batched, then
        HiGHS for the members it did not certify).
      options: the batched solver's settings.
      dtype: float dtype of the batched solver; float64 needs JAX's x64 mode.
      time_limit: seconds HiGHS may spend on one member.

    Returns:
      A :class:`SolveResult`.

    Raises:
      ValueError: an unknown ``method``.
      RuntimeError: float64 asked for while JAX's x64 mode is off.

    Example:
      >>> lp = LocalLP(np.array([[4.0, 1.0]]), np.ones(1), np.array([0.0, 1.0]),
      ...              np.array([0, 1]), np.array([True, False]))
      >>> solve(pack([lp]), method="exact").solution.cost.tolist()
      [1.0]
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if method == "exact":
        return SolveResult(solve_exact(problem, time_limit=time_limit), 0)
    solution = LPSolution(*jax.device_get(solve_batched(problem, options, dtype)))
    if method == "batched":
        return SolveResult(solution, 0)
    redo = np.flatnonzero((solution.status == ITERATION_LIMIT) | (solution.status == FAILED))
    if len(redo):
        host = TransportLP(*(np.asarray(a) for a in problem))
        solution = solve_exact(host, redo, into=solution, time_limit=time_limit)
    return SolveResult(solution, len(redo))


def solve_members(problems: Sequence[LocalLP], method: str = "auto", options: NewtonOptions = NewtonOptions(),
                  dtype=np.float64, time_limit: float | None = None) -> MembersResult:
    """Solves unpadded members: grouped by capacity class, packed, solved, unpadded.

    Arguments as in :func:`solve`; members are validated
    (:func:`~otjax.lp.problem.check_local`, a ``ValueError`` naming the problem).
    With ``"auto"`` and ``"exact"``, members whose optimum has a closed form
    (:func:`~otjax.lp.exact.closed_form_solution`) are solved so and never
    padded into a batch.

    Example:
      >>> lp = LocalLP(np.array([[4.0, 1.0]]), np.ones(1), np.array([0.0, 1.0]),
      ...              np.array([0, 1]), np.array([True, False]))
      >>> solve_members([lp], method="exact").solutions[0].plan.tolist()
      [[0.0, 1.0]]
    """
    out: list[MemberSolution | None] = [None] * len(problems)
    resolves = 0
    todo = list(range(len(problems)))
    if method in ("auto", "exact"):
        for i in todo:
            check_local(problems[i])
            out[i] = closed_form_solution(problems[i])
        todo = [i for i in todo if out[i] is None]
    for shape, rows in group_by_class([problems[i] for i in todo]).items():
        idx = [todo[r] for r in rows]
        batch = pack([problems[i] for i in idx], shape=shape)
        result = solve(batch, method, options, dtype, time_limit)
        sol = result.solution
        resolves += result.exact_resolves
        for b, i in enumerate(idx):
            s = problems[i].n_simplices
            out[i] = MemberSolution(plan=member_plan(sol, batch, b), density=np.asarray(sol.density[b, :s]),
                                    simplex_mass=np.asarray(sol.simplex_mass[b, :s]), cost=float(sol.cost[b]),
                                    status=int(sol.status[b]), iterations=int(sol.iterations[b]))
    return MembersResult(out, resolves)
