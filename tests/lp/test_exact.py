"""The HiGHS solver on stencils whose optimum is known in closed form."""

import subprocess
import sys

import numpy as np
import pytest

from otjax.lp.exact import constraints, solve_exact, solve_member
from otjax.lp.problem import CONVERGED, FAILED, INFEASIBLE, LocalLP, pack

# A facet's bins in the plane z = 0 and their capacities (summing to 1).
FACET_BINS = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.4, 0.4, 0.0]])
FACET_CAPACITY = np.array([0.4, 0.2, 0.25, 0.15])


def squared_distances(points, bins):
    return ((np.asarray(points)[:, None, :] - np.asarray(bins)[None, :, :]) ** 2).sum(-1)


def facet_and_vertex(points, mass, vertex_at, facets=1):
    """A LocalLP over ``facets`` copies of FACET_BINS (facet ``f`` shifted by ``10 f`` in z),
    then one vertex bin at ``vertex_at``."""
    bins = [FACET_BINS + [0, 0, 10.0 * f] for f in range(facets)]
    if vertex_at is not None:
        bins.append(np.asarray(vertex_at, float)[None, :])
    bins = np.concatenate(bins)
    n_f = facets * len(FACET_BINS)
    n_v = len(bins) - n_f
    return LocalLP(cost=squared_distances(points, bins), mass=np.asarray(mass, float),
                   capacity=np.concatenate([np.tile(FACET_CAPACITY, facets), np.zeros(n_v)]),
                   simplex=np.concatenate([np.repeat(np.arange(facets), len(FACET_BINS)),
                                           facets + np.arange(n_v)]).astype(np.int32),
                   is_vertex=np.arange(len(bins)) >= n_f)


def test_points_on_the_bins_in_proportion_cost_nothing():
    level = 3.0
    lp = facet_and_vertex(FACET_BINS, FACET_CAPACITY * level, vertex_at=[5.0, 5.0, 5.0])
    sol = solve_member(lp)
    assert sol.status == CONVERGED
    assert abs(sol.cost) < 1e-8
    np.testing.assert_allclose(sol.plan[:, :4], np.diag(FACET_CAPACITY * level), atol=1e-8)
    np.testing.assert_allclose(sol.density, [level, 0.0], atol=1e-8)
    np.testing.assert_allclose(sol.simplex_mass, [level, 0.0], atol=1e-8)


def test_one_point_above_a_facet_spreads_uniformly():
    # One point must cover the facet in proportion to the capacities: its cost
    # is h^2 plus the capacity-weighted mean squared distance in the plane.
    h, q, m = 0.5, np.array([0.2, 0.3]), 2.0
    in_plane = (0.4 * (0.2 ** 2 + 0.3 ** 2) + 0.2 * (0.8 ** 2 + 0.3 ** 2) + 0.25 * (0.2 ** 2 + 0.7 ** 2)
                + 0.15 * (0.2 ** 2 + 0.1 ** 2))
    expected = m * (h ** 2 + in_plane)  # 2 * (0.25 + 0.338)
    assert expected == pytest.approx(1.176, abs=1e-12)
    point = [[q[0], q[1], h]]
    far = facet_and_vertex(point, [m], vertex_at=[5.0, 5.0, 5.0])
    alone = facet_and_vertex(point, [m], vertex_at=None)
    for lp in (far, alone):
        sol = solve_member(lp)
        assert sol.status == CONVERGED
        assert sol.cost == pytest.approx(expected, abs=1e-8)
        np.testing.assert_allclose(sol.plan[0, :4], m * FACET_CAPACITY, atol=1e-8)
        assert sol.density[0] == pytest.approx(m, abs=1e-8)


def test_a_near_vertex_takes_a_point_whole():
    # The vertex bin 0.1 above the point costs 0.01 per unit, the facet 0.588.
    lp = facet_and_vertex([[0.2, 0.3, 0.5]], [2.0], vertex_at=[0.2, 0.3, 0.6])
    sol = solve_member(lp)
    assert sol.cost == pytest.approx(2.0 * 0.01, abs=1e-8)
    np.testing.assert_allclose(sol.density, [0.0, 0.0], atol=1e-8)
    np.testing.assert_allclose(sol.simplex_mass, [0.0, 2.0], atol=1e-8)


def test_the_vertex_bin_collects_a_far_outlier():
    level, outlier_mass = 2.0, 0.7
    outlier = [10.0, 0.0, 0.0]
    points = np.concatenate([FACET_BINS, [outlier]])
    mass = np.concatenate([FACET_CAPACITY * level, [outlier_mass]])
    lp = facet_and_vertex(points, mass, vertex_at=[10.0, 1.0, 0.0])
    sol = solve_member(lp)
    # Its squared distance to the vertex bin is 1; to the facet, about 100.
    assert sol.cost == pytest.approx(outlier_mass * 1.0, abs=1e-8)
    assert sol.plan[4, 4] == pytest.approx(outlier_mass, abs=1e-8)
    np.testing.assert_allclose(sol.density, [level, 0.0], atol=1e-8)
    np.testing.assert_allclose(sol.simplex_mass, [level, outlier_mass], atol=1e-8)


