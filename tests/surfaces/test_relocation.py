"""Vertex relocation (§4.3) and gradient refinement against NumPy oracles."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.lp.exact import solve_member
from otjax.lp.problem import FAILED
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.fixed_plan_cost import fixed_plan_cost
from otjax.surfaces.moves import local_target, propose_moves, star_stencil, stencil_plan
from otjax.surfaces.packed_entries import pack_entries, star_simplices
from otjax.surfaces.plan import BinSettings, Entries, SurfacePlan
from otjax.surfaces.refinement import refine
from otjax.surfaces.relaxation import LocalSolution
from otjax.surfaces.relocation import MIN_ASPECT, relocate, relocation_targets, star_targets
from tests.surfaces.complexes import delaunay_complex
from tests.surfaces.test_transport_plan import grid_complex


fixed_plan_gradient = jax.jit(jax.grad(fixed_plan_cost))


def exact(problems):
    return [LocalSolution(s.plan, s.cost, s.status) for s in map(solve_member, problems)]


def frozen(problems):
    """A solver that never changes the plan: every member failed."""
    return [LocalSolution(np.zeros_like(lp.cost), 0.0, FAILED) for lp in problems]


def bin_settings(max_bins=4):
    return BinSettings(diagonal=1.0, min_bins=1, max_bins=max_bins, max_stretch=np.inf)


def random_plan(c: SimplicialComplex, rng, n_points=30, max_bins=4, noise=0.05) -> SurfacePlan:
    """Points near the complex, each point's mass split between one or two
    random simplices; a facet's part spread over its bins by capacity, so
    every facet receives the uniform measure (a feasible plan)."""
    facets = sorted(c.triangles)
    verts = np.flatnonzero(c.alive).tolist()
    simplices = verts + facets
    anchor = c.positions[rng.integers(0, len(c.positions), n_points)]
    pts = anchor + rng.normal(0, noise, (n_points, 3))
    masses = rng.uniform(0.5, 2.0, n_points)
    base = SurfacePlan(c, pts, masses, bin_settings(max_bins))
    parts: dict = {}
    for i in range(n_points):
        k = rng.integers(1, 3)
        share = rng.dirichlet(np.ones(k)) * masses[i]
        for s, m in zip(rng.choice(len(simplices), k, replace=False), share):
            parts.setdefault(simplices[s], []).append((i, m))
    vertex_entries, facet_entries = {}, {}
    for s, got in parts.items():
        point, mass = np.array([g[0] for g in got]), np.array([g[1] for g in got])
        if isinstance(s, tuple):
            cap = base.bins[s].capacity
            nb = len(cap)
            facet_entries[s] = Entries(np.repeat(point, nb), np.tile(np.arange(nb), len(point)),
                                       (mass[:, None] * cap[None]).ravel())
        else:
            vertex_entries[s] = Entries(point, np.zeros(len(point), np.int64), mass)
    return SurfacePlan.from_entries(c, pts, masses, base.settings, base.bins, vertex_entries, facet_entries)


def numpy_cost(plan: SurfacePlan, simplices=None) -> float:
    """``sum m |p - b|^2`` entry by entry, bins from the barycentric weights."""
    pos, total = plan.complex.positions, 0.0
    if simplices is None:
        simplices = list(plan.vertex_entries) + list(plan.facet_entries)
    for s in simplices:
        e = plan.entries(s)
        if e is None:
            continue
        for p, b, m in zip(e.point, e.bin, e.mass):
            if isinstance(s, tuple):
                w = plan.bins[s].barycentric[b]
                q = w[0] * pos[s[0]] + w[1] * pos[s[1]] + w[2] * pos[s[2]]
            else:
                q = pos[s]
            total += m * float(np.sum((plan.points[p] - q) ** 2))
    return total


def share_quadratic(plan, v, simplex):
    """The rows of the share's least-squares problem in ``v``:
    ``sum m |p - alpha v - r|^2 = |A v - y|^2``, built entry by entry."""
    e = plan.entries(simplex)
    pos = plan.complex.positions
    rows_a, rows_y = [], []
    for p, b, m in zip(e.point, e.bin, e.mass):
        if isinstance(simplex, tuple):
            w = plan.bins[simplex].barycentric[b]
            alpha = sum(wk for wk, u in zip(w, simplex) if u == v)
            r = sum(wk * pos[u] for wk, u in zip(w, simplex) if u != v)
        else:
            alpha, r = 1.0, np.zeros(3)
        rows_a.append(np.sqrt(m) * alpha * np.eye(3))
        rows_y.append(np.sqrt(m) * (plan.points[p] - r))
    return np.concatenate(rows_a), np.concatenate(rows_y)


@pytest.fixture
def plan(rng):
    return random_plan(delaunay_complex(3, 12, 0.5), rng, 60)


def test_fixed_plan_cost_equals_a_numpy_loop(plan):
    packed = pack_entries(plan, list(plan.vertex_entries) + list(plan.facet_entries))
    got = float(fixed_plan_cost(packed.positions, packed.points, packed.entries))
    assert got == pytest.approx(numpy_cost(plan), rel=1e-12)
    assert plan.facet_entries and plan.vertex_entries


def test_fixed_plan_cost_gradient_equals_finite_differences(plan, rng):
    packed = pack_entries(plan, list(plan.vertex_entries) + list(plan.facet_entries))
    x = packed.positions + rng.normal(0, 0.1, packed.positions.shape)
    grad = np.asarray(fixed_plan_gradient(x, packed.points, packed.entries))
    cost = jax.jit(fixed_plan_cost)
    h = 1e-5
    fd = np.zeros_like(x)
    for i in range(len(packed.vertex_ids)):
        for d in range(3):
            e = np.zeros_like(x)
            e[i, d] = h
            fd[i, d] = (float(cost(x + e, packed.points, packed.entries))
                        - float(cost(x - e, packed.points, packed.entries))) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-7, atol=1e-8 * np.abs(fd).max())
    assert np.abs(grad[len(packed.vertex_ids):]).max(initial=0.0) == 0.0  # padding rows


def test_each_share_minimiser_is_the_least_squares_solution_and_a_minimum(plan, rng):
    vertices = [v for v in np.flatnonzero(plan.complex.alive) if plan.complex.vertex_triangles[v]][:6]
    got = star_targets(plan, vertices)
    checked = 0
    for (row, simplex), star, mass in zip(got.shares, got.share_target, got.share_mass):
        v = vertices[row]
        assert mass == pytest.approx(plan.simplex_mass(simplex), rel=1e-12)
        if plan.entries(simplex) is None:
            continue
        a, y = share_quadratic(plan, v, simplex)
        lsq = np.linalg.lstsq(a, y, rcond=None)[0]
        np.testing.assert_allclose(star, lsq, rtol=1e-9, atol=1e-12)
        at = np.sum((a @ star - y) ** 2)
        for _ in range(5):
            assert np.sum((a @ (star + rng.normal(0, 1e-3, 3)) - y) ** 2) > at
        checked += 1
    assert checked >= 6


def test_targets_average_the_shares_by_mass_or_solve_the_whole_star(plan):
    vertices = [v for v in np.flatnonzero(plan.complex.alive) if plan.complex.vertex_triangles[v]][:5]
    got = star_targets(plan, vertices)
    quad = relocation_targets(plan, vertices, quadratic=True)
    for row, v in enumerate(vertices):
        mine = [(s, t, m) for (r, s), t, m in zip(got.shares, got.share_target, got.share_mass)
                if r == row and plan.entries(s) is not None]
        weights = np.array([m for _, _, m in mine])
        paper = np.sum([m * t for _, t, m in mine], axis=0) / weights.sum()
        np.testing.assert_allclose(got.target[row], paper, rtol=1e-10)
        a, y = map(np.concatenate, zip(*(share_quadratic(plan, v, s) for s, _, _ in mine)))
        np.testing.assert_allclose(quad[row], np.linalg.lstsq(a, y, rcond=None)[0], rtol=1e-9, atol=1e-12)
    # one batched call gives what one call per vertex gives
    alone = np.concatenate([relocation_targets(plan, [v]) for v in vertices])
    np.testing.assert_allclose(got.target, alone, rtol=1e-12)


def exact_plane(displace=0.3):
    """A grid on z = 0 whose points sit exactly on the bins of its facets,
    each point on its own bin (cost 0), then the centre vertex lifted."""
    c = grid_complex(3)
    base = SurfacePlan(c, c.positions[:1], np.ones(1), bin_settings(3))
    pts, masses, facet_entries = [], [], {}
    for t in sorted(c.triangles):
        b = base.bins[t]
        ids = np.arange(len(pts), len(pts) + len(b.capacity))
        pts.extend(b.barycentric @ c.positions[list(t)])
        masses.extend(b.capacity)
        facet_entries[t] = Entries(ids, np.arange(len(ids)), b.capacity.copy())
    plan = SurfacePlan.from_entries(c, np.array(pts), np.array(masses), base.settings, base.bins, {},
                                    facet_entries)
    home = c.positions[4].copy()
    c.move(4, home + [0.0, 0.0, displace])
    return plan, home


@pytest.mark.parametrize("quadratic", [False, True])
def test_a_lifted_vertex_targets_its_place_and_halves_the_way_each_round(quadratic):
    plan, home = exact_plane(0.3)
    np.testing.assert_allclose(relocation_targets(plan, [4], quadratic)[0], home, atol=1e-12)
    stats = relocate(plan, [4], frozen, rounds=6, quadratic=quadratic)
    assert stats.accepted == 6 and stats.moved == (4,)
    np.testing.assert_allclose(plan.complex.positions[4], home + [0, 0, 0.3 / 2**6], atol=1e-12)
    assert plan.total_cost() == pytest.approx(numpy_cost(plan), rel=1e-12)


def test_relocation_with_resolves_brings_a_lifted_vertex_back_to_the_plane():
    plan, home = exact_plane(0.3)
    before = plan.total_cost()
    stats = relocate(plan, [4], exact, rounds=12)
    after = plan.total_cost()
    assert stats.delta == pytest.approx(after - before, rel=1e-9)
    assert after < 1e-3 * before
    assert abs(plan.complex.positions[4, 2]) < 1e-3
    assert np.linalg.norm(plan.complex.positions[4, :2] - home[:2]) < 0.05


def flattening_plan():
    """One triangle; all mass on vertex 2's bin, nearly all at a point on
    the line through vertices 0 and 1: the optimum flattens the facet."""
    c = SimplicialComplex(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    points, masses = np.array([[0.5, 0.0, 0.0], [0.5, 0.3, 0.0]]), np.array([1.0, 1e-9])
    plan = SurfacePlan(c, points, masses, bin_settings(1))
    plan.vertex_entries = {2: Entries(np.array([0, 1]), np.zeros(2, np.int64), masses)}
    return plan


def test_a_move_that_would_flatten_a_facet_is_not_made():
    plan = flattening_plan()
    stats = relocate(plan, [2], frozen, rounds=1, damping=1.0)
    assert stats.degenerate == 1 and stats.accepted == 0
    np.testing.assert_array_equal(plan.complex.positions[2], [0.0, 1.0, 0.0])
    stats = relocate(plan, [2], frozen, rounds=1, damping=0.5)
    assert stats.accepted == 1 and plan.complex.positions[2, 1] == pytest.approx(0.5, abs=1e-6)
    assert MIN_ASPECT < 0.2


def test_refine_takes_a_shorter_step_rather_than_flatten_a_facet():
    plan = flattening_plan()
    before = plan.total_cost()
    stats = refine(plan, [2])
    assert stats.step < 1.0 and stats.moved == (2,)
    assert plan.total_cost() < before
    a, b, c = plan.complex.positions
    assert np.linalg.norm(np.cross(b - a, c - a)) / 2 >= MIN_ASPECT * 1.0


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(5, 9), st.floats(0.2, 1.0), st.booleans())
def test_relocation_never_raises_the_total_cost(seed, n, keep, quadratic):
    rng = np.random.default_rng(seed)
    c = delaunay_complex(seed, n, keep)
    plan = random_plan(c, rng, 20, max_bins=3)
    before = numpy_cost(plan)
    vertices = rng.choice(n, min(n, 3), replace=False)
    stats = relocate(plan, vertices, exact, rounds=2, quadratic=quadratic)
    after = numpy_cost(plan)
    assert after <= before + 1e-12 * before
    assert stats.delta == pytest.approx(after - before, rel=1e-9, abs=1e-12 * before)
    np.testing.assert_allclose(plan.point_mass(), plan.masses, rtol=1e-12)
    assert set(stats.moved) <= set(stats.changed)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(5, 12), st.floats(0.2, 1.0))
def test_refine_never_raises_the_cost_and_lowers_it_where_the_gradient_is_not_zero(seed, n, keep):
    rng = np.random.default_rng(seed)
    c = delaunay_complex(seed, n, keep)
    plan = random_plan(c, rng, 25)
    free = [int(v) for v in rng.choice(n, min(n, 4), replace=False)]
    simplices = sorted({s for v in free for s in star_simplices(plan, v)}, key=str)
    packed = pack_entries(plan, simplices, free)
    grad = np.asarray(fixed_plan_gradient(packed.positions, packed.points, packed.entries))
    slope = np.linalg.norm(grad[np.searchsorted(packed.vertex_ids, free)])
    before = numpy_cost(plan)
    stats = refine(plan, free)
    after = numpy_cost(plan)
    assert after <= before + 1e-12 * before
    assert np.all(np.diff(stats.costs) <= 0)
    assert stats.cost_after - stats.cost_before == pytest.approx(after - before, rel=1e-8, abs=1e-12 * before)
    assert set(stats.moved) <= set(free)
    if slope > 1e-6 * max(before, 1e-300) ** 0.5:
        assert after < before


def test_refine_finds_the_plane_in_a_few_steps():
    plan, home = exact_plane(0.3)
    before = plan.total_cost()
    stats = refine(plan, [4])
    assert stats.moved == (4,) and stats.step == 1.0
    assert plan.total_cost() < 1e-20 * before
    np.testing.assert_allclose(plan.complex.positions[4], home, atol=1e-10)


def test_the_local_target_of_the_current_plan_is_the_kernel_target(plan):
    vertices = [int(v) for v in np.flatnonzero(plan.complex.alive) if plan.complex.vertex_triangles[v]]
    kernel = relocation_targets(plan, vertices)
    checked = 0
    for v, want in zip(vertices, kernel):
        st = star_stencil(plan, v)
        local = stencil_plan(plan, st)
        # the local plan is the plan's entries: same cost, same marginals
        assert float(np.sum(local * st.lp.cost)) == pytest.approx(st.cost, rel=1e-12)
        np.testing.assert_allclose(local.sum(axis=1), st.lp.mass, rtol=1e-12)
        got = local_target(plan, st, local, v)
        if got is None:
            continue
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)
        checked += 1
    assert checked >= 4


def test_a_proposed_move_brings_a_lifted_vertex_back_and_changes_nothing_until_applied():
    plan, home = exact_plane(0.3)
    before = plan.total_cost()
    pos = plan.complex.positions.copy()
    (move,) = propose_moves(plan, [4], exact, rounds=12)
    np.testing.assert_array_equal(plan.complex.positions, pos)
    assert plan.total_cost() == before
    assert move.vertex == 4 and move.rounds >= 6 and move.delta < -0.99 * before
    assert abs(move.position[2]) < 1e-3 and np.linalg.norm(move.position[:2] - home[:2]) < 0.05
    plan.complex.move(4, move.position)
    plan.assign(move.stencil, move.plan)
    assert plan.total_cost() == pytest.approx(before + move.delta, rel=1e-9, abs=1e-12 * before)


def test_no_move_is_proposed_where_none_lowers_the_cost_or_one_would_flatten_a_facet():
    plan, _ = exact_plane(0.0)  # every point on its bin: cost 0
    assert propose_moves(plan, [4], exact) == [None]
    assert propose_moves(flattening_plan(), [2], exact, rounds=1, damping=1.0) == [None]


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(5, 9), st.floats(0.2, 1.0))
def test_each_proposed_move_lowers_the_total_cost_by_its_delta(seed, n, keep):
    rng = np.random.default_rng(seed)
    c = delaunay_complex(seed, n, keep)
    plan = random_plan(c, rng, 20, max_bins=3)
    vertices = [int(v) for v in rng.choice(n, min(n, 3), replace=False)]
    moves = propose_moves(plan, vertices, exact, rounds=2)
    assert len(moves) == len(vertices)
    for move in moves:
        if move is None:
            continue
        trial = SurfacePlan.from_entries(c, plan.points, plan.masses, plan.settings, plan.bins,
                                         plan.vertex_entries, plan.facet_entries)
        old = c.positions[move.vertex].copy()
        before = numpy_cost(trial)
        c.move(move.vertex, move.position)
        trial.assign(move.stencil, move.plan)
        after = numpy_cost(trial)
        c.move(move.vertex, old)
        assert move.delta < 0 and 1 <= move.rounds <= 2
        assert after - before == pytest.approx(move.delta, rel=1e-9, abs=1e-12 * before)
        np.testing.assert_allclose(trial.point_mass(), plan.masses, rtol=1e-12)
