"""Input checks shared by every public entry point.

Each check raises a :class:`ValueError` whose message names the problem and,
where it helps, the offending row, so that bad input never reaches scipy or
JAX (where it would surface as a deep traceback or a silently wrong result).
The checks return clean float64 copies; they never modify their arguments.
"""

from __future__ import annotations

import numbers

import numpy as np

from otjax.predicates import orient

# A wrong type is a ValueError too, not a TypeError (the noqa: TRY004 below): DESIGN.md
# promises one exception type for bad input, which is what the CLI catches.


# Point and vertex ids travel as int32 in kernel buffers, and edge keys are packed as
# a * n + b in int64: both hold for fewer than 2^31 points.
MAX_POINTS = np.iinfo(np.int32).max


def _as_float_array(value, name: str, copy: bool = True) -> np.ndarray:
    """``value`` as a float64 array, refusing strings, booleans and complex numbers;
    without ``copy`` an array of a real dtype comes back as it is (no copy yet)."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as err:  # ragged nested lists
        raise ValueError(f"{name} must be an array of numbers: {err}") from None
    if arr.dtype.kind == "O":
        try:
            arr = arr.astype(np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be an array of numbers, got non-numeric entries") from None
    elif arr.dtype.kind not in "iuf":
        # Booleans and complex numbers convert silently in NumPy; neither is a coordinate.
        raise ValueError(f"{name} must be an array of real numbers, got dtype {arr.dtype}")
    return np.array(arr, dtype=np.float64) if copy else arr  # a copy: callers may keep theirs


def _first_rows(mask: np.ndarray) -> tuple[int, int]:
    """(count, first index) of the true entries of a ``(n,)`` bool mask."""
    rows = np.flatnonzero(mask)
    return len(rows), int(rows[0])


def _group_duplicates(points: np.ndarray):
    """Groups equal rows.

    Returns:
      ``(first, inverse)``: ``first (u,)`` the row index of each distinct point's
      first occurrence, in increasing order; ``inverse (n,)`` the group of each row.
    """
    # Adding 0.0 turns -0.0 into +0.0, so the two zeros (equal as numbers) group together.
    _, first, inverse = np.unique(points + 0.0, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(first, kind="stable")  # groups in order of first occurrence
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse]


def _all_collinear(points: np.ndarray) -> bool:
    """Whether ``(n, d)`` distinct points (``d`` = 2 or 3, ``n >= 2``) lie on one line, exactly.

    Uses the exact orientation predicate against two distinct points, so the
    answer is the true one for the input doubles (no tolerance). In 3D the
    three components of the cross product ``(b - a) x (p - a)`` are the 2D
    orientations of the projections on the coordinate planes.
    """
    # A power-of-two scaling is exact and keeps every orientation sign; it keeps the
    # float filter's products finite for coordinates near the ends of the float64 range.
    points = np.ldexp(points, -int(np.frexp(np.abs(points).max())[1]))
    a = points[0]
    b = points[np.argmax(np.abs(points - a).sum(1))]  # any other point works; the farthest reads best
    planes = [(0, 1)] if points.shape[1] == 2 else [(0, 1), (1, 2), (0, 2)]
    for i, j in planes:
        ij = [i, j]
        if np.any(orient(a[ij], b[ij], points[:, ij]) != 0):
            return False
    return True


def _check_masses(masses, n: int) -> np.ndarray:
    """``(n,)`` finite non-negative masses with a positive total, as float64."""
    mass = _as_float_array(masses, "masses")
    if mass.shape != (n,):
        raise ValueError(f"masses must have shape ({n},) to match points, got shape {mass.shape}")
    bad = ~np.isfinite(mass)
    if bad.any():
        count, first = _first_rows(bad)
        raise ValueError(f"masses contain NaN or inf in {count} entr(ies), first at index {first}")
    bad = mass < 0
    if bad.any():
        count, first = _first_rows(bad)
        raise ValueError(f"masses must be >= 0: {count} negative, first at index {first}")
    if not mass.max() > 0:  # the max, not the sum: a sum of huge masses overflows (the frame says so)
        raise ValueError("masses are all zero: the total mass must be positive")
    return mass


def check_points(
    points,
    masses=None,
    *,
    dim: int = 2,
    min_points: int = 3,
    merge_duplicates: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Validates a weighted point set.

    Args:
      points: ``(n, dim)`` array-like of finite real coordinates.
      masses: ``(n,)`` array-like of finite non-negative masses with a positive
        total, or ``None`` for unit masses.
      dim: number of coordinates per point (2 or 3).
      min_points: the fewest distinct points accepted.
      merge_duplicates: merge repeated points into one, summing their masses,
        in order of first occurrence. Otherwise a repeated point is an error.

    Returns:
      ``(points, masses)``: ``(n', dim)`` and ``(n',)`` float64 copies, where
      ``n' < n`` only when duplicates were merged.

    Raises:
      ValueError: naming the problem (shape, too few points, NaN/inf, bad
        masses, duplicate points, all points coincident; in 3D all points
        collinear). Collinear 2D points are valid: the curve method's pinned
        box corners make their triangulation well defined.

    Example:
      >>> p, m = check_points([[0, 0], [1, 0], [0, 1], [0, 1]], merge_duplicates=True)
      >>> p.shape, m.tolist()
      ((3, 2), [1.0, 1.0, 2.0])
    """
    pts = _as_float_array(points, "points", copy=False)
    if pts.ndim != 2 or pts.shape[1] != dim:
        raise ValueError(f"points must have shape (n, {dim}), got shape {pts.shape}")
    n = len(pts)
    if n < min_points:
        raise ValueError(f"need at least {min_points} points, got {n}")
    if n > MAX_POINTS:  # before the copy below
        raise ValueError(f"at most {MAX_POINTS} points (int32 indices), got {n}")
    pts = np.array(pts, dtype=np.float64)  # a copy: callers may keep theirs
    bad = ~np.isfinite(pts).all(1)
    if bad.any():
        count, first = _first_rows(bad)
        raise ValueError(f"points contain NaN or inf in {count} row(s), first at row {first}")

    mass = np.ones(n) if masses is None else _check_masses(masses, n)
    if np.all(pts == pts[0]):
        raise ValueError(f"all {n} points coincide at {pts[0].tolist()}")
    first, group = _group_duplicates(pts)
    if len(first) < n:
        if not merge_duplicates:
            is_dup = first[group] != np.arange(n)
            count, j = _first_rows(is_dup)
            i = int(first[group[j]])
            raise ValueError(
                f"{count} duplicate point(s): rows {i} and {j} are both {pts[j].tolist()}; "
                "pass merge_duplicates=True (CLI: --merge-duplicates) to merge them, summing their masses"
            )
        mass = np.bincount(group, weights=mass, minlength=len(first))
        pts = pts[first]
        if len(pts) < min_points:
            raise ValueError(f"need at least {min_points} distinct points, got {len(pts)} after merging")

    # In 2D the four pinned box corners span the plane whatever the points do, so
    # collinear points (a segment, a polyline along one line) are valid input.
    # A 3D complex needs more than a line.
    if dim == 3 and _all_collinear(pts):
        raise ValueError(f"all {len(pts)} distinct points are collinear: 3D reconstruction needs points off a line")
    return pts, mass


