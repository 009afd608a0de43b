"""The sparse surface transport plan against brute-force NumPy computations."""

import numpy as np
import pytest

from otjax.lp.exact import solve_member
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.plan import BinSettings, SurfacePlan


def grid_complex(n=4, fold=0.0):
    """An ``n x n`` vertex grid on the unit square, triangulated; ``fold``
    lifts the half ``x > 0.5`` into a crease of that slope."""
    g = np.stack(np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij"), -1).reshape(-1, 2)
    z = fold * np.maximum(g[:, 0] - 0.5, 0.0)
    tris = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            tris += [[a, a + n, a + n + 1], [a, a + n + 1, a + 1]]
    return SimplicialComplex(np.c_[g, z], np.array(tris))


@pytest.fixture
def plan(rng):
    c = grid_complex()
    pts = np.c_[rng.random((120, 2)), rng.normal(0, 0.02, 120)]
    return SurfacePlan(c, pts, rng.uniform(0.5, 2.0, 120), BinSettings(diagonal=np.sqrt(2.0)))


def test_initial_plan_sends_each_point_to_its_nearest_vertex(plan):
    d2 = ((plan.points[:, None, :] - plan.complex.positions[None]) ** 2).sum(-1)
    expected = float(np.sum(plan.masses * d2.min(axis=1)))
    assert plan.total_cost() == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(plan.point_mass(), plan.masses, rtol=1e-14)
    assert not plan.facet_entries


def test_every_facet_has_bins_whose_capacities_sum_to_one(plan):
    assert set(plan.bins) == plan.complex.triangles
    for t, b in plan.bins.items():
        assert b.capacity.sum() == pytest.approx(1.0, abs=1e-12)
        # centroids lie inside their triangle
        assert np.all(b.barycentric >= -1e-12) and np.allclose(b.barycentric.sum(1), 1.0)


def test_stencil_costs_are_squared_distances_to_bin_centroids(plan):
    facet = sorted(plan.complex.triangles)[3]
    verts = list(facet)
    s = plan.stencil(verts, [facet])
    corners = plan.complex.positions[list(facet)]
    centroids = np.array([w[0] * corners[0] + w[1] * corners[1] + w[2] * corners[2]
                          for w in plan.bins[facet].barycentric])
    positions = np.vstack([plan.complex.positions[verts], centroids])
    expected = np.array([[np.sum((plan.points[p] - q) ** 2) for q in positions] for p in s.points])
    np.testing.assert_allclose(s.lp.cost, expected, rtol=1e-12)
    # the partial masses are what the stencil's vertices carry now
    on = np.concatenate([plan.vertex_entries[v].point for v in verts if v in plan.vertex_entries])
    assert sorted(s.points.tolist()) == sorted(set(on.tolist()))
    np.testing.assert_allclose(s.lp.mass, plan.masses[s.points])


def test_assigning_a_solved_stencil_changes_only_its_simplices(plan):
    facet = sorted(plan.complex.triangles)[5]
    s = plan.stencil(list(facet), [facet])
    before = {v: plan.simplex_cost(v) for v in plan.vertex_entries if v not in facet}
    old_total = plan.total_cost()
    sol = solve_member(s.lp)
    plan.assign(s, sol.plan)
    assert {v: plan.simplex_cost(v) for v in before} == before
    assert plan.total_cost() == pytest.approx(old_total - s.cost + sol.cost, rel=1e-9)
    np.testing.assert_allclose(plan.point_mass(), plan.masses, rtol=1e-12)
    # the facet's bins receive mass proportional to their capacities
    e = plan.facet_entries[facet]
    received = np.bincount(e.bin, e.mass, minlength=len(plan.bins[facet].capacity))
    np.testing.assert_allclose(received, received.sum() * plan.bins[facet].capacity, rtol=1e-7, atol=1e-12)


def test_matrix_reproduces_masses_and_cost(plan):
    facet = sorted(plan.complex.triangles)[0]
    s = plan.stencil(list(facet), [facet])
    plan.assign(s, solve_member(s.lp).plan)
    m, columns = plan.matrix()
    np.testing.assert_allclose(np.asarray(m.sum(axis=1)).ravel(), plan.masses, rtol=1e-12)
    pos = np.array([plan.complex.positions[k] if not isinstance(k, tuple)
                    else plan.bins[k].barycentric[j] @ plan.complex.positions[list(k)] for k, j in columns])
    coo = m.tocoo()
    cost = np.sum(coo.data * ((plan.points[coo.row] - pos[coo.col]) ** 2).sum(-1))
    assert cost == pytest.approx(plan.total_cost(), rel=1e-12)
