"""jax.grad of the fixed-plan cost against central finite differences.

The cost with the assignment held fixed (``fixed_assignment_cost``) is
piecewise smooth in the vertex positions. Kinks sit where an edge switches
between solid and ghost, where a point is equidistant from both ends of a
ghost edge, or where two projections on an edge swap order. Finite
differences across a kink are meaningless, so configurations closer than a
margin to one are discarded (``assume``), and configurations are drawn from a
continuous distribution (a seed, not raw floats that hypothesis could shrink
to exact ties).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from otjax import curves, datasets

# Fixed shapes, so that one compilation serves every example; the number of
# live vertices / edges / points varies through zero masses and unused slots.
V, E, P = 7, 9, 48
REL_TOL = 1e-6
STEP = 1e-5  # relative to the configuration's scale


def _kink_margins(vertices, edge_index, points, mass, point_edge):
    """Smallest relative distance to a kink of the fixed-assignment cost."""
    margins = [np.inf]
    for e, (i, j) in enumerate(edge_index):
        sel = (point_edge == e) & (mass > 0)
        if not sel.any():
            continue
        a, b = vertices[i], vertices[j]
        d = b - a
        length = np.linalg.norm(d)
        u = d / length
        p, m = points[sel], mass[sel]
        t = (p - a) @ u
        n2 = ((p - a) @ np.array([-u[1], u[0]])) ** 2
        da, db = ((p - a) ** 2).sum(1), ((p - b) ** 2).sum(1)
        # Tangential order: gaps between consecutive projections.
        if len(t) > 1:
            margins.append(np.diff(np.sort(t)).min() / length)
        # Vertex cost min(|p-a|^2, |p-b|^2): distance from the bisector.
        margins.append(np.abs(da - db).min() / length**2)
        # Solid vs ghost: N + T against V.
        order = np.argsort(t, kind="stable")
        c = np.concatenate([[0.0], np.cumsum(m[order])[:-1]])
        mm = m.sum()
        centre = length * (c + 0.5 * m[order]) / mm
        tang = np.sum(m[order] * ((length * m[order] / mm) ** 2 / 12 + (t[order] - centre) ** 2))
        normal, vertex = np.sum(m * n2), np.sum(m * np.minimum(da, db))
        margins.append(abs(normal + tang - vertex) / max(normal + tang + vertex, 1e-300))
    return min(margins)


def _configuration(seed, n_vertices, n_edges, n_points):
    """Random vertices, edges, points near the edges, masses and assignment."""
    rng = np.random.default_rng(seed)
    scale = 10.0 ** rng.uniform(-2, 2)
    vertices = rng.uniform(-1, 1, (V, 2)) * scale
    pairs = np.array([(i, j) for i in range(n_vertices) for j in range(i + 1, n_vertices)])
    edge_index = pairs[rng.choice(len(pairs), size=min(n_edges, len(pairs)), replace=False)]
    edge_index = np.concatenate([edge_index, np.repeat(edge_index[:1], E - len(edge_index), 0)])
    point_edge = rng.integers(0, min(n_edges, len(pairs)), P)
    # Points along their edge (some beyond the ends), off the line by a noise
    # that is sometimes small (solid edges) and sometimes large (ghosts).
    a, b = vertices[edge_index[point_edge, 0]], vertices[edge_index[point_edge, 1]]
    s = rng.uniform(-0.2, 1.2, P)[:, None]
    spread = scale * 10.0 ** rng.uniform(-3, 0)
    points = a + s * (b - a) + rng.normal(0, spread, (P, 2))
    mass = rng.uniform(0.1, 2.0, P)
    mass[n_points:] = 0.0
    return vertices, edge_index, points, mass, point_edge, scale


@pytest.fixture(scope="module")
def cost_and_grad():
    with jax.enable_x64(True):
        f = jax.jit(curves.fixed_assignment_cost)
        g = jax.jit(jax.grad(curves.fixed_assignment_cost))
    return f, g


def _check(cost_and_grad, vertices, edge_index, points, mass, point_edge, scale):
    f, g = cost_and_grad
    with jax.enable_x64(True):
        args = tuple(jnp.asarray(x) for x in (edge_index, points, mass, point_edge))
        grad = np.asarray(g(jnp.asarray(vertices), *args))
        h = STEP * scale
        fd = np.zeros_like(vertices)
        for i in range(vertices.shape[0]):
            for k in range(2):
                plus, minus = vertices.copy(), vertices.copy()
                plus[i, k] += h
                minus[i, k] -= h
                up, down = float(f(jnp.asarray(plus), *args)), float(f(jnp.asarray(minus), *args))
                fd[i, k] = (up - down) / (2 * h)
    assert np.all(np.isfinite(grad))
    ref = max(np.abs(fd).max(), np.abs(grad).max())
    assert ref > 0
    np.testing.assert_allclose(grad, fd, rtol=REL_TOL, atol=REL_TOL * ref)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(
    seed=st.integers(0, 2**32 - 1),
    n_vertices=st.integers(2, V),
    n_edges=st.integers(1, E),
    n_points=st.integers(1, P),
)
def test_grad_matches_central_differences(cost_and_grad, seed, n_vertices, n_edges, n_points):
    config = _configuration(seed, n_vertices, n_edges, n_points)
    vertices, edge_index, points, mass, point_edge, _scale = config
    # Away from every kink by far more than the finite-difference step.
    assume(_kink_margins(vertices, edge_index, points, mass, point_edge) > 1e-3)
    _check(cost_and_grad, *config)


def test_grad_on_a_real_plan(cost_and_grad):
    """Same check on a real transport plan: 300 noisy star points onto a triangulation of 15 of them."""
    points, _ = datasets.star(300, noise=0.01, seed=4)
    mass = np.ones(len(points))
    # The engine's kernel sets the plan's edge costs (a bare plan holds none).
    plan = curves.CurveEngine(curves.Triangulation(points[::20]), points, mass).plan
    nv = len(plan.tri.xy)
    code = plan.pt_edge[:, 0] * nv + plan.pt_edge[:, 1]
    uniq, point_edge = np.unique(code, return_inverse=True)
    edge_index = np.stack([uniq // nv, uniq % nv], 1)
    vertices = plan.tri.xy.copy()
    assert any(plan.edge_solid.values()) and not all(plan.edge_solid.values())  # both kinds of edge
    with jax.enable_x64(True):
        exact = float(cost_and_grad[0](vertices, edge_index, points, mass, point_edge))
    # With the plan's own assignment, the function is the plan's cost.
    np.testing.assert_allclose(exact, plan.total_cost(), rtol=1e-9)
    margin = _kink_margins(vertices, edge_index, points, mass, point_edge)
    assert margin > 1e-4, margin
    _check(cost_and_grad, vertices, edge_index, points, mass, point_edge, 1.0)
