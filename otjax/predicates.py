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
# Orientations the float filter leaves unsure, up to this many in a call,
# are settled one at a time (~1 us each); more go to the vectorised path.
# There the rows the product comparison leaves are split by the same bound
# between the integer path (~2.3 us a row) and the expansions (~0.25 ms a
# call) (docs/decisions.md#scalar_unsure).
SCALAR_UNSURE = 96


def _subtracts_exactly(x, y, d) -> bool:
    """Whether ``d = fl(x - y)`` is exact: Knuth's two-sum error of ``x + (-y)`` is zero."""
    bb = d - x
    return (x - (d - bb)) + (-y - bb) == 0


def _exact_orient(ax, ay, bx, by, cx, cy) -> int:
    """Exact orientation sign of one triangle (six floats): products, else integers."""
    u, v, w, z = bx - ax, cy - ay, by - ay, cx - ax
    left, right = u * v, w * z
    # With the four differences exact, the determinant is left - right before
    # rounding, and rounding is monotone: distinct rounded products compare
    # as the exact ones. Near-equal coordinates subtract exactly, so this
    # settles most orientations the filter leaves to collinear input.
    if left != right and _subtracts_exactly(bx, ax, u) and _subtracts_exactly(cy, ay, v) \
            and _subtracts_exactly(by, ay, w) and _subtracts_exactly(cx, ax, z):
        return 1 if left > right else -1
    return _exact_orient_integer(ax, ay, bx, by, cx, cy)


