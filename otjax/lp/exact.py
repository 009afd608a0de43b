"""The exact solver: each member's LP handed to HiGHS, one at a time.

The oracle the batched solver is tested against, and the fallback for its
members that did not converge. Variables are the plan ``x_ij`` (row-major)
and one density ``l_s`` per simplex id; constraints are sparse and built
column-wise straight into HiGHS's own matrix (``highspy``, one solver object
per process, options set once): through ``scipy.optimize.linprog`` the
checks and conversions around a small LP cost twice the solve itself.

A member whose every point has a cheapest bin that is unconstrained (a
vertex bin, or the only bin of its facet: uniformity then binds nothing) is
solved in closed form: each point to such a bin attains the bound that
ignores uniformity, so no plan is cheaper.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import threading

import highspy
import numpy as np
import scipy.sparse

from otjax.lp.problem import (CONVERGED, FAILED, INFEASIBLE, ITERATION_LIMIT, LocalLP, LPSolution,
                              TransportLP, member)

# HiGHS's defaults (1e-7) are looser than the analytic tests' 1e-8.
TOLERANCE = 1e-10

_MODEL_STATUS = {
    highspy.HighsModelStatus.kOptimal: CONVERGED,
    highspy.HighsModelStatus.kInfeasible: INFEASIBLE,
    highspy.HighsModelStatus.kIterationLimit: ITERATION_LIMIT,
    highspy.HighsModelStatus.kTimeLimit: ITERATION_LIMIT,
}
_COLWISE, _MINIMIZE = int(highspy.MatrixFormat.kColwise), int(highspy.ObjSense.kMinimize)
_LOCAL = threading.local()  # one HiGHS object per thread: it holds the model


class MemberSolution(NamedTuple):
    """The exact solution of one unpadded member.

    Attributes:
      plan: ``(P, K)`` float, ``>= 0``.
      density: ``(S,)`` float. ``l_s`` of facet ids; 0 for vertex and unused ids.
      simplex_mass: ``(S,)`` float. Mass each simplex id receives.
      cost: float. ``sum_ij x_ij C_ij``.
      status: int. A status code of :mod:`otjax.lp.problem`.
      iterations: int. HiGHS's iterations.
      closed_form: bool. Solved without HiGHS (see the module docstring).
    """

    plan: np.ndarray
    density: np.ndarray
    simplex_mass: np.ndarray
    cost: float
    status: int
    iterations: int = 0
    closed_form: bool = False


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
    """The optimal plan of one member, by HiGHS (or in closed form, see the
    module docstring).

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
    cost = np.asarray(lp.cost, np.float64)
    free = unconstrained_bins(lp)
    plan = _closed_form(cost, np.asarray(lp.mass, np.float64), free)
    closed, iterations = plan is not None, 0
    if not closed:
        status, plan, iterations = _highs(lp, cost, free, time_limit)
        if status != CONVERGED:
            return MemberSolution(np.zeros((p, k)), np.zeros(s), np.zeros(s), 0.0, status, iterations)
    mass, density = simplex_totals(plan, lp, s)
    return MemberSolution(plan, density, mass, float(np.sum(plan * cost)), CONVERGED, iterations, closed)


def closed_form_solution(lp: LocalLP) -> MemberSolution | None:
    """The member's optimum if the closed form applies (module docstring), else None."""
    p, k = lp.cost.shape
    if p == 0 or k == 0:
        return None
    cost = np.asarray(lp.cost, np.float64)
    plan = _closed_form(cost, np.asarray(lp.mass, np.float64), unconstrained_bins(lp))
    if plan is None:
        return None
    mass, density = simplex_totals(plan, lp, lp.n_simplices)
    return MemberSolution(plan, density, mass, float(np.sum(plan * cost)), CONVERGED, 0, True)


def unconstrained_bins(lp: LocalLP) -> np.ndarray:
    """``(K,)`` bool: bins whose mass no uniformity constraint ties to another
    bin's (vertex bins, and the only bin of a facet)."""
    simplex = np.asarray(lp.simplex, np.int64)
    vertex = np.asarray(lp.is_vertex, bool)
    if len(simplex) == 0:
        return vertex
    per_facet = np.bincount(simplex[~vertex], minlength=int(simplex.max()) + 1)
    return vertex | (per_facet[simplex] == 1)


