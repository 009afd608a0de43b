"""Tests for otjax.curves.cost against the plain-Python oracle."""

from __future__ import annotations

import functools

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import Delaunay

from otjax.curves import cost, mass_before
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils
from tests.oracles import oracle_edge_cost, oracle_segment_sqdist, oracle_stencil_cost

METHODS = cost.TANGENTIAL_METHODS
PER_EDGE = ("edge_cost", "normal", "tangential", "vertex", "edge_mass")


# Both formulations in ONE compiled function, so each padded shape compiles
# once and every test below reuses a handful of shapes. Compiled at XLA
# backend optimisation level 0: about half the compile time, which dominates
# this file; the rounding may differ from the production build only in the
# last bits, and test_public_batched_functions checks the production build.
FAST_COMPILE = {"xla_backend_optimization_level": 0}


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def both_methods(batch: EdgeStencil) -> dict:
    return {m: jax.vmap(functools.partial(cost.stencil_cost, tangential_method=m))(batch) for m in METHODS}


def run_both(batch: EdgeStencil) -> dict:
    return jax.tree.map(np.asarray, both_methods(batch))


sqdist = jax.jit(cost.segment_sqdist, compiler_options=FAST_COMPILE)


def single(stencil: EdgeStencil, capacity=(16, 32)) -> EdgeStencil:
    """Packs one hand-made stencil into the (already compiled) default shape."""
    return pack_edge_stencils(
        [(stencil.edges, stencil.points, stencil.mass, stencil.cand)], Buckets(*capacity)
    )


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


N_REAL = 4  # real stencils per oracle batch; the other rows are padding


def assert_matches_oracle(batch: EdgeStencil, got, want: list[dict]):
    for b, w in enumerate(want):
        scale = sum(w["normal"]) + sum(w["tangential"]) + sum(w["vertex"])
        atol = 1e-12 * scale + 1e-300
        for key in PER_EDGE:
            np.testing.assert_allclose(
                getattr(got, key)[b], w[key], rtol=1e-9, atol=atol, err_msg=f"{key}[{b}]"
            )
        np.testing.assert_allclose(got.total[b], w["total"], rtol=1e-9, atol=atol)
        np.testing.assert_array_equal(got.solid[b], w["solid"])
        np.testing.assert_array_equal(got.assignment[b], w["assignment"])
    # Empty (padding) rows cost exactly nothing.
    pad = slice(len(want), None)
    for key in PER_EDGE + ("total",):
        assert np.all(getattr(got, key)[pad] == 0), key
    assert not got.solid[pad].any() and np.all(got.assignment[pad] == -1)


# ----------------------------------------------------------------------------
# Against the oracle, at every bucket size.


@pytest.fixture(scope="module", params=[(e, p) for e in (16, 32, 64) for p in (32, 64, 128, 256)], ids=str)
def bucket_case(request):
    e_cap, p_cap = request.param
    rng = np.random.default_rng(1000 * e_cap + p_cap)
    stencils = [
        make_stencil(rng, e_cap, p_cap),  # (nearly) full
        make_stencil(rng, e_cap // 2 + 1, p_cap // 2 + 1),  # padded
        make_stencil(rng, 3, 7, short_edge=False),
        make_stencil(rng, e_cap, 1),
    ]
    assert len(stencils) == N_REAL
    batch = pack_edge_stencils(stencils, Buckets(min_edges=e_cap, min_points=p_cap))
    assert batch.shape[1:] == (e_cap, p_cap)
    want = [oracle_stencil_cost(*row(batch, b)) for b in range(N_REAL)]
    return batch, want


def test_matches_oracle_at_bucket_sizes(bucket_case):
    batch, want = bucket_case
    got = run_both(batch)
    for method in METHODS:
        assert_matches_oracle(batch, got[method], want)
    # The generator does exercise both outcomes.
    g = got[METHODS[0]]
    assert g.solid.any() and (~g.solid & batch.edge_mask & (g.edge_mass > 0)).any()


def test_public_batched_functions():
    assert cost.resolve_tangential_method("auto", cost.RANK_MAX_POINTS) == "rank"
    assert cost.resolve_tangential_method("auto", 2 * cost.RANK_MAX_POINTS) == "sort"
    assert cost.resolve_tangential_method("sort", 8) == "sort"
    with pytest.raises(ValueError):
        cost.resolve_tangential_method("bogus", 8)
    # The production build (default optimisation, default method) agrees with
    # the test build.
    rng = np.random.default_rng(5)
    batch = pack_edge_stencils([make_stencil(rng, 16, 32) for _ in range(3)], Buckets(16, 32))
    got = jax.tree.map(np.asarray, cost.batched_stencil_cost(batch))
    want = run_both(batch)[cost.resolve_tangential_method(cost.DEFAULT_TANGENTIAL_METHOD, 32)]
    for key in PER_EDGE + ("total",):
        np.testing.assert_allclose(getattr(got, key), getattr(want, key), rtol=1e-12, atol=1e-15)
    for key in ("solid", "assignment"):
        np.testing.assert_array_equal(getattr(got, key), getattr(want, key))


def test_float32_runs_and_roughly_matches():
    rng = np.random.default_rng(7)
    stencils = [make_stencil(rng, 16, 32, short_edge=False) for _ in range(3)]
    b64 = pack_edge_stencils(stencils, Buckets(16, 32))
    b32 = pack_edge_stencils(stencils, Buckets(16, 32), dtype=np.float32)
    got32, got64 = both_methods(b32), run_both(b64)
    for method in METHODS:
        assert got32[method].total.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(got32[method].total), got64[method].total, rtol=1e-4)


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
    pts = np.stack([xs, np.linspace(-0.1, 0.1, n)], axis=1)[::-1]  # unsorted input
    stencil = EdgeStencil(
        edges=np.array([[[0.0, 0.0], [length, 0.0]]]),
        edge_mask=np.array([True]),
        points=pts,
        mass=np.full(n, mass / n),
        point_mask=np.ones(n, bool),
        cand=np.zeros((n, 3), np.int32),
    )
    expected = mass * length**2 / (12 * n**2)
    got = run_both(single(stencil))
    for method in METHODS:
        np.testing.assert_allclose(got[method].tangential[0, 0], expected, rtol=1e-12)
        np.testing.assert_allclose(got[method].normal[0, 0], np.sum(mass / n * pts[:, 1] ** 2), rtol=1e-12)
        assert got[method].solid[0, 0]
    assert oracle_edge_cost([0, 0], [length, 0], pts, np.full(n, mass / n))[1] == pytest.approx(expected)


