"""Input validation: every bad input is a ValueError naming the problem."""

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from otjax.validation import check_count, check_nonnegative, check_number, check_points, check_target


def assert_rejected(check, args, words):
    """``check(*args)`` raises a ValueError whose message contains every word."""
    with pytest.raises(ValueError) as info:
        check(*args)
    for word in words:
        assert word in str(info.value)

TRIANGLE = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]


@pytest.mark.parametrize(
    ("points", "masses", "words"),
    [
        ("abc", None, ["real numbers"]),
        ([[0, 0], [1, 0, 2], [0, 1]], None, ["array of numbers"]),
        ([[1j, 0]] * 3, None, ["real numbers", "complex"]),
        ([[True, False]] * 3, None, ["real numbers", "bool"]),
        ([{"x": 1}] * 3, None, ["numbers"]),
        ([0.0, 1.0, 2.0], None, ["(n, 2)", "(3,)"]),
        (np.zeros((3, 3)), None, ["(n, 2)", "(3, 3)"]),
        (np.zeros((2, 2, 2)), None, ["(n, 2)", "(2, 2, 2)"]),
        (np.zeros((0, 2)), None, ["at least 3", "got 0"]),
        ([], None, ["(n, 2)"]),
        ([[0, 0], [1, 0]], None, ["at least 3", "got 2"]),
        ([[0, 0], [1, np.nan], [0, 1], [np.inf, 2]], None, ["NaN or inf", "2 row", "row 1"]),
        (TRIANGLE, [1, 1], ["masses", "(3,)", "(2,)"]),
        (TRIANGLE, [[1, 1, 1]], ["masses", "(3,)", "(1, 3)"]),
        (TRIANGLE, [1, -1, -2], ["negative", "2", "index 1"]),
        (TRIANGLE, [1, np.nan, 1], ["masses", "NaN or inf", "index 1"]),
        (TRIANGLE, [1, 1, np.inf], ["masses", "NaN or inf", "index 2"]),
        (TRIANGLE, [0, 0, 0], ["all zero"]),
        (TRIANGLE, ["a", "b", "c"], ["masses", "real numbers"]),
        (
            [[0, 0], [1, 0], [0, 1], [1, 0], [0, 1]],
            None,
            ["2 duplicate", "rows 1 and 3", "merge_duplicates=True"],
        ),
        ([[0, 0], [1, 0], [0, 1], [1, 0]], None, ["--merge-duplicates"]),
        ([[2, 3]] * 5, None, ["all 5 points coincide"]),
    ],
)
def test_bad_points_raise_value_error_naming_the_problem(points, masses, words):
    assert_rejected(check_points, (points, masses), words)


@pytest.mark.parametrize("scale", [1.0, 2.0**-1000, 1e-300, 1e300])
def test_collinear_points_are_valid_in_2d(scale):
    """The pinned box corners make the triangulation of points on a line well defined."""
    line = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [-3.0, -3.0]]) * scale
    out, m = check_points(line)
    np.testing.assert_array_equal(out, line)
    np.testing.assert_array_equal(m, np.ones(4))
    horizontal = np.array([[0.0, 5.0], [1.0, 5.0], [7.0, 5.0]])
    np.testing.assert_array_equal(check_points(horizontal)[0], horizontal)
    out, m = check_points([[0, 0], [1, 1], [0, 0], [2, 2]], merge_duplicates=True)
    np.testing.assert_array_equal(out, [[0, 0], [1, 1], [2, 2]])
    np.testing.assert_array_equal(m, [2, 1, 1])


def test_collinearity_is_exact_in_3d():
    # One ulp off a line is not collinear: a rank test with a tolerance (SVD,
    # relative threshold) would call this set collinear and reject valid input.
    exact_collinear = np.array([[0.0, 0.0, 0.0], [0.5, 0.25, 1.0], [2.0, 1.0, 4.0], [-4.0, -2.0, -8.0]])
    with pytest.raises(ValueError, match="collinear"):
        check_points(exact_collinear, dim=3)
    nudged = exact_collinear.copy()
    nudged[1, 1] = np.nextafter(0.25, 1.0)  # one ulp off the line
    out, _ = check_points(nudged, dim=3)
    np.testing.assert_array_equal(out, nudged)


@pytest.mark.parametrize("scale", [1.0, 1e-300, 1e300, 2.0**-1070])
def test_collinearity_in_3d_at_any_scale(scale):
    """The exact test sees through a power-of-two rescaling: no overflow or underflow near the float64 ends."""
    line = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [2.0, 4.0, 6.0]]) * scale
    with pytest.raises(ValueError, match="collinear"):
        check_points(line, dim=3)
    off = line.copy()
    off[2, 2] = np.nextafter(off[2, 2], np.inf)
    check_points(off, dim=3)


def test_collinear_after_merging_is_rejected_in_3d():
    pts = [[0, 0, 0], [1, 1, 1], [0, 0, 0], [2, 2, 2]]
    with pytest.raises(ValueError, match="collinear"):
        check_points(pts, dim=3, merge_duplicates=True)


def test_too_few_after_merging_is_rejected():
    with pytest.raises(ValueError, match="distinct"):
        check_points([[0, 0], [1, 0], [1, 0], [0, 0]], merge_duplicates=True)


def test_collinear_in_3d():
    t = np.arange(5.0)[:, None]
    with pytest.raises(ValueError, match="collinear"):
        check_points(np.hstack([t, 2 * t, -t]), dim=3)
    pts, _ = check_points(np.array([[0, 0, 0], [1, 2, -1], [2, 4, -2], [0, 0, 1.0]]), dim=3)
    assert pts.shape == (4, 3)