def _exact_orient_integer(ax, ay, bx, by, cx, cy) -> int:
    # Every double is n / 2^k: over the largest denominator all six are
    # integers, and Python integer arithmetic is exact and ~20x faster than
    # Fraction (collinear data, e.g. noise-free polygons, needs an exact path
    # for almost every point lying on an edge).
    # Unrolled: generator overhead was half the cost of a call.
    (nax, dax), (nay, day) = float(ax).as_integer_ratio(), float(ay).as_integer_ratio()
    (nbx, dbx), (nby, dby) = float(bx).as_integer_ratio(), float(by).as_integer_ratio()
    (ncx, dcx), (ncy, dcy) = float(cx).as_integer_ratio(), float(cy).as_integer_ratio()
    den = max(dax, day, dbx, dby, dcx, dcy)
    ax, ay, bx, by = nax * (den // dax), nay * (den // day), nbx * (den // dbx), nby * (den // dby)
    cx, cy = ncx * (den // dcx), ncy * (den // dcy)
    det = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    return (det > 0) - (det < 0)


# Error-free transformations (Knuth's two-sum, Dekker's split and product)
# are exact while nothing overflows and no product's rounding error falls
# below the normal range; inputs outside this magnitude window take the
# Python-integer path instead.
_SPLITTER = 134217729.0  # 2^27 + 1
_SAFE_LO, _SAFE_HI = 2.0**-480, 2.0**480
# VecSum passes before a row is left to the integer path; on every input of
# the tests two passes decided all rows.
_MAX_PASSES = 6


def _two_sum(a, b):
    s = a + b
    bb = s - a
    return s, (a - (s - bb)) + (b - bb)


def _split(a):
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


def _two_product(a, b):
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, ((ah * bh - p) + ah * bl + al * bh) + al * bl


def _exact_orient_many(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Exact orientation signs of ``(N, 2)`` triangles, vectorised.

    Rows whose four coordinate differences are exact and whose two rounded
    products differ are decided by comparing those (as in
    :func:`_exact_orient`: a few operations a row, where the expansion
    below costs ~100); the others go to :func:`_exact_orient_expansion`,
    or one at a time to the integer path when at most
    :data:`SCALAR_UNSURE` are left.

    Returns:
      ``(N,)`` int8 in ``{-1, 0, +1}``.
    """
    ends = ((b[:, 0], a[:, 0]), (c[:, 1], a[:, 1]), (b[:, 1], a[:, 1]), (c[:, 0], a[:, 0]))
    u, v, w, z = (x - y for x, y in ends)
    left, right = u * v, w * z
    quick = left != right
    for x, y in ends:
        quick &= _two_sum(x, -y)[1] == 0
    out = np.where(left > right, 1, -1).astype(np.int8)
    rest = np.flatnonzero(~quick)
    if len(rest) > SCALAR_UNSURE:
        out[rest] = _exact_orient_expansion(a[rest], b[rest], c[rest])
    elif len(rest):  # fewer than the expansion's fixed cost (~0.3 ms) covers
        rows = np.concatenate([a[rest], b[rest], c[rest]], axis=1).tolist()
        out[rest] = [_exact_orient_integer(*r) for r in rows]
    return out


def _exact_orient_expansion(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Exact orientation signs of ``(N, 2)`` triangles by error-free expansion.

    The determinant ``(bx-ax)(cy-ay) - (by-ay)(cx-ax)`` is written exactly
    as a sum of 16 doubles (two-term differences, their pairwise products
    split error-free); repeated VecSum passes (Ogita, Rump and Oishi 2005)
    keep that sum exact while concentrating it in the last term, until the
    last term's magnitude exceeds the others' total and so gives the sign.
    Rows outside the exactness window, or still undecided, go to
    :func:`_exact_orient_integer`.
    """
    terms = []
    for (p, q, r, t) in ((b[:, 0], a[:, 0], c[:, 1], a[:, 1]), (b[:, 1], a[:, 1], c[:, 0], a[:, 0])):
        u, ue = _two_sum(p, -q)
        v, ve = _two_sum(r, -t)
        terms.append((u, ue, v, ve))
    factors = np.stack([x for group in terms for x in group], 1)  # (N, 8)
    mag = np.abs(factors)
    safe = np.all((mag == 0) | ((mag >= _SAFE_LO) & (mag <= _SAFE_HI)), axis=1)
    parts = []
    for sign, (u, ue, v, ve) in zip((1.0, -1.0), terms):
        for x, y in ((u, v), (u, ve), (ue, v), (ue, ve)):
            prod, err = _two_product(x, y)
            parts += [sign * prod, sign * err]
    t = np.stack(parts, 1)  # (N, 16), sums exactly to the determinant
    out = np.zeros(len(t), np.int8)
    undecided = safe.copy()
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(_MAX_PASSES):
            rows = np.flatnonzero(undecided)
            if not len(rows):
                break
            v = t[rows]
            for i in range(1, v.shape[1]):
                v[:, i], v[:, i - 1] = _two_sum(v[:, i], v[:, i - 1])
            t[rows] = v
            last = v[:, -1]
            rest = np.abs(v[:, :-1]).sum(1)
            # The float sum of 15 magnitudes is within 15 eps of the true one.
            sure = np.abs(last) > rest * (1.0 + 2.0**-40)
            zero = (last == 0) & (rest == 0)
            out[rows[sure]] = np.sign(last[sure]).astype(np.int8)
            undecided[rows[sure | zero]] = False
    for k in np.flatnonzero(undecided | ~safe):
        out[k] = _exact_orient_integer(a[k, 0], a[k, 1], b[k, 0], b[k, 1], c[k, 0], c[k, 1])
    return out


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
      >>> orient(np.array([[0., 0.]]), np.array([[1., 0.]]), np.array([[0., 1.], [2., 0.]]))
      array([1, 0], dtype=int8)
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
        k = np.flatnonzero(unsure)
        fa, fb, fc = (x.reshape(-1, 2)[k] for x in (a, b, c))
        if len(k) <= SCALAR_UNSURE:
            rows = np.concatenate([fa, fb, fc], axis=1).tolist()
            sign[k] = [_exact_orient(*r) for r in rows]
        else:
            sign[k] = _exact_orient_many(fa, fb, fc)
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


def orient_perturbed_scalar(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> int:
    """:func:`orient_perturbed` of one edge and point given as six Python floats.

    The same predicate without NumPy's per-call overhead, for callers left
    with a few unsure edges (exactly collinear input leaves many such calls).
    """
    s = orient_scalar(ax, ay, bx, by, px, py)
    if s:
        return s
    # The first non-zero of a_y - b_y and b_x - a_x: exact, as comparisons.
    if ay != by:
        return 1 if ay > by else -1
    return 1 if bx > ax else -1 if bx < ax else 0


def in_triangle_scalar(x0: float, y0: float, x1: float, y1: float, x2: float, y2: float,
                       px: float, py: float) -> bool:
    """:func:`in_triangle_perturbed` of one CCW triangle and point, as Python floats."""
    # Stops at the first edge not positive: the answer is their conjunction.
    return (orient_perturbed_scalar(x0, y0, x1, y1, px, py) > 0
            and orient_perturbed_scalar(x1, y1, x2, y2, px, py) > 0
            and orient_perturbed_scalar(x2, y2, x0, y0, px, py) > 0)


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