def test_a_facet_no_point_needs_gets_density_zero():
    lp = facet_and_vertex(FACET_BINS, FACET_CAPACITY, vertex_at=[5.0, 5.0, 5.0], facets=2)
    sol = solve_member(lp)
    assert abs(sol.cost) < 1e-8
    np.testing.assert_allclose(sol.density, [1.0, 0.0, 0.0], atol=1e-8)


def test_constraints_hold_for_the_optimal_plan(rng):
    lp = facet_and_vertex(rng.uniform(0, 1, (7, 3)), rng.uniform(0.5, 1.5, 7), vertex_at=[0.5, 0.5, 0.5],
                          facets=2)
    a_eq, b_eq = constraints(lp)
    assert a_eq.shape == (7 + 8, 7 * 9 + lp.n_simplices)
    sol = solve_member(lp)
    x = np.concatenate([sol.plan.ravel(), sol.density])
    np.testing.assert_allclose(a_eq @ x, b_eq, atol=1e-9)


def test_a_point_without_bins_is_infeasible():
    lp = LocalLP(np.zeros((2, 0)), np.ones(2), np.zeros(0), np.zeros(0, np.int32), np.zeros(0, bool))
    assert solve_member(lp).status == INFEASIBLE
    assert solve_exact(pack([lp])).status.tolist() == [INFEASIBLE]


def test_padded_batch_matches_members(rng):
    members = [facet_and_vertex(rng.uniform(0, 1, (n, 3)), rng.uniform(0.5, 1.5, n),
                                vertex_at=[0.5, 0.5, 2.0]) for n in (3, 9)]
    batch = pack(members)
    sol = solve_exact(batch)
    for b, lp in enumerate(members):
        one = solve_member(lp)
        assert sol.cost[b] == pytest.approx(one.cost, abs=1e-10)
        p, k = lp.cost.shape
        assert np.all(sol.plan[b, p:, :] == 0) and np.all(sol.plan[b, :, k:] == 0)
    only_second = solve_exact(batch, members=[1])
    assert only_second.cost[1] == pytest.approx(sol.cost[1], abs=1e-12)
    assert only_second.status.tolist() == [FAILED, CONVERGED] and np.all(only_second.plan[0] == 0)
    kept = solve_exact(batch, members=[0], into=only_second)
    np.testing.assert_allclose(kept.cost, sol.cost, atol=1e-12)


def _linprog_cost(lp):
    """The optimum by scipy's own HiGHS interface on the documented constraints:
    an oracle that shares neither the matrix built for highspy nor the closed form."""
    import scipy.optimize

    a_eq, b_eq = constraints(lp)
    c = np.concatenate([lp.cost.ravel(), np.zeros(lp.n_simplices)])
    res = scipy.optimize.linprog(c, A_eq=a_eq, b_eq=b_eq, bounds=(0, None), method="highs")
    assert res.status == 0
    return res.fun


def test_optimum_matches_an_independent_linprog_with_and_without_the_closed_form():
    from tests.lp.stencils import random_stencil

    rng = np.random.default_rng(5)
    closed = 0
    for trial in range(40):
        n_facets = int(rng.integers(1, 5))
        # Every facet with one bin (closed form possible) in half the trials.
        n_bins = n_facets + 2 if trial % 2 else int(rng.integers(n_facets + 2, 30))
        lp = random_stencil(rng, int(rng.integers(3, 40)), n_bins, n_facets, 2, noise=0.2)
        sol = solve_member(lp)
        assert sol.status == CONVERGED
        assert sol.cost == pytest.approx(_linprog_cost(lp), rel=1e-7, abs=1e-10)
        np.testing.assert_allclose(sol.plan.sum(axis=1), lp.mass, rtol=1e-9)
        closed += sol.closed_form
    assert 5 <= closed <= 35


def test_the_closed_form_is_refused_when_a_cheapest_bin_is_tied_by_uniformity():
    # One point sits on a facet bin of a two-bin facet: sending it there alone
    # would break uniformity, so the closed form must not be taken.
    lp = facet_and_vertex([[0.0, 0.0, 0.0]], [1.0], vertex_at=[0.0, 0.0, 0.3])
    sol = solve_member(lp)
    assert not sol.closed_form
    assert sol.cost == pytest.approx(_linprog_cost(lp), abs=1e-10)


def test_a_solve_prints_nothing():
    """HiGHS writes its banner straight to the process's stdout unless
    silenced before its first call: a library call must print nothing."""
    code = ("import numpy as np\n"
            "from otjax.lp.exact import solve_member\n"
            "from otjax.lp.problem import LocalLP\n"
            "lp = LocalLP(np.array([[1.0, 4.0], [4.0, 1.0], [1.0, 2.0]]), np.ones(3), np.array([0.5, 0.5]),\n"
            "             np.array([0, 0]), np.array([False, False]))\n"
            "assert solve_member(lp).iterations > 0\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and done.stderr == ""
