"""Facet filtering by mass density: values against an oracle, a monotone and
scale-free threshold, and what happens to edges and vertices."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.surfaces.filtering import facet_density, filter_facets, keep_facets
from tests.profiles import examples


def heron(a, b, c):
    x, y, z = np.linalg.norm(b - a), np.linalg.norm(c - b), np.linalg.norm(a - c)
    s = (x + y + z) / 2
    return np.sqrt(max(s * (s - x) * (s - y) * (s - z), 0.0))


def random_complex(seed, n_vertices=12, n_triangles=15):
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(n_vertices, 3))
    tri = np.array([rng.choice(n_vertices, 3, replace=False) for _ in range(n_triangles)])
    mass = rng.exponential(size=n_triangles) * (rng.random(n_triangles) > 0.2)
    return v, tri, mass


def test_densities_match_mass_over_heron_area():
    v, tri, mass = random_complex(0)
    d = facet_density(v, tri, mass)
    area = np.array([heron(*v[t]) for t in tri])
    np.testing.assert_allclose(d.area, area, rtol=1e-10)
    np.testing.assert_allclose(d.density, mass / area, rtol=1e-10)
    assert d.reference == pytest.approx(mass.sum() / area.sum(), rel=1e-12)
    np.testing.assert_allclose(d.relative, (mass / area) / (mass.sum() / area.sum()), rtol=1e-10)
    assert np.all(np.diff(d.sorted) <= 0) and np.array_equal(d.sorted, d.relative[d.order])


def test_zero_area_facets_are_never_kept_and_do_not_count():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0]], float)
    tri = np.array([[0, 1, 2], [0, 1, 3]])  # the second is flat on a line
    d = facet_density(v, tri, [1.0, 5.0])
    assert d.density[1] == 0 and d.reference == pytest.approx(2.0)
    assert keep_facets(d.relative, 0.0).tolist() == [True, False]


@settings(max_examples=examples(60, 600))
@given(seed=st.integers(0, 2**32 - 1), t=st.floats(0, 3), dt=st.floats(0, 3))
def test_higher_threshold_keeps_a_subset(seed, t, dt):
    v, tri, mass = random_complex(seed)
    rel = facet_density(v, tri, mass).relative
    low, high = keep_facets(rel, t), keep_facets(rel, t + dt)
    assert np.all(high <= low)
    assert np.array_equal(keep_facets(rel, 0.0), (mass > 0))  # threshold 0: every facet that carries mass


@settings(max_examples=examples(60, 600))
@given(seed=st.integers(0, 2**32 - 1), scale=st.floats(1e-6, 1e6), mass_scale=st.floats(1e-6, 1e6),
       shift=st.floats(-1e3, 1e3), t=st.floats(0, 2))
def test_scaling_points_and_masses_keeps_the_same_facets(seed, scale, mass_scale, shift, t):
    # The shift is in units of the shape's size: a shape 1e-6 wide moved 257 away is already rounded to
    # 1e-7 of its size when the input is written down, which no code can undo.
    v, tri, mass = random_complex(seed)
    a = facet_density(v, tri, mass)
    b = facet_density((v + shift) * scale, tri, mass * mass_scale)
    np.testing.assert_allclose(b.relative, a.relative, rtol=1e-6)
    away = np.abs(a.relative - t) > 1e-5 * max(1.0, t)  # the kept set may differ only on a tie
    assert np.array_equal(keep_facets(b.relative, t)[away], keep_facets(a.relative, t)[away])
    np.testing.assert_allclose(b.density, a.density * mass_scale / scale**2, rtol=1e-6)


def test_power_of_two_scaling_is_exact():
    v, tri, mass = random_complex(3)
    a = facet_density(v, tri, mass)
    b = facet_density(v * 2.0**40, tri, mass * 2.0**-30)
    assert np.array_equal(a.relative, b.relative)


def test_what_goes_with_dropped_facets():
    # Two triangles sharing an edge, a dense one and a sparse one, a dangling edge and an isolated vertex.
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [5, 5, 5], [6, 5, 5], [9, 9, 9]], float)
    tri = np.array([[0, 1, 2], [1, 2, 3]])
    mass = np.array([1.0, 0.01])
    edges, isolated = np.array([[4, 5]]), np.array([6])
    f = filter_facets(v, tri, mass, 0.5, edges, isolated)
    assert f.triangle_keep.tolist() == [True, False]
    assert f.vertex_index.tolist() == [0, 1, 2, -1, 3, 4, 5]  # vertex 3 lost its only facet and carries nothing
    np.testing.assert_array_equal(f.vertices, v[[0, 1, 2, 4, 5, 6]])
    assert f.triangles.tolist() == [[0, 1, 2]] and f.edges.tolist() == [[3, 4]] and f.isolated.tolist() == [5]
    # With vertex masses, a vertex that lost its facets but receives mass stays, isolated.
    f = filter_facets(v, tri, mass, 0.5, edges, isolated, vertex_mass=[0, 0, 0, 2.0, 0, 0, 1.0])
    assert f.vertex_index.tolist() == [0, 1, 2, 3, 4, 5, 6]
    assert f.isolated.tolist() == [6, 3]
    # A threshold above every facet keeps none; the dangling edge and the isolated vertex stay.
    f = filter_facets(v, tri, mass, 10.0, edges, isolated)
    assert len(f.triangles) == 0 and f.edges.tolist() == [[0, 1]] and f.isolated.tolist() == [2]


@pytest.mark.parametrize("bad", [-0.1, np.nan, np.inf, "1", True, None])
def test_bad_threshold_is_a_value_error(bad):
    with pytest.raises(ValueError, match="threshold"):
        keep_facets([1.0], bad)
