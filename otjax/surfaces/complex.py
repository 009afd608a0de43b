"""A 3D simplicial complex under half-edge collapses (NumPy and Python, no JAX).

Simplices are keyed by sorted vertex-id tuples: an edge ``(a, b)`` with
``a < b``, a triangle ``(a, b, c)`` with ``a < b < c``. The complex may be
non-manifold (an edge with any number of triangles), may have dangling edges
and isolated vertices, and is never required to be embedded (Digne et al.
2014, §4.1). What it keeps:

- ``edges``: a dict ``edge -> set of triangles`` incident to it, so the
  triangles sharing an edge with a triangle are three look-ups;
- ``triangles``: a set of triangle keys;
- per vertex, the set of its edges and the set of its triangles (its star),
  so a collapse touches only the two stars it merges.

Vertex ids are never reused; a collapsed vertex is marked dead. Every query
returns sorted tuples so that what is built from them (stencils, exports) is
deterministic.
"""

from __future__ import annotations

from typing import Iterable, NamedTuple

import numpy as np

Edge = tuple[int, int]
Triangle = tuple[int, int, int]


class LocalComplex(NamedTuple):
    """A set of simplices, each kind as a sorted tuple of sorted keys.

    Attributes:
      vertices: vertex ids.
      edges: ``(a, b)`` keys, ``a < b``.
      triangles: ``(a, b, c)`` keys, ``a < b < c``.
    """

    vertices: tuple[int, ...]
    edges: tuple[Edge, ...]
    triangles: tuple[Triangle, ...]


class CollapseChange(NamedTuple):
    """What a half-edge collapse did: enough to update state kept per simplex.

    Every simplex containing ``source`` was removed; each one's image (the same
    key with ``source`` replaced by ``target``) either was new (``added_*``),
    already existed and absorbs it (``merged_*``), or was degenerate (the
    edge ``(source, target)`` and the triangles containing both), and vanished.

    Attributes:
      source: the removed vertex.
      target: the vertex that received the star of ``source``.
      removed_edges, removed_triangles: keys that no longer exist.
      added_edges, added_triangles: keys that did not exist before.
      merged_edges, merged_triangles: keys that existed before and are now also
        the image of a removed simplex.
    """

    source: int
    target: int
    removed_edges: tuple[Edge, ...]
    removed_triangles: tuple[Triangle, ...]
    added_edges: tuple[Edge, ...]
    added_triangles: tuple[Triangle, ...]
    merged_edges: tuple[Edge, ...]
    merged_triangles: tuple[Triangle, ...]


class SplitChange(NamedTuple):
    """What splitting an edge at a vertex did (:meth:`SimplicialComplex.split_edge`).

    Attributes:
      edge: the edge ``(a, b)`` that was split; it no longer exists.
      vertex: the vertex it was split at.
      removed_triangles: the triangles on the edge, all gone.
      added_triangles: their halves that did not exist before.
    """

    edge: Edge
    vertex: int
    removed_triangles: tuple[Triangle, ...]
    added_triangles: tuple[Triangle, ...]


class ComplexArrays(NamedTuple):
    """The live complex as compact arrays (ids renumbered ``0 .. V-1``).

    Attributes:
      vertices: ``(V, 3)`` float64 positions of the live vertices.
      vertex_ids: ``(V,)`` int64 id of each row in the complex.
      triangles: ``(T, 3)`` int64 rows into ``vertices``, each row increasing.
      edges: ``(E, 2)`` int64 rows into ``vertices``, every edge (triangles' too), rows increasing.
      dangling: ``(E,)`` bool, True for edges of no triangle.
      isolated: ``(I,)`` int64 rows into ``vertices`` of vertices of no edge.
    """

    vertices: np.ndarray
    vertex_ids: np.ndarray
    triangles: np.ndarray
    edges: np.ndarray
    dangling: np.ndarray
    isolated: np.ndarray


def edge_key(a: int, b: int) -> Edge:
    """Canonical key of an edge: ``(min, max)``."""
    return (a, b) if a < b else (b, a)


def triangle_key(a: int, b: int, c: int) -> Triangle:
    """Canonical key of a triangle: its ids increasing."""
    return tuple(sorted((a, b, c)))  # type: ignore[return-value]


def triangle_edges(t: Triangle) -> tuple[Edge, Edge, Edge]:
    """The three edge keys of a triangle key."""
    a, b, c = t
    return (a, b), (a, c), (b, c)


