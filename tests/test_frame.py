"""The canonical frame: exact under power-of-two scalings, within a stated
bound (exact on grids) under translations, clear errors where float64 cannot
hold the normalised input."""

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.frame import CENTRE_BITS, MAX_COORDINATE, canonical_frame, to_canonical

TINY = np.finfo(np.float64).tiny


@st.composite
def grid_sets(draw, bits=20, max_n=30):
    """Points with coordinates ``i / 2^bits``, ``|i| <= 2^bits`` (not all equal), and integer masses."""
    n = draw(st.integers(3, max_n))
    coords = st.integers(-(2**bits), 2**bits)
    ints = np.array(draw(st.lists(st.tuples(coords, coords), min_size=n, max_size=n)), np.float64)
    if np.all(ints == ints[0]):
        ints[0, 0] += 1 if ints[0, 0] < 2**bits else -1
    masses = np.array(draw(st.lists(st.integers(0, 2**20), min_size=n, max_size=n)), np.float64)
    masses[draw(st.integers(0, n - 1))] += 1  # a positive total
    return np.ldexp(ints, -bits), masses


def exact(x) -> np.ndarray:
    """Float64 values as exact rationals (object array)."""
    return np.vectorize(Fraction, otypes=[object])(np.asarray(x, np.float64))


@settings(max_examples=200, deadline=None)
@given(data=grid_sets(), k=st.integers(-1000, 1000), j=st.integers(-1000, 1000))
def test_power_of_two_scalings_give_the_same_canonical_input_bitwise(data, k, j):
    points, masses = data
    scaled_p, scaled_m = np.ldexp(points, k), np.ldexp(masses, j)  # exact: every value stays normal
    assert np.array_equal(np.ldexp(scaled_p, -k), points) and np.array_equal(np.ldexp(scaled_m, -j), masses)
    f0, q0, m0 = to_canonical(points, masses)
    fk, qk, mk = to_canonical(scaled_p, scaled_m)
    assert fk.scale_exp == f0.scale_exp + k and fk.mass_exp == f0.mass_exp + j
    np.testing.assert_array_equal(fk.centre, np.ldexp(f0.centre, k))
    assert np.array_equal(qk, q0) and np.array_equal(mk, m0)
    np.testing.assert_array_equal(fk.points_out(q0), scaled_p)  # on this grid the way back is exact too
    cost0, cost_k = f0.cost_out(1.25), fk.cost_out(1.25)
    assert Fraction(cost_k[0]) * Fraction(2) ** cost_k[1] == Fraction(cost0[0]) * Fraction(2) ** (cost0[1] + 2 * k + j)


@settings(max_examples=200, deadline=None)
@given(data=grid_sets(bits=12), scale=st.sampled_from([1.0, 1e-300, 3e-9, 7e40, 1e300]),
       shift=st.floats(-1e12, 1e12))
def test_canonical_points_lie_in_a_unit_box_within_half_an_ulp(data, scale, shift):
    """``|q| < 1/2 + 2^-10``, canonical diagonal in ``(1/2, 1]``, and ``q`` is the exact
    ``(p - c) / s`` to within half an ulp of 1/2 (the one rounding of the translation)."""
    points, masses = data
    points = points * scale
    points = points + shift * float(np.ptp(points, 0).max())  # up to 1e12 times the box size
    if len(np.unique(points, axis=0)) < len(points) or np.all(points == points[0]):
        return  # the translation itself merged points: check_points refuses that input
    frame, q, _ = to_canonical(points, masses)
    assert np.abs(q).max() < 0.5 + 2.0**-CENTRE_BITS
    diag = np.linalg.norm(q.max(0) - q.min(0))
    assert 0.5 - 2.0**-52 < diag <= 1.0 + 2.0**-52
    s = Fraction(2) ** frame.scale_exp
    error = (exact(q) - (exact(points) - exact(frame.centre)) / s).astype(float)
    assert np.abs(error).max() <= 2.0**-54


@settings(max_examples=150, deadline=None)
@given(data=grid_sets(bits=11), steps=st.integers(-(2**40), 2**40))
def test_translations_on_the_grid_give_the_same_canonical_input(data, steps):
    """Points on a grid of 2^-11 in [-1, 1] (box scale s <= 4), moved by an integer (a
    multiple of s / 2^CENTRE_BITS) up to 2^40 (about 1e12 box sizes): exact."""
    points, masses = data
    shift = float(steps)
    moved = points + shift
    assert np.array_equal(moved - shift, points)  # the test's own translation is exact
    f0, q0, m0 = to_canonical(points, masses)
    f1, q1, m1 = to_canonical(moved, masses)
    assert f1.scale_exp == f0.scale_exp and np.array_equal(f1.centre, f0.centre + shift)
    assert np.array_equal(q1, q0) and np.array_equal(m1, m0)
    # The way back: one rounding, at most half an ulp of the translated coordinate.
    back = f1.points_out(q0)
    assert np.all(np.abs(back - moved) <= np.spacing(np.abs(moved)) / 2)


