"""Mass preceding each point along its edge: the ``C_i`` of the tangential cost.

The tangential cost of an edge (:func:`otjax.curves.cost.stencil_cost`)
orders the points of each edge by their coordinate along it and needs, for
each point, the mass of the points before it on the same edge. Two kernels
give it, with the same result up to rounding: :func:`mass_before_rank`
(sort-free, ``O(P^2)``) and :func:`mass_before_sort` (an exact integer-key
sort, :func:`sort_order`, and a segmented scan, ``O(P log P)``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def mass_before_rank(edge: jax.Array, t: jax.Array, m: jax.Array, num_bins: int | None = None) -> jax.Array:
    """Mass of the points on the same edge that precede each point along it.

    Sort-free: one ``(P, P)`` comparison, ``O(P^2)`` work. Ties in ``t`` are
    ordered by index, as a stable sort would.

    Args:
      edge: ``(P,)`` int edge (bin) of each point.
      t: ``(P,)`` coordinate of each point along its edge.
      m: ``(P,)`` masses.
      num_bins: unused; signature shared with :func:`mass_before_sort`.

    Returns:
      ``(P,)`` ``C_i = sum_j m_j [edge_j == edge_i] [j precedes i]``.
    """
    del num_bins
    n = t.shape[0]
    ti, tj = t[:, None], t[None, :]
    j_lt_i = jnp.asarray(np.tri(n, k=-1, dtype=bool))  # constant: j < i
    before = jnp.where(j_lt_i, tj <= ti, tj < ti) & (edge[:, None] == edge[None, :])
    # A masked sum rather than a matmul: float32 matmuls may run in reduced
    # precision (TF32) on accelerators.
    return jnp.sum(jnp.where(before, m[None, :], 0), axis=1)


def _segmented_exclusive_cumsum(seg: jax.Array, values: jax.Array) -> jax.Array:
    """Exclusive cumulative sum within runs of equal ``seg`` (Hillis-Steele).

    ``ceil(log2 n)`` shifted adds; a shift only adds across positions of the
    same run, which is contiguous, so no partial sum crosses a run boundary.
    The steps run in a ``fori_loop``: unrolled, XLA:CPU compiles them about 2x
    slower and runs them no faster (measured).

    Args:
      seg: ``(n,)`` run labels, equal labels contiguous.
      values: ``(n,)``.

    Returns:
      ``(n,)`` sum of ``values`` over earlier positions of the same run.
    """
    n = values.shape[0]
    idx = jnp.arange(n)
    # Shift by one first so that the inclusive scan below is exclusive, with
    # no subtraction (hence no cancellation).
    first = jnp.concatenate([jnp.ones((1,), bool), seg[1:] != seg[:-1]])
    acc = jnp.where(first, 0, jnp.roll(values, 1))

    def step(i, acc):
        k = jnp.left_shift(1, i)
        same_run = (idx >= k) & (jnp.roll(seg, k) == seg)
        return acc + jnp.where(same_run, jnp.roll(acc, k), 0)

    return jax.lax.fori_loop(0, max(n - 1, 1).bit_length(), step, acc)


def _float_order_key(t: jax.Array) -> jax.Array:
    """Signed integers of ``t``'s width that sort exactly as ``t`` does.

    IEEE floats of one sign order as their bit patterns; flipping the
    magnitude bits of negatives reverses their order. ``-0.0`` (the sign bit
    alone) is mapped to ``+0.0`` so that equal values get equal keys. Integer
    operations only: XLA:CPU may flush subnormals to zero in float
    comparisons, which would tie them with 0. Not for NaN.
    """
    int_type = {2: jnp.int16, 4: jnp.int32, 8: jnp.int64}[t.dtype.itemsize]
    bits = jax.lax.bitcast_convert_type(t, int_type)
    bits = jnp.where(bits == jnp.iinfo(int_type).min, 0, bits)
    return jnp.where(bits < 0, bits ^ jnp.iinfo(int_type).max, bits)


def exact_key_type(num_bins: int, n: int, x64: bool):
    """Integer type of :func:`_sort_order_exact`'s packed key ``(edge n + rank) n + index``,
    whose largest value is ``num_bins n^2 - 1``; ``None`` when no integer type of
    the mode holds it (the caller then sorts by two keys). Python integers: exact."""
    top = num_bins * n * n - 1
    if top <= np.iinfo(np.int32).max:
        return jnp.int32
    if x64 and top <= np.iinfo(np.int64).max:
        return jnp.int64
    return None


def _sort_order_exact(edge: jax.Array, t: jax.Array, num_bins: int) -> jax.Array:
    """:func:`sort_order` by two integer sorts and a binary search (a two-key
    sort when the packed key would overflow)."""
    n = t.shape[0]
    key_type = exact_key_type(num_bins, n, jax.config.jax_enable_x64)
    if key_type is None:
        return _sort_order_lex(edge, t)
    key_t = _float_order_key(t)
    rank_t = jnp.searchsorted(jnp.sort(key_t), key_t, side="left")
    idx = jnp.arange(n, dtype=key_type)
    key = (edge.astype(key_type) * n + rank_t.astype(key_type)) * n + idx
    return (jnp.sort(key) % n).astype(jnp.int32)


def _sort_order_quantized(edge: jax.Array, t: jax.Array, num_bins: int, q_bits: int) -> jax.Array:
    """:func:`sort_order` by one int64 sort of ``(edge, quantised t, index)``.

    ``t`` is mapped to ``q_bits``-bit integers per bin, ``floor((t - lo) *
    (2^q - 1) / (hi - lo))`` with ``lo, hi`` the bin's extremes: a rounded
    subtraction, a product with a positive constant and a floor are each
    non-decreasing, so ``q_i < q_j`` implies ``t_i < t_j``. The sort is
    therefore exact except inside a run of equal ``q`` (points closer than
    ``(hi - lo) / 2^q`` along their edge), where it falls back on index
    order; if such a run is not already ordered by ``t``, a stable two-key
    sort (:func:`_sort_order_lex`) decides instead, so the result is always
    the exact order.
    """
    n = t.shape[0]
    i_bits = max(n - 1, 1).bit_length()
    lo = jax.ops.segment_min(t, edge, num_segments=num_bins)[edge]
    hi = jax.ops.segment_max(t, edge, num_segments=num_bins)[edge]
    span = hi - lo
    top = float(2**q_bits - 1)
    scale = jnp.where(span > 0, top / jnp.where(span > 0, span, 1), 0)
    q = jnp.clip(jnp.floor((t - lo) * scale), 0, top).astype(jnp.int64)
    idx = jnp.arange(n, dtype=jnp.int64)
    key = (edge.astype(jnp.int64) << (q_bits + i_bits)) | (q << i_bits) | idx
    sk = jnp.sort(key)
    order = (sk & ((1 << i_bits) - 1)).astype(jnp.int32)
    run = sk[1:] >> i_bits == sk[:-1] >> i_bits  # same bin and same q
    # Compared as integer order keys: float comparisons may flush subnormals.
    ts = _float_order_key(t)[order]
    ambiguous = jnp.any(run & (ts[1:] < ts[:-1]))
    return jax.lax.cond(ambiguous, lambda: _sort_order_lex(edge, t), lambda: order)


def _sort_order_lex(edge: jax.Array, t: jax.Array) -> jax.Array:
    """:func:`sort_order` by one stable two-key sort: twice as slow as the
    quantised key, but one sort op, cheap to compile, for the rare fallback."""
    idx = jnp.arange(t.shape[0], dtype=jnp.int32)
    return jax.lax.sort((edge.astype(jnp.int32), _float_order_key(t), idx), num_keys=2, is_stable=True)[2]


def sort_order(edge: jax.Array, t: jax.Array, num_bins: int) -> jax.Array:
    """Permutation sorting points by ``(edge, t, index)``; same as a lexsort.

    XLA:CPU sorts a single integer operand with a native comparator, about
    5x faster than float keys or multi-operand (lexsort/argsort) sorts
    (measured). With 64-bit integers available, ``(edge, t, index)`` goes
    into one such key, ``t`` quantised per edge with an exact fallback
    (:func:`_sort_order_quantized`; 2.5x faster at 32k points, measured);
    otherwise ``t`` is ranked through its integer order key (one keys-only
    sort and a binary search) and ``(edge, rank, index)`` sorted, by one
    packed key where an integer type holds it (:func:`exact_key_type`), else
    by a two-key sort.

    Args:
      edge: ``(P,)`` int in ``[0, num_bins)``.
      t: ``(P,)`` float, no NaN.
      num_bins: static bound on ``edge``.

    Returns:
      ``(P,)`` int32 permutation.

    Raises:
      ValueError: ``P`` or ``num_bins`` beyond int32 indices.
    """
    n = t.shape[0]
    if n > np.iinfo(np.int32).max or num_bins > np.iinfo(np.int32).max:  # sizes, not only indices, are int32
        raise ValueError(f"a stencil of {n} points in {num_bins} bins exceeds the int32 indices of the sort")
    q_bits = 62 - max(n - 1, 1).bit_length() - max(num_bins - 1, 1).bit_length()
    if jax.config.jax_enable_x64 and q_bits >= 20:
        return _sort_order_quantized(edge, t, num_bins, min(q_bits, 52))
    return _sort_order_exact(edge, t, num_bins)


def mass_before_sort(edge: jax.Array, t: jax.Array, m: jax.Array, num_bins: int | None = None) -> jax.Array:
    """Same as :func:`mass_before_rank`, via a sort and a segmented scan.

    ``O(P log P)`` work. The scan is segmented (not a global cumsum minus the
    run offset) so that a light edge stays exact next to heavy ones.

    Args:
      edge: ``(P,)`` int edge (bin) of each point, in ``[0, num_bins)``.
      t: ``(P,)`` coordinate of each point along its edge.
      m: ``(P,)`` masses.
      num_bins: static bound on ``edge`` (sizes the packed sort key);
        default ``P``.

    Returns:
      ``(P,)`` ``C_i = sum_j m_j [edge_j == edge_i] [j precedes i]``.
    """
    order = sort_order(edge, t, t.shape[0] if num_bins is None else num_bins)
    before = _segmented_exclusive_cumsum(edge[order], m[order])
    return jnp.zeros_like(m).at[order].set(before, unique_indices=True)
