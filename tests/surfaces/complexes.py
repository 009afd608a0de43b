"""Hypothesis strategies for small 3D complexes, and a brute-force collapse oracle."""

from itertools import combinations

import numpy as np
from hypothesis import strategies as st
from scipy.spatial import ConvexHull, Delaunay

from otjax.surfaces.complex import SimplicialComplex


@st.composite
def random_complexes(draw):
    """Random triangles and dangling edges on a few vertices (non-manifold, with isolated vertices)."""
    n = draw(st.integers(3, 10))
    vid = st.integers(0, n - 1)
    tris = draw(st.lists(st.lists(vid, min_size=3, max_size=3, unique=True), max_size=16))
    edges = draw(st.lists(st.lists(vid, min_size=2, max_size=2, unique=True), max_size=8))
    pos = np.random.default_rng(draw(st.integers(0, 2**31 - 1))).random((n, 3))
    return SimplicialComplex(pos, np.array(tris, np.int64).reshape(-1, 3), np.array(edges, np.int64).reshape(-1, 2))


def delaunay_complex(seed: int, n: int = 14, keep: float = 0.5) -> SimplicialComplex:
    """A random subset of the faces of a 3D Delaunay of ``n`` random points, plus
    a random subset of the tetrahedra's edges (some dangling)."""
    rng = np.random.default_rng(seed)
    p = rng.random((n, 3))
    tets = Delaunay(p).simplices
    faces = np.unique(np.sort(np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]],
                                              tets[:, [1, 2, 3]]]), axis=1), axis=0)
    edges = np.unique(np.sort(np.concatenate([tets[:, list(e)] for e in combinations(range(4), 2)]), axis=1), axis=0)
    return SimplicialComplex(p, faces[rng.random(len(faces)) < keep], edges[rng.random(len(edges)) < 0.2])


delaunay_complexes = st.builds(delaunay_complex, st.integers(0, 2**31 - 1), st.integers(5, 20),
                               st.floats(0.05, 1.0))


def sphere_complex(seed: int, n: int = 20) -> SimplicialComplex:
    """A closed manifold triangulation of a sphere: the hull of points on it."""
    p = np.random.default_rng(seed).standard_normal((n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return SimplicialComplex(p, ConvexHull(p).simplices)


def simplex_sets(c: SimplicialComplex) -> set[frozenset]:
    """Every simplex of the complex (vertices, edges, triangles) as a frozenset."""
    out = {frozenset((int(v),)) for v in np.flatnonzero(c.alive)}
    out |= {frozenset(e) for e in c.edges}
    out |= {frozenset(t) for t in c.triangles}
    return out


def oracle_collapse(simplices: set[frozenset], source: int, target: int) -> set[frozenset]:
    """Rewrites every simplex with ``source -> target``; a simplex whose image
    has fewer vertices degenerates and is dropped; equal images merge (a set)."""
    out = set()
    for s in simplices:
        img = frozenset(target if v == source else v for v in s)
        if len(img) == len(s):
            out.add(img)
    return out
