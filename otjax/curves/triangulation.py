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

from typing import NamedTuple

import numpy as np
from scipy.spatial import Delaunay

from otjax.predicates import in_triangle_perturbed, orient, orient_scalar

N_CORNERS = 4


class CollapsePlan(NamedTuple):
    """What collapsing ``source`` onto ``target`` does, before doing it.

    Attributes:
      source, target: vertex ids; ``source`` disappears.
      ring: CCW one-ring of ``source`` before any flip.
      star: triangle ids around ``source`` before any flip (the changed region).
      clipped: ring vertices whose spoke ``(source, a)`` is flipped away, in
        order (each leaves the one-ring polygon).
      flipped_out: ``(c, a, b)`` CCW ears that the flips push out of the
        star; they survive the collapse.
      fan: ``(target, u, w)`` CCW triangles that replace the rest of the star.
    """

    source: int
    target: int
    ring: tuple[int, ...]
    star: tuple[int, ...]
    clipped: tuple[int, ...]
    flipped_out: tuple[tuple[int, int, int], ...]
    fan: tuple[tuple[int, int, int], ...]

    @property
    def new_triangles(self) -> tuple[tuple[int, int, int], ...]:
        """All triangles covering the changed region after the collapse."""
        return self.flipped_out + self.fan


class MovePlan(NamedTuple):
    """What moving ``vertex`` does to the triangulation: its star keeps its
    triangles (``new_triangles``, the fan ``(vertex, ring[k], ring[k+1])``),
    which change shape.

    Attributes:
      vertex: the moved vertex.
      ring: its CCW one-ring.
      star: its triangle ids (``star[k]`` is ``(vertex, ring[k], ring[k+1])``).
    """

    vertex: int
    ring: tuple[int, ...]
    star: tuple[int, ...]

    @property
    def source(self) -> int:
        """The moved vertex (the name a collapse plan gives its changed vertex)."""
        return self.vertex

    @property
    def target(self) -> int:
        """The moved vertex: a move keeps it."""
        return self.vertex

    @property
    def flipped_out(self) -> tuple:
        """No ears: a move flips nothing."""
        return ()

    @property
    def new_triangles(self) -> tuple[tuple[int, int, int], ...]:
        """The star's triangles, ``(vertex, ring[k], ring[k+1])``, CCW."""
        n = len(self.ring)
        return tuple((self.vertex, self.ring[k], self.ring[(k + 1) % n]) for k in range(n))


def edge_key(u: int, v: int) -> tuple[int, int]:
    """Canonical key of an undirected edge: ``(min, max)`` vertex id."""
    return (u, v) if u < v else (v, u)