def check_target(n_vertices, n_points: int, minimum: int = 1) -> int:
    """Validates a target vertex count against the number of points.

    Args:
      n_vertices: the requested count (an integer, not a bool or float).
      n_points: how many (distinct) points there are.
      minimum: the fewest vertices the method can return.

    Returns:
      ``n_vertices`` as a Python int.

    Example:
      >>> check_target(10, 500)
      10
    """
    if isinstance(n_vertices, bool) or not isinstance(n_vertices, numbers.Integral):
        raise ValueError(f"n_vertices must be an integer, got {n_vertices!r}")  # noqa: TRY004
    n_vertices = int(n_vertices)
    if n_vertices < minimum:
        raise ValueError(f"n_vertices must be at least {minimum}, got {n_vertices}")
    if n_vertices > n_points:
        raise ValueError(f"n_vertices ({n_vertices}) cannot exceed the number of points ({n_points})")
    return n_vertices


def check_nonnegative(name: str, value) -> float:
    """A finite number >= 0 (e.g. a tolerance or a relevance), as a Python float.

    Example:
      >>> check_nonnegative("relevance", 1)
      1.0
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {_show(value)}")  # noqa: TRY004
    value = _as_float(name, value)
    if value < 0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return value


def check_count(name: str, value, minimum: int = 0) -> int:
    """An integer >= ``minimum`` (e.g. a number of relocation steps), as a Python int.

    Example:
      >>> check_count("relocation", 2)
      2
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be an integer, got {_show(value)}")  # noqa: TRY004
    return _as_int(name, value, minimum)


def check_number(name: str, value, *, minimum: float = 0.0, integer: bool = False, allow_none: bool = False):
    """A finite number (or integer) ``>= minimum``, as a Python float (int);
    ``None`` passes through when ``allow_none``.

    Bad input is a ``ValueError`` everywhere in otjax, types included.

    Example:
      >>> check_number("choices", 15, minimum=1, integer=True)
      15
    """
    if value is None and allow_none:
        return None
    kind = numbers.Integral if integer else numbers.Real
    if isinstance(value, bool) or not isinstance(value, kind):
        what = "an integer" if integer else "a number"
        raise ValueError(f"{name} must be {what}, got {_show(value)}")  # noqa: TRY004
    if integer:
        return _as_int(name, value, minimum)
    value = _as_float(name, value)
    if value < minimum:
        raise ValueError(f"{name} must be finite and >= {minimum}, got {value!r}")
    return value


def _show(value) -> str:
    """``repr(value)``, cut short: a message stays one readable line whatever the value."""
    text = repr(value)
    return text if len(text) <= 60 else text[:40] + f"... ({len(text)} characters)"


def _as_float(name: str, value) -> float:
    """A finite Python float (a huge Python int does not fit one: an error, not an OverflowError)."""
    try:
        number = float(value)
    except OverflowError:
        number = float("inf")
    if not np.isfinite(number):
        raise ValueError(f"{name} must be a finite number, got {_show(value)}")
    return number


def _as_int(name: str, value, minimum) -> int:
    """An integer ``>= minimum`` that fits int64, where every integer parameter ends up."""
    value = int(value)
    if value < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {_show(value)}")
    if value > np.iinfo(np.int64).max:
        raise ValueError(f"{name} must be at most 2^63 - 1, got {_show(value)}")
    return value
