"""The batched solver against HiGHS on random padded stencils, and its statuses."""

import importlib

import jax
import numpy as np
import pytest

from otjax.lp.batched import NewtonOptions, solve_batched
from otjax.lp.exact import solve_exact
from otjax.lp.problem import CONVERGED, INFEASIBLE, ITERATION_LIMIT, LocalLP, pack
from otjax.lp.solve import solve, solve_members
from tests.lp.stencils import random_mix, random_stencil

# One padded shape and batch size for the whole module: it compiles once per dtype.
SHAPE = (200, 80, 16)
BATCH = 32


def packed(members, dtype=np.float64):
    return pack(members, dtype=dtype, shape=SHAPE, batch=BATCH)


@pytest.fixture(scope="module")
def compared():
    """200 random stencils solved by both solvers: ``(members, batches)`` where each
    batch is ``(indices, packed, batched_solution, exact_solution)``."""
    members = random_mix(np.random.default_rng(7), 200)
    batches = []
    for start in range(0, len(members), BATCH):
        idx = list(range(start, min(start + BATCH, len(members))))
        problem = packed([members[i] for i in idx])
        fast = jax.device_get(solve_batched(problem))
        batches.append((idx, problem, fast, solve_exact(problem, members=range(len(idx)))))
    return members, batches


def test_rounded_plans_are_feasible_and_padding_is_empty(compared):
    members, batches = compared
    for idx, packed, fast, _ in batches:
        for b, i in enumerate(idx):
            lp = members[i]
            p, k = lp.cost.shape
            plan = np.asarray(fast.plan[b])
            assert np.all(plan[p:, :] == 0) and np.all(plan[:, k:] == 0)
            x = plan[:p, :k]
            assert x.min() >= 0
            np.testing.assert_allclose(x.sum(axis=1), lp.mass, rtol=1e-6, atol=0)
            received = x.sum(axis=0)
            for s in np.unique(lp.simplex[~lp.is_vertex]):
                bins = (lp.simplex == s) & ~lp.is_vertex
                fill = received[bins] / lp.capacity[bins]
                assert fill.max() - fill.min() <= 1e-9 * max(fill.max(), 1e-12), (i, s)
                assert fast.density[b, s] == pytest.approx(fill.mean(), rel=1e-9, abs=1e-15)
            assert float(fast.cost[b]) == pytest.approx(float(np.sum(x * lp.cost)), rel=1e-12)
            simplex_mass = np.bincount(lp.simplex, received, minlength=lp.n_simplices)
            np.testing.assert_allclose(fast.simplex_mass[b, :lp.n_simplices], simplex_mass,
                                       rtol=1e-12, atol=1e-15)


def test_rounded_cost_is_near_the_highs_optimum(compared):
    members, batches = compared
    gaps, certified, status = [], [], []
    for idx, _, fast, exact in batches:
        n = len(idx)
        assert np.all(exact.status[:n] == CONVERGED)
        gaps.append((fast.cost[:n] - exact.cost[:n]) / exact.cost[:n])
        certified.append(fast.gap[:n])
        status.append(fast.status[:n])
        # The lower bound is a feasible dual value: never above the optimum.
        assert np.all(fast.lower_bound[:n] <= exact.cost[:n] * (1 + 1e-9))
    gaps, certified, status = map(np.concatenate, (gaps, certified, status))
    q = np.quantile(gaps, [0, 0.5, 0.9, 1])
    print(f"\nrounded cost gap vs HiGHS over {len(gaps)} stencils: min {q[0]:.2e} median {q[1]:.2e} "
          f"p90 {q[2]:.2e} max {q[3]:.2e}; converged {np.sum(status == CONVERGED)}")
    assert gaps.min() >= -1e-9  # a feasible plan cannot beat the optimum
    assert gaps.max() <= 1e-2
    assert np.median(gaps) <= 2e-3
    # A converged member's certificate holds against the true optimum.
    ok = status == CONVERGED
    assert np.all(gaps[ok] <= 1e-3 + 1e-12)
    assert np.all(certified[ok] <= 1e-3 + 1e-12)
    assert ok.mean() >= 0.95


def test_a_tiny_budget_is_flagged_and_auto_solves_exactly():
    rng = np.random.default_rng(3)
    members = [random_stencil(rng, 80, 40, 3, 2) for _ in range(4)]
    problem = packed(members)
    short = NewtonOptions(steps=2)
    fast = jax.device_get(solve_batched(problem, short))
    assert np.all(fast.status[:4] == ITERATION_LIMIT)
    assert np.all(fast.status[4:] == CONVERGED)  # empty members
    np.testing.assert_allclose(fast.plan.sum(axis=2)[:4, :80], problem.mass[:4, :80], rtol=1e-9)
    exact = solve_exact(problem)
    assert np.all(fast.cost[:4] > exact.cost[:4] * (1 + 1e-3))  # two steps are far from the optimum
    result = solve(problem, method="auto", options=short)
    assert result.exact_resolves == 4
    np.testing.assert_allclose(result.solution.cost, exact.cost, rtol=1e-9)
    assert np.all(result.solution.status == CONVERGED)
    default = solve(problem, method="auto")
    assert default.exact_resolves == 0
    np.testing.assert_allclose(default.solution.cost, exact.cost, rtol=1e-3)


