"""The exact solver: each member's LP handed to HiGHS, one at a time.

The oracle the batched solver is tested against, and the fallback for its
members that did not converge. Variables are the plan ``x_ij`` (row-major)
and one density ``l_s`` per simplex id; constraints are sparse.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
import scipy.optimize
import scipy.sparse

from otjax.lp.problem import (CONVERGED, FAILED, INFEASIBLE, ITERATION_LIMIT, LocalLP, LPSolution,
                              TransportLP, member)

# HiGHS's defaults (1e-7) are looser than the analytic tests' 1e-8.
TOLERANCE = 1e-10

_HIGHS_STATUS = {0: CONVERGED, 1: ITERATION_LIMIT, 2: INFEASIBLE}


class MemberSolution(NamedTuple):
    """The exact solution of one unpadded member.

    Attributes:
      plan: ``(P, K)`` float, ``>= 0``.
      density: ``(S,)`` float. ``l_s`` of facet ids; 0 for vertex and unused ids.
      simplex_mass: ``(S,)`` float. Mass each simplex id receives.
      cost: float. ``sum_ij x_ij C_ij``.
      status: int. A status code of :mod:`otjax.lp.problem`.
      iterations: int. HiGHS's iterations.
    """

    plan: np.ndarray
    density: np.ndarray
    simplex_mass: np.ndarray
    cost: float
    status: int
    iterations: int = 0


def constraints(lp: LocalLP) -> tuple[scipy.sparse.csr_matrix, np.ndarray]:
    """``(A_eq, b_eq)`` over the variables ``[x (P*K, row-major), l (S)]``.

    Rows: ``sum_j x_ij = m_i`` for each point, then ``sum_i x_ij - c_j l_s(j) = 0``
    for each facet bin, in bin order.
    """
    p, k = lp.cost.shape
    s = lp.n_simplices
    facet = np.flatnonzero(~np.asarray(lp.is_vertex, bool))
    nf = len(facet)
    x_index = np.arange(p * k).reshape(p, k)
    row_rows = np.repeat(np.arange(p), k)
    col_rows = p + np.repeat(np.arange(nf), p)
    col_vars = x_index[:, facet].T.ravel()
    l_rows = p + np.arange(nf)
    l_vars = p * k + np.asarray(lp.simplex)[facet]
    rows = np.concatenate([row_rows, col_rows, l_rows])
    cols = np.concatenate([x_index.ravel(), col_vars, l_vars])
    vals = np.concatenate([np.ones(p * k + p * nf), -np.asarray(lp.capacity, float)[facet]])
    a_eq = scipy.sparse.csr_matrix((vals, (rows, cols)), shape=(p + nf, p * k + s))
    b_eq = np.concatenate([np.asarray(lp.mass, float), np.zeros(nf)])
    return a_eq, b_eq


def simplex_totals(plan: np.ndarray, lp: LocalLP, n_simplices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(simplex_mass, density)``, each ``(n_simplices,)``, of a member's plan."""
    received = plan.sum(axis=0)
    simplex = np.asarray(lp.simplex, int)
    facet = ~np.asarray(lp.is_vertex, bool)
    mass = np.bincount(simplex, received, minlength=n_simplices)
    cap = np.bincount(simplex[facet], np.asarray(lp.capacity, float)[facet], minlength=n_simplices)
    facet_mass = np.bincount(simplex[facet], received[facet], minlength=n_simplices)
    density = np.divide(facet_mass, cap, out=np.zeros(n_simplices), where=cap > 0)
    return mass, density


