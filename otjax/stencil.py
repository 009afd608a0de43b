"""Stencil batches: the one place where topology (Python) meets cost (JAX).

A *stencil* is the local piece of a triangulation that one candidate operation
changes, written as it would be *after* the operation: the local edges and the
input points whose assignment may change. A *batch* stacks B stencils, padded to
a common capacity so that one ``jit``-compiled call scores them all.

Capacities come from :class:`Buckets`: powers of two that only ever grow (the
jax-md neighbour-list pattern: fixed capacity, overflow detected on the host,
reallocate). A stencil is never truncated.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class EdgeStencil(NamedTuple):
    """A batch of 2D edge stencils, padded to fixed capacities.

    Shapes (``B`` candidates, ``E`` local edges, ``P`` local points):

    Attributes:
      edges: ``(B, E, 2, 2)`` float. Endpoint coordinates of each local edge.
        ``edges[b, e, 0]`` is the endpoint with the lower global vertex id, so
        that every stencil orients a shared edge the same way. Padding: zeros.
      edge_mask: ``(B, E)`` bool. True for real edges.
      points: ``(B, P, 2)`` float. Input points of the stencil. Padding: zeros.
      mass: ``(B, P)`` float, ``>= 0``. Point masses; ``0`` on padding.
      point_mask: ``(B, P)`` bool. True for real points.
      cand: ``(B, P, 3)`` int32. Local edges a point may be assigned to (the
        three edges of the triangle that contains it, or one edge repeated for
        a point whose assignment is fixed). The nearest wins; exact ties go to
        the earliest entry, and the host lists entries in increasing global
        edge key, so ties are broken the same way everywhere. Padding: ``0``.

    Padded points have zero mass and padded edges receive no point, so padding
    contributes exactly zero cost and zero gradient.
    """

    edges: np.ndarray
    edge_mask: np.ndarray
    points: np.ndarray
    mass: np.ndarray
    point_mask: np.ndarray
    cand: np.ndarray

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(B, E, P)`` capacities of this batch."""
        b, e = self.edge_mask.shape
        return b, e, self.point_mask.shape[1]


def _next_pow2(n: int, floor: int) -> int:
    size = floor
    while size < n:
        size *= 2
    return size


class Buckets:
    """Padded capacities for stencil batches.

    * Edges: a high-water mark rounded up to a power of two. It grows when a
      stencil needs more (one recompile) and never shrinks, so it takes few
      values (local edge counts hardly vary).
    * Points: chosen per batch, the power of two that fits the batch's
      largest stencil (at least ``min_points``). Stencil sizes are heavy
      tailed (a vertex next to the box corners holds the outliers of a
      quarter of the box): a high-water mark made one such stencil inflate
      every later call (32 x 512 padded rows for a typical 15 x 100 points,
      measured: 3.3 ms instead of 0.8 ms per call).
    * Batch rows: a function of the point capacity, ``point_budget / P``
      clamped to ``[min_batch, max_batch]``, so that every call does about
      the same work and adds no shape of its own.

    A compiled shape is therefore fixed by ``P`` (and the slowly growing
    ``E``): at most ``log2`` of the largest stencil many. :meth:`batches`
    groups candidates so that large stencils do not pad small ones.

    Args:
      min_edges: initial edge capacity (power of two).
      min_points: smallest point capacity (power of two).
      max_batch: batch capacity for small stencils (power of two).
      point_budget: target for ``B * P``.
      min_batch: smallest batch capacity (power of two).

    Attributes:
      shapes_seen: every ``(B, E, P)`` handed out so far; its size bounds the
        number of compilations of a kernel driven by these buckets.
    """

    def __init__(self, min_edges: int = 16, min_points: int = 32, max_batch: int = 32,
                 point_budget: int = 8192, min_batch: int = 1):
        for name, v in (("min_edges", min_edges), ("min_points", min_points), ("max_batch", max_batch),
                        ("min_batch", min_batch)):
            if v < 1 or v & (v - 1):
                raise ValueError(f"{name} must be a positive power of two, got {v}")
        if min_batch > max_batch or point_budget < 1:
            raise ValueError("need 1 <= min_batch <= max_batch and point_budget >= 1")
        self.edges = min_edges
        self.points = min_points
        self.max_batch = max_batch
        self.min_batch = min_batch
        self.point_budget = point_budget
        self.shapes_seen: set[tuple[int, int, int]] = set()

    def point_capacity(self, max_points: int) -> int:
        """Point capacity of a batch whose largest stencil has ``max_points``."""
        return _next_pow2(max_points, self.points)

    def batch_capacity(self, point_capacity: int) -> int:
        """Rows of a batch padded to ``point_capacity`` points."""
        b = self.max_batch
        while b > self.min_batch and b * point_capacity > self.point_budget:
            b //= 2
        return b

    def grow(self, max_edges: int) -> None:
        """Raises the edge high-water mark to fit ``max_edges``."""
        self.edges = _next_pow2(max_edges, self.edges)

    def batches(self, sizes) -> list[np.ndarray]:
        """Groups stencils of ``sizes`` points into batches, largest first.

        Each batch takes the largest stencils left, as many as the batch
        capacity of the largest allows, so small stencils fill the spare
        rows of a large batch instead of being padded on their own.

        Returns:
          Index arrays into ``sizes``; each fits one :meth:`fit`.
        """
        sizes = np.asarray(sizes, np.int64)
        order = np.argsort(-sizes, kind="stable")
        out, i = [], 0
        while i < len(order):
            b = self.batch_capacity(self.point_capacity(max(int(sizes[order[i]]), 1)))
            out.append(order[i:i + b])
            i += b
        return out

    def fit(self, n_batch: int, max_edges: int, max_points: int) -> tuple[int, int, int]:
        """Capacities ``(B, E, P)`` for a batch; grows the edge high-water mark."""
        self.grow(max_edges)
        p = self.point_capacity(max_points)
        b = self.batch_capacity(p)
        if n_batch > b:
            raise ValueError(f"batch of {n_batch} exceeds the capacity {b}; chunk it (see batches())")
        shape = (b, self.edges, p)
        self.shapes_seen.add(shape)
        return shape


