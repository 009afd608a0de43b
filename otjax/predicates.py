"""Exact 2D orientation predicates.

Every topological decision (is this triangle positive? which triangle holds
this point? is this vertex in the kernel?) goes through these functions. They
evaluate in float64 with a forward error bound and fall back to exact rational
arithmetic when the float result is too close to zero to trust, so the answer
is always the sign of the exact determinant of the input doubles. A fold-over
can therefore never be created by rounding, whatever the input.

Point location uses a symbolic perturbation: a query point ``p`` is replaced by
``p + eps*(1, 0) + eps**2*(0, 1)`` for an infinitesimal ``eps``. The perturbed
point lies strictly inside exactly one triangle of any triangulation of a
region containing it, so "the triangle holding a point" is a function of the
geometry alone (not of history or vertex numbering).
"""

from __future__ import annotations

import numpy as np

# Shewchuk's bound for the 2x2 orientation determinant (Adaptive Precision
# Floating-Point Arithmetic, 1997): |det - fl(det)| <= ERR * (|l| + |r|).
_EPS = np.finfo(np.float64).eps / 2
ORIENT_ERR = (3.0 + 16.0 * _EPS) * _EPS


def _exact_orient(ax, ay, bx, by, cx, cy) -> int:
    # Every double is n / 2^k: over the largest denominator all six are
    # integers, and Python integer arithmetic is exact and ~20x faster than
    # Fraction (collinear data, e.g. noise-free polygons, needs this path for
    # almost every point lying on an edge).
    ratios = [float(v).as_integer_ratio() for v in (ax, ay, bx, by, cx, cy)]
    den = max(d for _, d in ratios)
    ax, ay, bx, by, cx, cy = (n * (den // d) for n, d in ratios)
    det = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    return (det > 0) - (det < 0)


def orient_scalar(ax: float, ay: float, bx: float, by: float, cx: float, cy: float) -> int:
    """Exact orientation sign of one triangle given as six Python floats.

    The same predicate as :func:`orient`, without NumPy's per-call overhead,
    for the topology code that asks one question at a time.
    """
    left = (bx - ax) * (cy - ay)
    right = (by - ay) * (cx - ax)
    det = left - right
    if abs(det) > ORIENT_ERR * (abs(left) + abs(right)):
        return 1 if det > 0 else -1
    if (cx == bx and cy == by) or ((bx == ax or cy == ay) and (by == ay or cx == ax)):
        return 0
    return _exact_orient(ax, ay, bx, by, cx, cy)


def orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Exact sign of the orientation of triangles ``(a, b, c)``.

    Args:
      a, b, c: ``(..., 2)`` float64 coordinates (broadcast together).

    Returns:
      ``(...)`` int8: ``+1`` counter-clockwise, ``-1`` clockwise, ``0`` collinear.

    Example:
      >>> orient(np.array([0., 0.]), np.array([1., 0.]), np.array([0., 1.]))
      array(1, dtype=int8)
    """
    a, b, c = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (a, b, c)))
    left = (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
    right = (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])
    det = left - right
    bound = ORIENT_ERR * (np.abs(left) + np.abs(right))
    sign = np.sign(det).astype(np.int8)
    # A product with an exactly-zero factor is exactly zero (float subtraction
    # of two doubles is zero only when they are equal), so the common case of
    # a query point sitting on a vertex needs no exact fallback.
    zero = ((b[..., 0] == a[..., 0]) | (c[..., 1] == a[..., 1])) & (
        (b[..., 1] == a[..., 1]) | (c[..., 0] == a[..., 0])
    )
    zero |= (c[..., 0] == b[..., 0]) & (c[..., 1] == b[..., 1])  # repeated point
    unsure = ~(np.abs(det) > bound) & ~zero
    if np.any(unsure):
        shape = sign.shape
        sign, unsure = sign.reshape(-1), unsure.reshape(-1)
        fa, fb, fc = (x.reshape(-1, 2) for x in (a, b, c))
        for k in np.nonzero(unsure)[0]:
            sign[k] = _exact_orient(fa[k, 0], fa[k, 1], fb[k, 0], fb[k, 1], fc[k, 0], fc[k, 1])
        sign = sign.reshape(shape)
    return sign


def orient_perturbed(a: np.ndarray, b: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Sign of ``orient(a, b, p')`` for the symbolically perturbed query ``p'``.

    ``p' = p + eps*(1, 0) + eps**2*(0, 1)``. Expanding the determinant in
    ``eps`` gives ``orient(a, b, p) - eps*(b_y - a_y) + eps**2*(b_x - a_x)``,
    so the sign is decided by the first non-zero of these three exact terms.
    It is zero only when ``a == b``.

    Args:
      a, b: ``(..., 2)`` edge endpoints.
      p: ``(..., 2)`` query points.

    Returns:
      ``(...)`` int8 in ``{-1, 0, +1}``.
    """
    a, b, p = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (a, b, p)))
    s = orient(a, b, p)
    first = np.sign(a[..., 1] - b[..., 1]).astype(np.int8)  # exact: a comparison
    second = np.sign(b[..., 0] - a[..., 0]).astype(np.int8)
    return np.where(s != 0, s, np.where(first != 0, first, second)).astype(np.int8)


def in_triangle_perturbed(tri: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Whether the perturbed query points lie inside CCW triangles.

    Args:
      tri: ``(..., 3, 2)`` positively oriented triangles.
      p: ``(..., 2)`` query points.

    Returns:
      ``(...)`` bool. For a triangulation, exactly one triangle per point.
    """
    # One predicate call over the three edges at once (the arrays are small
    # and NumPy's per-call overhead dominates).
    a = tri
    b = tri[..., [1, 2, 0], :]
    return (orient_perturbed(a, b, np.asarray(p)[..., None, :]) > 0).all(-1)
