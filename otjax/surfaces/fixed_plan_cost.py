"""The transport cost of a fixed plan as a JAX function of vertex positions (§4.3).

With the masses ``m_ij`` of a plan held fixed, every bin is a fixed
barycentric combination of the vertices of its simplex (a vertex bin is its
vertex), so the cost ``sum m |p - b|^2`` is a convex quadratic in the vertex
positions. This module holds the kernels over it, arrays only:

- :func:`fixed_plan_cost`: the cost;
- :func:`vertex_targets`: per vertex the closed-form minimiser of each
  simplex's share (the paper's ``v*(t)`` and ``v*(v)``) and their average;
- :func:`refine_positions`: a few conjugate-gradient steps on the cost with
  an exact line search, never raising it (the one solver seam of the gradient
  refinement: replacing the method means replacing this function).

Padding: entries of mass 0 contribute zero cost and zero gradient, whatever
their indices (which must still be in range).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp


class FixedPlanEntries(NamedTuple):
    """Plan entries with their bins spelled out in vertex terms (a pytree).

    Attributes:
      point: ``(E,)`` int row of the points array of each entry. Pad 0.
      corners: ``(E, 3)`` int rows of the positions array of the bin's
        simplex: a facet's three vertices, or ``(v, v, v)`` for the bin of
        vertex ``v``. Pad 0.
      barycentric: ``(E, 3)`` float weights of the corners giving the bin
        position (``(1, 0, 0)`` for a vertex bin). Pad 0.
      mass: ``(E,)`` float transported mass, ``>= 0``. Pad 0.
    """

    point: jnp.ndarray
    corners: jnp.ndarray
    barycentric: jnp.ndarray
    mass: jnp.ndarray


class TargetSegments(NamedTuple):
    """How entries group into (vertex, simplex) shares for :func:`vertex_targets`.

    An entry of a facet is listed once for each batch vertex of that facet it
    is relocating; segment ``s`` is one simplex seen from one batch vertex.

    Attributes:
      vertex: ``(E,)`` int row of the positions array of the vertex the entry
        relocates. Pad 0.
      segment: ``(E,)`` int segment of the entry, in ``[0, S)``. Pad 0 (the
        entry's mass is 0).
      row: ``(S,)`` int batch row of each segment's vertex, in ``[0, B)``.
        Pad 0 (the segment is empty).
      row_vertex: ``(B,)`` int row of the positions array of each batch
        vertex. Pad 0 (the row has no segment).
    """

    vertex: jnp.ndarray
    segment: jnp.ndarray
    row: jnp.ndarray
    row_vertex: jnp.ndarray


class VertexTargets(NamedTuple):
    """What :func:`vertex_targets` returns.

    Attributes:
      target: ``(B, 3)`` averaged optimal position of each batch vertex
        (its current position where ``valid`` is False).
      simplex_target: ``(S, 3)`` the minimiser ``v*`` of each segment's share
        alone (0 where the segment has no curvature).
      simplex_mass: ``(S,)`` mass of each segment (``m(t)``, ``m(v)``).
      valid: ``(B,)`` bool, True when some simplex of the vertex carries mass.
    """

    target: jnp.ndarray
    simplex_target: jnp.ndarray
    simplex_mass: jnp.ndarray
    valid: jnp.ndarray


def bin_points(positions: jnp.ndarray, entries: FixedPlanEntries) -> jnp.ndarray:
    """``(E, 3)`` bin position of each entry over ``positions`` ``(V, 3)``."""
    return jnp.einsum("ek,ekd->ed", entries.barycentric, positions[entries.corners])


def fixed_plan_cost(positions: jnp.ndarray, points: jnp.ndarray, entries: FixedPlanEntries) -> jnp.ndarray:
    """``sum_e mass_e |points[point_e] - bin_e(positions)|^2``, a scalar.

    Args:
      positions: ``(V, 3)`` vertex positions.
      points: ``(P, 3)`` input points.
      entries: :class:`FixedPlanEntries` of ``E`` entries.

    Example:
      >>> x = jnp.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
      >>> e = FixedPlanEntries(jnp.array([0]), jnp.array([[0, 1, 2]]), jnp.array([[0.5, 0.5, 0.0]]),
      ...                      jnp.array([2.0]))
      >>> float(fixed_plan_cost(x, jnp.array([[0.5, 0.0, 1.0]]), e))
      2.0
    """
    diff = points[entries.point] - bin_points(positions, entries)
    return jnp.sum(entries.mass * jnp.sum(diff * diff, axis=-1))


@functools.partial(jax.jit, static_argnames=("quadratic",))
def vertex_targets(positions: jnp.ndarray, points: jnp.ndarray, entries: FixedPlanEntries,
                   segments: TargetSegments, quadratic: bool = False) -> VertexTargets:
    """Closed-form optimal positions of many vertices with the plan fixed.

    For an entry of weight ``alpha`` on the relocated vertex ``v`` and bin
    position ``alpha v + r`` (``r``: the other corners' part), a share's cost
    ``sum m |p - alpha v - r|^2`` is least at::

        v* = sum m alpha (p - r) / sum m alpha^2

    the paper's ``v*(t)`` for a facet and the mean of its points for the
    vertex bin (``alpha = 1``, ``r = 0``). The average over the shares of a
    vertex is weighted by their masses (``quadratic=False``, the paper), or
    by their curvatures ``sum m alpha^2`` (``quadratic=True``), which is the
    minimiser of the vertex's whole fixed-plan cost.

    Args:
      positions: ``(V, 3)``; points: ``(P, 3)``; entries: ``E`` entries.
      segments: :class:`TargetSegments` with ``S`` segments and ``B`` rows.
      quadratic: the weighting (static).

    Returns:
      :class:`VertexTargets`.
    """
    same = entries.corners == segments.vertex[:, None]
    alpha = jnp.sum(jnp.where(same, entries.barycentric, 0.0), axis=1)
    rest = jnp.einsum("ek,ekd->ed", jnp.where(same, 0.0, entries.barycentric), positions[entries.corners])
    m = entries.mass
    n_seg = segments.row.shape[0]
    num = jax.ops.segment_sum((m * alpha)[:, None] * (points[entries.point] - rest), segments.segment, n_seg)
    den = jax.ops.segment_sum(m * alpha * alpha, segments.segment, n_seg)
    mass = jax.ops.segment_sum(m, segments.segment, n_seg)
    # A share whose entries all miss the vertex (alpha = 0) does not pin it down.
    curved = den > 0
    star = jnp.where(curved[:, None], num / jnp.where(curved, den, 1.0)[:, None], 0.0)
    if quadratic:
        top, weight = num, den
    else:
        weight = jnp.where(curved, mass, 0.0)
        top = weight[:, None] * star
    n_rows = segments.row_vertex.shape[0]
    top = jax.ops.segment_sum(top, segments.row, n_rows)
    weight = jax.ops.segment_sum(weight, segments.row, n_rows)
    valid = weight > 0
    current = positions[segments.row_vertex]
    target = jnp.where(valid[:, None], top / jnp.where(valid, weight, 1.0)[:, None], current)
    return VertexTargets(target, star, mass, valid)


class RefinedPositions(NamedTuple):
    """What :func:`refine_positions` returns.

    Attributes:
      positions: ``(V, 3)`` refined positions (free rows moved only).
      costs: ``(steps + 1,)`` fixed-plan cost at the start and after each
        step (a rejected or empty step repeats the previous value).
    """

    positions: jnp.ndarray
    costs: jnp.ndarray


def _bin_shift(direction, entries):
    return jnp.einsum("ek,ekd->ed", entries.barycentric, direction[entries.corners])


@functools.partial(jax.jit, static_argnames=("steps",))
def refine_positions(positions: jnp.ndarray, free_mask: jnp.ndarray, points: jnp.ndarray,
                     entries: FixedPlanEntries, steps: int) -> RefinedPositions:
    """Minimises :func:`fixed_plan_cost` over the free vertices by ``steps``
    conjugate-gradient steps (Polak-Ribiere, restarted when not descending).

    The cost is quadratic in the positions, so the line search is exact: along
    ``d`` it is ``f + t g.d + t^2 q`` with ``q = sum m |shift of the bin|^2``,
    least at ``t = -g.d / (2 q)``. A step whose computed cost is higher than
    the current one (rounding) is not taken and ends the descent, so the
    returned costs never rise.

    Args:
      positions: ``(V, 3)``; free_mask: ``(V,)`` bool, rows that may move.
      points: ``(P, 3)``; entries: :class:`FixedPlanEntries`.
      steps: number of steps (static).

    Returns:
      :class:`RefinedPositions`.
    """
    free = free_mask[:, None].astype(positions.dtype)
    value_and_grad = jax.value_and_grad(fixed_plan_cost)

    def gradient(x):
        f, g = value_and_grad(x, points, entries)
        return f, g * free

    def step(carry, _):
        x, f, g, d, done = carry
        slope = jnp.sum(g * d)
        # Not a descent direction (possible after rounding): restart on -g.
        d = jnp.where(slope < 0, d, -g)
        slope = jnp.where(slope < 0, slope, -jnp.sum(g * g))
        q = jnp.sum(entries.mass * jnp.sum(_bin_shift(d, entries) ** 2, axis=-1))
        t = jnp.where((q > 0) & (slope < 0), -slope / (2.0 * jnp.where(q > 0, q, 1.0)), 0.0)
        x_new = x + t * d
        f_new, g_new = gradient(x_new)
        take = (~done) & (t > 0) & (f_new < f)
        beta = jnp.maximum(0.0, jnp.sum(g_new * (g_new - g)) / jnp.maximum(jnp.sum(g * g), 1e-300))
        d_new = -g_new + beta * d
        carry = (jnp.where(take, x_new, x), jnp.where(take, f_new, f), jnp.where(take, g_new, g),
                 jnp.where(take, d_new, d), done | ~take)
        return carry, carry[1]

    f0, g0 = gradient(positions)
    init = (positions, f0, g0, -g0, jnp.asarray(False))
    (x, _, _, _, _), costs = jax.lax.scan(step, init, None, length=steps)
    return RefinedPositions(x, jnp.concatenate([f0[None], costs]))