def _orient1(xy: list, a: int, b: int, c: int) -> int:
    (ax, ay), (bx, by), (cx, cy) = xy[a], xy[b], xy[c]
    return orient_scalar(ax, ay, bx, by, cx, cy)


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
        """Delaunay of the vertices in ``use``; drops vertices Qhull mishandles.

        Qhull works in floating point: with near-duplicate or near-collinear
        input it may skip a vertex or emit a flat triangle. Every triangle is
        re-checked with the exact predicate; offending vertices are taken out
        (their points are still transported, only not as vertices) and the
        triangulation is rebuilt, so the result is always a valid embedding.
        """
        # Qhull's tolerances are relative to the coordinates' magnitude: feed
        # it centred, unit-scale copies (the exact checks use the originals).
        lo, hi = self.xy.min(0), self.xy.max(0)
        scaled = (self.xy - (lo + hi) / 2) / np.max(hi - lo)
        for _ in range(64):
            ids = np.nonzero(use)[0]
            dt = Delaunay(scaled[ids])
            simp = ids[dt.simplices]
            nbr = dt.neighbors.copy()
            s = orient(self.xy[simp[:, 0]], self.xy[simp[:, 1]], self.xy[simp[:, 2]])
            flip = s < 0
            simp[flip] = simp[flip][:, [0, 2, 1]]
            nbr[flip] = nbr[flip][:, [0, 2, 1]]
            bad = s == 0
            # Qhull's orientation is arbitrary, hence the re-orientation above;
            # but on near-degenerate input two of its triangles can overlap,
            # which shows as a directed edge used twice once all are CCW.
            directed = np.stack([simp, simp[:, [1, 2, 0]]], -1).reshape(-1, 2)
            _, first, count = np.unique(directed, axis=0, return_inverse=True, return_counts=True)
            bad |= (count[first.ravel()] > 1).reshape(-1, 3).any(1)
            used = np.zeros(len(self.xy), bool)
            used[simp.ravel()] = True
            missing = use & ~used
            if not bad.any() and not missing.any():
                break
            drop = np.zeros(len(self.xy), bool)
            drop[simp[bad].ravel()] = True
            drop |= missing
            drop &= ~self.pinned
            if not drop.any():  # a flat triangle made of corners only: impossible
                raise RuntimeError("could not build an embedded initial triangulation")
            use = use & ~drop
        else:
            raise RuntimeError("could not build an embedded initial triangulation")
        self.alive = use.copy()
        # Qhull's point location is a valid hint while the triangles are still
        # its own (triangle f is its simplex f); any change drops it.
        self._hint = (dt, (lo + hi) / 2, float(np.max(hi - lo)))
        self._xyl = self.xy.tolist()  # scalar predicates read Python floats
        self.tri = simp.tolist()
        self.nbr = nbr.tolist()
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

    def _neighbors_interior(self, v: int) -> set[int]:
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
            if _orient1(self._xyl, v, a, b) <= 0:
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
        xy = self._xyl
        for k in range(n):
            (ax, ay), (bx, by) = xy[polygon[k]], xy[polygon[(k + 1) % n]]
            if orient_scalar(ax, ay, bx, by, px, py) <= 0:
                return False
        return True

    def link_condition(self, u: int, v: int) -> bool:
        """Link condition for the interior edge ``(u, v)``.

        The common neighbours of ``u`` and ``v`` must be exactly the two
        vertices opposite the edge; otherwise the collapse would pinch the
        triangulation (duplicate an edge or a triangle).
        """
        ring, _ = self.star(u)
        if v not in ring:
            return False
        k = ring.index(v)
        opposite = {ring[k - 1], ring[(k + 1) % len(ring)]}
        return (set(ring) & self._neighbors_interior(v)) == opposite

    # ---------------------------------------------------------- flip planning
    def plan_collapse(self, source: int, target: int) -> CollapsePlan | None:
        """How to collapse ``source`` onto ``target`` without a fold-over.

        Implements de Goes et al. 2011, §3.2 "Systematically collapsing
        edges": while some edge ``(a, b)`` of the one-ring polygon of
        ``source`` blocks ``target`` (triangle ``(target, a, b)`` not CCW),
        take the blocking edges by decreasing cut ``D`` (how far from
        ``target`` their supporting line crosses ``source -> target``) and
        flip away the spoke of one endpoint, preferring the flip that leaves
        the smaller cut. A flip of spoke ``(source, a)`` pushes the ear
        ``(c, a, b)`` out of the star and removes ``a`` from the polygon.

        The paper states that the top blocking edge always has a flippable
        spoke; near-collinear rings disprove it (a flip is only legal when the
        quadrilateral around the spoke is convex, which involves ``source``).
        Since ``source`` disappears anyway, otjax then clips any valid ear of
        the polygon (convex corner, no other polygon vertex in the closed
        triangle). A simple polygon with four or more vertices always has two
        ears with distinct tips, so one is not ``target``; every step removes
        a vertex; a triangle never blocks. The procedure therefore always
        terminates with a collapsible half-edge, in at most ``deg - 3`` steps.
        Nothing is modified here; :meth:`collapse` applies the plan.

        Returns:
          The plan, or ``None`` if an end is pinned, the vertices are not
          adjacent, or the link condition fails after the flips.
        """
        if self.pinned[source] or self.pinned[target]:
            return None
        ring, star = self.star(source)
        if target not in ring:
            return None
        xy = self.xy
        poly = list(ring)
        clipped: list[int] = []
        flipped_out: list[tuple[int, int, int]] = []
        span = float(np.hypot(*(xy[target] - xy[source])))

        def cut(a: int, b: int) -> float:
            # Distance from target to where line (a, b) crosses source->target:
            # how much removing (a, b) from the polygon elongates its kernel.
            if _orient1(self._xyl, target, a, b) > 0:
                return 0.0
            e = xy[b] - xy[a]
            da = float(e[0] * (xy[source, 1] - xy[a, 1]) - e[1] * (xy[source, 0] - xy[a, 0]))
            db = float(e[0] * (xy[target, 1] - xy[a, 1]) - e[1] * (xy[target, 0] - xy[a, 0]))
            s = da / (da - db) if da != db else 1.0
            return (1.0 - min(max(s, 0.0), 1.0)) * span

        def is_ear(j: int, with_source: bool) -> bool:
            n = len(poly)
            c, a, b = poly[j - 1], poly[j], poly[(j + 1) % n]
            if a == target or _orient1(self._xyl, c, a, b) <= 0:
                return False
            if with_source:  # the paper's flip: quad (source, c, a, b) convex
                return _orient1(self._xyl, source, c, b) > 0
            # Scalar predicates with early exit: rings are short, and NumPy's
            # per-call overhead made this the hottest line on collinear data.
            xyl = self._xyl
            for x in poly:
                if x in (c, a, b):
                    continue
                if (_orient1(xyl, c, a, x) >= 0 and _orient1(xyl, a, b, x) >= 0
                        and _orient1(xyl, b, c, x) >= 0):
                    return False
            return True

        while True:
            n = len(poly)
            blocking = []
            for k in range(n):
                a, b = poly[k], poly[(k + 1) % n]
                if target not in (a, b) and _orient1(self._xyl, target, a, b) <= 0:
                    blocking.append((cut(a, b), k))
            if not blocking:
                break
            blocking.sort(key=lambda t: (-t[0], t[1]))
            chosen = None
            for with_source in (True, False):
                for _, k in blocking:
                    options = [
                        (cut(poly[j - 1], poly[(j + 1) % n]), j)
                        for j in (k, (k + 1) % n)
                        if is_ear(j, with_source)
                    ]
                    if options:
                        chosen = min(options)[1]
                        break
                if chosen is not None:
                    break
            if chosen is None:  # no blocking endpoint is an ear: clip any ear
                chosen = next(j for j in range(n) if is_ear(j, False))
            a = poly[chosen]
            flipped_out.append((poly[chosen - 1], a, poly[(chosen + 1) % n]))
            clipped.append(a)
            del poly[chosen]

        if not self._link_after_flips(source, target, poly, flipped_out):
            return None
        n = len(poly)
        fan = tuple(
            (target, poly[k], poly[(k + 1) % n])
            for k in range(n)
            if target not in (poly[k], poly[(k + 1) % n])
        )
        return CollapsePlan(source, target, tuple(ring), tuple(star), tuple(clipped),
                            tuple(flipped_out), fan)

    def _link_after_flips(self, source, target, poly, flipped_out) -> bool:
        nb = self._neighbors_interior(target)
        for c, _, b in flipped_out:  # the new diagonal (c, b)
            if c == target:
                nb.add(b)
            elif b == target:
                nb.add(c)
        k = poly.index(target)
        opposite = {poly[k - 1], poly[(k + 1) % len(poly)]}
        return (set(poly) & nb) == opposite

    # ------------------------------------------------------------ mutations
    def _slot_of_edge(self, f: int, u: int, v: int) -> int:
        """Index ``k`` such that edge ``(u, v)`` is opposite ``tri[f][k]``."""
        t = self.tri[f]
        for k in range(3):
            if {t[(k + 1) % 3], t[(k + 2) % 3]} == {u, v}:
                return k
        raise KeyError(f"edge ({u}, {v}) not in triangle {f}")

    def _replace_nbr(self, f: int, old: int, new: int) -> None:
        if f >= 0:
            n = self.nbr[f]
            n[n.index(old)] = new

    def flip(self, f: int, k: int) -> tuple[int, int]:
        """Flips the edge opposite ``tri[f][k]``; returns the two triangle ids.

        The caller guarantees the quadrilateral is strictly convex (checked
        with :func:`otjax.predicates.orient`; a non-convex flip raises).
        """
        g = self.nbr[f][k]
        if g < 0:
            raise ValueError("cannot flip a boundary edge")
        s, p, q = self.tri[f][k], self.tri[f][(k + 1) % 3], self.tri[f][(k + 2) % 3]
        j = self.nbr[g].index(f)
        r = self.tri[g][j]
        if _orient1(self._xyl, s, p, r) <= 0 or _orient1(self._xyl, s, r, q) <= 0:
            raise ValueError(f"edge ({p}, {q}) is not flippable")
        f_q = self.nbr[f][(k + 2) % 3]  # across (s, p)
        f_p = self.nbr[f][(k + 1) % 3]  # across (q, s)
        tg = self.tri[g]
        g_p = self.nbr[g][(tg.index(p))]  # across (r, q)
        g_q = self.nbr[g][(tg.index(q))]  # across (p, r)
        self._hint = None
        self.tri[f] = [s, p, r]
        self.nbr[f] = [g_q, g, f_q]
        self.tri[g] = [s, r, q]
        self.nbr[g] = [g_p, f_p, f]
        self._replace_nbr(g_q, g, f)
        self._replace_nbr(f_p, f, g)
        for v, h in ((s, f), (p, f), (r, g), (q, g)):
            self.vface[v] = h
            self._stars.pop(v, None)
        return f, g

    def flip_spoke(self, v: int, a: int) -> tuple[int, int]:
        """Flips the edge ``(v, a)`` of the star of interior vertex ``v``."""
        ring, faces = self.star(v)
        k = ring.index(a)
        f = faces[k]  # (v, a, ring[k+1]): edge (v, a) is opposite ring[k+1]
        return self.flip(f, self._slot_of_edge(f, v, a))

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
        self._hint = None
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
        self._hint = None
        self.xy[v] = p
        self._xyl[v] = [float(p[0]), float(p[1])]

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
        self._hint = None
        self.xy = xy.copy()
        self._xyl = self.xy.tolist()

    # ----------------------------------------------------------- location
    def locate_in(self, points: np.ndarray, faces: list[int]) -> np.ndarray:
        """Which of ``faces`` holds each (symbolically perturbed) point.

        Args:
          points: ``(n, 2)`` query points, all inside the union of ``faces``.
          faces: candidate triangle ids.

        Returns:
          ``(n,)`` int64 triangle ids.

        Raises:
          RuntimeError: a point lies in none of the faces (caller's bug).
        """
        if len(points) == 0:
            return np.zeros(0, np.int64)
        tri = self.xy[np.array([self.tri[f] for f in faces])]  # (F, 3, 2)
        inside = in_triangle_perturbed(tri[None], points[:, None, :])  # (n, F)
        hit = inside.argmax(1)
        if not inside[np.arange(len(points)), hit].all():
            raise RuntimeError("point location failed: a point lies outside the region")
        return np.asarray(faces, np.int64)[hit]

    def locate(self, points: np.ndarray) -> np.ndarray:
        """Triangle holding each perturbed point, over the whole triangulation.

        While the triangles are still Qhull's, its walk gives a guess per
        point that the exact test confirms; points near an edge, where the
        floating-point walk and the perturbed rule may disagree, try the
        guess's three neighbours. Whatever is left (and everything once the
        triangulation has changed) goes through an exact test against every
        triangle in chunks: simple, exact and slow, which is fine because the
        collapse loop never calls it (it relocates locally).

        Args:
          points: ``(n, 2)`` points inside the pinned box.

        Returns:
          ``(n,)`` int64 triangle ids.
        """
        points = np.asarray(points, np.float64).reshape(-1, 2)
        out = np.full(len(points), -1, np.int64)
        if self._hint is not None and len(points):
            dt, centre, scale = self._hint
            guess = np.asarray(dt.find_simplex((points - centre) / scale), np.int64)
            tri = np.asarray(self.tri, np.int64)
            nbr = np.asarray(self.nbr, np.int64)
            todo = np.flatnonzero(guess >= 0)
            for hop in range(4):
                if not len(todo):
                    break
                f = guess[todo] if hop == 0 else nbr[guess[todo], hop - 1]
                ok = f >= 0
                ok[ok] = in_triangle_perturbed(self.xy[tri[f[ok]]], points[todo[ok]])
                out[todo[ok]] = f[ok]
                todo = todo[~ok]
        rest = np.flatnonzero(out < 0)
        if len(rest):
            ids = self.triangle_ids()
            chunk = max(1, 2_000_000 // max(len(ids), 1))
            for s in range(0, len(rest), chunk):
                sel = rest[s:s + chunk]
                out[sel] = self.locate_in(points[sel], ids)
        return out

    # ---------------------------------------------------------- validation
    def check(self) -> None:
        """Raises ``AssertionError`` unless the structure is a valid embedding.

        Checks: every triangle strictly CCW (exact); no directed edge in two
        triangles (no overlap); neighbour links symmetric
        and consistent; every interior edge in two triangles, boundary edges
        only between corners; Euler characteristic of a disk; all live
        vertices referenced and strictly inside the pinned box.
        """
        t = self.triangles()
        xy = self.xy
        assert (orient(xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]) > 0).all(), "non-CCW triangle"
        for f, (tv, nv) in enumerate(zip(self.tri, self.nbr)):
            if tv is None:
                continue
            assert len(set(tv)) == 3, "repeated vertex in triangle"
            for k in range(3):
                g = nv[k]
                u, w = tv[(k + 1) % 3], tv[(k + 2) % 3]
                if g < 0:
                    assert self.pinned[u] and self.pinned[w], "boundary edge not between corners"
                    continue
                assert self.tri[g] is not None, "link to a freed triangle"
                assert f in self.nbr[g], "asymmetric neighbour link"
                assert {u, w} <= set(self.tri[g]), "neighbour does not share the edge"
        directed = t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
        assert len(np.unique(directed, axis=0)) == len(directed), "two triangles overlap (fold-over)"
        e = directed.copy()
        e.sort(axis=1)
        _, count = np.unique(e, axis=0, return_counts=True)
        assert count.max() <= 2, "edge in more than two triangles"
        n_boundary = int((count == 1).sum())
        assert n_boundary == N_CORNERS, f"boundary has {n_boundary} edges"
        used = np.unique(t)
        assert np.array_equal(used, np.nonzero(self.alive)[0]), "live vertex set mismatch"
        assert len(used) - len(count) + len(t) == 1, "Euler characteristic of a disk violated"
        lo, hi = xy[self.pinned].min(0), xy[self.pinned].max(0)
        inner = xy[self.alive & ~self.pinned]
        assert ((inner > lo) & (inner < hi)).all(), "vertex outside the pinned box"
