"""Optimal-transport cost of a stencil: points to edges and vertices.

Implements the transport plan of de Goes et al. 2011, Sec. 2.2-2.3, on one
:class:`~otjax.stencil.EdgeStencil` (or a batch of them through ``vmap``):

1. every point goes to the nearest of its (up to three) candidate edges;
2. the points of an edge ``e = (a, b)`` either stay on ``e`` ("solid"), at
   normal cost ``N`` plus tangential cost ``T`` (Eqs. 3-4), or each go to the
   nearer endpoint ("ghost"), at vertex cost ``V`` (Eq. 2); the cheaper wins.

All costs are *squared* W2 costs (the quantities under the square roots of
Eqs. 2-5), so they add over edges.

The kernels are written for fixed, padded shapes: padded points carry zero
mass and no assignment, padded edges receive no point, so padding contributes
exactly zero to values and gradients. Every division is guarded so that
neither values nor gradients are NaN on empty or degenerate edges.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from otjax.curves.mass_before import mass_before_rank, mass_before_sort
from otjax.stencil import EdgeStencil

TANGENTIAL_METHODS = ("rank", "sort")
# Measured on XLA:CPU (scripts/bench_edge_cost.py): the O(P^2) "rank" is up to
# ~1.5x faster for P <= 32 points per stencil, on par at 64 (in cache), and
# 3x slower at 128, growing with P; "sort" stays near 200 ns per point. The
# default "auto" takes the faster one for the (static) padded P.
RANK_MAX_POINTS = 32
DEFAULT_TANGENTIAL_METHOD = "auto"


def resolve_tangential_method(tangential_method: str, n_points: int) -> str:
    """``"rank"`` or ``"sort"``: ``"auto"`` resolved for ``n_points`` (padded P)."""
    if tangential_method == "auto":
        return "rank" if n_points <= RANK_MAX_POINTS else "sort"
    if tangential_method not in TANGENTIAL_METHODS:
        raise ValueError(
            f"tangential_method must be 'auto' or one of {TANGENTIAL_METHODS}, got {tangential_method!r}"
        )
    return tangential_method


class StencilCost(NamedTuple):
    """Transport cost of one stencil (add a leading ``B`` axis when batched).

    Attributes:
      total: ``()`` sum of ``edge_cost`` over real edges.
      edge_cost: ``(E,)`` cost charged to each edge: ``normal + tangential``
        if the edge is solid, else ``vertex``. Zero on padded and empty edges.
      normal: ``(E,)`` normal cost ``N`` of keeping the points on the edge.
      tangential: ``(E,)`` tangential cost ``T`` of keeping them on the edge.
      vertex: ``(E,)`` cost ``V`` of sending them to the nearer endpoint.
      edge_mass: ``(E,)`` mass ``M_e`` of the points assigned to the edge.
      solid: ``(E,)`` bool. The points stay on the edge.
      assignment: ``(P,)`` int32 local edge index of each point; ``-1`` for
        padded points.
    """

    total: jax.Array
    edge_cost: jax.Array
    normal: jax.Array
    tangential: jax.Array
    vertex: jax.Array
    edge_mass: jax.Array
    solid: jax.Array
    assignment: jax.Array


def _safe_div(num: jax.Array, den: jax.Array) -> jax.Array:
    """``num / den`` where ``den != 0``, else ``0``; NaN-free gradients.

    The inner ``where`` keeps the untaken branch finite, otherwise its
    ``inf``/``NaN`` derivative would leak through the outer ``where``.
    """
    ok = den != 0
    return jnp.where(ok, num / jnp.where(ok, den, 1), 0)


# Coordinates are combined explicitly rather than with ``jnp.sum(..., axis=-1)``:
# XLA:CPU compiles reductions over a size-2 minor axis into slow loops (about
# 20x slower than the unrolled form, measured).


def _dot(u: jax.Array, v: jax.Array) -> jax.Array:
    """Dot product over the last axis: ``(..., 2), (..., 2) -> (...)``."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]


def _cross(u: jax.Array, v: jax.Array) -> jax.Array:
    """2D cross product ``u x v`` over the last axis: ``(..., 2) -> (...)``."""
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _safe_norm(v: jax.Array) -> jax.Array:
    """Euclidean norm over the last axis, with a zero (not NaN) gradient at 0."""
    sq = _dot(v, v)
    ok = sq > 0
    return jnp.where(ok, jnp.sqrt(jnp.where(ok, sq, 1)), 0)


