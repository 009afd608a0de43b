"""Edge splits, T-junction closing and sliver removal: simplex-set oracle,
a cracked cube edge, the plan kept feasible."""

from itertools import combinations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from otjax.metrics3d import crease_error, edge_sharpness
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.plan import BinSettings, Entries, SurfacePlan
from otjax.surfaces.t_junctions import TJunction, close_t_junctions, find_t_junctions, split_slivers
from tests.surfaces.complexes import delaunay_complex, simplex_sets


def oracle_split(simplices: set[frozenset], a: int, b: int, v: int) -> set[frozenset]:
    """Drops every simplex holding ``a`` and ``b``; each dropped triangle
    ``abc`` with ``c != v`` comes back as ``avc`` and ``vbc`` with their edges."""
    out = {s for s in simplices if not {a, b} <= s}
    for s in simplices:
        if len(s) == 3 and {a, b} <= s and v not in s:
            (c,) = s - {a, b}
            for half in ({a, v, c}, {v, b, c}):
                out |= {frozenset(half)} | {frozenset(e) for e in combinations(half, 2)}
    return out


def splittable(c: SimplicialComplex) -> list[tuple[int, int, int]]:
    """Every ``(a, b, v)`` with the edges ``ab``, ``av`` and ``vb``."""
    return [(a, b, v) for (a, b) in sorted(c.edges)
            for v in sorted(set(c.neighbors(a)) & set(c.neighbors(b)))]


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1), st.integers(5, 14), st.floats(0.1, 1.0), st.integers(0, 10**6))
def test_split_edge_matches_the_simplex_set_oracle(seed, n, keep, pick):
    c = delaunay_complex(seed, n, keep)
    triples = splittable(c)
    if not triples:
        return
    a, b, v = triples[pick % len(triples)]
    before = simplex_sets(c)
    change = c.split_edge(a, b, v)
    c.check()
    assert simplex_sets(c) == oracle_split(before, a, b, v)
    assert not c.has_edge(a, b) and all(v in t for t in change.added_triangles)
    assert set(change.added_triangles) <= c.triangles


def test_split_edge_refuses_a_vertex_not_joined_to_both_ends():
    c = SimplicialComplex(np.eye(4, 3), np.array([[0, 1, 2]]), np.array([[2, 3]]))
    with pytest.raises(ValueError, match="cannot split"):
        c.split_edge(0, 1, 3)
    with pytest.raises(ValueError, match="cannot split"):
        c.split_edge(0, 3, 2)


def cracked_cube_edge(offset: float = 0.0) -> SimplicialComplex:
    """A top face (z = 1) ending on the edge ``a b`` and a side face (y = 0)
    ending on ``a v`` and ``v b``, ``v`` the middle of ``ab`` moved ``offset`` along -y."""
    x = np.array([[0, 0, 1], [1, 0, 1], [0.5, -offset, 1], [0, 1, 1], [1, 1, 1], [0, 0, 0], [1, 0, 0]], float)
    a, b, v, c1, c2, d1, d2 = range(7)
    top = [[a, b, c2], [a, c2, c1]]
    side = [[a, v, d1], [v, d2, d1], [v, b, d2]]
    return SimplicialComplex(x, np.array(top + side))


def test_a_cracked_cube_edge_is_found_and_closed_into_a_crease():
    c = cracked_cube_edge()
    line = np.array([[[0, 0, 1], [1, 0, 1]]], float)
    assert crease_error(c.positions, c.triangle_array(), line).mean > 0.4  # no edge holds both faces
    assert find_t_junctions(c) == [TJunction(0, 1, 2)]
    c.split_edge(0, 1, 2)
    assert find_t_junctions(c) == []
    sharp = edge_sharpness(c.positions, c.triangle_array())
    on_line = [i for i, e in enumerate(sharp.edges.tolist()) if sorted(e) in ([0, 2], [1, 2])]
    np.testing.assert_allclose(sharp.angle[on_line], np.pi / 2, atol=1e-12)
    assert crease_error(c.positions, c.triangle_array(), line).mean < 1e-12


def test_a_vertex_off_the_segment_is_no_t_junction():
    assert find_t_junctions(cracked_cube_edge(offset=0.02)) == [TJunction(0, 1, 2)]  # 175.4 degrees
    assert find_t_junctions(cracked_cube_edge(offset=0.05)) == []  # 168.6 degrees
    assert find_t_junctions(cracked_cube_edge(offset=0.25), angle=60.0) == [TJunction(0, 1, 2)]


