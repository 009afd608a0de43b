"""Vertex relocation (rounds of the shared loop over a curve engine) and
gradient refinement, against from-scratch costs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from otjax.curves.decimate import decimate
from otjax.curves.engine import CurveEngine
from otjax.curves.refinement import minimize_lbfgs, refine
from otjax.curves.triangulation import Triangulation
from otjax.decimation.relocation import relocate
from tests.curves.helpers import check_scratch, free_vertices, noisy_shape
from tests.oracles import oracle_edge_cost


def decimated(seed=0, n=400, keep=40, **options):
    rng = np.random.default_rng(seed)
    pts = noisy_shape(rng, n)
    engine = CurveEngine(Triangulation(pts[::4]), pts, rng.uniform(0.5, 1.5, n), **options)
    decimate(engine, keep)
    return engine


def test_relocation_lowers_the_cost_and_reports_what_it_touched():
    engine = decimated()
    before = engine.total_cost()
    xy = engine.plan.tri.xy.copy()
    vertices = free_vertices(engine)
    dirty, _, moved = relocate(engine, vertices)
    assert 0 < moved <= len(vertices)
    after = engine.total_cost()
    assert after < before
    assert after == pytest.approx(check_scratch(engine), rel=1e-9)
    engine.plan.tri.check()
    changed = {v for v in range(len(xy)) if np.any(engine.plan.tri.xy[v] != xy[v])}
    assert len(changed) == moved and changed <= dirty
    # A veto that rejects every move moves nothing.
    xy = engine.plan.tri.xy.copy()
    seen = []
    dirty, _, moved = relocate(engine, free_vertices(engine), lambda cand, cost: seen.append(cand) or False)
    assert (dirty, moved) == (set(), 0)
    assert seen and all(c.moved is not None for c in seen)
    np.testing.assert_array_equal(engine.plan.tri.xy, xy)


@pytest.mark.parametrize("seed, accepted", [(4, True), (1, False)])
def test_refinement_returns_a_new_engine_when_it_helps(seed, accepted):
    engine = decimated(seed=seed)
    before = engine.total_cost()
    xy = engine.plan.tri.xy.copy()
    new, info = refine(engine)
    assert set(info) == {"accepted", "cost_before", "cost_after", "step", "values"}
    assert info["cost_before"] == before
    assert info["values"] and info["values"][-1] <= info["values"][0]
    assert info["accepted"] == accepted  # both outcomes occur on this data
    if accepted:
        assert new is not engine and isinstance(new, CurveEngine)
        assert 0 < info["step"] <= 1 and info["cost_after"] < before
        assert new.total_cost() == info["cost_after"] == pytest.approx(check_scratch(new), rel=1e-9)
        new.plan.tri.check()
        assert new.incremental == engine.incremental and new.degree_bound == engine.degree_bound
    else:
        assert new is engine and info["cost_after"] == before and info["step"] == 0.0
        np.testing.assert_array_equal(engine.plan.tri.xy, xy)


def fixed_assignment_oracle(xy, keys, groups, points, mass) -> float:
    """The transport cost with each point kept on its edge of ``keys``, each edge the
    cheaper of solid and ghost: NumPy, independent of the JAX objective refine() minimises."""
    total = 0.0
    for (a, b), ids in zip(keys, groups):
        if mass[ids].sum() > 0:
            normal, tangential, vertex = oracle_edge_cost(xy[a], xy[b], points[ids], mass[ids])
            total += min(normal + tangential, vertex)
    return total


def oracle_gradient(xy, free, args, h=1e-6) -> np.ndarray:
    """Central differences of :func:`fixed_assignment_oracle` over the free vertices."""
    grad = np.zeros((len(free), 2))
    for i, v in enumerate(free):
        for d in range(2):
            up, down = xy.copy(), xy.copy()
            up[v, d] += h
            down[v, d] -= h
            grad[i, d] = (fixed_assignment_oracle(up, *args) - fixed_assignment_oracle(down, *args)) / (2 * h)
    return grad


def test_refinement_reaches_a_stationary_point_and_lowers_the_exact_cost_by_a_margin():
    """What refine() does not ensure by construction, checked by NumPy oracles on a case
    where its full step is taken (seed 4, measured): its vertices are a stationary point
    of the fixed-assignment cost (central differences: |grad| 2.9 at the start, 3e-10 at
    the end), that cost fell 22%, and the exact cost after every point is reassigned fell
    1.2% (0.70017 -> 0.69149): reassignment undoes most of the gain, not all of it."""
    engine = decimated(seed=4)
    plan = engine.plan
    keys, inverse = np.unique(plan.pt_edge, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    args = (keys, [np.flatnonzero(inverse == k) for k in range(len(keys))], plan.points, plan.mass)
    free = np.flatnonzero(plan.tri.alive & ~plan.tri.pinned)
    start_xy = plan.tri.xy.copy()
    start_fixed = fixed_assignment_oracle(start_xy, *args)
    start_exact = check_scratch(engine)
    new, info = refine(engine)
    assert info["accepted"] and info["step"] == 1.0
    xy = new.plan.tri.xy
    end_fixed = fixed_assignment_oracle(xy, *args)
    assert end_fixed == pytest.approx(info["values"][-1], rel=1e-9)  # the objective is the oracle's cost
    assert end_fixed <= 0.85 * start_fixed
    grad_start, grad_end = (np.linalg.norm(oracle_gradient(x, free, args)) for x in (start_xy, xy))
    assert grad_start > 1.0 and grad_end <= 1e-6 * grad_start
    assert check_scratch(new) <= (1 - 0.006) * start_exact


def test_a_refined_engine_keeps_every_option():
    engine = decimated(seed=4, incremental=False, update_min_rows=0, max_source_degree=24)
    new, info = refine(engine)
    assert info["accepted"] and new is not engine
    assert (new.incremental, new.degree_bound, new.scorer.pipeline.dtype) == (False, 24, np.float64)
    assert new.update_min_rows == 0


def test_refinement_needs_x64():
    engine = decimated(seed=3, n=200, keep=20)
    with jax.enable_x64(False), pytest.raises(RuntimeError, match="float64"):
        refine(engine)


def test_minimize_lbfgs_finds_a_quadratic_minimum():
    target = jnp.asarray([1.5, -2.0, 0.25])
    x, values = minimize_lbfgs(lambda x, t: jnp.sum((x - t) ** 2), jnp.zeros(3), args=(target,))
    np.testing.assert_allclose(np.asarray(x), np.asarray(target), atol=1e-6)
    assert values[0] == pytest.approx(float(jnp.sum(target**2))) and values[-1] < 1e-10
