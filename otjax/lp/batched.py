"""The batched solver: damped Newton on the entropic semi-dual, jit + vmap.

For one member, with facet-bin potentials ``g`` (vertex bins fixed at 0),
each point's row of the entropic plan is a softmax::

    x_ij = m_i softmax_j((g_j - C_ij) / eps)

so row sums are exact by construction, and minimising the convex
``Phi(g) = eps sum_i m_i logsumexp_j((g_j - C_ij) / eps)`` under one linear
constraint per facet, ``sum_{j in s} c_j g_j = 0``, makes each facet's column
sums proportional to its capacities (the constraint's multiplier is ``l_s``).

A step: bounds at ``g`` (the plan rounded to an exactly feasible one, an
upper bound; the dual value of ``g``, a lower bound; the best of each is
kept); a Sinkhorn step (the closed-form KL projection of each facet's
columns, which moves bins no point reaches yet); ``eps`` lowered if ``g``
solved the current one; a Newton step in the null space of the facet
constraints with Armijo backtracking. A member is done when its certified
gap is within tolerance; the loop stops when every member is done or the
step budget is spent (a fixed budget: under ``vmap`` an open-ended loop
would run as long as its slowest member). Why this solver and its
constants: ``docs/decisions.md#lp_solver``.
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
    """Settings of :func:`solve_batched` (``docs/decisions.md#lp_solver``); all but
    ``steps`` are static, so a new value of one compiles the solver anew.

    Attributes:
      steps: at most this many steps per member (a fixed budget).
      rtol: a member converges when ``cost - lower_bound <= rtol * cost + atol``.
      atol: absolute gap tolerance, in cost units times mass.
      eps_start: first ``eps``, relative to the member's cost spread (the
        mass-weighted mean over points of ``mean_j C_ij - min_j C_ij``).
      decay: factor on ``eps`` once the current one is solved.
      uniformity: ``eps`` counts as solved once every facet bin's column sum
        is within this fraction of the member's mass of ``c_j l_s``.
      eps_floor: smallest ``eps``, relative to the cost spread.
      ridge: curvature added to a facet bin, relative to the curvature
        ``c_j l_s / eps`` it has at its share.
      backtracks: at most this many halvings of a step in the line search.
      predict: start each ``eps`` from ``g`` extrapolated linearly in ``eps``.
      chunk: a batch larger than this (and a multiple of it) is solved in
        chunks of this many members, one after the other (0: never).
    """

    steps: int = 48
    rtol: float = 1e-3
    atol: float = 0.0
    eps_start: float = 0.1
    decay: float = 0.3
    uniformity: float = 1e-6
    eps_floor: float = 1e-9
    ridge: float = 1e-6
    backtracks: int = 12
    predict: bool = True
    chunk: int = 16


class _Member(NamedTuple):
    """One member's arrays inside the solver (no batch axis)."""

    cost: jax.Array  # (P, K); 0 on padding
    mass: jax.Array  # (P,); 0 on padding
    capacity: jax.Array  # (K,); c_j on facet bins, 0 elsewhere
    real: jax.Array  # (K,) bool: bins a point may use
    free: jax.Array  # (K,) bool: facet bins (their potential moves)
    onehot: jax.Array  # (K, S): facet bin j belongs to facet s
    sink: jax.Array  # (P, K): where a unit of point i's rounding deficit goes
    sink_cost: jax.Array  # (P,): its cost


class _State(NamedTuple):
    g: jax.Array  # (K,) potentials, sum_{j in s} c_j g_j = 0
    eps: jax.Array  # () current regularisation
    eps_min: jax.Array  # () its floor
    best_ub: jax.Array  # () cost of the best rounded plan so far
    best_g: jax.Array  # (K,) the potentials it was rounded from
    best_eps: jax.Array  # () and their eps
    best_lb: jax.Array  # () best dual value so far
    done: jax.Array  # () bool: certified within tolerance
    steps: jax.Array  # () int32: steps taken before done
    g_prev: jax.Array  # (K,) g when the previous eps was solved
    eps_prev: jax.Array  # () that eps (0: none yet)


