"""The batched solver: damped Newton on the entropic semi-dual, jit + vmap.

For one member, with facet-bin potentials ``g`` (vertex bins fixed at 0),
each point's row of the entropic plan is a softmax::

    x_ij = m_i softmax_j((g_j - C_ij) / eps)

so row sums are exact by construction, and minimising the convex
``Phi(g) = eps sum_i m_i logsumexp_j((g_j - C_ij) / eps)`` under one linear
constraint per facet, ``sum_{j in s} c_j g_j = 0``, makes each facet's column
sums proportional to its capacities (the constraint's multiplier is ``l_s``).
Each step solves the KKT system of that constraint (a dense SPD solve), backtracks to an Armijo step, and lowers ``eps`` while the
member's certified gap is above tolerance. Every step also rounds the plan
to an exactly feasible one (an upper bound) and evaluates the dual (a lower
bound); the best of each is kept.

The step budget is fixed: under ``vmap`` a data-dependent loop would run
every member as long as the slowest. Why Newton rather than Sinkhorn, and
the constants: ``docs/decisions.md#lp_solver``.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from otjax.lp.linalg import spd_solve
from otjax.lp.problem import CONVERGED, FAILED, INFEASIBLE, ITERATION_LIMIT, LPSolution, TransportLP


class NewtonOptions(NamedTuple):
    """Static settings of :func:`solve_batched` (``docs/decisions.md#lp_solver``).

    Attributes:
      steps: Newton steps per member (a fixed budget).
      rtol: a member converges when ``cost - lower_bound <= rtol * cost + atol``.
      atol: absolute gap tolerance, in cost units times mass.
      eps_start: first ``eps``, relative to the member's cost spread (the
        mass-weighted mean over points of ``mean_j C_ij - min_j C_ij``).
      decay: factor on ``eps`` after each step while the gap is above ``rtol``.
      eps_floor: smallest ``eps``, relative to the cost spread.
      backtracks: at most this many halvings of a step in the line search.
      uniformity: ``eps`` is lowered once every facet bin's column sum is
        within this fraction of the member's mass of ``c_j l_s``.
      ridge: added curvature of a facet bin, relative to the curvature
        ``c_j l_s / eps`` it has at its share.
    """

    steps: int = 64
    rtol: float = 1e-3
    atol: float = 0.0
    eps_start: float = 0.3
    decay: float = 0.6
    eps_floor: float = 1e-9
    backtracks: int = 12
    uniformity: float = 1e-6
    ridge: float = 1e-3


class _Member(NamedTuple):
    """One member's arrays inside the solver (no batch axis)."""

    cost: jax.Array  # (P, K); 0 on padding
    mass: jax.Array  # (P,)
    capacity: jax.Array  # (K,); 0 outside facet bins
    real: jax.Array  # (K,) bool: bins a point may use
    free: jax.Array  # (K,) bool: facet bins (their potential moves)
    vertex: jax.Array  # (K,) bool: real vertex bins
    onehot: jax.Array  # (K, S) float: facet bin j belongs to facet s


class _State(NamedTuple):
    g: jax.Array  # (K,) potentials; sum_{j in s} c_j g_j = 0
    eps: jax.Array  # () current regularisation
    best_ub: jax.Array  # () cost of the best rounded plan so far
    best_g: jax.Array  # (K,) the potentials it was rounded from
    best_eps: jax.Array  # () and their eps
    best_lb: jax.Array  # () best dual value so far
    eps_min: jax.Array  # () floor of eps


def _logits(mb: _Member, g, eps):
    return jnp.where(mb.real[None, :], (g[None, :] - mb.cost) / eps, -jnp.inf)


def _objective(mb: _Member, g, eps):
    """``Phi(g)``: the entropic semi-dual, to minimise."""
    return eps * jnp.sum(mb.mass * jax.nn.logsumexp(_logits(mb, g, eps), axis=1))