def test_members_without_vertex_bins_or_without_bins():
    rng = np.random.default_rng(5)
    facets_only = random_stencil(rng, 60, 30, 3, 0)
    assert not facets_only.is_vertex.any()
    no_bins = LocalLP(np.zeros((5, 0)), np.ones(5), np.zeros(0), np.zeros(0, np.int32), np.zeros(0, bool))
    usual = random_stencil(rng, 50, 20, 2, 2)
    problem = packed([facets_only, no_bins, usual])
    fast = jax.device_get(solve_batched(problem))
    exact = solve_exact(problem, members=range(3))
    assert fast.status[:3].tolist() == [CONVERGED, INFEASIBLE, CONVERGED]
    assert exact.status[:3].tolist() == [CONVERGED, INFEASIBLE, CONVERGED]
    for b in (0, 2):
        assert exact.cost[b] <= fast.cost[b] <= exact.cost[b] * (1 + 1e-3)
    assert np.all(fast.plan[1] == 0)
    np.testing.assert_allclose(fast.plan[0].sum(axis=1)[:60], facets_only.mass, rtol=1e-9)


def test_solve_members_returns_unpadded_solutions_in_order():
    rng = np.random.default_rng(11)
    members = [random_stencil(rng, p, k, 2, 1) for p, k in ((12, 9), (70, 30), (13, 10))]
    result = solve_members(members, method="exact")
    assert result.exact_resolves == 0
    for lp, sol in zip(members, result.solutions):
        assert sol.plan.shape == lp.cost.shape and sol.density.shape == (lp.n_simplices,)
        assert sol.status == CONVERGED
        np.testing.assert_allclose(sol.plan.sum(axis=1), lp.mass, rtol=1e-9)
        assert sol.cost == pytest.approx(float(np.sum(sol.plan * lp.cost)), rel=1e-12)
    with pytest.raises(ValueError, match="method must be one of"):
        solve(pack(members), method="simplex")


def test_float64_needs_x64():
    # float32 runs are measured by scripts/bench_surface_lp.py: a second dtype
    # would compile the solver once more here.
    rng = np.random.default_rng(13)
    problem = pack([random_stencil(rng, 30, 12, 2, 1)])
    with jax.enable_x64(False):
        with pytest.raises(RuntimeError, match="x64"):
            solve_batched(problem)


def test_solve_members_solves_closed_form_members_without_a_batch(monkeypatch):
    solve_module = importlib.import_module("otjax.lp.solve")  # the package exports a function of that name

    rng = np.random.default_rng(17)
    general = random_stencil(rng, 20, 12, 2, 1)
    # every facet with one bin and the points on them: each point's cheapest bin binds nothing
    single = random_stencil(rng, 15, 3, 2, 1, noise=0.0)
    packed = []
    real_pack = solve_module.pack
    monkeypatch.setattr(solve_module, "pack", lambda members, **kw: packed.append(len(members)) or
                        real_pack(members, **kw))
    result = solve_members([single, general], method="exact")
    assert packed == []  # HiGHS takes each member as it is
    assert result.solutions[0].closed_form and not result.solutions[1].closed_form
    from otjax.lp.exact import solve_member

    for lp, sol in zip([single, general], result.solutions):
        assert sol.cost == pytest.approx(solve_member(lp).cost, rel=1e-9, abs=1e-12)


def test_auto_batches_only_groups_worth_a_compiled_shape(monkeypatch):
    solve_module = importlib.import_module("otjax.lp.solve")
    from otjax.lp.exact import solve_member

    rng = np.random.default_rng(19)
    single = random_stencil(rng, 15, 3, 2, 1, noise=0.0)
    group = [random_stencil(rng, 20 + i, 12, 2, 1) for i in range(solve_module.MIN_BATCH)]
    odd = random_stencil(rng, 90, 40, 3, 2)  # alone in its padded shape
    assert len({solve_module.member_shape(lp) for lp in group}) == 1
    assert solve_module.member_shape(odd) != solve_module.member_shape(group[0])
    packed = []
    real_pack = solve_module.pack
    monkeypatch.setattr(solve_module, "pack", lambda members, **kw: packed.append((len(members), kw["batch"]))
                        or real_pack(members, **kw))
    members = [single, *group, odd]
    result = solve_members(members, method="auto")
    assert packed == [(len(group), solve_module.BATCH)]
    assert result.batched_calls == 1
    assert result.solutions[0].closed_form
    for lp, sol in zip(members, result.solutions):
        assert sol.status == CONVERGED and sol.plan.shape == lp.cost.shape
        np.testing.assert_allclose(sol.plan.sum(axis=1), lp.mass, rtol=1e-6)
        assert sol.cost == pytest.approx(solve_member(lp).cost, rel=2e-3)