def test_vertex_ties_are_exact_and_go_to_the_earliest_candidate():
    a, b, c = np.array([0.0, 0.0]), np.array([1.0, 0.3]), np.array([0.2, 0.9])
    p = np.array([[-0.3, -0.2], [0.0, 0.0], [1.0, 0.3]])  # vertex region of a; on a; on b
    d_ab = sqdist(p, a, b)
    d_ac = sqdist(p, a, c)
    d_ca = sqdist(p, c, a)  # a as second endpoint
    np.testing.assert_array_equal(d_ab[:2], d_ac[:2])
    np.testing.assert_array_equal(d_ab[:2], d_ca[:2])
    assert float(d_ab[1]) == 0.0 and float(d_ab[2]) == 0.0
    assert oracle_segment_sqdist(p[0], a, b) == float(d_ab[0])
    stencil = EdgeStencil(
        edges=np.array([[c, a], [a, b], [b, c]]),
        edge_mask=np.ones(3, bool),
        points=p,
        mass=np.ones(3),
        point_mask=np.ones(3, bool),
        cand=np.array([[1, 0, 2], [0, 1, 2], [2, 1, 0]], np.int32),
    )
    # Same answer inside the compiled batched kernel (where fusion may differ).
    for method in METHODS:
        np.testing.assert_array_equal(run_both(single(stencil))[method].assignment[0, :3], [1, 0, 2])


def test_segment_sqdist_interior():
    # Interior foot; degenerate segment (distance to the point).
    p = np.array([[0.5, 2.0], [3.0, 4.0]])
    a = np.zeros((2, 2))
    b = np.array([[1.0, 0.0], [0.0, 0.0]])
    np.testing.assert_array_equal(sqdist(p, a, b), [4.0, 25.0])


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def _mass_before_both(edge, t, m):
    return {
        "rank": mass_before.mass_before_rank(edge, t, m),
        "sort": mass_before.mass_before_sort(edge, t, m, num_bins=4),
        "order": mass_before.sort_order(edge, t, 4),
    }


def test_mass_before_with_ties_signs_and_zeros():
    # Exact ties (including -0.0 == +0.0), negative coordinates, zero masses:
    # both formulations equal the definition, ties ordered by index.
    rng = np.random.default_rng(2)
    n = 16
    edge = rng.integers(0, 4, n).astype(np.int32)
    t = rng.choice([-1.5, -0.25, -0.0, 0.0, 0.75, 2.0], n)
    m = rng.choice([0.0, 0.5, 1.0, 3.0], n)
    want = [
        sum(m[j] for j in range(n) if edge[j] == edge[i] and (t[j] < t[i] or (t[j] == t[i] and j < i)))
        for i in range(n)
    ]
    got = _mass_before_both(edge, t, m)
    for method in METHODS:
        np.testing.assert_array_equal(np.asarray(got[method]), want, err_msg=method)
    np.testing.assert_array_equal(np.asarray(got["order"]), np.lexsort((np.where(t == 0, 0.0, t), edge)))


# ----------------------------------------------------------------------------
# Refinement stability (paper, after Eq. 4).