def _entropic_plan(mb: _Member, g, eps):
    logits = _logits(mb, g, eps)
    shifted = logits - jnp.max(logits, axis=1, keepdims=True)
    # Weights below the cut are zeroed: products of two of them would be
    # subnormal, which the CPU handles ~100x slower (and they carry no mass).
    cut = 0.4 * np.log(jnp.finfo(logits.dtype).tiny)
    w = jnp.where(shifted > cut, jnp.exp(jnp.maximum(shifted, cut)), 0)
    return mb.mass[:, None] * (w / jnp.sum(w, axis=1, keepdims=True))


def _round(mb: _Member, plan):
    """An exactly feasible plan from an approximate one (cost: an upper bound).

    Rows are scaled down to at most ``m_i``; each facet's columns down to a
    common ``l_s = min_k r_k / c_k``; each point's deficit then goes to its
    cheapest sink: a vertex bin, or a whole facet spread by capacity (which
    keeps the facet uniform, so a member without vertex bins stays feasible).
    """
    rows = plan.sum(axis=1)
    plan = plan * jnp.where(rows > mb.mass, mb.mass / jnp.where(rows > 0, rows, 1), 1)[:, None]
    received = plan.sum(axis=0)
    ratio = jnp.where(mb.free, received / jnp.where(mb.free, mb.capacity, 1), jnp.inf)
    level = jnp.min(jnp.where(mb.onehot > 0, ratio[:, None], jnp.inf), axis=0)  # (S,)
    level = jnp.where(jnp.isfinite(level), level, 0)
    want = mb.capacity * (mb.onehot @ level)
    plan = plan * jnp.where(mb.free, want / jnp.where(received > 0, received, 1), 1)[None, :]
    deficit = jnp.maximum(mb.mass - plan.sum(axis=1), 0)
    cap_of = mb.capacity[:, None] * mb.onehot  # (K, S)
    spread = cap_of / jnp.where(cap_of.sum(axis=0) > 0, cap_of.sum(axis=0), 1)  # (K, S)
    facet_cost = jnp.where(cap_of.sum(axis=0) > 0, mb.cost @ spread, jnp.inf)  # (P, S)
    vertex_cost = jnp.where(mb.vertex[None, :], mb.cost, jnp.inf)  # (P, K)
    to_vertex = jnp.min(vertex_cost, axis=1) <= jnp.min(facet_cost, axis=1)
    vertex_pick = jax.nn.one_hot(jnp.argmin(vertex_cost, axis=1), plan.shape[1], dtype=plan.dtype)
    facet_pick = jax.nn.one_hot(jnp.argmin(facet_cost, axis=1), spread.shape[1], dtype=plan.dtype) @ spread.T
    extra = jnp.where(to_vertex[:, None], vertex_pick, facet_pick)
    return plan + deficit[:, None] * extra


def _lower_bound(mb: _Member, g):
    """A feasible LP dual value: ``g`` shifted per facet to ``sum c g = 0``, then its c-transform."""
    cap_of = mb.capacity[:, None] * mb.onehot
    total = jnp.where(cap_of.sum(axis=0) > 0, cap_of.sum(axis=0), 1)
    shift = mb.onehot @ ((g @ cap_of) / total)
    gf = jnp.where(mb.free, g - shift, 0)
    reduced = jnp.where(mb.real[None, :], mb.cost - gf[None, :], jnp.inf)
    return jnp.sum(mb.mass * jnp.min(reduced, axis=1))


def _facet_level(mb: _Member, received):
    """``(K,)`` ``c_j * l_s(j)`` with ``l_s`` the facet's mean fill ``sum r / sum c`` (0 off facets)."""
    cap = mb.capacity @ mb.onehot
    level = (received @ mb.onehot) / jnp.where(cap > 0, cap, 1)
    return mb.capacity * (mb.onehot @ level)