def _member(problem: TransportLP, dtype) -> _Member:
    live = problem.bin_mask.any()
    # A member without bins runs on a stand-in bin (it is flagged infeasible).
    real = problem.bin_mask | ((~live) & (jnp.arange(problem.bin_mask.shape[0]) == 0))
    free = real & ~problem.is_vertex
    vertex = real & problem.is_vertex
    n_s = problem.simplex_mask.shape[0]
    onehot = ((problem.simplex[:, None] == jnp.arange(n_s)[None, :]) & free[:, None]).astype(dtype)
    cost = jnp.where(real[None, :] & problem.point_mask[:, None], problem.cost, 0).astype(dtype)
    capacity = jnp.where(free, problem.capacity, 0).astype(dtype)
    # A deficit goes to the cheaper of the nearest vertex bin and the facet
    # of least mean cost, spread by capacity (which keeps the facet uniform).
    cap_of = capacity[:, None] * onehot
    total = cap_of.sum(axis=0)
    spread = cap_of / jnp.where(total > 0, total, 1)
    facet_cost = jnp.where(total > 0, cost @ spread, jnp.inf)  # (P, S)
    vertex_cost = jnp.where(vertex[None, :], cost, jnp.inf)  # (P, K)
    to_vertex = jnp.min(vertex_cost, axis=1) <= jnp.min(facet_cost, axis=1)
    vertex_pick = jax.nn.one_hot(jnp.argmin(vertex_cost, axis=1), cost.shape[1], dtype=dtype)
    facet_pick = jax.nn.one_hot(jnp.argmin(facet_cost, axis=1), n_s, dtype=dtype) @ spread.T
    sink = jnp.where(to_vertex[:, None], vertex_pick, facet_pick)
    return _Member(cost=cost, mass=jnp.where(problem.point_mask, problem.mass, 0).astype(dtype),
                   capacity=capacity, real=real, free=free, onehot=onehot, sink=sink,
                   sink_cost=jnp.sum(sink * cost, axis=1))


def _cost_spread(mb: _Member):
    """Mass-weighted mean over points of ``mean_j C_ij - min_j C_ij`` (the scale of ``eps``)."""
    mean = jnp.sum(jnp.where(mb.real[None, :], mb.cost, 0), axis=1) / jnp.maximum(mb.real.sum(), 1)
    low = jnp.min(jnp.where(mb.real[None, :], mb.cost, jnp.inf), axis=1)
    total = jnp.maximum(mb.mass.sum(), jnp.finfo(mb.mass.dtype).tiny)
    spread = jnp.sum(mb.mass * (mean - low)) / total
    return jnp.maximum(spread, jnp.finfo(mb.mass.dtype).eps * jnp.maximum(jnp.max(mean), 1e-30))


def _logits(mb: _Member, g, eps):
    return jnp.where(mb.real[None, :], (g[None, :] - mb.cost) / eps, -jnp.inf)


def _objective(mb: _Member, g, eps):
    """``Phi(g)``: the entropic semi-dual, to minimise."""
    return eps * jnp.sum(mb.mass * jax.nn.logsumexp(_logits(mb, g, eps), axis=1))


class _Plan(NamedTuple):
    plan: jax.Array  # (P, K) entropic plan, rows summing to m_i
    logits: jax.Array  # (P, K)
    log_norm: jax.Array  # (P,) logsumexp of each row's logits


def _entropic_plan(mb: _Member, g, eps) -> _Plan:
    logits = _logits(mb, g, eps)
    top = jnp.max(logits, axis=1, keepdims=True)
    shifted = logits - top
    # Weights below the cut are zeroed: products of two of them would be
    # subnormal, which the CPU handles ~100x slower (and they carry no mass).
    cut = 0.4 * np.log(jnp.finfo(logits.dtype).tiny)
    w = jnp.where(shifted > cut, jnp.exp(jnp.maximum(shifted, cut)), 0)
    norm = jnp.sum(w, axis=1, keepdims=True)
    return _Plan(mb.mass[:, None] * (w / norm), logits, (top + jnp.log(norm))[:, 0])


def _facet_level(mb: _Member, received):
    """``(K,)`` ``c_j * l_s(j)`` with ``l_s = sum r / sum c`` over the facet (0 off facets)."""
    cap = mb.capacity @ mb.onehot
    return mb.capacity * (mb.onehot @ ((received @ mb.onehot) / jnp.where(cap > 0, cap, 1)))


def _scaled(mb: _Member, plan):
    """``plan`` scaled down to rows ``<= m_i`` and uniform facets ``l_s = min_k r_k / c_k``."""
    rows = plan.sum(axis=1)
    plan = plan * jnp.where(rows > mb.mass, mb.mass / jnp.where(rows > 0, rows, 1), 1)[:, None]
    received = plan.sum(axis=0)
    ratio = jnp.where(mb.free, received / jnp.where(mb.free, mb.capacity, 1), jnp.inf)
    level = jnp.min(jnp.where(mb.onehot > 0, ratio[:, None], jnp.inf), axis=0)  # (S,)
    want = mb.capacity * (mb.onehot @ jnp.where(jnp.isfinite(level), level, 0))
    return plan * jnp.where(mb.free, want / jnp.where(received > 0, received, 1), 1)[None, :]