REFINE_BUCKETS = {"min_edges": 16, "min_points": 128}  # a shape compiled above
MAX_REFINE_POINTS = 25  # x5 copies still fit 128 points

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
    cand = draw(
        st.lists(st.lists(st.integers(0, n_edges - 1), min_size=3, max_size=3), min_size=n, max_size=n)
    )
    k = draw(st.integers(2, 5))
    return edges, points, mass, np.array(cand, np.int32), k


@settings(max_examples=30, deadline=None)
@given(refinable_stencils())
def test_refinement_stability(data):
    edges, points, mass, cand, k = data
    fine = (edges, np.repeat(points, k, axis=0), np.repeat(mass / k, k), np.repeat(cand, k, axis=0))
    batch = pack_edge_stencils([(edges, points, mass, cand), fine], Buckets(**REFINE_BUCKETS))
    got = run_both(batch)
    for method in METHODS:
        g = got[method]
        scale = float(np.sum(g.normal[0] + g.tangential[0] + g.vertex[0]))
        atol = 1e-12 * scale + 1e-300
        for key in PER_EDGE + ("total",):
            np.testing.assert_allclose(
                getattr(g, key)[1], getattr(g, key)[0], rtol=1e-9, atol=atol, err_msg=key
            )


# ----------------------------------------------------------------------------
# Gradients.


def _total(edges, points, mass, batch, method):
    s = batch._replace(edges=edges, points=points, mass=mass)
    return jnp.sum(jax.vmap(functools.partial(cost.stencil_cost, tangential_method=method))(s).total)


@functools.partial(jax.jit, compiler_options=FAST_COMPILE)
def grads_both(batch: EdgeStencil) -> dict:
    return {
        m: jax.grad(_total, argnums=(0, 1, 2))(batch.edges, batch.points, batch.mass, batch, m)
        for m in METHODS
    }


def test_gradients_are_finite():
    rng = np.random.default_rng(3)
    edges, points, mass, cand = make_stencil(rng, 12, 20)
    edges[2, 1] = edges[2, 0]  # zero-length edge
    cand[:4] = 2  # ... that receives points
    points[4] = edges[0, 0]  # exactly on a vertex
    cand[5:8] = 3
    mass[(cand == 3).any(axis=1)] = 0.0  # an edge whose points all have zero mass
    batch = pack_edge_stencils([(edges, points, mass, cand)], Buckets(16, 32))

    out = run_both(batch)
    for method in METHODS:
        assert not out[method].solid[0, 2] and out[method].normal[0, 2] == 0.0
        assert out[method].edge_mass[0, 3] == 0.0 and out[method].edge_cost[0, 3] == 0.0
    grads = jax.tree.map(np.asarray, grads_both(batch))
    for method in METHODS:
        g_edges, g_points, g_mass = grads[method]
        for g in (g_edges, g_points, g_mass):
            assert np.all(np.isfinite(g))
        # Padding gets exactly zero gradient.
        assert np.all(g_edges[1:] == 0) and np.all(g_edges[0, len(edges) :] == 0)
        assert np.all(g_points[1:] == 0) and np.all(g_points[0, len(points) :] == 0)


def test_gradient_matches_finite_differences():
    rng = np.random.default_rng(11)
    batch = pack_edge_stencils([make_stencil(rng, 12, 20, short_edge=False)], Buckets(16, 32))
    grads = grads_both(batch)
    h = 1e-6
    probes = [(0, 0), (3, 1), (7, 0), (12, 1)]
    shifted = []
    for i, j in probes:
        for sign in (1, -1):
            p = batch.points.copy()
            p[0, i, j] += sign * h
            shifted.append(batch._replace(points=p))
    # One batch of rows per probe would be a new shape; reuse the compiled one.
    totals = [run_both(s) for s in shifted]
    for method in METHODS:
        g = np.asarray(grads[method][1])
        for n, (i, j) in enumerate(probes):
            fd = (totals[2 * n][method].total[0] - totals[2 * n + 1][method].total[0]) / (2 * h)
            np.testing.assert_allclose(g[0, i, j], fd, rtol=1e-5, atol=1e-8)


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_sort_order_equals_lexsort_with_near_ties(data):
    """The quantised one-sort path (with its exact fallback) vs np.lexsort."""
    n = data.draw(st.integers(2, 300))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    edge = rng.integers(0, data.draw(st.integers(1, 8)), n).astype(np.int32)
    base = rng.choice([-1.0, 0.0, 0.3, 1e-300, 2.5], n) if data.draw(st.booleans()) else rng.random(n)
    # Neighbouring floats: far below any quantisation step.
    t = base + np.where(rng.random(n) < 0.5, 0.0, np.spacing(base) * rng.integers(-3, 4, n))
    t[rng.random(n) < 0.1] = -0.0
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(mass_before.sort_order, static_argnums=2)(edge, t, 8))
    np.testing.assert_array_equal(got, np.lexsort((np.arange(n), np.where(t == 0, 0.0, t), edge)))
