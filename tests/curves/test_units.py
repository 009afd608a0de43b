"""reconstruct_curve does not depend on the input's units: bitwise under
power-of-two scalings across float64's range, exact under translations on a
grid, the same shape at 1e-300 and 1e300; collinear input gives its segment."""

import warnings
from fractions import Fraction

import numpy as np
import pytest

from otjax.curves.reconstruct import reconstruct_curve

N_POINTS = 48


def noisy_square(n=N_POINTS, seed=3, bits=11):
    """Points along the unit square's sides, noise 1% of a side, on a grid of ``2^-bits``."""
    rng = np.random.default_rng(seed)
    t = rng.random(n) * 4
    side = np.floor(t).astype(int)
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    pts = corners[side] + (t - side)[:, None] * (corners[(side + 1) % 4] - corners[side])
    pts += 0.01 * rng.standard_normal((n, 2))
    pts = np.ldexp(np.round(np.ldexp(pts, bits)), -bits)
    _, first = np.unique(pts, axis=0, return_index=True)
    return pts[np.sort(first)]


def run(points, masses=None, n_vertices=4, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow or underflow anywhere
        return reconstruct_curve(points, masses, n_vertices=n_vertices, **kwargs)


def cost_of(result) -> Fraction:
    """The total cost in input units, exactly: ``total_cost * 2^cost_exponent``."""
    return Fraction(result.total_cost) * Fraction(2) ** result.params.get("cost_exponent", 0)


@pytest.fixture(scope="module")
def square():
    points = noisy_square()
    masses = np.random.default_rng(7).integers(1, 9, len(points)).astype(np.float64)
    return points, masses, run(points, masses)


def assert_same_shape(result, base, atol, scale=1.0):
    """The same graph, each vertex of ``result`` over ``scale`` within ``atol`` of its
    counterpart in ``base`` (the numbering may differ)."""
    assert len(result.vertices) == len(base.vertices) and len(result.edges) == len(base.edges)
    dist = np.linalg.norm(result.vertices[:, None] / scale - base.vertices[None], axis=2)
    match = dist.argmin(1)
    assert sorted(match) == list(range(len(base.vertices))) and dist.min(1).max() <= atol
    assert {frozenset(match[e]) for e in result.edges} == {frozenset(e) for e in base.edges}
    assert sorted(match[result.isolated]) == sorted(base.isolated)


def assert_scaled(result, base, k, j=0):
    """``result`` is ``base`` with lengths times ``2^k`` and masses times ``2^j``, bitwise."""
    expected = np.ldexp(base.vertices, k)
    normal = np.abs(expected) >= np.finfo(np.float64).tiny
    assert np.array_equal(result.vertices[normal], expected[normal])
    assert np.all(np.abs(result.vertices - expected)[~normal] <= 2.0**-1075)  # subnormal: one rounding
    assert np.array_equal(result.edges, base.edges) and np.array_equal(result.isolated, base.isolated)
    assert np.array_equal(result.edge_mass, np.ldexp(base.edge_mass, j))
    assert np.array_equal(result.edge_relevance, base.edge_relevance)
    assert cost_of(result) == cost_of(base) * Fraction(2) ** (2 * k + j)


def test_the_reference_case_is_the_square(square):
    _, _, base = square
    assert len(base.vertices) == 4 and len(base.edges) == 4
    np.testing.assert_allclose(np.sort(np.abs(base.vertices - 0.5).max(1)), 0.5, atol=0.04)


@pytest.mark.parametrize(("k", "j"), [(-1000, 0), (-381, 700), (517, -900), (1000, 0)])
def test_power_of_two_scalings_scale_the_result_bitwise(square, k, j):
    points, masses, base = square
    result = run(np.ldexp(points, k), np.ldexp(masses, j))
    assert_scaled(result, base, k, j)
    np.testing.assert_array_equal(result.points, np.ldexp(points, k))
    if abs(2 * k + j) > 1000:  # out of float64's range in input units: given with an exponent
        assert result.params["cost_exponent"] != 0


def test_a_translation_on_the_grid_by_1e12_sizes_translates_the_result(square):
    points, masses, base = square
    shift = np.ldexp(2.0**40 + 5.0, 0)  # ~1.1e12 times the box, a multiple of its centre grid
    moved = points + np.array([shift, -3 * shift])
    assert np.array_equal(moved - [shift, -3 * shift], points)  # the input itself is exact
    result = run(moved, masses)
    assert np.array_equal(result.edges, base.edges)
    assert result.total_cost == base.total_cost and np.array_equal(result.edge_mass, base.edge_mass)
    # Only the last addition of the centre rounds: half an ulp of the translated coordinate.
    expected = base.vertices + [shift, -3 * shift]
    assert np.all(np.abs(result.vertices - expected) <= np.spacing(np.abs(expected)) / 2)


@pytest.mark.parametrize("scale", [1e-300, 1e-160, 1e160, 1e300])
def test_decimal_scalings_near_the_float64_ends_give_the_same_shape(square, scale):
    """Not powers of two: the input rounds differently, the shape stays."""
    points, masses, base = square
    result = run(points * scale, masses)
    assert_same_shape(result, base, atol=0.02, scale=scale)
    assert float(cost_of(result) / (cost_of(base) * Fraction(scale) ** 2)) == pytest.approx(1, rel=0.1)


def test_subnormal_masses_give_the_result_of_unit_masses(square):
    """Equal masses of any size become exactly 1 in the canonical frame: the same run, bitwise."""
    points, _, _ = square
    result, unit = run(points, np.full(len(points), 1e-320)), run(points)
    assert np.array_equal(result.vertices, unit.vertices) and np.array_equal(result.edges, unit.edges)
    assert np.array_equal(result.edge_relevance, unit.edge_relevance)
    assert result.edge_mass.sum() == pytest.approx(len(points) * 1e-320, rel=1e-2)
    assert result.params["cost_exponent"] < -1000


def test_a_tolerance_is_a_length_in_input_units(square):
    points, masses, base = square
    a = run(points, masses, tolerance=0.02)
    b = run(np.ldexp(points, -600), masses, tolerance=np.ldexp(0.02, -600))
    assert_scaled(b, a, -600)
    assert a.params["tolerance"] == 0.02 and b.params["tolerance"] == np.ldexp(0.02, -600)
    assert len(a.vertices) >= len(base.vertices)


def test_points_float64_cannot_separate_at_their_scale_are_refused():
    points = np.array([[0.0, 0.0], [1e-20, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    with pytest.raises(ValueError, match="closer than float64 resolves"):
        reconstruct_curve(points, n_vertices=3)


@pytest.mark.parametrize("direction", [(1.0, 0.0), (0.0, 1.0), (0.6, -0.8)])
def test_collinear_points_give_their_segment(direction, rng):
    t = np.sort(rng.random(40))
    points = 3.0 + np.outer(t, direction)
    result = run(points, n_vertices=2)
    assert len(result.vertices) == 2 and result.edges.tolist() == [[0, 1]]
    ends = points[[0, -1]]
    got = result.vertices[np.argsort(result.vertices @ np.asarray(direction))]
    np.testing.assert_allclose(got, ends, atol=0.1)  # 10% of the length: the optimal ends sit inside
    along = (result.vertices - 3.0) @ np.array([-direction[1], direction[0]])
    np.testing.assert_allclose(along, 0.0, atol=1e-12)  # on the line


def test_more_vertices_on_a_line_give_a_polyline_along_it(rng):
    t = np.sort(rng.random(40)) * 4
    points = np.stack([t, 0.5 * t - 1], 1)
    result = run(points, n_vertices=4)
    assert len(result.vertices) == 4 and len(result.edges) == 3
    np.testing.assert_array_equal(np.sort(np.bincount(result.edges.ravel())), [1, 1, 2, 2])  # a chain
    np.testing.assert_allclose(result.vertices[:, 1], 0.5 * result.vertices[:, 0] - 1, atol=1e-12)
    x = np.sort(result.vertices[:, 0])
    np.testing.assert_allclose(x[[0, -1]], t[[0, -1]], atol=0.4)  # 10% of the length
