"""Invariants of the simplicial complex under half-edge collapses."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from otjax.surfaces.complex import SimplicialComplex
from tests.surfaces.complexes import (
    delaunay_complexes, oracle_collapse, random_complexes, simplex_sets, sphere_complex,
)

SETTINGS = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def euler_change(c: SimplicialComplex, s: int, t: int) -> int:
    """V - E + T after minus before, counted on the complex before the collapse:
    the vertex ``s`` and the edge ``st`` go, each common neighbour's edge merges,
    each triangle ``stx`` goes and each ``sab`` with an existing ``tab`` merges."""
    nbr = {v: {x for e in c.edges if v in e for x in e if x != v} for v in (s, t)}
    tris = {frozenset(x) for x in c.triangles}
    on_edge = sum(1 for x in tris if {s, t} <= x)
    merged = sum(1 for x in tris if s in x and t not in x and frozenset(x - {s} | {t}) in tris)
    return len(nbr[s] & nbr[t]) - on_edge - merged


def collapse_and_verify(c: SimplicialComplex, s: int, t: int) -> None:
    before = simplex_sets(c)
    n_before, chi_before = c.n_vertices, c.euler_characteristic()
    expected_chi = chi_before + euler_change(c, s, t)
    link_ok = c.link_condition(s, t)
    star_s = {x for x in before if s in x}
    simulated = c.simulate_collapse(s, t)
    change = c.collapse(s, t)
    c.check()
    after = simplex_sets(c)
    assert after == oracle_collapse(before, s, t)
    assert c.n_vertices == n_before - 1 and not c.alive[s]
    assert c.euler_characteristic() == expected_chi
    if link_ok:
        assert c.euler_characteristic() == chi_before
    assert c.vertex_closure(t) == simulated
    # The change record: what went, what is new, what absorbed a removed simplex.
    removed = {frozenset(x) for x in change.removed_edges + change.removed_triangles}
    assert removed == {x for x in star_s if len(x) > 1}
    added = {frozenset(x) for x in change.added_edges + change.added_triangles}
    merged = {frozenset(x) for x in change.merged_edges + change.merged_triangles}
    assert added.isdisjoint(before) and merged <= before and (added | merged) <= after
    assert added | merged == {frozenset(t if v == s else v for v in x) for x in removed if not {s, t} <= x}


def random_collapses(c: SimplicialComplex, seed: int, steps: int) -> int:
    rng = np.random.default_rng(seed)
    done = 0
    for _ in range(steps):
        half = c.half_edges()
        if not half:
            break
        s, t = half[rng.integers(len(half))]
        collapse_and_verify(c, s, t)
        done += 1
    return done


@SETTINGS
@given(c=random_complexes(), seed=st.integers(0, 2**31 - 1))
def test_random_complexes_stay_valid_under_collapses(c, seed):
    c.check()
    n_edges = c.n_edges
    done = random_collapses(c, seed, 12)
    assert done > 0 or n_edges == 0


@SETTINGS
@given(c=delaunay_complexes, seed=st.integers(0, 2**31 - 1))
def test_delaunay_complexes_stay_valid_under_collapses(c, seed):
    c.check()
    random_collapses(c, seed, 8)


@SETTINGS
@given(c=delaunay_complexes, seed=st.integers(0, 2**31 - 1))
def test_removing_a_triangle_drops_it_and_its_edges_no_other_triangle_has(c, seed):
    rng = np.random.default_rng(seed)
    for _ in range(4):
        if not c.triangles:
            break
        t = sorted(c.triangles)[rng.integers(c.n_triangles)]
        others = c.triangles - {t}
        edges_before, alive_before = set(c.edges), c.alive.copy()
        sides = {(t[0], t[1]), (t[0], t[2]), (t[1], t[2])}
        # an oracle from the triangle list alone: the sides on no other triangle go
        lone = {e for e in sides if not any(set(e) <= set(u) for u in others)}
        removed = c.remove_triangle(t)
        c.check()
        assert set(removed) == lone and c.triangles == others
        assert set(c.edges) == edges_before - lone
        np.testing.assert_array_equal(c.alive, alive_before)
    with pytest.raises(KeyError):
        c.remove_triangle((-3, -2, -1))  # no such triangle


@SETTINGS
@given(seed=st.integers(0, 2**31 - 1))
def test_closed_surface_keeps_euler_characteristic_and_manifoldness(seed):
    c = sphere_complex(seed, 16)
    assert c.euler_characteristic() == 2
    rng = np.random.default_rng(seed)
    for _ in range(6):
        half = c.half_edges()
        ok = next((half[k] for k in rng.permutation(len(half)) if c.link_condition(*half[k])), None)
        if ok is None:  # a tetrahedron's boundary: every collapse would pinch it
            assert c.n_vertices == 4
            break
        collapse_and_verify(c, *ok)
        assert c.euler_characteristic() == 2
        assert all(len(ts) == 2 for ts in c.edges.values())
        # Every vertex link stays one cycle: as many link edges as link vertices, connected.
        for v in np.flatnonzero(c.alive):
            link = c.link(int(v))
            assert len(link.edges) == len(link.vertices) >= 3


def crossing_planes(k: int = 5) -> tuple[SimplicialComplex, list[int]]:
    """Two square grids, one in z = 0 and one in y = 0, sharing the vertices of
    the line y = z = 0 (a non-manifold junction, open boundaries). Returns the
    complex and the ids along the junction line in order of x."""
    xs = np.linspace(-1, 1, k)
    pos, ids = [], {}

    def vid(key, p):
        if key not in ids:
            ids[key] = len(pos)
            pos.append(p)
        return ids[key]

    tris = []
    for plane in ("z", "y"):
        grid = {}
        for i, x in enumerate(xs):
            for j, w in enumerate(xs):
                on_line = w == 0.0
                p = (x, w, 0.0) if plane == "z" else (x, 0.0, w)
                grid[i, j] = vid(("line", i) if on_line else (plane, i, j), p)
        for i in range(k - 1):
            for j in range(k - 1):
                a, b, c, d = grid[i, j], grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]
                tris += [(a, b, c), (a, c, d)]
    line = [ids["line", i] for i in range(k)]
    return SimplicialComplex(np.array(pos), np.array(tris)), line


def test_junction_of_two_planes_survives_a_collapse_along_it():
    c, line = crossing_planes(5)
    c.check()
    assert sum(len(ts) == 4 for ts in c.edges.values()) == 4  # the junction's edges
    n_tri = c.n_triangles
    boundary_before = sum(len(ts) == 1 for ts in c.edges.values())
    s, t = line[2], line[3]  # the middle of the line onto its neighbour
    assert len(c.edge_triangles(s, t)) == 4
    collapse_and_verify(c, s, t)
    # The four triangles on the collapsed edge go; the junction keeps its other three edges.
    assert c.n_triangles == n_tri - 4
    junction = [e for e, ts in c.edges.items() if len(ts) == 4]
    assert sorted(junction) == sorted(tuple(sorted(e)) for e in [(line[0], line[1]), (line[1], t), (t, line[4])])
    assert all(len(ts) in (1, 2, 4) for ts in c.edges.values())
    assert sum(len(ts) == 1 for ts in c.edges.values()) == boundary_before
    # The line's end (a corner of all four half-sheets) onto the line: one triangle
    # per half-sheet goes, each sheet's open boundary keeps its length.
    collapse_and_verify(c, line[4], t)
    assert c.n_triangles == n_tri - 8
    assert sum(len(ts) == 1 for ts in c.edges.values()) == boundary_before
    junction = [e for e, ts in c.edges.items() if len(ts) == 4]
    assert sorted(junction) == sorted(tuple(sorted(e)) for e in [(line[0], line[1]), (line[1], t)])


def test_queries_on_an_octahedron():
    pos = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    tris = [(a, b, c) for a in (0, 1) for b in (2, 3) for c in (4, 5)]
    c = SimplicialComplex(pos, np.array(tris), np.array([[0, 1]]))
    c.check()
    assert (c.n_vertices, c.n_edges, c.n_triangles) == (6, 13, 8)
    assert c.triangle_neighbors((0, 2, 4)) == ((0, 2, 5), (0, 3, 4), (1, 2, 4))
    assert c.link(4).vertices == (0, 1, 2, 3)
    assert set(c.link(4).edges) == {(0, 2), (0, 3), (1, 2), (1, 3)}
    assert c.edge_link(0, 2) == (4, 5)
    assert c.edge_link(0, 1) == ()
    # The extra edge (0, 1) joins two vertices whose links share the cycle 2-4-3-5: pinched.
    assert not c.link_condition(0, 1)
    # It also makes 1 a common neighbour of 0 and 2 outside any triangle 0-1-2.
    assert not c.link_condition(0, 2)
    assert c.link_condition(2, 4)
    closure = c.edge_closure(0, 4)
    assert closure.vertices == (0, 1, 2, 3, 4, 5)
    assert len(closure.triangles) == 6  # four around 0, four around 4, two shared


def test_arrays_renumber_live_vertices():
    pos = np.arange(18, dtype=float).reshape(6, 3)
    c = SimplicialComplex(pos, np.array([[0, 1, 2], [2, 1, 3]]), np.array([[3, 4]]))
    c.collapse(0, 1)
    a = c.to_arrays()
    np.testing.assert_array_equal(a.vertex_ids, [1, 2, 3, 4, 5])
    np.testing.assert_array_equal(a.vertices, pos[[1, 2, 3, 4, 5]])
    np.testing.assert_array_equal(a.triangles, [[0, 1, 2]])
    np.testing.assert_array_equal(a.edges, [[0, 1], [0, 2], [1, 2], [2, 3]])
    np.testing.assert_array_equal(a.dangling, [False, False, False, True])
    np.testing.assert_array_equal(a.isolated, [4])


def test_construction_dedupes_and_rejects_bad_input():
    pos = np.zeros((4, 3))
    c = SimplicialComplex(pos, np.array([[0, 1, 2], [2, 0, 1], [1, 2, 0]]), np.array([[1, 0], [0, 1]]))
    assert (c.n_triangles, c.n_edges) == (1, 3)
    with pytest.raises(ValueError, match="repeated vertex"):
        SimplicialComplex(pos, np.array([[0, 1, 1]]))
    with pytest.raises(ValueError, match="outside"):
        SimplicialComplex(pos, np.array([[0, 1, 4]]))
    with pytest.raises(ValueError, match="shape"):
        SimplicialComplex(np.zeros((4, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="finite"):
        SimplicialComplex(np.full((4, 3), np.nan), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="no edge"):
        c.collapse(0, 3)
    with pytest.raises(ValueError, match="no edge"):
        c.simulate_collapse(2, 2)


@pytest.mark.parametrize("corrupt", ["star", "edge_list", "dead", "missing_face"])
def test_check_finds_broken_invariants(corrupt):
    c = SimplicialComplex(np.zeros((5, 3)), np.array([[0, 1, 2], [1, 2, 3]]), np.array([[3, 4]]))
    c.check()
    if corrupt == "star":
        c.vertex_triangles[0].discard((0, 1, 2))
    elif corrupt == "edge_list":
        c.edges[(1, 2)].discard((1, 2, 3))
    elif corrupt == "dead":
        c.alive[4] = False
    else:
        c.triangles.add((0, 1, 4))
    with pytest.raises(AssertionError):
        c.check()
