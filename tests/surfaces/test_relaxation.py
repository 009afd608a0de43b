"""Local relaxation (Algorithm 2): monotone, feasible, close to the global optimum."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.lp.exact import solve_member
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.initial_complex import (box_corners, initial_settings, sample_subset, tetrahedra,
                                            tetrahedra_facets, two_tetrahedra_rule)
from otjax.surfaces.plan import BinSettings, SurfacePlan
from otjax.surfaces.relaxation import LocalSolution, StencilIndex, facet_ring, relax, rounds_of
from tests.surfaces.test_transport_plan import grid_complex


def exact(problems):
    return [LocalSolution(s.plan, s.cost, s.status) for s in map(solve_member, problems)]


def folded_plan(rng, n_points=250):
    """Points on and off a surface folded along x = 0.5, a few outliers above it."""
    c = grid_complex(4, fold=0.8)
    xy = rng.random((n_points, 2))
    z = 0.8 * np.maximum(xy[:, 0] - 0.5, 0.0) + rng.normal(0, 0.01, n_points)
    z[:10] += rng.uniform(0.2, 0.4, 10)  # outliers
    return SurfacePlan(c, np.c_[xy, z], np.ones(n_points), BinSettings(diagonal=np.sqrt(2.64)))


def test_cost_never_rises_after_any_local_solve(rng, monkeypatch):
    plan = folded_plan(rng, 150)
    totals = [plan.total_cost()]
    assign = plan.assign

    def spy(stencil, written):
        assign(stencil, written)
        totals.append(plan.total_cost())

    monkeypatch.setattr(plan, "assign", spy)
    stats = relax(plan, exact, max_sweeps=2)
    assert stats.accepted == len(totals) - 1 > 10
    steps = np.diff(totals)
    assert np.all(steps <= 1e-12 * totals[0]), steps.max()
    assert totals[-1] < 0.5 * totals[0]


def test_relaxation_reaches_the_global_optimum_within_two_percent(rng):
    plan = folded_plan(rng)
    stats = relax(plan, exact)
    np.testing.assert_allclose(plan.point_mass(), plan.masses, rtol=1e-12)
    c = plan.complex
    whole = plan.stencil(np.flatnonzero(c.alive), sorted(c.triangles))
    optimum = solve_member(whole.lp).cost
    assert optimum <= plan.total_cost() <= 1.02 * optimum
    assert stats.costs[-1] == pytest.approx(plan.total_cost(), rel=1e-12)
    # every facet that received mass received it uniformly
    for t, e in plan.facet_entries.items():
        got = np.bincount(e.bin, e.mass, minlength=len(plan.bins[t].capacity))
        np.testing.assert_allclose(got, got.sum() * plan.bins[t].capacity, rtol=1e-6, atol=1e-12)


def test_a_rejected_solution_leaves_the_plan_unchanged(rng):
    plan = folded_plan(rng, 100)
    before = plan.total_cost()

    def worse(problems):  # feasible, but everything on the costliest bin of each row
        out = []
        for lp in problems:
            x = np.zeros_like(lp.cost)
            vertex = np.flatnonzero(lp.is_vertex)
            j = vertex[np.argmax(lp.cost[:, vertex], axis=1)]
            x[np.arange(len(j)), j] = lp.mass
            out.append(LocalSolution(x, float(np.sum(x * lp.cost)), 0))
        return out

    stats = relax(plan, worse, max_sweeps=1)
    assert stats.accepted < stats.solves
    assert plan.total_cost() <= before


@settings(max_examples=200, deadline=None)
@given(st.lists(st.lists(st.integers(0, 12), min_size=1, max_size=5), max_size=30))
def test_rounds_are_vertex_disjoint_first_fit_partitions(stencils):
    rounds = rounds_of(stencils)
    assert sorted(i for r in rounds for i in r) == list(range(len(stencils)))
    for r in rounds:
        seen = set()
        for i in r:
            assert not seen & set(stencils[i])
            seen |= set(stencils[i])
    # first fit: a stencil in round r meets some stencil of every earlier round
    where = {i: k for k, r in enumerate(rounds) for i in r}
    for i, k in where.items():
        for earlier in range(k):
            assert any(set(stencils[i]) & set(stencils[j]) for j in rounds[earlier] if j < i)


@pytest.mark.parametrize("sweeps", [1, 2])
def test_stencils_ruled_out_before_a_sweep_cannot_lower_the_cost(sweeps):
    # The initial complex's setting: a Delaunay of a subset, two-tetrahedra stencils.
    rng = np.random.default_rng(11)
    pts = np.c_[rng.random((300, 2)), 0.5 + rng.normal(0, 0.003, 300)]
    subset = sample_subset(len(pts), 0.15, 1)
    vertices = np.vstack([pts[subset], box_corners(pts)])
    tets = tetrahedra(vertices)
    facets = tetrahedra_facets(tets)
    plan = SurfacePlan(SimplicialComplex(vertices, facets), pts, np.ones(len(pts)), initial_settings(pts))
    rule = two_tetrahedra_rule(tets)
    relax(plan, exact, rule, max_sweeps=sweeps)
    simplices = [rule(tuple(t)) for t in facets.tolist()]
    live = StencilIndex(plan, simplices).improvable(plan)
    gains = []
    for (vs, fs), flagged in zip(simplices, live):
        s = plan.stencil(vs, fs)
        optimum = solve_member(s.lp).cost if len(s.points) else 0.0
        if not flagged:
            assert optimum >= s.cost * (1 - 1e-9) - 1e-12
        gains.append(s.cost - optimum)
    # after a sweep the test rules stencils out; the kept ones include every one that gains
    assert live.sum() < 0.8 * len(live)
    assert max(g for g, f in zip(gains, live) if f) > 0
