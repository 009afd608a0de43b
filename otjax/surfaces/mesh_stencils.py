"""The combinatorics of a mesh of fixed connectivity as flat arrays: rows of
variable length (:class:`Ragged`), local problems given by their simplices
(:class:`Stencils`), the graph of vertices whose closed stars meet
(:func:`distance2_graph`) and the paper's stencil of each facet
(:func:`facet_rings`). :class:`~otjax.surfaces.star_plan.StarPlan` builds
its stars and rings from these.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse


class Ragged(NamedTuple):
    """Rows of variable length (CSR): row ``r`` is ``index[ptr[r]:ptr[r + 1]]``."""

    ptr: np.ndarray
    index: np.ndarray

    def take(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(values, row, column)`` of the concatenated ``rows`` ``(B,)``: each
        value, the position in ``rows`` it came from, its place in that row."""
        rows = np.asarray(rows, np.int64)
        lo, n = self.ptr[rows], self.ptr[rows + 1] - self.ptr[rows]
        row = np.repeat(np.arange(len(rows)), n)
        column = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        return self.index[lo[row] + column], row, column


def ragged(values: np.ndarray, row: np.ndarray, n_rows: int) -> Ragged:
    """The :class:`Ragged` of ``values`` grouped by ``row`` (non-decreasing, ``< n_rows``)."""
    return Ragged(np.concatenate([[0], np.cumsum(np.bincount(row, minlength=n_rows))]).astype(np.int64),
                  np.asarray(values, np.int64))


class Stencils(NamedTuple):
    """Local problems given by their simplices, one row each: sorted vertex
    ids and sorted facets (rows of :attr:`otjax.surfaces.star_plan.MeshBins.keys`)."""

    vertices: Ragged
    facets: Ragged

    def take(self, rows: np.ndarray) -> Stencils:
        """The stencils ``rows`` ``(B,)``, in that order."""
        v, vrow, _ = self.vertices.take(rows)
        f, frow, _ = self.facets.take(rows)
        return Stencils(ragged(v, vrow, len(rows)), ragged(f, frow, len(rows)))

    def incidence(self, n_columns: int, facets: bool = False) -> scipy.sparse.csr_matrix:
        """``(rows, n_columns)`` CSR, 1 where a stencil holds a vertex (or, with ``facets``, a facet)."""
        r = self.facets if facets else self.vertices
        n = len(r.ptr) - 1
        row = np.repeat(np.arange(n), np.diff(r.ptr))
        return scipy.sparse.csr_matrix((np.ones(len(row)), (row, r.index)), shape=(n, n_columns))


def distance2_graph(triangles: np.ndarray, n_vertices: int) -> scipy.sparse.csr_matrix:
    """``(V, V)`` CSR, nonzero where two vertices' closed stars share a vertex
    (they are at most two edges apart), the diagonal included."""
    t = np.asarray(triangles, np.int64).reshape(-1, 3)
    a = np.concatenate([t[:, 0], t[:, 1], t[:, 2], t[:, 1], t[:, 2], t[:, 0]])
    b = np.concatenate([t[:, 1], t[:, 2], t[:, 0], t[:, 0], t[:, 1], t[:, 2]])
    ring = scipy.sparse.csr_matrix((np.ones(len(a)), (a, b)), shape=(n_vertices, n_vertices))
    ring = (ring + scipy.sparse.identity(n_vertices, format="csr")).tocsr()
    two = (ring @ ring).tocsr()
    two.sort_indices()
    return two


def facet_rings(keys: np.ndarray, n_vertices: int) -> Stencils:
    """The paper's stencil of each facet of ``keys`` ``(T, 3)``: it, the facets
    sharing an edge with it, and their vertices, each sorted."""
    t = len(keys)
    edges = np.concatenate([keys[:, [0, 1]], keys[:, [0, 2]], keys[:, [1, 2]]])
    _, edge = np.unique(edges[:, 0] * n_vertices + edges[:, 1], return_inverse=True)
    by_edge = scipy.sparse.csr_matrix((np.ones(3 * t), (np.tile(np.arange(t), 3), edge.ravel())),
                                      shape=(t, int(edge.max(initial=-1)) + 1))
    ring = (by_edge @ by_edge.T).tocsr()
    ring.sort_indices()
    corners = scipy.sparse.csr_matrix((np.ones(3 * t), (np.repeat(np.arange(t), 3), keys.ravel())),
                                      shape=(t, n_vertices))
    verts = (ring @ corners).tocsr()
    verts.sort_indices()
    return Stencils(Ragged(verts.indptr.astype(np.int64), verts.indices.astype(np.int64)),
                    Ragged(ring.indptr.astype(np.int64), ring.indices.astype(np.int64)))