def segment_sqdist(p: jax.Array, a: jax.Array, b: jax.Array) -> jax.Array:
    """Squared distance from points to segments.

    With ``t = (p - a).(b - a) / |b - a|^2`` (``0`` on a degenerate segment):
    ``|p - a|^2`` if ``t <= 0``, ``|p - b|^2`` if ``t >= 1``, else the squared
    distance to the supporting line, ``((b - a) x (p - a))^2 / |b - a|^2``. The two vertex tests are made on
    signs, ``(p - a).(b - a) <= 0`` and ``(p - b).(b - a) >= 0``, not on the
    rounded quotient: a point exactly on ``b`` then lands in the ``b`` region
    whatever rounding (reciprocals, FMA contraction) the compiler picks. So a
    point on a vertex is at exactly 0 from every edge incident to it, and a
    point in the vertex region of ``a`` gets bitwise-identical distances to all
    edges sharing ``a``; exact ties are then broken by candidate order only.

    Args:
      p: ``(..., 2)`` points.
      a: ``(..., 2)`` first segment endpoints.
      b: ``(..., 2)`` second segment endpoints.

    Returns:
      ``(...)`` squared distances (leading shapes broadcast).
    """
    d = b - a
    pa = p - a
    pb = p - b
    along = _dot(pa, d)
    # Interior distance as cross^2 / |d|^2: one rounding of exact-able terms,
    # so exact ties between edges (lattice data) stay bitwise ties.
    interior = _safe_div(_cross(d, pa) ** 2, _dot(d, d))
    return jnp.where(along <= 0, _dot(pa, pa), jnp.where(_dot(pb, d) >= 0, _dot(pb, pb), interior))


def _nearest_candidate(stencil: EdgeStencil) -> tuple[jax.Array, jax.Array]:
    """Nearest candidate edge of each point, and that edge's endpoints.

    Returns:
      ``(assignment (P,) int32, endpoints (P, 2, 2))``; see :func:`assign_points`.
      Padded points get ``-1`` (and endpoints that nothing uses).
    """
    cand = jnp.asarray(stencil.cand)
    # mode="clip": cand is in range by contract, and the clipped gather is
    # several times faster on XLA:CPU than the default bounds-filling one.
    seg = jnp.take(jnp.asarray(stencil.edges), cand, axis=0, mode="clip")  # (P, 3, 2, 2)
    d2 = segment_sqdist(jnp.asarray(stencil.points)[:, None, :], seg[..., 0, :], seg[..., 1, :])
    k = jnp.argmin(d2, axis=1)  # first occurrence on exact ties
    picked = jnp.take_along_axis(cand, k[:, None], axis=1)[:, 0]
    assignment = jnp.where(jnp.asarray(stencil.point_mask), picked, -1).astype(jnp.int32)
    # A second gather from edges, not a select among the three candidates:
    # the select compiles slower and runs ~3x slower on XLA:CPU (measured).
    endpoints = jnp.take(jnp.asarray(stencil.edges), picked, axis=0, mode="clip")
    return assignment, endpoints


def assign_points(stencil: EdgeStencil) -> jax.Array:
    """Assigns each point to the nearest of its candidate edges.

    Args:
      stencil: one unbatched stencil: ``edges (E, 2, 2)``, ``points (P, 2)``,
        ``point_mask (P,)``, ``cand (P, 3)``.

    Returns:
      ``(P,)`` int32 local edge index per point; exact ties go to the earliest
      ``cand`` entry. ``-1`` for padded points.
    """
    return _nearest_candidate(stencil)[0]


_MASS_BEFORE = {"rank": mass_before_rank, "sort": mass_before_sort}