def _round(mb: _Member, plan):
    """An exactly feasible plan from an approximate one: :func:`_scaled`, then
    each point's deficit to its sink. Works without vertex bins."""
    plan = _scaled(mb, plan)
    return plan + jnp.maximum(mb.mass - plan.sum(axis=1), 0)[:, None] * mb.sink


def _rounded_cost(mb: _Member, plan):
    """The cost of :func:`_round` without building it: an upper bound on the optimum."""
    plan = _scaled(mb, plan)
    return jnp.sum(plan * mb.cost) + jnp.sum(jnp.maximum(mb.mass - plan.sum(axis=1), 0) * mb.sink_cost)


def _lower_bound(mb: _Member, g):
    """A feasible LP dual value: ``g`` shifted per facet to ``sum c g = 0``, then its c-transform."""
    cap_of = mb.capacity[:, None] * mb.onehot
    total = jnp.where(cap_of.sum(axis=0) > 0, cap_of.sum(axis=0), 1)
    gf = jnp.where(mb.free, g - mb.onehot @ ((g @ cap_of) / total), 0)
    reduced = jnp.where(mb.real[None, :], mb.cost - gf[None, :], jnp.inf)
    return jnp.sum(mb.mass * jnp.min(reduced, axis=1))


def _uniformize(mb: _Member, g, eps, ep: _Plan):
    """The KL projection of each facet's column sums onto ``{c_j l}`` (a Sinkhorn step).

    ``log l`` is the c-weighted mean of ``log(r_j / c_j)``, so ``sum c_j g_j``
    is unchanged. A bin whose mass fell under the plan's cut uses its largest
    term instead (a lower bound of ``log r_j``), so it still moves.
    """
    received = ep.plan.sum(axis=0)
    log_m = jnp.log(jnp.where(mb.mass > 0, mb.mass, 1))
    terms = jnp.where(mb.mass[:, None] > 0, ep.logits - ep.log_norm[:, None] + log_m[:, None], -jnp.inf)
    tiny = jnp.finfo(received.dtype).tiny
    log_r = jnp.where(received > tiny, jnp.log(jnp.maximum(received, tiny)), jnp.max(terms, axis=0))
    log_rc = jnp.where(mb.free, log_r - jnp.log(jnp.where(mb.free, mb.capacity, 1)), 0)
    cap = mb.capacity @ mb.onehot
    log_l = ((mb.capacity * log_rc) @ mb.onehot) / jnp.where(cap > 0, cap, 1)
    step = mb.onehot @ log_l - log_rc
    return jnp.where(mb.free & jnp.isfinite(step), g + eps * step, g)


def _newton_direction(mb: _Member, eps, ep: _Plan, ridge: float):
    """``(direction, gradient)``: the Newton step of ``Phi`` in the null space of the facet constraints.

    With ``W`` the facets' normalised capacity vectors (orthonormal: facets
    share no bin) and ``P = I - W W^T``, it solves
    ``(P H P + h W W^T) d = -P grad``: the ``W`` part of ``d`` vanishes, so
    ``sum_{j in s} c_j d_j = 0``, and one SPD solve replaces the KKT system.
    """
    received = ep.plan.sum(axis=0)
    grad = jnp.where(mb.free, received, 0)
    pi = ep.plan / jnp.where(mb.mass > 0, mb.mass, 1)[:, None]
    hess = (jnp.diag(received) - pi.T @ ep.plan) / eps
    both = mb.free[:, None] & mb.free[None, :]
    # A bin no point reaches has a zero row: a ridge of the curvature it has
    # at its share keeps the system definite and its step near eps / ridge.
    floor = (ridge * _facet_level(mb, received) + jnp.finfo(hess.dtype).tiny) / eps
    hess = jnp.where(both, hess, 0) + jnp.diag(jnp.where(mb.free, floor, 1))
    w = mb.capacity[:, None] * mb.onehot
    w = w / jnp.sqrt(jnp.maximum(jnp.sum(w * w, axis=0), jnp.finfo(w.dtype).tiny))  # (K, S)
    ph = hess - w @ (w.T @ hess)
    php = ph - (ph @ w) @ w.T
    scale = jnp.max(jnp.diagonal(hess))
    system = php + scale * (w @ w.T)
    projected = grad - w @ (w.T @ grad)
    direction = spd_solve(system, -projected[:, None])[:, 0]
    return jnp.where(mb.free, direction, 0), grad


