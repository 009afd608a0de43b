"""The exact orientation predicate against rational arithmetic.

Inputs are built to be hard for floating point: points on a line through
two others (rounded), on lattices, a few ulps off a line, and coordinates
spread over float64's whole exponent range, where the error-free path must
hand over to the integer one.
"""

from fractions import Fraction
from unittest import mock

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax import predicates
from otjax.predicates import (in_triangle_perturbed, in_triangle_scalar, orient, orient_perturbed,
                              orient_perturbed_scalar, orient_scalar)
from tests.profiles import examples


def _oracle(a, b, c) -> int:
    ax, ay, bx, by, cx, cy = (Fraction(float(v)) for v in (*a, *b, *c))
    det = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    return (det > 0) - (det < 0)


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def hard_triangles(draw, n=24):
    """``(n, 3, 2)`` triangles, most of them collinear or within ulps of it."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    scale = 2.0 ** draw(st.integers(-600, 400))  # the determinant must stay finite
    a = rng.normal(size=(n, 2)) * scale
    d = rng.normal(size=(n, 2)) * scale * 2.0 ** draw(st.integers(-60, 10))
    b = a + d
    c = a + rng.uniform(-3, 3, size=(n, 1)) * d
    kind = draw(st.sampled_from(["rounded-line", "ulps-off", "lattice", "offset-lattice"]))
    if kind == "ulps-off":
        c = c + np.spacing(np.abs(c)) * rng.integers(-2, 3, size=c.shape)
    elif kind in ("lattice", "offset-lattice"):
        step = 2.0 ** draw(st.integers(-30, 30))
        pts = rng.integers(-8, 9, size=(n, 3, 2)) * step
        if kind == "offset-lattice":
            pts = pts + draw(st.floats(-1e12, 1e12)) * step  # rounded translation of the lattice
        a, b, c = pts[:, 0], pts[:, 1], pts[:, 2]
    return np.stack([a, b, c], 1)


@settings(max_examples=examples(200, 3000))
@given(hard_triangles())
def test_orient_is_the_sign_of_the_exact_determinant(t):
    want = [_oracle(*tri) for tri in t]
    np.testing.assert_array_equal(orient(t[:, 0], t[:, 1], t[:, 2]), want)  # few unsure: one at a time
    with mock.patch.object(predicates, "SCALAR_UNSURE", 0):  # every unsure one vectorised
        np.testing.assert_array_equal(orient(t[:, 0], t[:, 1], t[:, 2]), want)
    assert [orient_scalar(*t[k].ravel()) for k in range(len(t))] == want
    # The vectorised path directly: its product comparison, then the few rows
    # left one at a time (at most SCALAR_UNSURE) or by the expansion.
    np.testing.assert_array_equal(predicates._exact_orient_many(t[:, 0], t[:, 1], t[:, 2]), want)
    with mock.patch.object(predicates, "SCALAR_UNSURE", 0):
        np.testing.assert_array_equal(predicates._exact_orient_many(t[:, 0], t[:, 1], t[:, 2]), want)
    assert [predicates._exact_orient_integer(*t[k].ravel()) for k in range(len(t))] == want


@settings(max_examples=examples(200, 3000))
@given(hard_triangles(), st.integers(0, 2**32 - 1))
def test_scalar_perturbed_predicates_equal_the_vectorised_ones(t, seed):
    """Query points on, or within ulps of, an edge's line, on a vertex, or
    on the edge's lattice: the perturbation decides the collinear ones."""
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    rng = np.random.default_rng(seed)
    c = np.where(rng.random((len(t), 1)) < 0.2, a, c)  # some on a vertex
    want = orient_perturbed(a, b, c)
    assert [orient_perturbed_scalar(*a[k], *b[k], *c[k]) for k in range(len(t))] == want.tolist()
    assert [orient_perturbed_scalar(*b[k], *a[k], *c[k]) for k in range(len(t))] == \
        orient_perturbed(b, a, c).tolist()
    # Triangles with the edge (a, b), the query near it, a third corner on either side.
    d = a + np.roll(b - a, 1, axis=1) * [[-1.0, 1.0]] * rng.choice([-1.0, 1.0], (len(t), 1))
    tri = np.stack([a, b, d], 1)
    want = in_triangle_perturbed(tri, c)
    assert [in_triangle_scalar(*tri[k].ravel(), *c[k]) for k in range(len(t))] == want.tolist()


@settings(max_examples=examples(200, 3000))
@given(st.lists(st.tuples(*[finite] * 6), min_size=1, max_size=8))
def test_orient_across_the_exponent_range(rows):
    """Any finite doubles, subnormal to huge in one triangle: the products
    leave the error-free window and must still be exact."""
    # Beyond +-2^480 the float filter itself overflows; the library only asks
    # about canonical-frame coordinates, far inside.
    t = np.clip(np.array(rows, np.float64).reshape(-1, 3, 2), -2.0**480, 2.0**480)
    want = [_oracle(*tri) for tri in t]
    np.testing.assert_array_equal(orient(t[:, 0], t[:, 1], t[:, 2]), want)
    with mock.patch.object(predicates, "SCALAR_UNSURE", 0):
        np.testing.assert_array_equal(orient(t[:, 0], t[:, 1], t[:, 2]), want)


def test_exactly_collinear_and_one_ulp_off():
    a = np.array([[0.5, 0.25]] * 3)
    b = np.array([[1.5, 0.75]] * 3)
    c = np.array([[3.5, 1.75], [3.5, np.nextafter(1.75, 2.0)], [3.5, np.nextafter(1.75, 0.0)]])
    np.testing.assert_array_equal(orient(a, b, c), [0, 1, -1])
