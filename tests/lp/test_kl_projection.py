"""The closed form of a facet's KL projection, against brute-force minimisation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from otjax.lp import batched
from otjax.lp.problem import pack
from tests.lp.stencils import random_stencil


def kl_to_target(level, received, capacity):
    """KL(c l | r) = sum_j c_j l log(c_j l / r_j) - c_j l + r_j: the divergence of a
    plan whose columns are rescaled from sums r_j to c_j l."""
    target = capacity * level
    return float(np.sum(target * np.log(target / received) - target + received))


def brute_force_level(received, capacity):
    res = minimize_scalar(lambda t: kl_to_target(np.exp(t), received, capacity), bracket=(-5.0, 5.0),
                          options={"xtol": 1e-14})
    return float(np.exp(res.x))


@pytest.mark.parametrize("size", [1, 2, 7, 30])
def test_geometric_mean_is_the_kl_minimiser(rng, size):
    received = rng.uniform(0.01, 3.0, size)
    capacity = rng.uniform(0.1, 1.0, size)
    closed = np.exp(np.sum(capacity * np.log(received / capacity)) / np.sum(capacity))
    assert closed == pytest.approx(brute_force_level(received, capacity), rel=1e-7)
    # A minimum: any other level is worse.
    for other in (closed * 0.99, closed * 1.01):
        assert kl_to_target(other, received, capacity) > kl_to_target(closed, received, capacity)


def test_the_solver_step_rescales_columns_to_the_projection(rng):
    # Before the rows renormalise, the Sinkhorn step multiplies column j of
    # the plan by exp(dg_j / eps): the new column sums must be c_j l* with
    # l* the brute-force KL minimiser of each facet.
    lp = random_stencil(rng, 40, 24, n_facets=3, n_vertices=2)
    k = lp.cost.shape[1]
    eps = 0.05

    @jax.jit
    def step(problem, g):
        mb = batched._member(problem, np.float64)
        g = g * mb.free
        ep = batched._entropic_plan(mb, g, eps)
        return batched._uniformize(mb, g, eps, ep) - g, ep.plan.sum(axis=0)

    problem = batched.TransportLP(*(jnp.asarray(a[0]) for a in pack([lp])))
    moved, received = map(np.asarray, step(problem, jnp.asarray(rng.normal(0, 0.05, problem.cost.shape[1]))))
    scaled = received * np.exp(moved / eps)
    for s in range(3):
        bins = np.flatnonzero((lp.simplex == s) & ~lp.is_vertex)
        level = brute_force_level(received[bins], lp.capacity[bins])
        np.testing.assert_allclose(scaled[bins], lp.capacity[bins] * level, rtol=1e-7)
    assert np.all(moved[k - 2:] == 0)  # vertex bins keep g = 0
