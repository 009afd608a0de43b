"""A 2D triangulation that stays embedded under half-edge collapses and flips.

The structure is the classic triangle/neighbour one: ``tri[f] = [v0, v1, v2]``
counter-clockwise, ``nbr[f][k]`` the triangle across the edge opposite
``tri[f][k]`` (``-1`` on the outer boundary). Four pinned corners of a loose
bounding box form the outer boundary, so every other vertex is interior and
has a closed one-ring. Triangle and vertex slots are never reused: a collapse
frees two triangles, a flip rewrites two in place.

All geometric decisions use the exact predicates of
:mod:`otjax.predicates`. Collapses follow de Goes et al. 2011, §3.2: the
link condition, the kernel test, and the flip procedure that makes every
half-edge collapsible (:meth:`Triangulation.plan_collapse`).
"""

from __future__ import annotations

import numpy as np

from otjax.curves import embedding
from otjax.curves.collapse import CollapsePlan, MovePlan, edge_key, orient_ids, plan_collapse
from otjax.predicates import in_triangle_perturbed, orient, orient_scalar

N_CORNERS = embedding.N_CORNERS


class Triangulation:
    """Embedded triangulation of a point set inside four pinned corners.

    Args:
      vertices: ``(V, 2)`` float64 distinct vertex positions (no corners).
      margin: the pinned box extends ``margin`` times the larger side of the
        vertices' bounding box beyond it on every side.

    Attributes:
      xy: ``(V + 4, 2)`` float64 positions; ids ``V .. V+3`` are the corners.
      pinned: ``(V + 4,)`` bool, True for the corners.
      alive: ``(V + 4,)`` bool, False for collapsed or never-inserted vertices.
      tri, nbr: per-triangle lists (see module docstring); ``None`` when freed.

    Example:
      >>> t = Triangulation(np.random.default_rng(0).random((20, 2)))
      >>> t.n_vertices
      24
    """

    def __init__(self, vertices: np.ndarray, margin: float = 0.5):
        vertices = np.asarray(vertices, np.float64)
        if vertices.ndim != 2 or vertices.shape[1] != 2 or len(vertices) == 0:
            raise ValueError(f"vertices must have shape (V, 2) with V >= 1, got {vertices.shape}")
        if not np.all(np.isfinite(vertices)):
            raise ValueError("vertices must be finite")
        lo, hi = vertices.min(0), vertices.max(0)
        side = float(np.max(hi - lo))
        pad = margin * side if side > 0 else 1.0
        corners = np.array(
            [[lo[0] - pad, lo[1] - pad], [hi[0] + pad, lo[1] - pad],
             [hi[0] + pad, hi[1] + pad], [lo[0] - pad, hi[1] + pad]]
        )
        self.xy = np.vstack([vertices, corners])
        nv = len(self.xy)
        self.pinned = np.zeros(nv, bool)
        self.pinned[-N_CORNERS:] = True
        self.alive = np.ones(nv, bool)
        self._build(np.ones(nv, bool))

    # ------------------------------------------------------------------ build
    def _build(self, use: np.ndarray) -> None:
        """The exact Delaunay of the vertices in ``use`` (:func:`otjax.curves.embedding.delaunay`)."""
        d = embedding.delaunay(self.xy, self.pinned, use)
        self.alive = d.alive
        self.xy_list = self.xy.tolist()  # scalar predicates read Python floats
        self.tri = d.triangles.tolist()
        self.nbr = d.neighbours.tolist()
        self._stars: dict[int, tuple] = {}
        self.vface = [-1] * len(self.xy)
        for f, t in enumerate(self.tri):
            for v in t:
                self.vface[v] = f

    # -------------------------------------------------------------- queries
    @property
    def n_vertices(self) -> int:
        """Number of live vertices, corners included."""
        return int(self.alive.sum())

    def triangles(self) -> np.ndarray:
        """``(F, 2)``-style array ``(F, 3)`` of live triangle vertex ids, CCW."""
        return np.array([t for t in self.tri if t is not None], dtype=np.int64).reshape(-1, 3)

    def triangle_ids(self) -> list[int]:
        """Ids of the live triangles."""
        return [f for f, t in enumerate(self.tri) if t is not None]

    def edges(self) -> np.ndarray:
        """``(E, 2)`` sorted array of live edge keys ``(min, max)``."""
        t = self.triangles()
        e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
        e.sort(axis=1)
        return np.unique(e, axis=0)

    def star(self, v: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
        """CCW one-ring of an interior vertex.

        Cached: the greedy loop asks for the same stars many times between
        two changes; :meth:`collapse` and :meth:`flip` drop the entries of
        the vertices whose stars they touch.

        Returns:
          ``(ring, faces)``: ``ring[k]`` is the k-th neighbour and ``faces[k]``
          the triangle ``(v, ring[k], ring[k+1])``.
        """
        hit = self._stars.get(v)
        if hit is not None:
            return hit
        if self.pinned[v] or not self.alive[v]:
            raise ValueError(f"vertex {v} is pinned or dead and has no closed star")
        f0 = self.vface[v]
        ring, faces = [], []
        f = f0
        while True:
            t = self.tri[f]
            k = t.index(v)
            ring.append(t[(k + 1) % 3])
            faces.append(f)
            f = self.nbr[f][(k + 1) % 3]  # across edge (v, t[k+2])
            if f == f0:
                out = (tuple(ring), tuple(faces))
                self._stars[v] = out
                return out
            if f < 0 or len(faces) > len(self.tri):
                raise RuntimeError(f"broken star around vertex {v}")

    def neighbors(self, v: int) -> set[int]:
        """Vertex ids adjacent to ``v`` (works for pinned corners too)."""
        out = set()
        for f, t in enumerate(self.tri):
            if t is not None and v in t:
                out.update(t)
        out.discard(v)
        return out

    def interior_neighbors(self, v: int) -> set[int]:
        """Neighbours of ``v``, from its star when it has one."""
        return set(self.star(v)[0]) if not self.pinned[v] else self.neighbors(v)

    def half_edges(self) -> list[tuple[int, int]]:
        """All half-edges ``(source, target)`` eligible for collapse.

        A half-edge is eligible when neither end is a pinned corner: corners
        are never removed and never receive a collapsed vertex.
        """
        out = []
        for u, v in self.edges():
            if not (self.pinned[u] or self.pinned[v]):
                out.append((int(u), int(v)))
                out.append((int(v), int(u)))
        return out

    # ----------------------------------------------------------- predicates
    def in_kernel(self, polygon: list[int], v: int) -> bool:
        """Whether ``v`` lies strictly inside the kernel of a CCW polygon.

        Edges incident to ``v`` are skipped: they vanish when ``v`` becomes
        the apex of the fan over the polygon.
        """
        n = len(polygon)
        for k in range(n):
            a, b = polygon[k], polygon[(k + 1) % n]
            if v in (a, b):
                continue
            if orient_ids(self.xy_list, v, a, b) <= 0:
                return False
        return True

    def in_kernel_at(self, polygon: list[int], p: np.ndarray) -> bool:
        """Whether point ``p`` lies strictly inside the kernel of a CCW polygon.

        This is the embedding test of a vertex relocation: moving the centre
        of a star to ``p`` keeps every triangle of the star positively
        oriented exactly when ``p`` sees every polygon edge on its left.
        """
        n = len(polygon)
        px, py = float(p[0]), float(p[1])
        xy = self.xy_list
        for k in range(n):
            (ax, ay), (bx, by) = xy[polygon[k]], xy[polygon[(k + 1) % n]]
            if orient_scalar(ax, ay, bx, by, px, py) <= 0:
                return False
        return True

    # ---------------------------------------------------------- flip planning
    def plan_collapse(self, source: int, target: int) -> CollapsePlan | None:
        """How to collapse ``source`` onto ``target`` without a fold-over
        (:func:`otjax.curves.collapse.plan_collapse`); nothing is modified,
        :meth:`collapse` applies the plan."""
        return plan_collapse(self, source, target)

    # ------------------------------------------------------------ mutations
    def _slot_of_edge(self, f: int, u: int, v: int) -> int:
        """Index ``k`` such that edge ``(u, v)`` is opposite ``tri[f][k]``."""
        t = self.tri[f]
        for k in range(3):
            if {t[(k + 1) % 3], t[(k + 2) % 3]} == {u, v}:
                return k
        raise KeyError(f"edge ({u}, {v}) not in triangle {f}")

    def collapse(self, plan: CollapsePlan) -> list[int]:
        """Applies a :class:`CollapsePlan`: removes ``source``, retriangulates.

        The star of ``source`` (``deg`` triangles) is replaced by the plan's
        ``deg - 2`` triangles (flipped-out ears and the fan of ``target``);
        this is exactly the state that the flips followed by the half-edge
        collapse produce, written in one step. Two triangle slots are freed.

        Returns:
          The ids of the triangles now covering the region, in the order of
          ``plan.new_triangles``.
        """
        v = plan.source
        ring, star = self.star(v)
        if tuple(ring) != plan.ring or tuple(star) != plan.star:
            raise ValueError("stale collapse plan: the star of the source has changed")
        n = len(ring)
        # Boundary edges keep their direction: the region lies on their left.
        outside = {}
        for k in range(n):
            f = star[k]
            outside[(ring[k], ring[(k + 1) % n])] = self.nbr[f][self.tri[f].index(v)]
        ids = list(star[: n - 2])
        twin = {}
        for f, t in zip(ids, plan.new_triangles):
            self.tri[f] = list(t)
            for k in range(3):
                twin[(t[(k + 1) % 3], t[(k + 2) % 3])] = f
        for f in star[n - 2:]:
            self.tri[f] = self.nbr[f] = None
        for f, t in zip(ids, plan.new_triangles):
            nb = [-1, -1, -1]
            for k in range(3):
                e = (t[(k + 1) % 3], t[(k + 2) % 3])
                if e in outside:
                    g = outside[e]
                    nb[k] = g
                    if g >= 0:  # by edge, not by id: ids of the star are reused
                        self.nbr[g][self._slot_of_edge(g, *e)] = f
                else:
                    nb[k] = twin[(e[1], e[0])]
            self.nbr[f] = nb
            for u in t:
                self.vface[u] = f
        self.alive[v] = False
        self.vface[v] = -1
        for u in (v,) + tuple(ring):
            self._stars.pop(u, None)
        return ids

    def move(self, v: int, p: np.ndarray) -> None:
        """Moves interior vertex ``v`` to ``p`` inside the kernel of its one-ring.

        Raises:
          ValueError: ``v`` is pinned or dead, or ``p`` would fold a triangle.
        """
        ring, _ = self.star(v)
        if not self.in_kernel_at(ring, p):
            raise ValueError(f"moving vertex {v} to {tuple(p)} would fold a triangle over")
        self.xy[v] = p
        self.xy_list[v] = [float(p[0]), float(p[1])]

    def set_positions(self, xy: np.ndarray) -> None:
        """Moves many vertices at once; the corners must stay where they are.

        Raises:
          ValueError: a corner moves, or some triangle would not be strictly
            counter-clockwise (exact test) -- nothing is changed then.
        """
        xy = np.asarray(xy, np.float64)
        if xy.shape != self.xy.shape:
            raise ValueError(f"positions must have shape {self.xy.shape}, got {xy.shape}")
        if np.any(xy[self.pinned] != self.xy[self.pinned]):
            raise ValueError("the pinned corners cannot move")
        t = self.triangles()
        if not (orient(xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]) > 0).all():
            raise ValueError("these positions would fold a triangle over")
        self.xy = xy.copy()
        self.xy_list = self.xy.tolist()

    # ----------------------------------------------------- location, checks
    def locate_in(self, points: np.ndarray, faces: list[int]) -> np.ndarray:
        """Which of ``faces`` holds each perturbed point (:func:`otjax.curves.embedding.locate_in`)."""
        return embedding.locate_in(self, points, faces)

    def locate(self, points: np.ndarray) -> np.ndarray:
        """Triangle holding each perturbed point (:func:`otjax.curves.embedding.locate`)."""
        return embedding.locate(self, points)

    def check(self) -> None:
        """Raises ``AssertionError`` unless the structure is a valid embedding
        (:func:`otjax.curves.embedding.check`)."""
        embedding.check(self)
