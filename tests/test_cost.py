"""Tests for otjax.curves.cost against the plain-Python oracle."""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from scipy.spatial import Delaunay  # noqa: E402

from otjax.curves import cost  # noqa: E402
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils  # noqa: E402
from tests.oracles import oracle_edge_cost, oracle_segment_sqdist, oracle_stencil_cost  # noqa: E402

BATCHED = {"rank": cost.batched_stencil_cost_rank, "sort": cost.batched_stencil_cost_sort}
PER_EDGE = ("edge_cost", "normal", "tangential", "vertex", "edge_mass")


# ----------------------------------------------------------------------------
# Stencil generation: local patches of a random Delaunay triangulation.


def make_stencil(rng, max_edges, n_points, short_edge=True):
    """A patch of triangles with at most ``max_edges`` edges and ``n_points`` points.

    Edges share endpoints; a point inside a triangle lists that triangle's
    edges (by increasing global key); some points sit exactly on vertices,
    some are pinned to one edge from anywhere (they project outside it), some
    have zero mass. With ``short_edge`` two vertices are 1e-7 apart.
    """
    nv = max_edges // 2 + 10
    verts = rng.random((nv, 2))
    if short_edge:
        ang = rng.uniform(0, 2 * np.pi)
        verts[1] = verts[0] + 1e-7 * np.array([np.cos(ang), np.sin(ang)])
    tris = Delaunay(verts).simplices
    seed = verts[0] if short_edge else verts[rng.integers(nv)]
    tris = tris[np.argsort(np.linalg.norm(verts[tris].mean(axis=1) - seed, axis=1))]

    keys: set[tuple[int, int]] = set()
    chosen = []
    for t in tris:
        tk = {tuple(sorted((int(t[i]), int(t[j])))) for i, j in ((0, 1), (1, 2), (0, 2))}
        if len(keys | tk) <= max_edges:
            keys |= tk
            chosen.append(t)
    keys_sorted = sorted(keys)
    local = dict(zip(keys_sorted, rng.permutation(len(keys_sorted)).tolist()))
    edges = np.zeros((len(keys), 2, 2))
    for (i, j), e in local.items():
        edges[e] = verts[i], verts[j]

    points = np.zeros((n_points, 2))
    cand = np.zeros((n_points, 3), np.int32)
    for k in range(n_points):
        t = chosen[rng.integers(len(chosen))]
        tk = sorted(tuple(sorted((int(t[i]), int(t[j])))) for i, j in ((0, 1), (1, 2), (0, 2)))
        cand[k] = [local[key] for key in tk]
        kind = rng.random()
        if kind < 0.75:
            points[k] = rng.dirichlet([1.0, 1.0, 1.0]) @ verts[t]
        elif kind < 0.87:
            points[k] = verts[t[rng.integers(3)]]
        else:
            cand[k] = cand[k, rng.integers(3)]
            points[k] = rng.uniform(-0.5, 1.5, 2)
    mass = rng.uniform(0.1, 2.0, n_points)
    mass[rng.random(n_points) < 0.1] = 0.0
    return edges, points, mass, cand


def row(batch: EdgeStencil, b: int) -> EdgeStencil:
    return EdgeStencil(*(np.asarray(x[b]) for x in batch))


def assert_matches_oracle(batch: EdgeStencil, got, rtol=1e-9, check_flags=True):
    for b in range(batch.shape[0]):
        want = oracle_stencil_cost(*row(batch, b))
        scale = sum(want["normal"]) + sum(want["tangential"]) + sum(want["vertex"])
        atol = 1e-12 * scale + 1e-300
        for key in PER_EDGE:
            np.testing.assert_allclose(getattr(got, key)[b], want[key], rtol=rtol, atol=atol, err_msg=f"{key}[{b}]")
        np.testing.assert_allclose(got.total[b], want["total"], rtol=rtol, atol=atol)
        if check_flags:
            np.testing.assert_array_equal(got.solid[b], want["solid"])
            np.testing.assert_array_equal(got.assignment[b], want["assignment"])


# ----------------------------------------------------------------------------
# Against the oracle, at every bucket size.


