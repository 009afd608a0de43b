"""Batched point-in-triangle tests: a filtered JAX kernel, adaptive stages, exact on the host.

Exporting a collapse stencil locates every point of the star among the new
triangles: (point, triangle) pairs by the million late in a large run, where
the NumPy predicate cost ~360 ns a pair (measured: 40 of 60 s of a 50k-point
run's exhaustive end). :func:`in_triangle_filtered` evaluates the same
orientation determinants in JAX, with Shewchuk's forward error bound, and
answers "inside", "outside" or "unsure"; :func:`locate_pairs` settles the
unsure pairs with the exact host predicate
(:func:`otjax.predicates.in_triangle_perturbed`, or its scalar form
:func:`otjax.predicates.in_triangle_scalar` for a few pairs). Its answers
are therefore exactly the host predicate's, pair for pair.

Why the filter is sound even if XLA fuses a multiply-add: the bound covers the
rounding of both products and the subtraction; a fused evaluation rounds
fewer times, so its error is no larger.

:func:`orient_adaptive` adds Shewchuk's stages B and C in JAX, for the
scoring kernel's rows the filter leaves unsure (exactly collinear input):
they decide all but orientations within ~1e-32 relative of zero with inexact
coordinate differences, which stay with the host.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from otjax.batch.pipeline import require_x64
from otjax.predicates import ORIENT_ERR, in_triangle_perturbed, in_triangle_scalar

INSIDE, OUTSIDE, UNSURE = 1, 0, -1
# Pairs per kernel call: one size, one compiled shape. A chunk costs ~0.25 ms;
# a small export pads to it, a large one dispatches several asynchronously.
CHUNK = 1 << 14
# Fewer pairs than this are tested on the host, the filter in NumPy (below
# the cost of one kernel call).
MIN_PAIRS = 512
# Unsure pairs, up to this many in a call, are settled one at a time in
# Python (~2.4 us a pair); more by the vectorised predicate (~60 us a call,
# then ~1-2 us a pair): break-even at 64-96 pairs on the clean 3k-point
# star's unsure pairs, where 72% of the calls leave at most 64.
SCALAR_PAIRS = 64
# Rows of a triangle's second corners: edge k runs from corner k to corner k + 1.
_NEXT_CORNER = np.array([2, 3, 4, 5, 0, 1])


def _orient_perturbed_filtered(ax, ay, bx, by, px, py, xp=jnp) -> tuple[jax.Array, jax.Array]:
    """Sign of ``orient(a, b, p + eps (1, eps))`` where the float filter is sure.

    Args:
      ax, ay, bx, by, px, py: ``(N,)`` float64 coordinates.
      xp: the array module (``jax.numpy`` in kernels, ``numpy`` on the host).

    Returns:
      ``(positive, negative)`` ``(N,)`` bool; both False when the float
      determinant is too close to zero to trust (and not zero by
      construction).
    """
    left = (bx - ax) * (py - ay)
    right = (by - ay) * (px - ax)
    det = left - right
    sure = xp.abs(det) > ORIENT_ERR * (xp.abs(left) + xp.abs(right))
    # Both products exactly zero (an exactly-zero factor each), or p == b:
    # det is 0 and the perturbation decides, by exact comparisons, as on the
    # host: the sign of a_y - b_y, else of b_x - a_x.
    zero = (((bx == ax) | (py == ay)) & ((by == ay) | (px == ax))) | ((px == bx) & (py == by))
    up = xp.where(ay != by, ay > by, bx > ax)
    down = xp.where(ay != by, ay < by, bx < ax)
    positive = xp.where(zero, up, sure & (det > 0))
    negative = xp.where(zero, down, sure & (det < 0))
    return positive, negative


def in_triangle_rows(tri, px, py, xp=jnp) -> jax.Array:
    """Filtered perturbed point-in-triangle test on coordinate rows.

    Args:
      tri: ``(6, ...)`` float64 rows ``x0, y0, x1, y1, x2, y2`` of
        counter-clockwise triangles.
      px, py: ``(...)`` float64 coordinates of the query points.
      xp: the array module (``jax.numpy`` in kernels, ``numpy`` on the host).

    Returns:
      ``(...)`` int8: :data:`INSIDE`, :data:`OUTSIDE` or :data:`UNSURE`. A
      pair is outside as soon as one edge is surely on the wrong side.
    """
    x0, y0, x1, y1, x2, y2 = tri
    p0, n0 = _orient_perturbed_filtered(x0, y0, x1, y1, px, py, xp)
    p1, n1 = _orient_perturbed_filtered(x1, y1, x2, y2, px, py, xp)
    p2, n2 = _orient_perturbed_filtered(x2, y2, x0, y0, px, py, xp)
    return xp.where(n0 | n1 | n2, OUTSIDE, xp.where(p0 & p1 & p2, INSIDE, UNSURE)).astype(xp.int8)


# Shewchuk's adaptive orientation (1997, orient2dadapt), its first stages:
# the float determinant's error bounds of its stages B and C, and the
# splitter of Dekker's exact product.
_EPS = 2.0 ** -53
_ERR_B = (2.0 + 12.0 * _EPS) * _EPS
_ERR_C = (9.0 + 64.0 * _EPS) * _EPS * _EPS
_ERR_RESULT = (3.0 + 8.0 * _EPS) * _EPS
_SPLITTER = 134217729.0  # 2^27 + 1
_TINY = 2.0 ** -400  # products of two larger numbers, and their tails, do not underflow


def _two_sum(a, b):
    """``(x, y)`` with ``x = fl(a + b)`` and ``x + y = a + b`` exactly (Knuth)."""
    x = a + b
    b_virtual = x - a
    a_virtual = x - b_virtual
    return x, (a - a_virtual) + (b - b_virtual)


def _diff_tail(a, b, x):
    """``y`` with ``x + y = a - b`` exactly, for ``x = fl(a - b)``."""
    b_virtual = a - x
    a_virtual = x + b_virtual
    return (a - a_virtual) + (b_virtual - b)


def _two_products(a, b, c, d):
    """``((x, y), (z, w))``: ``x + y = a b`` and ``z + w = c d`` exactly (Dekker).

    The products and the splitter's products pass an optimisation barrier:
    the algorithm needs them rounded as written, and a compiler contracting
    one of them into a fused multiply-add with a later subtraction would
    break the exactness.
    """
    x, z, sa, sb, sc, sd = jax.lax.optimization_barrier(
        (a * b, c * d, _SPLITTER * a, _SPLITTER * b, _SPLITTER * c, _SPLITTER * d))

    def split(v, sv):
        hi = sv - (sv - v)
        return hi, v - hi

    def tail(p, u, su, v, sv):
        uh, ul = split(u, su)
        vh, vl = split(v, sv)
        return ul * vl - (((p - uh * vh) - ul * vh) - uh * vl)

    return (x, tail(x, a, sa, b, sb)), (z, tail(z, c, sc, d, sd))


def orient_adaptive(ax, ay, bx, by, px, py):
    """Sign of ``orient(a, b, p + eps (1, eps))``, where Shewchuk's stages A-C decide it.

    Stage A is the float filter; B evaluates the determinant of the rounded
    differences exactly (a four-term expansion) and is exact when the
    differences are; C adds the differences' first-order tails under its
    error bound. Left undecided are the determinants C cannot bound away
    from zero with inexact differences (points within ``~1e-32`` relative of
    the line through ``a`` and ``b``); the host's exact predicate settles
    those. An exactly zero determinant is decided by the perturbation, by
    exact comparisons as in :func:`otjax.predicates.orient_perturbed`.

    Args:
      ax, ay, bx, by, px, py: ``(N,)`` float64 coordinates.

    Returns:
      ``(positive, negative)`` ``(N,)`` bool, both False where undecided.
    """
    acx, bcx, acy, bcy = ax - px, bx - px, ay - py, by - py
    (left, left_tail), (right, right_tail) = _two_products(acx, bcy, acy, bcx)
    detsum = jnp.abs(left) + jnp.abs(right)
    # Shewchuk's Two_Two_Diff: b3 + b2 + b1 + b0 = (left + left_tail) - (right + right_tail),
    # a nonoverlapping expansion, b3 the most significant.
    i, b0 = _two_sum(left_tail, -right_tail)
    j, k = _two_sum(left, i)
    i2, b1 = _two_sum(k, -right)
    b3, b2 = _two_sum(j, i2)
    det = ((b0 + b1) + b2) + b3
    acx_tail, bcx_tail = _diff_tail(ax, px, acx), _diff_tail(bx, px, bcx)
    acy_tail, bcy_tail = _diff_tail(ay, py, acy), _diff_tail(by, py, bcy)
    exact = (acx_tail == 0) & (bcx_tail == 0) & (acy_tail == 0) & (bcy_tail == 0)
    # With exact differences the expansion is the determinant: its sign is
    # that of the most significant non-zero term.
    lead = jnp.where(b3 != 0, b3, jnp.where(b2 != 0, b2, jnp.where(b1 != 0, b1, b0)))
    sure_b = jnp.abs(det) >= _ERR_B * detsum
    tails = (acx * bcy_tail + bcy * acx_tail) - (acy * bcx_tail + bcx * acy_tail)
    det_c = det + tails
    sure_c = jnp.abs(det_c) >= _ERR_C * detsum + _ERR_RESULT * jnp.abs(det)
    value = jnp.where(exact, lead, jnp.where(sure_b, det, det_c))
    # The bounds assume no underflow: a difference this small (never in the
    # normalised frame) leaves the pair to the host.
    normal = jnp.all(jnp.stack([(d == 0) | (jnp.abs(d) > _TINY) for d in (acx, bcx, acy, bcy)]), 0)
    # A product that rounds to zero has an exactly zero factor (no underflow).
    zero = normal & ((exact & (lead == 0)) | ((left == 0) & (right == 0)))
    known = normal & (exact | sure_b | sure_c)
    up = jnp.where(ay != by, ay > by, bx > ax)
    down = jnp.where(ay != by, ay < by, bx < ax)
    positive = jnp.where(zero, up, known & (value > 0))
    negative = jnp.where(zero, down, known & (value < 0))
    return positive, negative


def in_triangle_adaptive(tri, px, py):
    """:func:`in_triangle_rows` decided by :func:`orient_adaptive` instead of the filter alone.

    Returns:
      ``(...)`` int8: :data:`INSIDE`, :data:`OUTSIDE` or, where an edge is
      left undecided and none is surely outside, :data:`UNSURE`.
    """
    x0, y0, x1, y1, x2, y2 = tri
    p0, n0 = orient_adaptive(x0, y0, x1, y1, px, py)
    p1, n1 = orient_adaptive(x1, y1, x2, y2, px, py)
    p2, n2 = orient_adaptive(x2, y2, x0, y0, px, py)
    return jnp.where(n0 | n1 | n2, OUTSIDE, jnp.where(p0 & p1 & p2, INSIDE, UNSURE)).astype(jnp.int8)


@jax.jit
def in_triangle_filtered(tri: jax.Array, p: jax.Array) -> jax.Array:
    """:func:`in_triangle_rows` on ``(6, N)`` triangles and ``(2, N)`` points.

    Coordinates come as rows (structure of arrays): XLA:CPU vectorises that
    layout about 3x better than ``(N, 3, 2)`` (measured: 14 vs 35-59 ns a
    pair).
    """
    return in_triangle_rows(tri, p[0], p[1])


@functools.cache
def _padding(size: int) -> tuple[np.ndarray, np.ndarray]:
    # A padded pair: a unit triangle and a point outside it (never read).
    tri = np.zeros((6, size))
    tri[2] = tri[5] = 1.0
    return tri, np.full((2, size), 2.0)


def _kernel_codes(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """:func:`in_triangle_filtered` of ``(6, N)`` triangles and ``(2, N)`` points, in chunks.

    Returns:
      ``(N,)`` int8 codes, as :func:`in_triangle_rows`.
    """
    n = p.shape[1]
    out = np.empty(n, np.int8)
    require_x64("exact point location")
    pending = []
    for s in range(0, n, CHUNK):
        t, q = tri[:, s:s + CHUNK], p[:, s:s + CHUNK]
        if q.shape[1] < CHUNK:
            pad_t, pad_q = _padding(CHUNK)
            t = np.concatenate([t, pad_t[:, q.shape[1]:]], 1)
            q = np.concatenate([q, pad_q[:, q.shape[1]:]], 1)
        pending.append((s, in_triangle_filtered(t, q)))  # dispatched asynchronously
    for s, res in pending:
        res = np.asarray(res)
        out[s:s + len(res)] = res[: n - s]
    return out


def _edge_signs(tri: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_orient_perturbed_filtered` of the three edges at once, in NumPy.

    One pass over ``(3, N)`` rows rather than three over ``(N,)``: on the
    few hundred pairs of a typical host call NumPy's per-call overhead, not
    the arithmetic, is the cost.

    Args:
      tri: ``(6, N)`` float64 rows ``x0, y0, x1, y1, x2, y2``.
      p: ``(2, N)`` float64 query points, as rows.

    Returns:
      ``(positive, negative)``, each ``(3, N)`` bool; row ``k`` is the edge
      from corner ``k`` to corner ``k + 1 mod 3``.
    """
    ends = tri[_NEXT_CORNER]
    return _orient_perturbed_filtered(tri[0::2], tri[1::2], ends[0::2], ends[1::2], p[0], p[1], np)