def test_extreme_but_valid_inputs_are_accepted():
    base = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    for points in (base * 2.0**1021, base * 5e-324, base * 1e290 + 1e300, base * 1e-300 + 1e-290):
        frame, q, m = to_canonical(points, np.ones(3))
        assert np.isfinite(q).all() and len(np.unique(q, axis=0)) == 3
        assert np.isfinite(frame.points_out(q)).all()
    frame, _, m = to_canonical(base, np.full(3, 1e-320))  # subnormal masses, all alike: exact
    np.testing.assert_array_equal(frame.masses_out(m), np.full(3, 1e-320))


@pytest.mark.parametrize(
    ("points", "masses", "words"),
    [
        ([[0, 0], [MAX_COORDINATE, 0], [0, 1]], None, ["out of range", "2^1022"]),
        ([[0, 0], [1, 0], [0, -1.7e308]], None, ["out of range"]),
        ([[0, 0], [1, 0], [0, 1]], [1.0, 1e-320, 1.0], ["masses span", "index 1", "underflow"]),
        ([[0, 0], [1, 0], [0, 1]], [1e300, 1e-30, 1.0], ["masses span", "index 1"]),
        ([[0, 0], [1, 0], [0, 1]], [1.7e308, 1.7e308, 1e300], ["total mass overflows"]),
        ([[0, 0], [1e-20, 0], [1, 0], [1, 1]], None, ["points 0 and 1", "closer than float64 resolves"]),
        ([[1e12, 0], [1e12, 1e-18], [1e12 + 1, 0], [1e12, 1]], None, ["points 0 and 1", "closer than float64"]),
        # Collapsed by the scaling itself (the third point's y underflows), not by the translation.
        ([[0, 0], [0, 6.90174635e69], [0, 2.71128045e-254]], None, ["points 0 and 2", "closer than float64"]),
        # A box 2e-300 wide at 5e8 from the origin: its units overflow the far coordinate.
        ([[0, 5.36870912e8], [1e-300, 5.36870912e8], [-1e-300, 5.36870912e8]], None,
         ["too small for its distance from the origin"]),
    ],
)
def test_input_float64_cannot_hold_after_normalising_is_refused(points, masses, words):
    points = np.array(points, np.float64)
    masses = np.ones(len(points)) if masses is None else np.array(masses, np.float64)
    with pytest.raises(ValueError) as info:
        to_canonical(points, masses)
    for word in words:
        assert word in str(info.value)


def test_a_small_mass_next_to_a_large_one_is_kept_while_it_stays_normal():
    masses = np.array([1.0, 2.0**-1000, 0.0])
    frame, _, m = to_canonical(np.array([[0.0, 0], [1, 0], [0, 1]]), masses)
    np.testing.assert_array_equal(frame.masses_out(m), masses)


@pytest.mark.parametrize(
    ("scale_exp", "mass_exp", "cost", "expect_exponent"),
    [
        (0, 0, 0.0, 0),
        (0, 0, 3.5, 0),
        (500, 22, 3.5, 0),  # 3.5 * 2^1022 is still finite
        (512, 0, 3.5, 1024),  # overflows: given with its exponent
        (-520, 0, 3.5, -1040),  # subnormal in input units: given with its exponent
        (-600, -1000, 0.0, 0),  # zero stays plain
    ],
)
def test_costs_map_back_without_losing_digits(scale_exp, mass_exp, cost, expect_exponent):
    frame = canonical_frame(np.array([[0.0, 0], [1, 0], [0, 1]]), np.ones(3))._replace(
        scale_exp=scale_exp, mass_exp=mass_exp, mass_mantissa=1.0)
    value, exponent = frame.cost_out(cost)
    assert exponent == expect_exponent
    unit = Fraction(frame.mass_mantissa) * Fraction(2) ** (2 * scale_exp + mass_exp)  # mass unit times s^2
    assert Fraction(value) * Fraction(2) ** exponent == Fraction(cost) * unit
    if exponent == 0:
        assert value == 0 or value >= TINY


def test_a_tolerance_maps_in_exactly():
    frame, _, _ = to_canonical(np.array([[0.0, 0], [3.0, 0], [0, 4.0]]), np.ones(3))
    assert frame.scale_exp == 3  # diagonal 5 -> s = 8
    assert frame.length_in(0.3) == 0.3 / 8


def test_a_tolerance_past_float64_in_canonical_units_is_infinite_without_a_warning():
    tiny, _, _ = to_canonical(np.array([[0.0, 0], [3e-300, 0], [0, 4e-300]]), np.ones(3))
    assert tiny.length_in(1e300) == np.inf  # pytest turns a RuntimeWarning into an error
    huge, _, _ = to_canonical(np.array([[0.0, 0], [3e300, 0], [0, 4e300]]), np.ones(3))
    assert huge.length_in(1e-300) == 0.0
