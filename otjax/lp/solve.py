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
from otjax.lp.exact import MemberSolution, closed_form_solution, solve_exact, solve_member
from otjax.lp.problem import (FAILED, ITERATION_LIMIT, LocalLP, LPSolution, TransportLP, capacity_class,
                              check_local, member_plan, pack)

METHODS = ("auto", "batched", "exact")
#: Members per batched call of :func:`solve_members`, however many share a
#: shape: the batch size is part of the compiled shape, and one compilation
#: (seconds) costs more than many padded members (docs/decisions.md#member_batches).
BATCH = 16
#: With ``"auto"``, :func:`solve_members` sends a shape group of fewer
#: members to HiGHS: a batched call costs about as much as this many HiGHS
#: solves of a small member, and the shape may never come again.
MIN_BATCH = 8
#: Smallest padded points and bins of a member in :func:`solve_members`:
#: few, coarse shapes, each compiled once.
MIN_POINTS = 32
MIN_BINS = 32


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
      batched_calls: calls of the batched solver.
    """

    solutions: list[MemberSolution]
    exact_resolves: int
    batched_calls: int = 0


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


def member_shape(lp: LocalLP) -> tuple[int, int, int]:
    """``(P, K, S)`` padded shape of a member in :func:`solve_members`:
    powers of two from :data:`MIN_POINTS` and :data:`MIN_BINS`, the simplex
    axis as wide as the bins' (a simplex has at least one bin), so a shape
    is set by two numbers."""
    k = capacity_class(lp.cost.shape[1], MIN_BINS)
    return capacity_class(lp.cost.shape[0], MIN_POINTS), k, max(k, capacity_class(lp.n_simplices, MIN_BINS))


def solve_members(problems: Sequence[LocalLP], method: str = "auto", options: NewtonOptions = NewtonOptions(),
                  dtype=np.float64, time_limit: float | None = None) -> MembersResult:
    """Solves unpadded members: grouped by padded shape, solved, unpadded.

    Arguments as in :func:`solve`; members are validated
    (:func:`~otjax.lp.problem.check_local`, a ``ValueError`` naming the problem).
    With ``"auto"`` and ``"exact"``, members whose optimum has a closed form
    (:func:`~otjax.lp.exact.closed_form_solution`) are solved so and never
    padded into a batch. The batched solver sees few compiled shapes
    however the members vary: each group of one :func:`member_shape` is
    solved in batches of :data:`BATCH` members; with ``"auto"`` a group of
    fewer than :data:`MIN_BATCH` goes to HiGHS instead.

    Example:
      >>> lp = LocalLP(np.array([[4.0, 1.0]]), np.ones(1), np.array([0.0, 1.0]),
      ...              np.array([0, 1]), np.array([True, False]))
      >>> solve_members([lp], method="exact").solutions[0].plan.tolist()
      [[0.0, 1.0]]
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    out: list[MemberSolution | None] = [None] * len(problems)
    resolves = calls = 0
    groups: dict[tuple[int, int, int], list[int]] = {}
    for i, lp in enumerate(problems):
        check_local(lp)
        if 0 in lp.cost.shape:  # nothing to move or nowhere to go: decided without a solver
            out[i] = solve_member(lp, time_limit)
        elif method != "batched":
            out[i] = closed_form_solution(lp)
        if out[i] is None:
            groups.setdefault(member_shape(lp), []).append(i)
    for shape, idx in sorted(groups.items()):
        if method == "exact" or (method == "auto" and len(idx) < MIN_BATCH):
            for i in idx:  # unpadded: no batch to build and unpack
                out[i] = solve_member(problems[i], time_limit)
            continue
        for lo in range(0, len(idx), BATCH):
            part = idx[lo:lo + BATCH]
            batch = pack([problems[i] for i in part], shape=shape, batch=BATCH, check=False)
            result = solve(batch, method, options, dtype, time_limit)
            sol = result.solution
            resolves += result.exact_resolves
            calls += 1
            for b, i in enumerate(part):
                s = problems[i].n_simplices
                out[i] = MemberSolution(plan=member_plan(sol, batch, b), density=np.asarray(sol.density[b, :s]),
                                        simplex_mass=np.asarray(sol.simplex_mass[b, :s]), cost=float(sol.cost[b]),
                                        status=int(sol.status[b]), iterations=int(sol.iterations[b]))
    return MembersResult(out, resolves, calls)
