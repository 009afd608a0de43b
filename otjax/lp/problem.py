"""A padded batch of local transport LPs, and the solution both solvers return.

One member: points ``i`` with masses ``m_i > 0``, bins ``j`` with a cost
``C_ij`` (squared distance, computed by the caller), each bin in one simplex
``s(j)``. Vertex bins receive any amount; the bins of a facet ``s`` receive
``c_j * l_s`` for one free density ``l_s >= 0`` (a uniform measure on the
facet). The LP::

    minimise   sum_ij x_ij C_ij
    subject to x_ij >= 0,  sum_j x_ij = m_i,  sum_i x_ij = c_j * l_s(j) (facet bins)

Members of different sizes are padded to a few capacity classes (powers of
two) so that few shapes compile; masks mark the real entries, which come
first in every member.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

# Per-member status codes of LPSolution.status.
CONVERGED = 0  # certified: the plan is feasible and its cost within tolerance of the optimum
ITERATION_LIMIT = 1  # the step budget ran out first: the plan is feasible, its cost an upper bound
INFEASIBLE = 2  # a point of positive mass has no bin to go to
FAILED = 3  # the solver hit a numerical error; the plan is not to be used

STATUS_NAMES = {CONVERGED: "converged", ITERATION_LIMIT: "iteration limit", INFEASIBLE: "infeasible",
                FAILED: "failed"}

# Smallest capacity of each padded axis (points, bins, simplices).
MIN_POINTS = 8
MIN_BINS = 8
MIN_SIMPLICES = 4


class LocalLP(NamedTuple):
    """One unpadded member (NumPy arrays).

    Attributes:
      cost: ``(P, K)`` float, ``>= 0``. Cost of moving unit mass from point ``i``
        to bin ``j`` (squared distance, in the caller's units).
      mass: ``(P,)`` float, ``> 0``. Point masses.
      capacity: ``(K,)`` float. ``c_j > 0`` for facet bins; ignored for vertex bins.
      simplex: ``(K,)`` int. Local simplex id of each bin, in ``[0, S)``; an id
        is either a vertex's (its vertex bins) or a facet's (its facet bins).
      is_vertex: ``(K,)`` bool. True for vertex bins (unconstrained).
    """

    cost: np.ndarray
    mass: np.ndarray
    capacity: np.ndarray
    simplex: np.ndarray
    is_vertex: np.ndarray

    @property
    def n_simplices(self) -> int:
        """``S``: one more than the largest simplex id (0 without bins)."""
        return int(self.simplex.max()) + 1 if len(self.simplex) else 0


class BatchShape(NamedTuple):
    """The capacities of a :class:`TransportLP` batch, ``(B, P, K, S)``.

    Attributes:
      members: ``B``, the members of the batch.
      points: ``P``, the point capacity of each member.
      bins: ``K``, the bin capacity of each member.
      simplices: ``S``, the simplex capacity of each member.
    """

    members: int
    points: int
    bins: int
    simplices: int


class TransportLP(NamedTuple):
    """A padded batch of ``B`` members; a pytree of arrays (NumPy or JAX).

    Shapes: ``P`` points, ``K`` bins, ``S`` simplices per member (capacities;
    ``S`` is static through the shape of ``simplex_mask``). Real entries come
    first in each member; padding is neutral and receives no plan mass.

    Attributes:
      cost: ``(B, P, K)`` float. Pad 0.
      mass: ``(B, P)`` float, ``>= 0``. Pad 0.
      capacity: ``(B, K)`` float. ``c_j > 0`` on facet bins; 0 on vertex bins and padding.
      simplex: ``(B, K)`` int32 in ``[0, S)``. Pad 0 (ignored: ``bin_mask``).
      is_vertex: ``(B, K)`` bool. Pad False.
      point_mask: ``(B, P)`` bool. True for real points.
      bin_mask: ``(B, K)`` bool. True for real bins.
      simplex_mask: ``(B, S)`` bool. True for the simplex ids a real bin uses.
    """

    cost: np.ndarray
    mass: np.ndarray
    capacity: np.ndarray
    simplex: np.ndarray
    is_vertex: np.ndarray
    point_mask: np.ndarray
    bin_mask: np.ndarray
    simplex_mask: np.ndarray

    @property
    def shape(self) -> BatchShape:
        """The :class:`BatchShape` ``(B, P, K, S)``: capacities of this batch."""
        b, p, k = self.cost.shape
        return BatchShape(b, p, k, self.simplex_mask.shape[1])


class LPSolution(NamedTuple):
    """Solutions of a :class:`TransportLP` batch, padded like it.

    Attributes:
      plan: ``(B, P, K)`` float. The transport plan ``x_ij``: exactly feasible
        (rows sum to ``m_i``, each facet's bins carry ``c_j * l_s``) up to
        rounding; 0 on padding.
      simplex_mass: ``(B, S)`` float. Mass each simplex receives; 0 for unused ids.
      density: ``(B, S)`` float. ``l_s`` of facet simplices; 0 for vertex and unused ids.
      cost: ``(B,)`` float. ``sum_ij x_ij C_ij`` of ``plan``.
      lower_bound: ``(B,)`` float. A certified lower bound on the optimum (a
        feasible dual value); equals ``cost`` for the exact solver.
      violation: ``(B,)`` float. Largest marginal violation of ``plan``, relative
        to the member's total mass (row sums and facet uniformity).
      status: ``(B,)`` int8. :data:`CONVERGED`, :data:`ITERATION_LIMIT`,
        :data:`INFEASIBLE` or :data:`FAILED`.
      iterations: ``(B,)`` int32. Steps the solver took (the batched solver's
        steps before convergence; HiGHS's simplex iterations).
    """

    plan: np.ndarray
    simplex_mass: np.ndarray
    density: np.ndarray
    cost: np.ndarray
    lower_bound: np.ndarray
    violation: np.ndarray
    status: np.ndarray
    iterations: np.ndarray

    @property
    def gap(self):
        """``(B,)`` ``(cost - lower_bound) / cost`` (0 where the cost is 0)."""
        cost = np.asarray(self.cost)
        diff = cost - np.asarray(self.lower_bound)
        return np.where(cost > 0, diff / np.where(cost > 0, cost, 1), np.maximum(diff, 0))


def check_local(lp: LocalLP) -> None:
    """Raises a ``ValueError`` naming the first problem of a member's arrays."""
    p, k = np.shape(lp.cost)[:2] if np.ndim(lp.cost) == 2 else (-1, -1)
    if p < 0:
        raise ValueError(f"cost must be a (P, K) array, got shape {np.shape(lp.cost)}")
    for name, arr in (("mass", lp.mass), ("capacity", lp.capacity), ("simplex", lp.simplex),
                      ("is_vertex", lp.is_vertex)):
        want = (p,) if name == "mass" else (k,)
        if np.shape(arr) != want:
            raise ValueError(f"{name} must have shape {want} to match cost {(p, k)}, got {np.shape(arr)}")
    if not np.all(np.isfinite(lp.cost)) or np.any(np.asarray(lp.cost) < 0):
        raise ValueError("cost must be finite and non-negative")
    if not np.all(np.isfinite(lp.mass)) or np.any(np.asarray(lp.mass) <= 0):
        raise ValueError("mass must be finite and positive")
    simplex = np.asarray(lp.simplex)
    if k and simplex.min() < 0:
        raise ValueError("simplex ids must be >= 0")
    vertex = np.asarray(lp.is_vertex, bool)
    facet_cap = np.asarray(lp.capacity)[~vertex]
    if not np.all(np.isfinite(facet_cap)) or np.any(facet_cap <= 0):
        raise ValueError("facet bins need a finite positive capacity")
    if k:
        n = simplex.max() + 1
        vertex_count = np.bincount(simplex[vertex], minlength=n)
        facet_count = np.bincount(simplex[~vertex], minlength=n)
        if np.any((vertex_count > 0) & (facet_count > 0)):
            raise ValueError("a simplex id is used by both vertex and facet bins")


def lower_bound(lp: LocalLP) -> float:
    """``sum_i m_i min_j C_ij``: no plan of the member costs less (0 without
    points or bins).

    Example:
      >>> lower_bound(LocalLP(np.array([[4.0, 1.0]]), np.array([2.0]), np.array([0.0, 1.0]),
      ...                     np.array([0, 1]), np.array([True, False])))
      2.0
    """
    if lp.cost.size == 0:
        return 0.0
    return float(np.dot(lp.mass, lp.cost.min(axis=1)))


def capacity_class(n: int, smallest: int) -> int:
    """The padded size of an axis holding ``n`` entries: a power of two ``>= smallest``.

    Example:
      >>> capacity_class(100, 8)
      128
    """
    size = smallest
    while size < n:
        size *= 2
    return size


def member_classes(problems: Sequence[LocalLP]) -> tuple[tuple[int, int, int], ...]:
    """``(P, K, S)`` capacity class of each member."""
    return tuple((capacity_class(lp.cost.shape[0], MIN_POINTS), capacity_class(lp.cost.shape[1], MIN_BINS),
                  capacity_class(lp.n_simplices, MIN_SIMPLICES)) for lp in problems)


def group_by_class(problems: Sequence[LocalLP]) -> dict[tuple[int, int, int], list[int]]:
    """Indices of the members of each ``(P, K, S)`` capacity class, in order.

    Packing each group separately keeps padding under half of each axis.

    Example:
      >>> small = LocalLP(np.ones((3, 2)), np.ones(3), np.ones(2), np.zeros(2, int), np.zeros(2, bool))
      >>> group_by_class([small, small])
      {(8, 8, 4): [0, 1]}
    """
    groups: dict[tuple[int, int, int], list[int]] = {}
    for i, cls in enumerate(member_classes(problems)):
        groups.setdefault(cls, []).append(i)
    return groups


def pack(problems: Sequence[LocalLP], dtype=np.float64, shape: tuple[int, int, int] | None = None,
         batch: int | None = None, check: bool = True) -> TransportLP:
    """Pads members into one :class:`TransportLP` (NumPy arrays).

    Args:
      problems: the members, unpadded.
      dtype: float dtype of ``cost``, ``mass`` and ``capacity``.
      shape: ``(P, K, S)`` capacities; by default the largest capacity class
        among the members (:func:`capacity_class`). A member that does not fit
        raises (nothing is truncated).
      batch: ``B``, at least ``len(problems)``; by default the power of two
        that fits them (the batch size is part of the compiled shape too).
        Members past the problems are empty: no point, no bin, cost 0.
      check: validate each member first (:func:`check_local`).

    Example:
      >>> lp = LocalLP(np.array([[0.0, 1.0]]), np.ones(1), np.array([0.0, 1.0]),
      ...              np.array([0, 1]), np.array([True, False]))
      >>> pack([lp]).shape
      BatchShape(members=1, points=8, bins=8, simplices=4)
    """
    if check:
        for lp in problems:
            check_local(lp)
    if shape is None:
        classes = member_classes(problems) or ((MIN_POINTS, MIN_BINS, MIN_SIMPLICES),)
        shape = tuple(max(c[a] for c in classes) for a in range(3))
    p_cap, k_cap, s_cap = shape
    b = capacity_class(len(problems), 1) if batch is None else batch
    if b < len(problems):
        raise ValueError(f"batch {b} is smaller than the {len(problems)} members")
    out = TransportLP(
        cost=np.zeros((b, p_cap, k_cap), dtype), mass=np.zeros((b, p_cap), dtype),
        capacity=np.zeros((b, k_cap), dtype), simplex=np.zeros((b, k_cap), np.int32),
        is_vertex=np.zeros((b, k_cap), bool), point_mask=np.zeros((b, p_cap), bool),
        bin_mask=np.zeros((b, k_cap), bool), simplex_mask=np.zeros((b, s_cap), bool))
    for m, lp in enumerate(problems):
        p, k = lp.cost.shape
        if p > p_cap or k > k_cap or lp.n_simplices > s_cap:
            raise ValueError(f"member {m} of size {(p, k, lp.n_simplices)} exceeds the capacity {shape}")
        vertex = np.asarray(lp.is_vertex, bool)
        out.cost[m, :p, :k] = lp.cost
        out.mass[m, :p] = lp.mass
        out.capacity[m, :k] = np.where(vertex, 0, lp.capacity)
        out.simplex[m, :k] = lp.simplex
        out.is_vertex[m, :k] = vertex
        out.point_mask[m, :p] = True
        out.bin_mask[m, :k] = True
        out.simplex_mask[m, np.asarray(lp.simplex, int)] = True
    return out


def member(batch: TransportLP, b: int) -> LocalLP:
    """Member ``b`` of a batch, without its padding (NumPy arrays)."""
    pm = np.asarray(batch.point_mask[b])
    bm = np.asarray(batch.bin_mask[b])
    return LocalLP(cost=np.asarray(batch.cost[b])[pm][:, bm], mass=np.asarray(batch.mass[b])[pm],
                   capacity=np.asarray(batch.capacity[b])[bm], simplex=np.asarray(batch.simplex[b])[bm],
                   is_vertex=np.asarray(batch.is_vertex[b])[bm])


def member_plan(solution: LPSolution, batch: TransportLP, b: int) -> np.ndarray:
    """``(P, K)`` plan of member ``b`` without its padding."""
    pm = np.asarray(batch.point_mask[b])
    bm = np.asarray(batch.bin_mask[b])
    return np.asarray(solution.plan[b])[pm][:, bm]