def _line_search(mb: _Member, g, eps, phi0, direction, grad, backtracks: int):
    """Largest ``t`` in ``1, 1/2, ...`` with ``Phi(g + t d) <= Phi(g) + t/4 grad.d``; 0 if none.

    The test allows ``Phi``'s rounding error: near the optimum the decrease
    falls below it, and a strict test would stop the quadratic convergence.
    """
    slope = jnp.dot(grad, direction)
    phi0 = phi0 + 16 * jnp.finfo(phi0.dtype).eps * jnp.abs(phi0)

    def not_done(carry):
        _, ok, k = carry
        return (~ok) & (k < backtracks)

    def halve(carry):
        t, _, k = carry
        t = t * 0.5
        return t, _objective(mb, g + t * direction, eps) <= phi0 + 0.25 * t * slope, k + 1

    ok0 = _objective(mb, g + direction, eps) <= phi0 + 0.25 * slope
    t, ok, _ = jax.lax.while_loop(not_done, halve, (jnp.ones_like(eps), ok0, 0))
    return jnp.where(ok & (slope < 0), t, 0)


def _init_state(mb: _Member, options: NewtonOptions) -> _State:
    zeros = jnp.zeros_like(mb.capacity)
    spread = _cost_spread(mb)
    eps0 = options.eps_start * spread
    inf = jnp.asarray(jnp.inf, mb.cost.dtype)
    return _State(zeros, eps0, options.eps_floor * spread, inf, zeros, eps0, -inf, jnp.asarray(False),
                  jnp.asarray(0, jnp.int32), zeros, jnp.zeros_like(eps0))


def _step(mb: _Member, st: _State, options: NewtonOptions) -> _State:
    """One step (see the module docstring); a member already done keeps its state."""
    ep = _entropic_plan(mb, st.g, st.eps)
    ub = _rounded_cost(mb, ep.plan)
    lb = _lower_bound(mb, st.g)
    better = ub < st.best_ub
    best_ub = jnp.where(better, ub, st.best_ub)
    best_lb = jnp.maximum(st.best_lb, jnp.where(jnp.isfinite(lb), lb, -jnp.inf))
    done = best_ub - best_lb <= options.rtol * best_ub + options.atol
    received = ep.plan.sum(axis=0)
    off = jnp.max(jnp.where(mb.free, jnp.abs(received - _facet_level(mb, received)), 0))
    solved = off <= options.uniformity * jnp.sum(mb.mass)
    g = _uniformize(mb, st.g, st.eps, ep)
    lower = solved & ~done
    eps = jnp.where(lower, jnp.maximum(st.eps * options.decay, st.eps_min), st.eps)
    # Continuation: extrapolate g linearly in eps from the last two solved levels.
    known = st.eps_prev > st.eps
    slope = jnp.where(known, (g - st.g_prev) / jnp.where(known, st.eps_prev - st.eps, 1), 0)
    g_prev, eps_prev = jnp.where(lower, g, st.g_prev), jnp.where(lower, st.eps, st.eps_prev)
    if options.predict:
        g = jnp.where(lower, g + (st.eps - eps) * slope, g)
    ep = _entropic_plan(mb, g, eps)
    direction, grad = _newton_direction(mb, eps, ep, options.ridge)
    phi0 = eps * jnp.sum(mb.mass * ep.log_norm)
    t = _line_search(mb, g, eps, phi0, direction, grad, options.backtracks)
    g = jnp.where(jnp.all(jnp.isfinite(direction)), g + t * direction, g)
    new = _State(g, eps, st.eps_min, best_ub, jnp.where(better, st.g, st.best_g),
                 jnp.where(better, st.eps, st.best_eps), best_lb, done, st.steps + (~done).astype(jnp.int32),
                 g_prev, eps_prev)
    return jax.tree.map(lambda old, upd: jnp.where(st.done, old, upd), st, new)