def cracked_complex(seed: int, n: int, keep: float) -> SimplicialComplex:
    """:func:`delaunay_complex` with one or two cracks: for a facet ``abw``, a
    new vertex ``v`` on the segment ``ab`` and the triangles ``avx``, ``vbx``
    (``x`` any other vertex), so ``ab`` is a T-junction at ``v``."""
    base = delaunay_complex(seed, n, keep)
    tris = base.triangle_array()
    if not len(tris):
        return base
    rng = np.random.default_rng([seed, 1])
    pos, extra = base.positions, []
    for t in tris[rng.integers(len(tris), size=rng.integers(1, 3))]:
        a, b, _ = rng.permutation(t)
        x = rng.choice([u for u in range(n) if u not in (a, b)])
        v = len(pos)
        pos = np.vstack([pos, pos[a] + rng.uniform(0.2, 0.8) * (pos[b] - pos[a])])
        extra += [[a, v, x], [v, b, x]]
    return SimplicialComplex(pos, np.vstack([tris, extra]), base.edge_array())


def random_plan(c: SimplicialComplex, rng) -> SurfacePlan:
    """A feasible plan: points near the vertices on their vertex bins, the
    rest spread over a random facet's bins by capacity."""
    alive = np.flatnonzero(c.alive)
    tris = c.triangle_array()
    n = 3 * len(alive) + 4 * len(tris)
    points = rng.random((n, 3))
    plan = SurfacePlan(c, points, rng.uniform(0.5, 2.0, n), BinSettings(np.sqrt(3), min_bins=1, max_bins=4))
    plan.vertex_entries, plan.facet_entries = {}, {}
    owner = rng.integers(-len(alive), len(tris), n) if len(tris) else -rng.integers(1, len(alive) + 1, n)
    for i in range(n):
        if owner[i] < 0:
            key, k, cap = int(alive[-owner[i] - 1]), 1, np.ones(1)
            store = plan.vertex_entries
        else:
            key = tuple(int(x) for x in tris[owner[i]])
            cap = plan.bins[key].capacity
            k, store = len(cap), plan.facet_entries
        old = store.get(key, Entries(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)))
        store[key] = Entries(np.r_[old.point, np.full(k, i)], np.r_[old.bin, np.arange(k)],
                             np.r_[old.mass, plan.masses[i] * cap])
    return plan


def check_feasible(plan: SurfacePlan) -> None:
    plan.complex.check()
    np.testing.assert_allclose(plan.point_mass(), plan.masses, rtol=1e-12)
    for f, e in plan.facet_entries.items():
        assert f in plan.complex.triangles
        cap = plan.bins[f].capacity
        np.testing.assert_allclose(np.bincount(e.bin, e.mass, len(cap)), cap * e.mass.sum(), rtol=1e-9, atol=1e-12)
        assert len(set(zip(e.point.tolist(), e.bin.tolist()))) == len(e.point)
    for v, e in plan.vertex_entries.items():
        assert plan.complex.alive[v] and np.all(e.bin == 0)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1), st.integers(5, 14), st.floats(0.2, 1.0), st.floats(2.0, 20.0))
def test_closing_keeps_the_plan_feasible_and_leaves_no_t_junction(seed, n, keep, angle):
    rng = np.random.default_rng(seed)
    c = cracked_complex(seed, n, keep)
    plan = random_plan(c, rng)
    before = len(find_t_junctions(c, angle))
    assume(before >= 1)  # a crack can be refused (a half would be a sliver): those examples test nothing here
    splits = close_t_junctions(plan, angle)
    assert splits >= min(1, before)  # a split can undo another T-junction of the round
    assert find_t_junctions(plan.complex, angle) == []
    check_feasible(plan)


def test_closing_a_plan_moves_the_split_facets_mass_to_their_halves():
    c = cracked_cube_edge()
    plan = random_plan(c, np.random.default_rng(3))
    top = (0, 1, 4)
    mass = plan.simplex_mass(top)
    assert close_t_junctions(plan) == 1
    assert top not in plan.complex.triangles
    halves = [(0, 2, 4), (1, 2, 4)]
    assert sum(plan.simplex_mass(h) for h in halves) == pytest.approx(mass, rel=1e-12)
    check_feasible(plan)


def test_the_sliver_on_a_split_edge_hands_its_mass_to_its_corners():
    c = cracked_cube_edge()
    x = c.positions
    c = SimplicialComplex(x, np.vstack([c.triangle_array(), [[0, 1, 2]]]))  # (a, b, v): flat
    plan = random_plan(c, np.random.default_rng(4))
    sliver = plan.simplex_mass((0, 1, 2))
    corners = sum(plan.simplex_mass(v) for v in (0, 1, 2))
    assert sliver > 0 and close_t_junctions(plan) == 1
    assert (0, 1, 2) not in plan.complex.triangles and not plan.complex.has_edge(0, 1)
    assert sum(plan.simplex_mass(v) for v in (0, 1, 2)) == pytest.approx(corners + sliver, rel=1e-12)
    check_feasible(plan)