def _uniformize(mb: _Member, g, eps):
    """The KL projection of each facet's column sums onto ``{c_j l}`` (a Sinkhorn step).

    ``log l`` is the c-weighted mean of ``log(r_j / c_j)``, so ``sum c_j g_j``
    is unchanged; computed in the log domain so that bins no point reaches
    still move.
    """
    logits = _logits(mb, g, eps)
    log_rows = jnp.log(jnp.where(mb.mass > 0, mb.mass, 1)) - jax.nn.logsumexp(logits, axis=1)
    log_r = jax.nn.logsumexp(jnp.where(mb.mass[:, None] > 0, logits + log_rows[:, None], -jnp.inf), axis=0)
    log_rc = jnp.where(mb.free, log_r - jnp.log(jnp.where(mb.free, mb.capacity, 1)), 0)
    cap = mb.capacity @ mb.onehot
    log_l = ((mb.capacity * log_rc) @ mb.onehot) / jnp.where(cap > 0, cap, 1)
    step = (mb.onehot @ log_l) - log_rc
    return jnp.where(mb.free & jnp.isfinite(step), g + eps * step, g)


def _newton_direction(mb: _Member, g, eps, ridge: float):
    """``(direction, gradient)``: the KKT step of ``Phi`` keeping ``sum_{j in s} c_j g_j`` fixed."""
    plan = _entropic_plan(mb, g, eps)
    received = plan.sum(axis=0)
    grad = jnp.where(mb.free, received, 0)
    pi = jnp.where(mb.mass[:, None] > 0, plan / jnp.where(mb.mass > 0, mb.mass, 1)[:, None], 0)
    hess = (jnp.diag(received) - pi.T @ plan) / eps
    both = mb.free[:, None] & mb.free[None, :]
    # A bin no point reaches has a zero row: a ridge of the curvature it has
    # once it holds its share keeps the system definite and its step ~eps/ridge.
    floor = ridge * _facet_level(mb, received) / eps + jnp.finfo(hess.dtype).tiny / eps
    hess = jnp.where(both, hess, 0) + jnp.diag(jnp.where(mb.free, floor, 1))
    a = (mb.capacity[:, None] * mb.onehot).T  # (S, K)
    solved = spd_solve(hess, jnp.concatenate([grad[:, None], a.T], axis=1))
    h_grad, h_a = solved[:, 0], solved[:, 1:]  # H^-1 grad, H^-1 A^T (K, S)
    schur = a @ h_a
    unused = jnp.diagonal(schur) <= 0
    schur = schur + jnp.diag(jnp.where(unused, 1, 0))
    nu = jnp.linalg.solve(schur, -(a @ h_grad))
    direction = -(h_grad + h_a @ nu)
    return jnp.where(mb.free, direction, 0), grad


def _line_search(mb: _Member, g, eps, direction, grad, backtracks: int):
    """Largest ``t`` in ``1, 1/2, ...`` with ``Phi(g + t d) <= Phi(g) + t/4 grad.d``; 0 if none."""
    phi0 = _objective(mb, g, eps)
    slope = jnp.dot(grad, direction)

    def not_done(carry):
        t, ok, k = carry
        return (~ok) & (k < backtracks)

    def halve(carry):
        t, _, k = carry
        t = t * 0.5
        return t, _objective(mb, g + t * direction, eps) <= phi0 + 0.25 * t * slope, k + 1

    ok0 = _objective(mb, g + direction, eps) <= phi0 + 0.25 * slope
    t, ok, _ = jax.lax.while_loop(not_done, halve, (jnp.ones_like(eps), ok0, 0))
    return jnp.where(ok & (slope < 0), t, 0)