def test_merge_duplicates_sums_masses_in_first_occurrence_order():
    pts = [[5, 5], [0, 0], [5, 5], [1, 0], [0, 0], [0, 1], [-0.0, 0.0]]
    masses = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0]
    out, m = check_points(pts, masses, merge_duplicates=True)
    np.testing.assert_array_equal(out, [[5, 5], [0, 0], [1, 0], [0, 1]])
    # -0.0 equals 0.0 as a number, so it merges with the origin.
    np.testing.assert_array_equal(m, [5.0, 82.0, 8.0, 32.0])
    assert m.sum() == sum(masses)


def test_merge_duplicates_without_duplicates_is_identity():
    pts, m = check_points(TRIANGLE, [1, 2, 3], merge_duplicates=True)
    np.testing.assert_array_equal(pts, TRIANGLE)
    np.testing.assert_array_equal(m, [1, 2, 3])


def test_inputs_are_not_modified_and_outputs_are_copies():
    pts = np.array(TRIANGLE)
    masses = np.array([1.0, 2.0, 3.0])
    out, m = check_points(pts, masses)
    out[0, 0] = 99.0
    m[0] = 99.0
    assert pts[0, 0] == 0.0 and masses[0] == 1.0


def test_zero_masses_are_allowed_if_total_is_positive():
    _, m = check_points(TRIANGLE, [0, 0, 1])
    np.testing.assert_array_equal(m, [0, 0, 1])


@settings(max_examples=40, deadline=None)
@given(
    n=st.integers(3, 60),
    seed=st.integers(0, 2**31 - 1),
    integer_input=st.booleans(),
    with_masses=st.booleans(),
)
def test_valid_input_passes_unchanged(n, seed, integer_input, with_masses):
    rng = np.random.default_rng(seed)
    if integer_input:  # distinct integer points on a non-degenerate grid
        flat = rng.choice(10_000, size=n, replace=False)
        pts = np.stack([flat // 100, flat % 100], 1)
        d = pts - pts[0]
        assume(np.any(d[:, 0] * d[1, 1] - d[:, 1] * d[1, 0] != 0))  # exact in integers: not collinear
    else:
        pts = rng.standard_normal((n, 2)) * 10.0 ** rng.integers(-8, 8)
    masses = rng.random(n) + 0.1 if with_masses else None
    out, m = check_points(pts, masses)
    assert out.dtype == np.float64 and m.dtype == np.float64
    assert out.shape == (n, 2) and m.shape == (n,)
    np.testing.assert_array_equal(out, np.asarray(pts, dtype=np.float64))
    np.testing.assert_array_equal(m, np.ones(n) if masses is None else masses)


@pytest.mark.parametrize(
    ("value", "n_points", "words"),
    [
        (2.5, 10, ["integer"]),
        ("5", 10, ["integer"]),
        (True, 10, ["integer"]),
        (None, 10, ["integer"]),
        (0, 10, ["at least 1"]),
        (-3, 10, ["at least 1"]),
        (11, 10, ["exceed", "10"]),
    ],
)
def test_check_target_rejects(value, n_points, words):
    assert_rejected(check_target, (value, n_points), words)


def test_check_target_accepts():
    assert check_target(np.int64(10), 10) == 10
    assert type(check_target(np.int32(3), 10)) is int
    with pytest.raises(ValueError, match="at least 4"):
        check_target(3, 10, minimum=4)


@pytest.mark.parametrize("value", [-1.0, np.nan, np.inf, "1", None, True])
def test_check_nonnegative_rejects(value):
    with pytest.raises(ValueError, match="relevance"):
        check_nonnegative("relevance", value)


def test_check_nonnegative_and_count_accept():
    assert check_nonnegative("t", 0) == 0.0
    assert check_nonnegative("t", np.float32(2.5)) == 2.5
    assert check_count("k", np.int64(3)) == 3
    with pytest.raises(ValueError, match="k must be >= 1"):
        check_count("k", 0, minimum=1)
    with pytest.raises(ValueError, match="integer"):
        check_count("k", 1.0)


@pytest.mark.parametrize(
    ("check", "value", "words"),
    [
        (lambda v: check_number("tolerance", v), 10**400, ["tolerance", "finite", "characters"]),
        (lambda v: check_number("tolerance", v), float("inf"), ["tolerance", "finite"]),
        (lambda v: check_number("choices", v, minimum=1, integer=True), 2**63, ["choices", "2^63 - 1"]),
        (lambda v: check_number("choices", v, minimum=1, integer=True), -(10**30), ["choices", ">= 1"]),
        (lambda v: check_nonnegative("relevance", v), -(10**400), ["relevance", "finite"]),
        (lambda v: check_count("relocation", v), 10**19, ["relocation", "2^63 - 1"]),
    ],
)
def test_numbers_python_cannot_hold_in_float64_or_int64_are_value_errors(check, value, words):
    with pytest.raises(ValueError) as info:
        check(value)
    message = str(info.value)
    assert all(w in message for w in words) and len(message) < 200


def test_the_largest_integers_and_floats_pass():
    assert check_number("seed", 2**63 - 1, integer=True) == 2**63 - 1
    assert check_number("tolerance", 1.7976931348623157e308) == 1.7976931348623157e308


def test_masses_whose_sum_overflows_pass_validation_without_a_warning():
    # Validation compares the largest mass with zero; the canonical frame refuses the total.
    _, m = check_points(TRIANGLE, [1.7e308, 1.7e308, 1.0])
    assert np.isfinite(m).all()
