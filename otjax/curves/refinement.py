"""Gradient refinement of the vertex positions with the assignment held fixed.

With the point-to-edge assignment frozen, the transport cost is a smooth
function of the vertex positions (:func:`otjax.curves.cost.fixed_assignment_cost`);
:func:`refine` minimises it by L-BFGS over every free vertex and keeps the
result only if the exact cost, every point reassigned, goes down.
:func:`minimize_lbfgs` is the one place otjax calls jaxopt.
"""

from __future__ import annotations

import functools
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from otjax.batch.pipeline import require_x64
from otjax.curves.cost import fixed_assignment_cost
from otjax.curves.engine import CurveEngine


@functools.cache
def _lbfgs(fun, maxiter: int, tol: float):
    """Jitted ``(init_state, update)`` of a jaxopt L-BFGS for ``fun``, built once.

    A solver made per call (with a closure as ``fun``) is a new function to
    ``jax.jit`` every time: each refinement recompiled, 3-10 s on CPU.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="jaxopt is no longer maintained")
        import jaxopt

    solver = jaxopt.LBFGS(fun=fun, maxiter=maxiter, tol=tol)
    return jax.jit(solver.init_state), jax.jit(solver.update)


def minimize_lbfgs(fun, x0, maxiter: int = 100, tol: float = 1e-10, args: tuple = ()):
    """Minimises ``fun`` from ``x0`` with L-BFGS; the one place otjax calls jaxopt.

    jaxopt works with current JAX but is no longer maintained; replacing it
    (e.g. by optax's L-BFGS) means replacing this function only.

    Args:
      fun: scalar JAX function ``fun(x, *args)``. Pass data through ``args``
        rather than closing over it: the compiled solver is cached per
        ``fun`` (and shapes), so a module-level ``fun`` compiles once.
      x0: starting point.
      maxiter: iteration limit.
      tol: stop when the gradient norm falls below it.
      args: extra arguments of ``fun``.

    Returns:
      ``(x, values)``: the final point and the objective after each
      iteration (``values[0]`` at ``x0``).
    """
    init, update = _lbfgs(fun, maxiter, tol)
    state = init(x0, *args)
    x = x0
    values = [float(state.value)]
    for _ in range(maxiter):
        x, state = update(x, state, *args)
        values.append(float(state.value))
        if float(state.error) <= tol:
            break
    return x, values


def _refine_objective(x, base, free, edge_index, points, mass, point_edge):
    return fixed_assignment_cost(base.at[free].set(x), edge_index, points, mass, point_edge)


def refine(engine: CurveEngine, maxiter: int = 100, max_halvings: int = 6) -> tuple[CurveEngine, dict]:
    """Gradient refinement of all vertex positions with the assignment fixed.

    Minimises :func:`otjax.curves.cost.fixed_assignment_cost` over the free
    vertices by L-BFGS, then walks from the start towards that minimiser:
    the largest step ``2^-k`` that keeps the triangulation embedded (exact
    orientation of every triangle) and lowers the exact cost after every
    point is reassigned from scratch is kept. Otherwise nothing changes, so
    refinement never makes a reconstruction worse.

    Args:
      engine: the current :class:`~otjax.curves.engine.CurveEngine` (its
        triangulation is moved in place if accepted).
      maxiter: L-BFGS iterations.
      max_halvings: steps tried: ``1, 1/2, ..., 2^-(max_halvings-1)``.

    Returns:
      ``(engine, info)``: a new engine over the moved triangulation (or the
        old one, unchanged) and a dict
      with ``accepted``, ``cost_before``, ``cost_after``, ``step`` (backtracking
      factor) and ``values`` (objective per iteration).
    """
    plan = engine.plan
    tri = plan.tri
    nv = len(tri.xy)
    code = plan.pt_edge[:, 0] * nv + plan.pt_edge[:, 1]
    uniq, point_edge = np.unique(code, return_inverse=True)
    edge_index = np.stack([uniq // nv, uniq % nv], 1)
    free = np.nonzero(tri.alive & ~tri.pinned)[0]
    v0 = tri.xy.copy()
    before = plan.total_cost()
    info = {"accepted": False, "cost_before": before, "cost_after": before, "step": 0.0, "values": []}
    if not len(free):
        return engine, info
    require_x64("refine")
    data = (jnp.asarray(v0), jnp.asarray(free), jnp.asarray(edge_index), jnp.asarray(plan.points),
            jnp.asarray(plan.mass), jnp.asarray(point_edge))
    x, values = minimize_lbfgs(_refine_objective, jnp.asarray(v0[free]), maxiter=maxiter, args=data)
    x = np.asarray(x)
    info["values"] = values
    # The nearest-edge reassignment can undo part of the gain (a point that
    # moves onto a ghost edge pays its vertex distance), so the step is
    # backtracked on the exact cost after reassignment, not on the objective.
    step = 1.0
    for _ in range(max_halvings):
        trial = v0.copy()
        trial[free] = v0[free] + step * (x - v0[free])
        try:
            tri.set_positions(trial)
        except ValueError:
            step /= 2
            continue
        new = CurveEngine(tri, plan.points, plan.mass, dtype=engine.scorer.pipeline.dtype,
                          max_source_degree=engine.degree_bound, incremental=engine.incremental,
                          update_min_rows=engine.update_min_rows)
        after = new.total_cost()
        if after < before:
            info.update(accepted=True, cost_after=after, step=step)
            return new, info
        step /= 2
    tri.set_positions(v0)
    return engine, info