def _closed_form(cost: np.ndarray, mass: np.ndarray, free: np.ndarray) -> np.ndarray | None:
    """Each point on its cheapest bin if every point has a cheapest bin that
    is unconstrained (then the plan attains the bound that drops uniformity,
    hence is optimal); None otherwise."""
    if not np.any(free):
        return None
    free_cost = np.where(free[None, :], cost, np.inf)
    best = np.argmin(free_cost, axis=1)
    rows = np.arange(len(cost))
    if np.any(free_cost[rows, best] > cost.min(axis=1)):
        return None
    plan = np.zeros_like(cost)
    plan[rows, best] = mass
    return plan


def _solver() -> highspy.Highs:
    h = getattr(_LOCAL, "highs", None)
    if h is None:
        # The bare solver class: highspy's ``Highs`` wrapper enables callbacks on
        # construction, which makes HiGHS print its banner on stdout before
        # ``output_flag`` can be set. The calls below are the base class's.
        h = getattr(highspy, "_Highs", highspy.Highs)()
        h.setOptionValue("output_flag", False)
        h.setOptionValue("primal_feasibility_tolerance", TOLERANCE)
        h.setOptionValue("dual_feasibility_tolerance", TOLERANCE)
        # Local transport LPs are small and have nothing to reduce: presolve costs more than it saves
        # (docs/decisions.md#lp_solver).
        h.setOptionValue("presolve", "off")
        _LOCAL.highs = h
    return h


def _highs(lp: LocalLP, cost: np.ndarray, free: np.ndarray, time_limit: float | None):
    """``(status, plan, iterations)`` of one member solved by HiGHS.

    The matrix is built column-wise: column ``x_ij`` has a 1 in point row
    ``i`` and, for a constrained bin, a 1 in that bin's row; column ``l_s``
    has ``-c_j`` in the rows of its facet's bins. Unconstrained bins get no
    row (their uniformity equation is ``x = l``, satisfied by a free ``l``).
    """
    p, k = cost.shape
    s = lp.n_simplices
    simplex = np.asarray(lp.simplex, np.int64)
    con = np.flatnonzero(~free)
    con = con[np.argsort(simplex[con], kind="stable")]
    row_of = np.full(k, -1)
    row_of[con] = p + np.arange(len(con))
    per_x = 1 + (row_of >= 0)
    counts = np.concatenate([np.tile(per_x, p), np.bincount(simplex[con], minlength=s)])
    start = np.concatenate([[0], np.cumsum(counts)])
    nnz = int(start[-1])
    index = np.empty(nnz, np.int32)
    value = np.ones(nnz)
    first = start[:p * k]
    index[first] = np.repeat(np.arange(p), k)
    second = np.flatnonzero(np.tile(row_of >= 0, p))
    index[first[second] + 1] = np.tile(row_of, p)[second]
    index[start[p * k]:] = row_of[con]
    value[start[p * k]:] = -np.asarray(lp.capacity, np.float64)[con]

    h = _solver()
    h.setOptionValue("time_limit", highspy.kHighsInf if time_limit is None else float(time_limit))
    # The arrays go to HiGHS as they are: filling a HighsLp's fields converts each one element by
    # element, which took as long as solving these small LPs. Integrality 0: every column continuous.
    n_col, bound = p * k + s, np.concatenate([np.asarray(lp.mass, np.float64), np.zeros(len(con))])
    h.passModel(n_col, p + len(con), nnz, _COLWISE, _MINIMIZE, 0.0,
                np.concatenate([cost.ravel(), np.zeros(s)]), np.zeros(n_col), np.full(n_col, highspy.kHighsInf),
                bound, bound, start[:-1].astype(np.int32), index, value, np.zeros(n_col, np.int32))
    h.run()
    status = _MODEL_STATUS.get(h.getModelStatus(), FAILED)
    iterations = int(h.getInfo().simplex_iteration_count)
    if status != CONVERGED:
        return status, None, iterations
    x = np.asarray(h.getSolution().col_value[:p * k], np.float64)
    return status, np.maximum(x.reshape(p, k), 0.0), iterations


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