def _settle(tri: np.ndarray, p: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Exact answers of the pairs ``idx`` the filter left unsure, ``(k,)`` bool.

    A few go one at a time through the scalar predicate, where NumPy's
    per-call overhead would dominate; more through the vectorised one (which
    evaluates exactly only the edges its own filter leaves unsure).
    """
    t, q = np.take(tri, idx, axis=1).T, np.take(p, idx, axis=1).T
    if len(idx) <= SCALAR_PAIRS:
        return np.array([in_triangle_scalar(*c, *x) for c, x in zip(t.tolist(), q.tolist())], bool)
    return in_triangle_perturbed(t.reshape(-1, 3, 2), q)


def locate_pairs(tri: np.ndarray, p: np.ndarray, min_pairs: int = MIN_PAIRS) -> np.ndarray:
    """Exact perturbed point-in-triangle test for many pairs.

    Same answers as :func:`otjax.predicates.in_triangle_perturbed`,
    computed by the filtered kernel in fixed-size chunks (below
    ``min_pairs``, by the same filter in NumPy); the unsure pairs (a handful
    on noisy data, more on exactly collinear data) go to the exact host
    predicate (:func:`_settle`).

    Args:
      tri: ``(6, N)`` float64 rows ``x0, y0, x1, y1, x2, y2`` of
        counter-clockwise triangles.
      p: ``(2, N)`` float64 query points, as rows.
      min_pairs: below this many pairs the filter runs in NumPy instead of
        the kernel (the answers do not depend on it).

    Returns:
      ``(N,)`` bool.
    """
    if p.shape[1] < min_pairs:
        # The kernel's filter in NumPy, on the rows as they are: cheaper than
        # the exact predicate's (N, 3, 2) layout on every pair.
        positive, negative = _edge_signs(tri, p)
        hold = positive.all(0)
        unsure = np.flatnonzero(~(hold | negative.any(0)))
    else:
        out = _kernel_codes(tri, p)
        hold, unsure = out == INSIDE, np.flatnonzero(out == UNSURE)
    if len(unsure):
        hold[unsure] = _settle(tri, p, unsure)
    return hold
