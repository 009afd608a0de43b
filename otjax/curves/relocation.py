"""Vertex relocation: the closed form of de Goes et al. 2011 §3.3, and a
gradient refinement with the assignment held fixed.

Both only ever propose positions; a move is applied only when it keeps the
triangulation embedded (the new position is inside the kernel of the one-ring)
and lowers the exact transport cost computed by the batched kernel after
reassigning the points of the star. The paper moves unconditionally (inside
the kernel); otjax also asks for a decrease, because the closed form minimises
only the normal part for a frozen assignment and can, rarely, raise the total.
"""

from __future__ import annotations

import functools

import numpy as np

from otjax.curves.plan import TransportPlan


def optimal_position(plan: TransportPlan, v: int) -> np.ndarray | None:
    """Closed-form position of ``v`` minimising the normal part of its cost.

    With the assignment frozen, the points sent to ``v`` itself (``S_v``, from
    its ghost edges) and those on its solid edges ``(v, b)`` (``S_(v,b)``,
    with ``q_i = (1 - l_i) v + l_i b`` the projection on the supporting line)
    give the quadratic ``sum_Sv m |p - v|^2 + sum m |p - q|^2``, minimised by::

        v* = (sum_Sv m p + sum m (1 - l)(p - l b)) / (M_v + sum m (1 - l)^2)

    Args:
      plan: current transport plan.
      v: an interior (non-pinned, live) vertex.

    Returns:
      ``(2,)`` position, or ``None`` if no point is transported to ``v``'s
      edges or to ``v`` (nothing pins it down).
    """
    tri = plan.tri
    _, star = tri.star(v)
    ids = np.concatenate([plan.face_pts[f] for f in star])
    if not len(ids):
        return None
    keys = np.take(plan.pt_edge, ids, axis=0)
    touch = (keys[:, 0] == v) | (keys[:, 1] == v)
    ids, keys = ids[touch], keys[touch]
    if not len(ids):
        return None
    other = np.where(keys[:, 0] == v, keys[:, 1], keys[:, 0])
    solid = plan.solid_of(keys)
    p, m = np.take(plan.points, ids, axis=0), plan.mass[ids]
    x, b = tri.xy[v], tri.xy[other]
    d = b - x
    lam = np.einsum("ij,ij->i", p - x, d) / np.einsum("ij,ij->i", d, d)
    # Ghost edges send each point to its nearer end: only those nearer v count.
    to_v = ~solid & (np.einsum("ij,ij->i", p - x, p - x) <= np.einsum("ij,ij->i", p - b, p - b))
    w_num = np.where(solid, m * (1 - lam), np.where(to_v, m, 0.0))
    num = np.where(solid[:, None], w_num[:, None] * (p - lam[:, None] * b), w_num[:, None] * p).sum(0)
    den = np.where(solid, m * (1 - lam) ** 2, np.where(to_v, m, 0.0)).sum()
    if not den > 0:
        return None
    return num / den


def relocate(plan: TransportPlan, vertices, admissible=None) -> tuple[set[int], int]:
    """Moves each of ``vertices`` to its closed-form position where that helps.

    Moves of adjacent vertices interact (they share edges), so the work is
    done in rounds: each round exports the relocation stencils of every
    vertex still waiting, scores them in one batched call, and applies the
    improving ones greedily by decreasing gain, skipping any whose stencil a
    move of this round has touched; those wait for the next round. Every
    vertex is considered once.

    Args:
      plan: the transport plan, modified in place.
      vertices: vertex ids (pinned and dead ones are skipped).
      admissible: optional ``(candidate, cost) -> bool`` veto (the
        tolerance mode uses it).

    Returns:
      ``(dirty, moved)``: vertices whose collapse stencils changed, and how
      many vertices moved.
    """
    tri = plan.tri
    waiting = [v for v in dict.fromkeys(vertices) if tri.alive[v] and not tri.pinned[v]]
    dirty: set[int] = set()
    moved = 0
    while waiting:
        moves = [(v, pos) for v, pos in ((v, optimal_position(plan, v)) for v in waiting)
                 if pos is not None and np.all(np.isfinite(pos)) and np.any(pos != tri.xy[v])]
        cands, delta, rows = plan.score_batches(plan.relocation_exports(moves))
        if not cands:
            break
        blocked: set[int] = set()
        done: set[int] = set()
        for i in np.argsort(delta, kind="stable"):
            c = cands[i]
            v = c.plan.source
            if delta[i] >= 0:
                done.add(v)
                continue
            if v in blocked:
                continue
            if admissible is not None and not admissible(c, rows[i]):
                done.add(v)
                continue
            # Stencils that overlap this move are stale: their vertices wait.
            changed = plan.apply(c, rows[i])
            dirty |= changed
            blocked |= changed
            moved += 1
            done.add(v)
        proposed = {c.plan.source for c in cands}
        waiting = [v for v in waiting if v in proposed and v not in done]
    return dirty, moved


@functools.cache
def _lbfgs(fun, maxiter: int, tol: float):
    """Jitted ``(init_state, update)`` of a jaxopt L-BFGS for ``fun``, built once.

    A solver made per call (with a closure as ``fun``) is a new function to
    ``jax.jit`` every time: each refinement recompiled, 3-10 s on CPU.
    """
    import warnings

    import jax

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
    from otjax.curves.cost import fixed_assignment_cost

    return fixed_assignment_cost(base.at[free].set(x), edge_index, points, mass, point_edge)


def refine(plan: TransportPlan, maxiter: int = 100, max_halvings: int = 6) -> tuple[TransportPlan, dict]:
    """Gradient refinement of all vertex positions with the assignment fixed.

    Minimises :func:`otjax.curves.cost.fixed_assignment_cost` over the free
    vertices by L-BFGS, then walks from the start towards that minimiser:
    the largest step ``2^-k`` that keeps the triangulation embedded (exact
    orientation of every triangle) and lowers the exact cost after every
    point is reassigned from scratch is kept. Otherwise nothing changes, so
    refinement never makes a reconstruction worse.

    Args:
      plan: current plan (its triangulation is moved in place if accepted).
      maxiter: L-BFGS iterations.
      max_halvings: steps tried: ``1, 1/2, ..., 2^-(max_halvings-1)``.

    Returns:
      ``(plan, info)``: the new plan (or the old one, unchanged) and a dict
      with ``accepted``, ``cost_before``, ``cost_after``, ``step`` (backtracking
      factor) and ``values`` (objective per iteration).
    """
    import jax
    import jax.numpy as jnp


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
        return plan, info
    with jax.enable_x64(True):
        base = jnp.asarray(v0)

        data = (base, jnp.asarray(free), jnp.asarray(edge_index), jnp.asarray(plan.points),
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
        new = TransportPlan(tri, plan.points, plan.mass, plan.dtype, plan.max_source_degree)
        after = new.total_cost()
        if after < before:
            info.update(accepted=True, cost_after=after, step=step)
            new.n_kernel_calls += plan.n_kernel_calls
            return new, info
        step /= 2
    tri.set_positions(v0)
    return plan, info