def replace_vertex(simplex: tuple[int, ...], source: int, target: int) -> tuple[int, ...] | None:
    """The key of ``simplex`` with ``source`` replaced by ``target``; None
    when that repeats ``target`` (the simplex degenerates)."""
    return None if target in simplex else tuple(sorted(target if v == source else v for v in simplex))


def closure(edges: Iterable[Edge], triangles: Iterable[Triangle], vertices: Iterable[int] = ()) -> LocalComplex:
    """The smallest complex holding the given simplices: all their faces added."""
    tris, es = set(triangles), set(edges)
    for t in tris:
        es.update(triangle_edges(t))
    vs = set(vertices)
    for e in es:
        vs.update(e)
    return LocalComplex(tuple(sorted(vs)), tuple(sorted(es)), tuple(sorted(tris)))


class SimplicialComplex:
    """A possibly non-manifold complex of vertices, edges and triangles in 3D.

    Args:
      vertices: ``(V, 3)`` float64 positions; every row is a live vertex.
      triangles: ``(T, 3)`` int vertex ids; repeated triangles (in any vertex
        order) are kept once, a triangle with a repeated id is an error.
      edges: optional ``(E, 2)`` extra edges (dangling or not), deduplicated
        the same way; the edges of the triangles are always added.

    Raises:
      ValueError: wrong shapes, non-finite positions, ids out of range, or a
        degenerate simplex.

    Example:
      >>> c = SimplicialComplex(np.eye(3), np.array([[0, 1, 2]]))
      >>> c.n_vertices, c.n_edges, c.n_triangles
      (3, 3, 1)
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray, edges: np.ndarray | None = None):
        vertices = np.array(vertices, dtype=np.float64)
        if vertices.ndim != 2 or vertices.shape[1] != 3:
            raise ValueError(f"vertices must have shape (V, 3), got {vertices.shape}")
        if not np.all(np.isfinite(vertices)):
            raise ValueError("vertex positions must be finite")
        nv = len(vertices)
        tri = _id_array(triangles, 3, nv, "triangles")
        edg = _id_array(np.zeros((0, 2), np.int64) if edges is None else edges, 2, nv, "edges")
        self.positions = vertices
        self.alive = np.ones(nv, bool)
        self.edges: dict[Edge, set[Triangle]] = {}
        self.triangles: set[Triangle] = set()
        self.vertex_edges: list[set[Edge]] = [set() for _ in range(nv)]
        self.vertex_triangles: list[set[Triangle]] = [set() for _ in range(nv)]
        for a, b in edg.tolist():
            self._add_edge(edge_key(a, b))
        for a, b, c in tri.tolist():
            self._add_triangle(triangle_key(a, b, c))

    # ------------------------------------------------------------ counts
    @property
    def n_vertices(self) -> int:
        """Number of live vertices (isolated ones included)."""
        return int(self.alive.sum())

    @property
    def n_edges(self) -> int:
        """Number of edges."""
        return len(self.edges)

    @property
    def n_triangles(self) -> int:
        """Number of triangles."""
        return len(self.triangles)

    def euler_characteristic(self) -> int:
        """``V - E + T`` over live simplices."""
        return self.n_vertices - self.n_edges + self.n_triangles

    # ----------------------------------------------------------- queries
    def has_edge(self, a: int, b: int) -> bool:
        """Whether the edge ``{a, b}`` exists."""
        return edge_key(a, b) in self.edges

    def neighbors(self, v: int) -> tuple[int, ...]:
        """Vertices sharing an edge with ``v``, increasing."""
        return tuple(sorted(a if a != v else b for a, b in self.vertex_edges[v]))

    def half_edges(self) -> list[tuple[int, int]]:
        """Every ``(source, target)`` pair of an edge, both directions, sorted."""
        return sorted([(a, b) for a, b in self.edges] + [(b, a) for a, b in self.edges])

    def edge_triangles(self, a: int, b: int) -> tuple[Triangle, ...]:
        """Triangles incident to the edge ``{a, b}`` (empty for a dangling edge)."""
        return tuple(sorted(self.edges[edge_key(a, b)]))

    def triangle_neighbors(self, t: Triangle) -> tuple[Triangle, ...]:
        """Triangles sharing an edge with triangle ``t`` (``t`` excluded):
        the facet stencil of the local relaxation (§3.3)."""
        t = triangle_key(*t)
        if t not in self.triangles:
            raise KeyError(f"triangle {t} is not in the complex")
        out = set()
        for e in triangle_edges(t):
            out.update(self.edges[e])
        out.discard(t)
        return tuple(sorted(out))

    def star(self, v: int) -> LocalComplex:
        """The simplices containing ``v`` (the open star; not closed)."""
        return LocalComplex((v,), tuple(sorted(self.vertex_edges[v])), tuple(sorted(self.vertex_triangles[v])))

    def vertex_closure(self, v: int) -> LocalComplex:
        """The closed star of ``v``: its simplices and all their faces."""
        return closure(self.vertex_edges[v], self.vertex_triangles[v], (v,))

    def edge_closure(self, a: int, b: int) -> LocalComplex:
        """The closure of the stars of both ends of an edge: the neighbourhood a
        collapse of ``(a, b)`` in either direction changes (§4.2)."""
        return closure(
            self.vertex_edges[a] | self.vertex_edges[b],
            self.vertex_triangles[a] | self.vertex_triangles[b],
            (a, b),
        )

    def link(self, v: int) -> LocalComplex:
        """The link of ``v``: the faces of its closed star that miss ``v``."""
        vs = self.neighbors(v)
        es = tuple(sorted(tuple(x for x in t if x != v) for t in self.vertex_triangles[v]))
        return LocalComplex(vs, es, ())  # type: ignore[arg-type]

    def edge_link(self, a: int, b: int) -> tuple[int, ...]:
        """The link of the edge ``{a, b}``: the third vertex of each of its triangles."""
        return tuple(sorted(x for t in self.edges[edge_key(a, b)] for x in t if x != a and x != b))

    def link_condition(self, a: int, b: int) -> bool:
        """``Lk(a) ∩ Lk(b) == Lk(ab)``: the collapse of ``(a, b)`` then keeps the
        homotopy type (Dey et al. 1999); the decimation does not require it."""
        la, lb = self.link(a), self.link(b)
        common_v = set(la.vertices) & set(lb.vertices)
        common_e = set(la.edges) & set(lb.edges)
        return not common_e and common_v == set(self.edge_link(a, b))

    # --------------------------------------------------------- collapse
    def simulate_collapse(self, source: int, target: int) -> LocalComplex:
        """The closed star of ``target`` after collapsing ``source`` onto it,
        without changing anything: what a stencil scores for this collapse.

        Equal to ``vertex_closure(target)`` after :meth:`collapse`.
        """
        self._check_half_edge(source, target)
        edges = {e for e in self.vertex_edges[target] if source not in e}
        tris = {t for t in self.vertex_triangles[target] if source not in t}
        for e in self.vertex_edges[source]:
            img = replace_vertex(e, source, target)
            if img is not None:
                edges.add(img)  # type: ignore[arg-type]
        for t in self.vertex_triangles[source]:
            img = replace_vertex(t, source, target)
            if img is not None:
                tris.add(img)  # type: ignore[arg-type]
        return closure(edges, tris, (target,))

    def collapse(self, source: int, target: int) -> CollapseChange:
        """Merges ``source`` into ``target`` along their edge (§4.2).

        Every simplex containing ``source`` is rewritten with ``target``;
        images that repeat ``target`` are dropped and images that already
        exist merge. The image of a closed complex under a vertex map is
        closed, so the result is again a simplicial complex; no link condition
        is required (the topology may change, as the paper allows).

        Raises:
          ValueError: a dead vertex, ``source == target``, or no edge between them.
        """
        self._check_half_edge(source, target)
        removed_t = tuple(sorted(self.vertex_triangles[source]))
        removed_e = tuple(sorted(self.vertex_edges[source]))
        for t in removed_t:
            self._remove_triangle(t)
        for e in removed_e:
            self._remove_edge(e)
        self.alive[source] = False
        added_e, merged_e = self._add_images(removed_e, source, target)
        added_t, merged_t = self._add_images(removed_t, source, target)
        return CollapseChange(source, target, removed_e, removed_t, added_e, added_t, merged_e, merged_t)

    def split_edge(self, a: int, b: int, v: int) -> SplitChange:
        """Splits the edge ``(a, b)`` at ``v``, a vertex joined to both ends.

        Each triangle ``(a, b, c)`` with ``c != v`` becomes ``(a, v, c)`` and
        ``(v, b, c)`` (merging with any that exist), the triangle ``(a, b, v)``
        goes, and so does the edge, which ``(a, v)`` and ``(v, b)`` replace.
        Where ``v`` lies on the segment this changes the topology only: it
        joins the facets on ``(a, b)`` to those around ``v``.

        Raises:
          ValueError: no edge ``(a, b)``, or ``v`` not joined to both ends.
        """
        e = edge_key(a, b)
        if e not in self.edges or v in e or not (self.has_edge(a, v) and self.has_edge(v, b)):
            raise ValueError(f"cannot split edge ({a}, {b}) at {v}: it needs the edges ({a}, {b}), "
                             f"({a}, {v}) and ({v}, {b})")
        removed = tuple(sorted(self.edges[e]))
        for t in removed:
            self._remove_triangle(t)
        self._remove_edge(e)
        added = []
        for t in removed:
            (c,) = set(t) - {a, b}
            if c != v:
                added += [h for h in (triangle_key(a, v, c), triangle_key(v, b, c)) if self._add_triangle(h)]
        return SplitChange(e, v, removed, tuple(sorted(added)))

    def remove_triangle(self, t: Triangle) -> tuple[Edge, ...]:
        """Removes triangle ``t`` (``KeyError`` if absent) and its edges no other
        triangle has, which it returns; its vertices stay."""
        t = triangle_key(*t)
        if t not in self.triangles:
            raise KeyError(f"triangle {t} is not in the complex")
        self._remove_triangle(t)
        lone = tuple(e for e in triangle_edges(t) if not self.edges[e])
        for e in lone:
            self._remove_edge(e)
        return lone

    def move(self, v: int, position: np.ndarray) -> None:
        """Sets the position of live vertex ``v`` (topology is unchanged)."""
        if not self.alive[v]:
            raise ValueError(f"vertex {v} is dead")
        p = np.asarray(position, np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"a vertex position must be 3 finite floats, got {position!r}")
        self.positions[v] = p

    # ----------------------------------------------------------- export
    def triangle_array(self) -> np.ndarray:
        """``(T, 3)`` int64 triangle keys (original ids), sorted rows."""
        return np.array(sorted(self.triangles), np.int64).reshape(-1, 3)

    def edge_array(self) -> np.ndarray:
        """``(E, 2)`` int64 edge keys (original ids), sorted rows."""
        return np.array(sorted(self.edges), np.int64).reshape(-1, 2)

    def isolated_vertices(self) -> np.ndarray:
        """``(I,)`` int64 ids of live vertices with no edge."""
        return np.array([v for v in np.flatnonzero(self.alive) if not self.vertex_edges[v]], np.int64)

    def to_arrays(self) -> ComplexArrays:
        """The live complex with vertices renumbered compactly (:class:`ComplexArrays`)."""
        ids = np.flatnonzero(self.alive).astype(np.int64)
        row = np.full(len(self.alive), -1, np.int64)
        row[ids] = np.arange(len(ids))
        edges = self.edge_array()
        dangling = np.array([not self.edges[e] for e in sorted(self.edges)], bool)
        return ComplexArrays(
            self.positions[ids].copy(), ids, row[self.triangle_array()], row[edges], dangling,
            row[self.isolated_vertices()],
        )

    # ----------------------------------------------------------- checks
    def check(self) -> None:
        """Raises ``AssertionError`` naming the first broken invariant: faces
        present, ids alive and keys canonical, star maps equal to the simplex
        sets."""
        _check_complex(self)

    # --------------------------------------------------------- internals
    def _check_half_edge(self, source: int, target: int) -> None:
        n = len(self.alive)
        if not (0 <= source < n and 0 <= target < n) or not (self.alive[source] and self.alive[target]):
            raise ValueError(f"half-edge ({source}, {target}) has a dead or unknown vertex")
        if source == target or edge_key(source, target) not in self.edges:
            raise ValueError(f"there is no edge between {source} and {target}")

    def _add_edge(self, e: Edge) -> bool:
        if e in self.edges:
            return False
        self.edges[e] = set()
        self.vertex_edges[e[0]].add(e)
        self.vertex_edges[e[1]].add(e)
        return True

    def _add_triangle(self, t: Triangle) -> bool:
        if t in self.triangles:
            return False
        self.triangles.add(t)
        for e in triangle_edges(t):
            self._add_edge(e)
            self.edges[e].add(t)
        for v in t:
            self.vertex_triangles[v].add(t)
        return True

    def _remove_triangle(self, t: Triangle) -> None:
        self.triangles.remove(t)
        for e in triangle_edges(t):
            self.edges[e].remove(t)
        for v in t:
            self.vertex_triangles[v].remove(t)

    def _remove_edge(self, e: Edge) -> None:
        if self.edges.pop(e):
            raise AssertionError(f"edge {e} removed while triangles still use it")
        self.vertex_edges[e[0]].remove(e)
        self.vertex_edges[e[1]].remove(e)

    def _add_images(self, removed, source: int, target: int):
        """Adds the non-degenerate images of ``removed`` simplices; returns
        ``(added, merged)`` key tuples, sorted."""
        added, merged = [], []
        for s in removed:
            img = replace_vertex(s, source, target)
            if img is None:
                continue
            new = self._add_edge(img) if len(img) == 2 else self._add_triangle(img)  # type: ignore[arg-type]
            (added if new else merged).append(img)
        return tuple(sorted(added)), tuple(sorted(merged))


def _id_array(a, width: int, nv: int, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.size == 0:
        return np.zeros((0, width), np.int64)
    if a.ndim != 2 or a.shape[1] != width or not np.issubdtype(a.dtype, np.integer):
        raise ValueError(f"{name} must be an integer array of shape (n, {width}), got {a.dtype} {a.shape}")
    if a.min() < 0 or a.max() >= nv:
        raise ValueError(f"{name} refer to vertex ids outside 0..{nv - 1}")
    s = np.sort(a, axis=1)
    if np.any(s[:, 1:] == s[:, :-1]):
        bad = a[np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], axis=1))[0]]
        raise ValueError(f"{name} contain a degenerate simplex with a repeated vertex: {bad.tolist()}")
    return a.astype(np.int64)


def _fail(msg: str) -> None:
    raise AssertionError(msg)


def _check_complex(c: SimplicialComplex) -> None:
    nv = len(c.alive)
    for t in c.triangles:
        if len(t) != 3 or not (0 <= t[0] < t[1] < t[2] < nv):
            _fail(f"triangle key {t} is not three increasing vertex ids")
        for v in t:
            if not c.alive[v]:
                _fail(f"triangle {t} uses dead vertex {v}")
            if t not in c.vertex_triangles[v]:
                _fail(f"triangle {t} missing from the star of vertex {v}")
        for e in triangle_edges(t):
            if e not in c.edges:
                _fail(f"edge {e} of triangle {t} is not in the complex")
            if t not in c.edges[e]:
                _fail(f"triangle {t} missing from the triangles of its edge {e}")
    for e, ts in c.edges.items():
        if len(e) != 2 or not (0 <= e[0] < e[1] < nv):
            _fail(f"edge key {e} is not two increasing vertex ids")
        for v in e:
            if not c.alive[v]:
                _fail(f"edge {e} uses dead vertex {v}")
            if e not in c.vertex_edges[v]:
                _fail(f"edge {e} missing from the star of vertex {v}")
        for t in ts:
            if t not in c.triangles or e not in triangle_edges(t):
                _fail(f"edge {e} lists {t}, which is not one of its triangles")
    for v in range(nv):
        if not c.alive[v] and (c.vertex_edges[v] or c.vertex_triangles[v]):
            _fail(f"dead vertex {v} still has a star")
        for e in c.vertex_edges[v]:
            if v not in e or e not in c.edges:
                _fail(f"star of vertex {v} lists edge {e}, which is not one of its edges")
        for t in c.vertex_triangles[v]:
            if v not in t or t not in c.triangles:
                _fail(f"star of vertex {v} lists triangle {t}, which is not one of its triangles")
    if sum(len(s) for s in c.vertex_edges) != 2 * len(c.edges):
        _fail("vertex-edge stars do not count every edge twice")
    if sum(len(s) for s in c.vertex_triangles) != 3 * len(c.triangles):
        _fail("vertex-triangle stars do not count every triangle three times")
    if sum(len(s) for s in c.edges.values()) != 3 * len(c.triangles):
        _fail("edge-triangle lists do not count every triangle three times")