def _finish(mb: _Member, problem: TransportLP, st: _State, options: NewtonOptions) -> LPSolution:
    """The best rounded plan (the last step's point included), its totals and status."""
    last = _entropic_plan(mb, st.g, st.eps).plan
    use_last = _rounded_cost(mb, last) <= st.best_ub
    g, eps = jnp.where(use_last, st.g, st.best_g), jnp.where(use_last, st.eps, st.best_eps)
    plan = _round(mb, _entropic_plan(mb, g, eps).plan)
    plan = jnp.where(problem.bin_mask[None, :] & problem.point_mask[:, None], plan, 0)
    lb = jnp.maximum(st.best_lb, _lower_bound(mb, st.g))
    cost = jnp.sum(plan * mb.cost)
    received = plan.sum(axis=0)
    n_s = problem.simplex_mask.shape[0]
    of_simplex = (problem.simplex[:, None] == jnp.arange(n_s)[None, :]) & problem.bin_mask[:, None]
    cap = mb.capacity @ mb.onehot
    density = jnp.where(cap > 0, (received @ mb.onehot) / jnp.where(cap > 0, cap, 1), 0)
    total = jnp.maximum(mb.mass.sum(), jnp.finfo(plan.dtype).tiny)
    row_err = jnp.max(jnp.abs(plan.sum(axis=1) - mb.mass))
    col_err = jnp.max(jnp.where(mb.free, jnp.abs(received - mb.capacity * (mb.onehot @ density)), 0))
    violation = jnp.maximum(row_err, col_err) / total
    lb = jnp.minimum(lb, cost)
    ok = (cost - lb <= options.rtol * cost + options.atol) & (violation <= options.rtol)
    infeasible = (~problem.bin_mask.any()) & jnp.any(mb.mass > 0)
    finite = jnp.isfinite(cost) & jnp.all(jnp.isfinite(plan))
    status = jnp.where(ok, CONVERGED, ITERATION_LIMIT)
    status = jnp.where(infeasible, INFEASIBLE, jnp.where(finite, status, FAILED)).astype(jnp.int8)
    return LPSolution(plan=plan, simplex_mass=received @ of_simplex.astype(plan.dtype), density=density,
                      cost=cost, lower_bound=lb, violation=violation, status=status, iterations=st.steps)


@functools.partial(jax.jit, static_argnames=("options", "dtype"))
def _solve_jit(problem: TransportLP, steps, options: NewtonOptions, dtype) -> LPSolution:
    b, c = problem.cost.shape[0], options.chunk
    if not c or b <= c or b % c:
        return _solve_chunk(problem, steps, options, dtype)
    # Chunks run one after the other, each until its own members are done:
    # a chunk's arrays stay in cache and a slow member holds back c others, not b.
    chunks = jax.tree.map(lambda a: a.reshape(b // c, c, *a.shape[1:]), problem)
    out = jax.lax.map(lambda p: _solve_chunk(p, steps, options, dtype), chunks)
    return jax.tree.map(lambda a: a.reshape(b, *a.shape[2:]), out)


def _solve_chunk(problem: TransportLP, steps, options: NewtonOptions, dtype) -> LPSolution:
    members = jax.vmap(lambda p: _member(p, dtype))(problem)
    state = jax.vmap(lambda mb: _init_state(mb, options))(members)
    step = jax.vmap(lambda mb, st: _step(mb, st, options))

    def more(carry):
        k, st = carry
        return (k < steps) & ~jnp.all(st.done)

    _, state = jax.lax.while_loop(more, lambda c: (c[0] + 1, step(members, c[1])), (0, state))
    return jax.vmap(lambda mb, p, st: _finish(mb, p, st, options))(members, problem, state)


def require_float64(dtype) -> None:
    """Raises a ``RuntimeError`` when float64 is asked for while JAX's x64 mode is off.

    JAX would otherwise narrow the inputs to float32 without a word.
    """
    if np.dtype(dtype) == np.float64 and jax.dtypes.canonicalize_dtype(np.float64) != np.float64:
        raise RuntimeError("the batched LP solver in float64 needs JAX's x64 mode: run it inside "
                           "`with jax.enable_x64(True):` or pass dtype=np.float32")


def solve_batched(problem: TransportLP, options: NewtonOptions = NewtonOptions(),
                  dtype=np.float64) -> LPSolution:
    """Solves every member of a padded batch within a fixed step budget (JAX arrays out).

    Args:
      problem: the padded batch (NumPy or JAX arrays).
      options: step budget and tolerances (a new value other than ``steps``
        compiles anew).
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
      ...     sol = solve_batched(pack([lp]))
      >>> round(float(sol.cost[0]), 6), int(sol.status[0]) == CONVERGED
      (1.0, True)
    """
    require_float64(dtype)
    dtype = np.dtype(dtype)
    problem = TransportLP(*(a.astype(dtype) if a.dtype.kind == "f" else a
                            for a in map(jnp.asarray, problem)))
    # The budget is traced, not static: changing it does not compile anew.
    return _solve_jit(problem, jnp.asarray(options.steps, jnp.int32), options._replace(steps=0), dtype)