def stencil_cost(stencil: EdgeStencil, tangential_method: str = DEFAULT_TANGENTIAL_METHOD) -> StencilCost:
    """Transport cost of one unbatched stencil.

    For an edge ``(a, b)`` of length ``L`` and direction ``u``, with assigned
    points ``p_i`` of mass ``m_i`` (total ``M_e``) and coordinates
    ``t_i = (p_i - a) . u`` along the supporting line (not clamped):

    * ``N = sum m_i ((p_i - a) x u)^2``;
    * ``T = sum m_i (l_i^2 / 12 + (t_i - c_i)^2)``, with bins ordered by ``t``:
      ``l_i = L m_i / M_e`` and bin centre ``c_i = L (C_i + m_i / 2) / M_e``,
      ``C_i`` the mass preceding point ``i``;
    * ``V = sum m_i min(|p_i - a|^2, |p_i - b|^2)``.

    The edge is solid iff ``M_e > 0``, ``L > 0`` and ``N + T < V``; its cost is
    then ``N + T``, otherwise ``V``. A degenerate edge (``L == 0``) reports
    ``N = T = 0``.

    Args:
      stencil: one stencil without the batch axis: ``edges (E, 2, 2)``,
        ``edge_mask (E,)``, ``points (P, 2)``, ``mass (P,)``,
        ``point_mask (P,)``, ``cand (P, 3)``.
      tangential_method: how ``C_i`` is found: ``"rank"`` (``(P, P)``
        comparisons), ``"sort"`` (integer-key sort and segmented scan), or
        ``"auto"`` (the faster for this ``P``, see
        :func:`resolve_tangential_method`). Same result up to rounding.

    Returns:
      A :class:`StencilCost`.
    """
    method = resolve_tangential_method(tangential_method, jnp.shape(stencil.mass)[0])
    edges = jnp.asarray(stencil.edges)
    edge_mask = jnp.asarray(stencil.edge_mask)
    points = jnp.asarray(stencil.points)
    point_mask = jnp.asarray(stencil.point_mask)
    m = jnp.where(point_mask, jnp.asarray(stencil.mass), 0)
    n_edges = edges.shape[0]

    assignment, seg = _nearest_candidate(stencil)
    # Padded points go to an extra bin E that is dropped.
    bin_of = jnp.where(point_mask, assignment, n_edges)

    def per_edge(x: jax.Array) -> jax.Array:
        # Scatter-add: by far the cheapest on XLA:CPU (and deterministic there);
        # accelerators may add in a nondeterministic order.
        return jax.ops.segment_sum(x, bin_of, num_segments=n_edges + 1)[:n_edges]

    # Per-point geometry in the frame of the assigned edge.
    a, b = seg[:, 0], seg[:, 1]
    d = b - a
    length = _safe_norm(d)
    u = d / jnp.where(length > 0, length, 1)[:, None]  # zero on degenerate edges
    pa = points - a
    pb = points - b
    t = _dot(pa, u)
    nrm2 = _cross(u, pa) ** 2
    vtx2 = jnp.minimum(_dot(pa, pa), _dot(pb, pb))

    sums = per_edge(jnp.stack([m, m * nrm2, m * vtx2], axis=-1))
    edge_mass, normal, vertex = sums[:, 0], sums[:, 1], sums[:, 2]

    mass_before = _MASS_BEFORE[method](bin_of, t, m, n_edges + 1)
    scale = _safe_div(length, jnp.take(edge_mass, jnp.maximum(assignment, 0), mode="clip"))  # L / M_e
    bin_len = scale * m
    centre = scale * (mass_before + 0.5 * m)
    tangential = per_edge(m * (bin_len**2 / 12 + (t - centre) ** 2))

    edge_length = _safe_norm(edges[:, 1] - edges[:, 0])
    solid = (normal + tangential < vertex) & (edge_mass > 0) & (edge_length > 0) & edge_mask
    edge_cost = jnp.where(edge_mask, jnp.where(solid, normal + tangential, vertex), 0)
    return StencilCost(
        total=jnp.sum(edge_cost),
        edge_cost=edge_cost,
        normal=normal,
        tangential=tangential,
        vertex=vertex,
        edge_mass=edge_mass,
        solid=solid,
        assignment=assignment,
    )


def _batched(tangential_method: str):
    def cost(stencil: EdgeStencil) -> StencilCost:
        return stencil_cost(stencil, tangential_method)

    return jax.jit(jax.vmap(cost))


batched_stencil_cost_rank = _batched("rank")
"""``jit(vmap(stencil_cost))`` with the pairwise-rank tangential part."""

batched_stencil_cost_sort = _batched("sort")
"""``jit(vmap(stencil_cost))`` with the sort-based tangential part."""

batched_stencil_cost = _batched(DEFAULT_TANGENTIAL_METHOD)
"""Batched :func:`stencil_cost` with the default method: ``EdgeStencil`` with
leading ``B`` axis -> :class:`StencilCost` with leading ``B`` axis."""



def fixed_assignment_cost(vertices: jax.Array, edge_index: jax.Array, points: jax.Array,
                          mass: jax.Array, point_edge: jax.Array) -> jax.Array:
    """Total transport cost as a differentiable function of vertex positions.

    The assignment of points to edges is held fixed (the plan's combinatorial
    part); everything continuous is recomputed from ``vertices``: the normal
    and tangential parts (the tangential order of the projections included)
    and, per edge, the cheaper of keeping its points or sending them to the
    endpoints. The function is piecewise smooth: ``jax.grad`` is exact away
    from the measure-zero set where two projections swap order or an edge
    switches between solid and ghost.

    Args:
      vertices: ``(V, 2)`` float vertex positions.
      edge_index: ``(E, 2)`` int vertex ids per edge, lower id first.
      points: ``(P, 2)`` float input points.
      mass: ``(P,)`` float masses.
      point_edge: ``(P,)`` int index into ``edge_index`` of each point's edge.

    Returns:
      Scalar squared-W2 cost.

    Example:
      >>> import jax, jax.numpy as jnp
      >>> v = jnp.array([[0.0, 0.0], [1.0, 0.0]])
      >>> p = jnp.array([[0.25, 0.1], [0.75, -0.1]])
      >>> g = jax.grad(fixed_assignment_cost)(v, jnp.array([[0, 1]]), p, jnp.ones(2), jnp.array([0, 0]))
      >>> g.shape
      (2, 2)
    """
    edge_index = jnp.asarray(edge_index)
    point_edge = jnp.asarray(point_edge, jnp.int32)
    stencil = EdgeStencil(
        edges=jnp.asarray(vertices)[edge_index],
        edge_mask=jnp.ones(edge_index.shape[0], bool),
        points=jnp.asarray(points),
        mass=jnp.asarray(mass),
        point_mask=jnp.ones(point_edge.shape[0], bool),
        cand=jnp.repeat(point_edge[:, None], 3, axis=1),
    )
    return stencil_cost(stencil).total