def ragged_index(lengths) -> tuple[np.ndarray, np.ndarray]:
    """Row and column of every element of ragged rows laid end to end.

    Args:
      lengths: ``(R,)`` non-negative row lengths.

    Returns:
      ``(row, col)``, each ``(sum(lengths),)`` int64: element ``k`` of the
      concatenation is ``col[k]``-th of row ``row[k]``.

    Example:
      >>> ragged_index([2, 0, 3])
      (array([0, 0, 2, 2, 2]), array([0, 1, 0, 1, 2]))
    """
    lengths = np.asarray(lengths, np.int64)
    row = np.repeat(np.arange(len(lengths)), lengths)
    col = np.arange(int(lengths.sum())) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    return row, col


def pack_ragged(edges, n_edges, points, mass, cand, n_points, buckets: Buckets, dtype=np.float64) -> EdgeStencil:
    """Pads stencils given end to end into one :class:`EdgeStencil` batch.

    One scatter per field, whatever the number of stencils (a Python loop
    over candidates cost ~30 us each in the decimation loop).

    Args:
      edges: ``(sum E_i, 2, 2)`` local edges of every stencil, in order.
      n_edges: ``(S,)`` local edge count ``E_i`` of each stencil.
      points, mass, cand: ``(sum P_i, 2)``, ``(sum P_i,)``, ``(sum P_i, 3)``.
      n_points: ``(S,)`` point count ``P_i`` of each stencil.
      buckets: capacity policy; grown if a stencil does not fit.
      dtype: float dtype of coordinates and masses.

    Returns:
      A batch whose first ``S`` rows hold the stencils in order; the
      remaining rows are empty (all-masked) padding.
    """
    n_edges, n_points = np.asarray(n_edges, np.int64), np.asarray(n_points, np.int64)
    b_cap, e_cap, p_cap = buckets.fit(len(n_edges), max(int(n_edges.max(initial=0)), 1),
                                      max(int(n_points.max(initial=0)), 1))
    out_edges = np.zeros((b_cap, e_cap, 2, 2), dtype)
    edge_mask = np.zeros((b_cap, e_cap), bool)
    r, c = ragged_index(n_edges)
    out_edges[r, c] = edges
    edge_mask[r, c] = True
    out_points = np.zeros((b_cap, p_cap, 2), dtype)
    out_mass = np.zeros((b_cap, p_cap), dtype)
    point_mask = np.zeros((b_cap, p_cap), bool)
    out_cand = np.zeros((b_cap, p_cap, 3), np.int32)
    r, c = ragged_index(n_points)
    out_points[r, c] = points
    out_mass[r, c] = mass
    point_mask[r, c] = True
    out_cand[r, c] = cand
    return EdgeStencil(out_edges, edge_mask, out_points, out_mass, point_mask, out_cand)


def pack_edge_stencils(
    stencils: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    buckets: Buckets,
    dtype=np.float64,
) -> EdgeStencil:
    """Pads a list of single stencils into one :class:`EdgeStencil` batch.

    Args:
      stencils: per candidate ``(edges (E_i, 2, 2), points (P_i, 2),
        mass (P_i,), cand (P_i, 3))``.
      buckets: capacity policy; grown if a stencil does not fit.
      dtype: float dtype of coordinates and masses.

    Returns:
      A batch whose first ``len(stencils)`` rows hold the stencils in order;
      the remaining rows are empty (all-masked) padding.
    """
    def cat(i, shape):
        parts = [np.asarray(s[i]).reshape((-1,) + shape) for s in stencils]
        return np.concatenate(parts) if parts else np.zeros((0,) + shape)

    return pack_ragged(cat(0, (2, 2)), [len(s[0]) for s in stencils], cat(1, (2,)), cat(2, ()),
                       cat(3, (3,)), [len(s[1]) for s in stencils], buckets, dtype)
