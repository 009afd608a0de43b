"""The canonical frame: entry points compute on coordinates and masses of order one.

Squared-distance forms (``cross^2 / |d|^2``, ``m |p - v|^2``) need ``|x|^4``
and ``m x^2`` to fit in float64, which fails long before ``x`` itself does
(coordinates near ``1e-160`` or ``1e160``). So an entry point maps its
validated input here, computes, and maps the results back to the user's units.

The map, for points in a bounding box of diagonal ``D``:

* ``q = p / s - c / s`` with ``s = 2^scale_exp`` the smallest power of two
  ``>= D`` (the canonical diagonal is in ``(1/2, 1]``) and ``c`` the box
  centre rounded (half up) to a multiple of ``s / 2^CENTRE_BITS``;
* masses ``m / M`` with ``M`` the largest mass, ``M = mass_mantissa 2^mass_exp``;
* back: vertices ``q s + c``, masses ``x M``, lengths ``x s``,
  costs (mass times squared length) ``x s^2 M``.

Exactness. A product with a power of two is exact unless it is subnormal,
and ``scale_exp``, ``c`` and ``mass_exp`` follow an exact power-of-two
scaling of the input, so an input scaled exactly by ``2^k`` gives bitwise the
same canonical points and masses, hence the same computation; the results
mapped back are ``2^k`` times the unscaled ones bitwise, except components of
magnitude below ``2^-1022`` (subnormal), which are within ``2^-1075``. Translation: ``q`` is one rounded
subtraction, exact when ``p`` and ``c`` share a power-of-two grid fine enough
for their difference (for instance ``p`` within a factor of two of ``c``, or a
translation by a multiple of ``s / 2^CENTRE_BITS`` of points on a grid);
otherwise it is off by at most half an ulp of ``|q| <= 1``, that is
``2^-54 s <= 2^-53 D`` in input units. Mapping a vertex back adds one more
rounding, half an ulp of its coordinate in input units; so a result computed
on input translated by ``T`` is the untranslated result plus ``T`` to within
an ulp of ``|T| + D`` per coordinate whenever the canonical input is the same.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# The centre sits on a grid of s / 2^CENTRE_BITS: coarse enough that a translation by
# a multiple of it moves the centre exactly, and that an input within a quarter box of
# the origin is only scaled (exactly), fine enough that |q| stays below 1/2 + 2^-2
# (docs/decisions.md#centre_bits).
# Rounded half up, not half to even: floor(x + 1/2 + N) = floor(x + 1/2) + N for an
# integer N, while round-half-even may break a tie the other way after a translation; and
# not down, which puts the common box centred at a multiple of the grid on a rounding edge.
CENTRE_BITS = 2
# Input coordinates must stay below this so that results in input units (vertices up to
# a box diagonal outside the points) cannot overflow.
MAX_COORDINATE = 2.0**1022
_TINY = np.finfo(np.float64).tiny  # 2^-1022, the smallest normal float64


class Frame(NamedTuple):
    """A canonical frame (see the module doc).

    Attributes:
      centre: ``(d,)`` float64, the box centre rounded to the grid, in input units.
      scale_exp: ``s = 2^scale_exp`` (kept as an exponent: ``s`` itself may
        not be a finite float64).
      mass_exp, mass_mantissa: the mass unit is ``mass_mantissa * 2^mass_exp``
        (the largest input mass; ``mass_mantissa`` in ``[1/2, 1)``), so that
        equal masses of any size all become exactly 1.
    """

    centre: np.ndarray
    scale_exp: int
    mass_exp: int
    mass_mantissa: float = 1.0

    def points_in(self, points: np.ndarray) -> np.ndarray:
        """``(n, d)`` input points to canonical coordinates."""
        return np.ldexp(points, -self.scale_exp) - np.ldexp(self.centre, -self.scale_exp)

    def points_out(self, q: np.ndarray) -> np.ndarray:
        """``(n, d)`` canonical points to input units."""
        return np.ldexp(np.asarray(q, np.float64), self.scale_exp) + self.centre

    def length_in(self, x: float) -> float:
        """A length (a distance tolerance) in canonical units; ``inf`` past float64, where
        it is longer than anything in the canonical box anyway."""
        with np.errstate(over="ignore", under="ignore"):
            return float(np.ldexp(x, -self.scale_exp))

    def masses_in(self, masses: np.ndarray) -> np.ndarray:
        """``(n,)`` masses in canonical units (one rounding each; exact for the largest)."""
        return np.ldexp(masses, -self.mass_exp) / self.mass_mantissa

    def masses_out(self, m) -> np.ndarray:
        """Masses (``edge_mass``, transported masses) in input units."""
        return np.ldexp(np.asarray(m, np.float64) * self.mass_mantissa, self.mass_exp)

    def cost_out(self, cost: float) -> tuple[float, int]:
        """A cost (mass times squared length) in input units, as ``(value, exponent)``.

        The cost is ``value * 2^exponent``. ``exponent`` is 0 whenever the cost
        is zero or a normal float64 in input units; otherwise (it would
        overflow, or underflow and lose digits) ``value`` is the canonical cost
        and ``exponent = 2 scale_exp + mass_exp``, so no digit is lost.
        """
        exponent = 2 * self.scale_exp + self.mass_exp
        cost = float(cost) * self.mass_mantissa
        with np.errstate(over="ignore", under="ignore"):
            value = float(np.ldexp(cost, exponent))
        if value == 0.0 and cost == 0.0 or np.isfinite(value) and value >= _TINY:
            return value, 0
        return cost, exponent


def _power_of_two_at_least(x: float) -> int:
    """The exponent ``e`` of the smallest ``2^e >= x``, for finite ``x > 0``."""
    mantissa, e = np.frexp(x)  # x = mantissa 2^e, mantissa in [1/2, 1)
    return int(e) - 1 if mantissa == 0.5 else int(e)


def canonical_frame(points: np.ndarray, masses: np.ndarray) -> Frame:
    """The canonical frame of validated points and masses.

    Args:
      points: ``(n, d)`` finite float64, not all equal.
      masses: ``(n,)`` finite float64 ``>= 0`` with a positive total.

    Raises:
      ValueError: a coordinate of magnitude ``>= 2^1022`` (results in input
        units could overflow), positive masses so much smaller than the
        largest that they underflow once it is scaled to one, or a total mass
        that overflows float64.
    """
    points = np.asarray(points, np.float64)
    big = np.abs(points).max(initial=0.0)
    if big >= MAX_COORDINATE:
        raise ValueError(
            f"coordinates up to {big:.3g} in magnitude are out of range: results near the points "
            f"must stay finite in float64, so |x| must be below 2^1022 ({MAX_COORDINATE:.3g})"
        )
    # The parameters are computed on an exact power-of-two rescaling with the largest |x| in
    # [1/2, 1): halving a subnormal loses its last bit, and hi - lo may overflow.
    e_big = int(np.frexp(big)[1])
    unit = np.ldexp(points, -e_big)
    lo, hi = unit.min(0), unit.max(0)
    half = hi / 2 - lo / 2
    widest = float(half.max())
    if not widest > 0:
        raise ValueError("all points coincide: the bounding box has no extent")
    e_wide = _power_of_two_at_least(widest)
    # The half diagonal as (norm of exactly normalised half extents) * 2^e_wide: the exponent
    # chosen depends only on the normalised values, so it follows a power-of-two scaling exactly.
    half_diag = float(np.linalg.norm(np.ldexp(half, -e_wide)))
    scale_exp = e_wide + _power_of_two_at_least(half_diag) + 1  # of unit's box
    mid = lo / 2 + hi / 2
    grid_exp = max(scale_exp - CENTRE_BITS, -1074 - e_big)  # a grid float64 holds in input units
    centre = mid.copy()
    # |mid| >= 2^53 grid: mid is already a multiple of the grid.
    near = np.frexp(mid)[1] <= 53 + grid_exp  # |mid| < 2^(53 + grid_exp), compared in exponents
    centre[near] = np.ldexp(np.floor(np.ldexp(mid[near], -grid_exp) + 0.5), grid_exp)
    centre = np.ldexp(centre, e_big)  # exact: a multiple of 2^(grid_exp + e_big) >= 2^-1074
    scale_exp += e_big
    mass_exp = _mass_exp(masses)
    mantissa = float(np.ldexp(np.asarray(masses, np.float64).max(), -mass_exp))
    return Frame(centre, scale_exp, mass_exp, mantissa)


def _mass_exp(masses: np.ndarray) -> int:
    masses = np.asarray(masses, np.float64)
    largest = float(masses.max())
    mass_exp = int(np.frexp(largest)[1])  # largest / 2^mass_exp in [1/2, 1)
    scaled = np.ldexp(masses, -mass_exp)
    lost = (masses > 0) & (scaled < _TINY)
    if lost.any():
        i = int(np.flatnonzero(lost)[0])
        raise ValueError(
            f"masses span too wide a range for float64: {np.count_nonzero(lost)} positive mass(es), "
            f"first at index {i} ({masses[i]:.3g}), are below 2^-1022 times the largest ({largest:.3g}) "
            "and would underflow; set them to 0 or rescale"
        )
    with np.errstate(over="ignore"):
        total = np.ldexp(scaled.sum(), mass_exp)
    if not np.isfinite(total):
        raise ValueError(f"the total mass overflows float64 (largest mass {largest:.3g}); rescale the masses")
    return mass_exp


def to_canonical(points, masses) -> tuple[Frame, np.ndarray, np.ndarray]:
    """``(frame, canonical points, canonical masses)`` of validated input.

    Raises:
      ValueError: as :func:`canonical_frame`, or two distinct points that
        coincide in the canonical frame (they differ by less than float64
        resolves at the scale of the bounding box, e.g. a point near the
        origin of a box far from it).
    """
    points = np.asarray(points, np.float64)
    frame = canonical_frame(points, masses)
    with np.errstate(over="ignore", invalid="ignore"):  # a box far thinner than its distance from 0
        q = frame.points_in(points)
        # Rows mapped exactly cannot collide: p/s did not underflow (it scales back to p) and
        # (q + c/s) recovers p/s. Only if some row was rounded is the (sorting) duplicate
        # check worth its time.
        scaled = np.ldexp(points, -frame.scale_exp)
        shift = np.ldexp(frame.centre, -frame.scale_exp)
    if not np.all(np.isfinite(q)):
        raise ValueError("the points' bounding box is too small for its distance from the origin: float64 "
                         "cannot hold them in units of the box; move them nearer the origin")
    if np.any(np.ldexp(scaled, frame.scale_exp) != points) or np.any(q + shift != scaled):
        _, first, inverse = np.unique(q + 0.0, axis=0, return_index=True, return_inverse=True)
        if len(first) < len(q):
            inverse = inverse.reshape(-1)
            j = int(np.flatnonzero(first[inverse] != np.arange(len(q)))[0])
            i = int(first[inverse[j]])
            raise ValueError(
                f"points {i} and {j} ({points[i].tolist()} and {points[j].tolist()}) are distinct but "
                "closer than float64 resolves at the scale of the bounding box: they coincide once "
                "translated to its centre and scaled to its size; merge or move them"
            )
    return frame, q, frame.masses_in(np.asarray(masses, np.float64))