def _member(problem: TransportLP, dtype) -> _Member:
    live = problem.bin_mask.any()
    # A member without bins runs on a stand-in bin (it is flagged infeasible).
    real = problem.bin_mask | ((~live) & (jnp.arange(problem.bin_mask.shape[0]) == 0))
    free = real & ~problem.is_vertex
    n_s = problem.simplex_mask.shape[0]
    onehot = ((problem.simplex[:, None] == jnp.arange(n_s)[None, :]) & free[:, None]).astype(dtype)
    return _Member(cost=jnp.where(real[None, :] & problem.point_mask[:, None], problem.cost, 0).astype(dtype),
                   mass=jnp.where(problem.point_mask, problem.mass, 0).astype(dtype),
                   capacity=jnp.where(free, problem.capacity, 0).astype(dtype), real=real, free=free,
                   vertex=real & problem.is_vertex, onehot=onehot)


def _cost_spread(mb: _Member):
    """Mass-weighted mean over points of ``mean_j C_ij - min_j C_ij`` (the scale of ``eps``)."""
    n_real = jnp.maximum(mb.real.sum(), 1)
    mean = jnp.sum(jnp.where(mb.real[None, :], mb.cost, 0), axis=1) / n_real
    low = jnp.min(jnp.where(mb.real[None, :], mb.cost, jnp.inf), axis=1)
    total = jnp.maximum(mb.mass.sum(), jnp.finfo(mb.mass.dtype).tiny)
    spread = jnp.sum(mb.mass * (mean - low)) / total
    return jnp.maximum(spread, jnp.finfo(mb.mass.dtype).eps * jnp.maximum(jnp.max(mean), 1e-30))


def _init_state(mb: _Member, options: NewtonOptions) -> _State:
    zeros = jnp.zeros_like(mb.capacity)
    spread = _cost_spread(mb)
    eps0 = options.eps_start * spread
    inf = jnp.asarray(jnp.inf, mb.cost.dtype)
    return _State(zeros, eps0, inf, zeros, eps0, -inf, options.eps_floor * spread)


def _step(mb: _Member, st: _State, options: NewtonOptions) -> _State:
    """Bounds at ``g``, then ``eps`` lowered if ``g`` solves it, a Sinkhorn step and a Newton step."""
    plan = _entropic_plan(mb, st.g, st.eps)
    ub = jnp.sum(_round(mb, plan) * mb.cost)
    lb = _lower_bound(mb, st.g)
    better = ub < st.best_ub
    best_ub = jnp.where(better, ub, st.best_ub)
    best_lb = jnp.maximum(st.best_lb, jnp.where(jnp.isfinite(lb), lb, -jnp.inf))
    done = best_ub - best_lb <= options.rtol * best_ub + options.atol
    received = plan.sum(axis=0)
    off = jnp.max(jnp.where(mb.free, jnp.abs(received - _facet_level(mb, received)), 0))
    solved = off <= options.uniformity * jnp.sum(mb.mass)
    eps = jnp.where(done | ~solved, st.eps, jnp.maximum(st.eps * options.decay, st.eps_min))
    g = _uniformize(mb, st.g, eps)
    direction, grad = _newton_direction(mb, g, eps, options.ridge)
    t = _line_search(mb, g, eps, direction, grad, options.backtracks)
    g = jnp.where(jnp.all(jnp.isfinite(direction)), g + t * direction, g)
    return _State(g, eps, best_ub, jnp.where(better, st.g, st.best_g), jnp.where(better, st.eps, st.best_eps),
                  best_lb, st.eps_min)


def _solve_one(problem: TransportLP, options: NewtonOptions, dtype) -> LPSolution:
    mb = _member(problem, dtype)
    st = jax.lax.fori_loop(0, options.steps, lambda _, st: _step(mb, st, options), _init_state(mb, options))
    # The last step's point has not been rounded yet.
    last = _round(mb, _entropic_plan(mb, st.g, st.eps))
    last_ub = jnp.sum(last * mb.cost)
    plan = jnp.where(last_ub <= st.best_ub, last, _round(mb, _entropic_plan(mb, st.best_g, st.best_eps)))
    lb = jnp.maximum(st.best_lb, _lower_bound(mb, st.g))
    return _summary(mb, problem, plan, lb, options)