def solve_member(lp: LocalLP, time_limit: float | None = None) -> MemberSolution:
    """The optimal plan of one member, by HiGHS.

    A member with points but no bin is :data:`INFEASIBLE`; HiGHS's other
    stops (iteration or time limit: :data:`ITERATION_LIMIT`; numerical
    trouble: :data:`FAILED`) come back with a zero plan.

    Example:
      >>> lp = LocalLP(np.array([[4.0, 1.0]]), np.ones(1), np.array([0.0, 1.0]),
      ...              np.array([0, 1]), np.array([True, False]))
      >>> solve_member(lp).cost
      1.0
    """
    p, k = lp.cost.shape
    s = lp.n_simplices
    if p == 0:
        return MemberSolution(np.zeros((0, k)), np.zeros(s), np.zeros(s), 0.0, CONVERGED)
    if k == 0:
        return MemberSolution(np.zeros((p, 0)), np.zeros(s), np.zeros(s), 0.0, INFEASIBLE)
    a_eq, b_eq = constraints(lp)
    c = np.concatenate([np.asarray(lp.cost, float).ravel(), np.zeros(s)])
    options = {"primal_feasibility_tolerance": TOLERANCE, "dual_feasibility_tolerance": TOLERANCE}
    if time_limit is not None:
        options["time_limit"] = float(time_limit)
    res = scipy.optimize.linprog(c, A_eq=a_eq, b_eq=b_eq, bounds=(0, None), method="highs", options=options)
    status = _HIGHS_STATUS.get(res.status, FAILED)
    if status != CONVERGED or res.x is None:
        return MemberSolution(np.zeros((p, k)), np.zeros(s), np.zeros(s), 0.0, status, int(res.nit))
    plan = np.maximum(res.x[: p * k].reshape(p, k), 0.0)
    mass, density = simplex_totals(plan, lp, s)
    return MemberSolution(plan, density, mass, float(np.sum(plan * lp.cost)), CONVERGED, int(res.nit))


def marginal_violation(plan: np.ndarray, lp: LocalLP) -> float:
    """Largest violation of a member's row sums and facet uniformity, over its total mass."""
    total = float(np.sum(lp.mass))
    if total == 0:
        return 0.0
    worst = np.max(np.abs(plan.sum(axis=1) - lp.mass), initial=0.0)
    received = plan.sum(axis=0)
    facet = ~np.asarray(lp.is_vertex, bool)
    _, density = simplex_totals(plan, lp, lp.n_simplices)
    want = np.asarray(lp.capacity, float) * density[np.asarray(lp.simplex, int)]
    worst = max(worst, np.max(np.abs(received - want)[facet], initial=0.0))
    return float(worst / total)


def solve_exact(batch: TransportLP, members: Sequence[int] | None = None,
                into: LPSolution | None = None, time_limit: float | None = None) -> LPSolution:
    """Solves members of a padded batch with HiGHS (NumPy in, NumPy out).

    Args:
      batch: the padded problems.
      members: indices to solve; all by default.
      into: a solution of the same batch whose other members are kept (its
        arrays are copied, not written in place). Without it, members not
        solved come back with a zero plan and status :data:`FAILED`.
      time_limit: seconds HiGHS may spend on one member.

    Returns:
      An :class:`LPSolution` with ``lower_bound == cost`` for converged members.
    """
    b, p_cap, k_cap, s_cap = batch.shape
    dtype = np.asarray(batch.cost).dtype
    if into is None:
        out = LPSolution(np.zeros((b, p_cap, k_cap), dtype), np.zeros((b, s_cap), dtype),
                         np.zeros((b, s_cap), dtype), np.zeros(b, dtype), np.zeros(b, dtype),
                         np.zeros(b, dtype), np.full(b, FAILED, np.int8), np.zeros(b, np.int32))
    else:
        out = LPSolution(*(np.array(a) for a in into))
    for m in range(b) if members is None else members:
        lp = member(batch, m)
        sol = solve_member(lp, time_limit)
        p, k = lp.cost.shape
        s = lp.n_simplices
        pm, bm = np.asarray(batch.point_mask[m]), np.asarray(batch.bin_mask[m])
        plan = np.zeros((p_cap, k_cap), dtype)
        plan[np.ix_(np.flatnonzero(pm), np.flatnonzero(bm))] = sol.plan
        out.plan[m] = plan
        out.simplex_mass[m] = 0
        out.simplex_mass[m, :s] = sol.simplex_mass
        out.density[m] = 0
        out.density[m, :s] = sol.density
        out.cost[m] = sol.cost
        out.lower_bound[m] = sol.cost if sol.status == CONVERGED else -np.inf
        out.violation[m] = marginal_violation(sol.plan, lp) if sol.status == CONVERGED else np.inf
        out.status[m] = sol.status
        out.iterations[m] = sol.iterations
    return out