def widest_cosine(x: np.ndarray, t) -> float:
    """The cosine of a triangle's widest corner angle, from its side vectors (an independent oracle)."""
    cos = []
    for k in range(3):
        u, w = x[t[k - 1]] - x[t[k]], x[t[(k + 1) % 3]] - x[t[k]]
        n = np.linalg.norm(u) * np.linalg.norm(w)
        cos.append(u @ w / n if n > 0 else -1.0)
    return min(cos)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**31 - 1), st.integers(5, 14), st.floats(0.3, 1.0), st.floats(0.05, 0.95),
       st.integers(1, 3))
@example(45392429, 5, 0.5, 0.5, 3)  # three corners moved onto one point: a sliver with a zero-length edge
def test_splitting_slivers_keeps_the_plan_feasible_and_leaves_only_four_on_a_line(seed, n, keep, at, flat):
    c = delaunay_complex(seed, n, keep)
    tris = c.triangle_array()
    assume(len(tris) >= 1)
    rng = np.random.default_rng([seed, 2])
    for t in tris[rng.choice(len(tris), size=min(flat, len(tris)), replace=False)]:
        a, b, v = rng.permutation(t)
        c.positions[v] = c.positions[a] + at * (c.positions[b] - c.positions[a])  # v onto the segment ab
    plan = random_plan(c, rng)
    flat_cos = -np.cos(np.radians(5.0))
    lines = [t for t in c.triangles if widest_cosine(c.positions, t) <= flat_cos]
    splits = split_slivers(plan)
    assert splits >= 1 or not lines or all(four_on_a_line(plan.complex, t, flat_cos) for t in lines)
    x = plan.complex.positions
    # what is left on a line shares its long edge with a facet whose third corner is on it too
    assert all(four_on_a_line(plan.complex, t, flat_cos) for t in plan.complex.triangles
               if widest_cosine(x, t) <= flat_cos)
    assert split_slivers(plan) == 0
    check_feasible(plan)


def four_on_a_line(c: SimplicialComplex, t, flat_cos: float) -> bool:
    """Whether a facet ``t`` on a line shares its long edge with another facet
    one of whose halves, split at ``t``'s middle corner, would be on a line too."""
    x = c.positions

    def cos_at(k):
        u, w = x[t[k - 1]] - x[t[k]], x[t[(k + 1) % 3]] - x[t[k]]
        n = np.linalg.norm(u) * np.linalg.norm(w)
        return u @ w / n if n > 0 else -1.0

    k = min(range(3), key=cos_at)
    v, a, b = t[k], t[k - 1], t[(k + 1) % 3]
    for other in c.edge_triangles(a, b):
        (o,) = set(other) - {a, b}
        if o != v and min(widest_cosine(x, (a, v, o)), widest_cosine(x, (v, b, o))) <= flat_cos:
            return True
    return False


def test_three_corners_on_one_crease_line_lose_their_facet_and_its_long_edge():
    c = cracked_cube_edge()
    c = SimplicialComplex(c.positions, np.vstack([c.triangle_array(), [[0, 1, 2]]]))  # v on ab: flat
    plan = random_plan(c, np.random.default_rng(5))
    total = plan.masses.sum()
    assert split_slivers(plan) == 1
    assert (0, 1, 2) not in plan.complex.triangles and not plan.complex.has_edge(0, 1)
    # the top face now ends on the two halves, as the side face does: one crease
    sharp = edge_sharpness(plan.complex.positions, plan.complex.triangle_array())
    on_line = [i for i, e in enumerate(sharp.edges.tolist()) if sorted(e) in ([0, 2], [1, 2])]
    np.testing.assert_allclose(sharp.angle[on_line], np.pi / 2, atol=1e-12)
    assert plan.point_mass().sum() == pytest.approx(total, rel=1e-12)
    check_feasible(plan)


def test_a_thin_facet_off_the_line_stays():
    c = cracked_cube_edge(offset=0.05)  # v at 168.6 degrees from ab
    c = SimplicialComplex(c.positions, np.vstack([c.triangle_array(), [[0, 1, 2]]]))
    plan = random_plan(c, np.random.default_rng(6))
    assert split_slivers(plan) == 0 and (0, 1, 2) in plan.complex.triangles