def _summary(mb: _Member, problem: TransportLP, plan, lb, options: NewtonOptions) -> LPSolution:
    live = problem.bin_mask.any()
    infeasible = (~live) & jnp.any(mb.mass > 0)
    plan = jnp.where(problem.bin_mask[None, :] & problem.point_mask[:, None], plan, 0)
    cost = jnp.sum(plan * mb.cost)
    received = plan.sum(axis=0)
    n_s = problem.simplex_mask.shape[0]
    all_of = (problem.simplex[:, None] == jnp.arange(n_s)[None, :]) & problem.bin_mask[:, None]
    simplex_mass = received @ all_of.astype(plan.dtype)
    cap = mb.capacity @ mb.onehot
    density = jnp.where(cap > 0, (received @ mb.onehot) / jnp.where(cap > 0, cap, 1), 0)
    total = jnp.maximum(mb.mass.sum(), jnp.finfo(plan.dtype).tiny)
    row_err = jnp.max(jnp.abs(plan.sum(axis=1) - mb.mass))
    col_err = jnp.max(jnp.where(mb.free, jnp.abs(received - mb.capacity * (mb.onehot @ density)), 0))
    violation = jnp.maximum(row_err, col_err) / total
    lb = jnp.minimum(lb, cost)
    ok = (cost - lb <= options.rtol * cost + options.atol) & (violation <= options.rtol)
    finite = jnp.isfinite(cost) & jnp.all(jnp.isfinite(plan))
    status = jnp.where(infeasible, INFEASIBLE, jnp.where(~finite, FAILED, jnp.where(ok, CONVERGED, ITERATION_LIMIT)))
    return LPSolution(plan=plan, simplex_mass=simplex_mass, density=density, cost=cost, lower_bound=lb,
                      violation=violation, status=status.astype(jnp.int8))


@functools.partial(jax.jit, static_argnames=("options", "dtype"))
def _solve_jit(problem: TransportLP, options: NewtonOptions, dtype) -> LPSolution:
    return jax.vmap(lambda member: _solve_one(member, options, dtype))(problem)


def require_float64(dtype) -> None:
    """Raises a ``RuntimeError`` when float64 is asked for while JAX's x64 mode is off.

    JAX would otherwise narrow the inputs to float32 without a word.
    """
    if np.dtype(dtype) == np.float64 and jax.dtypes.canonicalize_dtype(np.float64) != np.float64:
        raise RuntimeError("the batched LP solver in float64 needs JAX's x64 mode: run it inside "
                           "`with jax.enable_x64(True):` or pass dtype=np.float32")


def solve_batched(problem: TransportLP, options: NewtonOptions = NewtonOptions(), dtype=np.float64) -> LPSolution:
    """Solves every member of a padded batch with a fixed Newton budget (JAX arrays out).

    Args:
      problem: the padded batch (NumPy or JAX arrays).
      options: step budget and tolerances (static: a new value compiles anew).
      dtype: float dtype of the computation (float64 needs JAX's x64 mode).

    Returns:
      An :class:`LPSolution`: exactly feasible plans (up to rounding) whose
      cost is an upper bound, a certified lower bound, and a status per member
      (:data:`CONVERGED` when the gap is within tolerance). Nothing raises
      inside: failures are statuses.

    Example:
      >>> from otjax.lp.problem import LocalLP, pack
      >>> lp = LocalLP(np.array([[4.0, 1.0]]), np.ones(1), np.array([0.0, 1.0]),
      ...              np.array([0, 1]), np.array([True, False]))
      >>> with jax.enable_x64(True):
      ...     float(solve_batched(pack([lp])).cost[0])
      1.0
    """
    require_float64(dtype)
    dtype = np.dtype(dtype)
    problem = TransportLP(*(a.astype(dtype) if a.dtype.kind == "f" else a for a in map(jnp.asarray, problem)))
    return _solve_jit(problem, options, dtype)