@pytest.fixture(scope="module", params=[(e, p) for e in (16, 32, 64) for p in (32, 64, 128, 256)], ids=str)
def bucket_batch(request):
    e_cap, p_cap = request.param
    rng = np.random.default_rng(1000 * e_cap + p_cap)
    stencils = [
        make_stencil(rng, e_cap, p_cap),  # (nearly) full
        make_stencil(rng, e_cap // 2 + 1, p_cap // 2 + 1),  # padded
        make_stencil(rng, 3, 7, short_edge=False),
        make_stencil(rng, e_cap, 1),
    ]
    batch = pack_edge_stencils(stencils, Buckets(min_edges=e_cap, min_points=p_cap))
    assert batch.shape == (16, e_cap, p_cap)
    return batch


@pytest.mark.parametrize("method", ["rank", "sort"])
def test_matches_oracle_at_bucket_sizes(bucket_batch, method):
    got = jax.tree.map(np.asarray, BATCHED[method](bucket_batch))
    assert_matches_oracle(bucket_batch, got)
    # Empty (padding) rows cost exactly nothing.
    assert np.all(got.total[4:] == 0) and np.all(got.assignment[4:] == -1)
    # The generator does exercise both outcomes.
    assert got.solid.any() and (~got.solid & bucket_batch.edge_mask & (got.edge_mass > 0)).any()


def test_default_method_is_exposed():
    assert cost.DEFAULT_TANGENTIAL_METHOD in cost.TANGENTIAL_METHODS
    assert cost.batched_stencil_cost is BATCHED[cost.DEFAULT_TANGENTIAL_METHOD]


def test_float32_runs_and_roughly_matches():
    rng = np.random.default_rng(7)
    stencils = [make_stencil(rng, 16, 32, short_edge=False) for _ in range(3)]
    b64 = pack_edge_stencils(stencils, Buckets(min_edges=16, min_points=32))
    b32 = pack_edge_stencils(stencils, Buckets(min_edges=16, min_points=32), dtype=np.float32)
    for method in ("rank", "sort"):
        got = BATCHED[method](b32)
        assert got.total.dtype == jnp.float32
        want = np.asarray(BATCHED[method](b64).total)
        np.testing.assert_allclose(np.asarray(got.total), want, rtol=1e-4)


# ----------------------------------------------------------------------------
# Closed-form cases.


def test_single_point_at_midpoint():
    # One unit mass at the middle of an edge of length 2: T = L^2 / 12.
    n, t, v = oracle_edge_cost([0, 0], [2, 0], [[1, 0]], [1.0])
    assert (n, t, v) == (0.0, pytest.approx(4 / 12), 1.0)


def test_uniform_sampling_tangential():
    # n equal masses at the bin centres: T = M L^2 / (12 n^2), whatever the
    # normal offsets.
    n, length, mass = 5, 3.0, 2.0
    xs = (np.arange(n) + 0.5) * length / n
    pts = np.stack([xs, np.linspace(-0.1, 0.1, n)], axis=1)
    stencil = EdgeStencil(
        edges=np.array([[[0.0, 0.0], [length, 0.0]]]),
        edge_mask=np.array([True]),
        points=pts,
        mass=np.full(n, mass / n),
        point_mask=np.ones(n, bool),
        cand=np.zeros((n, 3), np.int32),
    )
    for method in ("rank", "sort"):
        got = cost.stencil_cost(stencil, method)
        np.testing.assert_allclose(got.tangential[0], mass * length**2 / (12 * n**2), rtol=1e-12)
        np.testing.assert_allclose(got.normal[0], np.sum(mass / n * pts[:, 1] ** 2), rtol=1e-12)
        assert bool(got.solid[0])
    assert oracle_edge_cost([0, 0], [length, 0], pts, np.full(n, mass / n))[1] == pytest.approx(
        mass * length**2 / (12 * n**2)
    )


def test_vertex_ties_are_exact_and_go_to_the_earliest_candidate():
    a, b, c = np.array([0.0, 0.0]), np.array([1.0, 0.3]), np.array([0.2, 0.9])
    p = np.array([[-0.3, -0.2], [0.0, 0.0]])  # vertex region of a; on a
    d_ab = cost.segment_sqdist(p, a, b)
    d_ac = cost.segment_sqdist(p, a, c)
    d_ca = cost.segment_sqdist(p, c, a)  # a as second endpoint
    np.testing.assert_array_equal(d_ab, d_ac)
    np.testing.assert_array_equal(d_ab, d_ca)
    assert float(d_ab[1]) == 0.0
    assert oracle_segment_sqdist(p[0], a, b) == float(d_ab[0])
    stencil = EdgeStencil(
        edges=np.array([[c, a], [a, b], [b, c]]),
        edge_mask=np.ones(3, bool),
        points=p,
        mass=np.ones(2),
        point_mask=np.ones(2, bool),
        cand=np.array([[1, 0, 2], [0, 1, 2]], np.int32),
    )
    np.testing.assert_array_equal(cost.assign_points(stencil), [1, 0])


def test_segment_sqdist_interior():
    d = cost.segment_sqdist(jnp.array([0.5, 2.0]), jnp.array([0.0, 0.0]), jnp.array([1.0, 0.0]))
    assert float(d) == 4.0
    # Degenerate segment: distance to the point.
    d = cost.segment_sqdist(jnp.array([3.0, 4.0]), jnp.zeros(2), jnp.zeros(2))
    assert float(d) == 25.0


# ----------------------------------------------------------------------------
# Refinement stability (paper, after Eq. 4).

REFINE_BUCKETS = dict(min_edges=16, min_points=128)
MAX_REFINE_POINTS = 25  # x5 copies fits the 128-point bucket: one compiled shape

coord = st.floats(-1.0, 1.0, allow_nan=False, allow_subnormal=False)
xy = st.tuples(coord, coord)


@st.composite
def refinable_stencils(draw):
    n_edges = draw(st.integers(1, 5))
    edges = np.array(draw(st.lists(st.tuples(xy, xy), min_size=n_edges, max_size=n_edges)), float)
    n = draw(st.integers(1, MAX_REFINE_POINTS))
    points = np.array(draw(st.lists(xy, min_size=n, max_size=n)), float)
    mass = np.array(
        draw(st.lists(st.one_of(st.just(0.0), st.floats(1e-3, 1.0)), min_size=n, max_size=n)), float
    )
    cand = np.array(draw(st.lists(st.lists(st.integers(0, n_edges - 1), min_size=3, max_size=3), min_size=n, max_size=n)))
    k = draw(st.integers(2, 5))
    return edges, points, mass, cand.astype(np.int32), k


@settings(max_examples=40, deadline=None)
@given(refinable_stencils())
def test_refinement_stability(data):
    edges, points, mass, cand, k = data
    fine = (edges, np.repeat(points, k, axis=0), np.repeat(mass / k, k), np.repeat(cand, k, axis=0))
    batch = pack_edge_stencils([(edges, points, mass, cand), fine], Buckets(**REFINE_BUCKETS))
    for method in ("rank", "sort"):
        got = jax.tree.map(np.asarray, BATCHED[method](batch))
        scale = float(np.sum(got.normal[0] + got.tangential[0] + got.vertex[0]))
        atol = 1e-12 * scale + 1e-300
        for key in PER_EDGE:
            np.testing.assert_allclose(getattr(got, key)[1], getattr(got, key)[0], rtol=1e-9, atol=atol, err_msg=key)
        np.testing.assert_allclose(got.total[1], got.total[0], rtol=1e-9, atol=atol)


# ----------------------------------------------------------------------------
# Gradients.


def _degenerate_batch():
    rng = np.random.default_rng(3)
    edges, points, mass, cand = make_stencil(rng, 12, 20)
    edges[2, 1] = edges[2, 0]  # zero-length edge
    cand[:4] = 2  # ... that receives points
    points[4] = edges[0, 0]  # exactly on a vertex
    mass[5:8] = 0.0
    cand[5:8] = 3  # an edge whose points all have zero mass
    batch = pack_edge_stencils([(edges, points, mass, cand)], Buckets(min_edges=16, min_points=32))
    return batch, len(edges)


@pytest.mark.parametrize("method", ["rank", "sort"])
def test_gradients_are_finite(method):
    batch, n_edges = _degenerate_batch()

    def total(edges, points, mass):
        return jnp.sum(BATCHED[method](batch._replace(edges=edges, points=points, mass=mass)).total)

    out = BATCHED[method](batch)
    assert not out.solid[0, 2] and float(out.normal[0, 2]) == 0.0
    grads = jax.grad(total, argnums=(0, 1, 2))(batch.edges, batch.points, batch.mass)
    for g in grads:
        assert np.all(np.isfinite(np.asarray(g)))
    # Padding gets exactly zero gradient.
    g_edges, g_points, _ = (np.asarray(g) for g in grads)
    assert np.all(g_edges[1:] == 0) and np.all(g_edges[0, n_edges:] == 0)
    assert np.all(g_points[1:] == 0) and np.all(g_points[0, 20:] == 0)


def test_gradient_matches_finite_differences():
    rng = np.random.default_rng(11)
    batch = pack_edge_stencils([make_stencil(rng, 12, 20, short_edge=False)], Buckets(min_edges=16, min_points=32))

    def total(points):
        return jnp.sum(cost.batched_stencil_cost(batch._replace(points=points)).total)

    g = np.asarray(jax.grad(total)(batch.points))
    h = 1e-6
    for i, j in [(0, 0), (3, 1), (7, 0), (12, 1)]:
        dp = np.zeros_like(batch.points)
        dp[0, i, j] = h
        fd = (float(total(batch.points + dp)) - float(total(batch.points - dp))) / (2 * h)
        np.testing.assert_allclose(g[0, i, j], fd, rtol=1e-5, atol=1e-8)
