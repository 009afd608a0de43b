"""Planning a half-edge collapse: the flip procedure that makes it possible.

A :class:`CollapsePlan` says what collapsing ``source`` onto ``target`` does
before doing it; a :class:`MovePlan` says the same of a vertex move. The
plans are pure data (tuples of ids): the triangulation applies them.
:func:`plan_collapse` implements de Goes et al. 2011, §3.2 "Systematically
collapsing edges", made total (see its docstring).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.predicates import ORIENT_ERR, orient_scalar


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


def orient_ids(xy: list, a: int, b: int, c: int) -> int:
    """Exact orientation of the vertices ``a, b, c`` of ``xy`` (a list of ``[x, y]``).

    :func:`~otjax.predicates.orient_scalar` with its float filter inline
    (the same arithmetic, the same answer): planning asks it ~10^6 times
    a run and most answers are certain, so the exact predicate is called
    only when unsure.
    """
    (ax, ay), (bx, by), (cx, cy) = xy[a], xy[b], xy[c]
    left = (bx - ax) * (cy - ay)
    right = (by - ay) * (cx - ax)
    det = left - right
    bound = ORIENT_ERR * (abs(left) + abs(right))
    if det > bound:
        return 1
    if -det > bound:
        return -1
    return orient_scalar(ax, ay, bx, by, cx, cy)


class _Corners:
    """Ear tests of the corners ``(c, a, b)`` of polygons cut from the ring of
    ``source``, shared by the targets planned together.

    Both tests depend on the ring's positions alone; the polygons of the
    targets share most corners (every target starts from the ring), so each
    corner is tested once per source.
    """

    def __init__(self, xyl: list, source: int, ring):
        self.xyl, self.source, self.ring = xyl, source, ring
        self._flip: dict[tuple[int, int, int], bool] = {}
        self._inside: dict[tuple[int, int, int], tuple | None] = {}

    def flips(self, c: int, a: int, b: int) -> bool:
        """Whether the paper's flip may take ``a`` out: corner ``(c, a, b)``
        convex and quadrilateral ``(source, c, a, b)`` convex."""
        key = (c, a, b)
        hit = self._flip.get(key)
        if hit is None:
            xyl = self.xyl
            hit = self._flip[key] = orient_ids(xyl, c, a, b) > 0 and orient_ids(xyl, self.source, c, b) > 0
        return hit

    def clips(self, c: int, a: int, b: int, poly: list) -> bool:
        """Whether ``(c, a, b)`` is an ear of ``poly`` (a subsequence of the
        ring): a convex corner with no other vertex of ``poly`` in the
        closed triangle."""
        key = (c, a, b)
        inside = self._inside.get(key, False)
        if inside is False:
            inside = self._inside[key] = self._in_triangle(c, a, b)
        if inside is None:
            return False
        for x in inside:
            if x in poly:
                return False
        return True

    def _in_triangle(self, c: int, a: int, b: int) -> tuple | None:
        """The ring vertices other than ``c, a, b`` in the closed triangle
        ``(c, a, b)``, or ``None`` if the corner is not convex."""
        xyl = self.xyl
        if orient_ids(xyl, c, a, b) <= 0:
            return None
        return tuple(x for x in self.ring if x != c and x != a and x != b and orient_ids(xyl, c, a, x) >= 0
                     and orient_ids(xyl, a, b, x) >= 0 and orient_ids(xyl, b, c, x) >= 0)


class _Ring:
    """The one-ring polygon of a collapse being planned, and its tests.

    ``cuts[k]`` is the cut of polygon edge ``k`` (``(poly[k], poly[k+1])``)
    when it blocks ``target``, else ``None``; a clip replaces the two edges
    at the clipped vertex by one, so only that edge is tested again.
    """

    def __init__(self, corners: _Corners, target: int):
        self.corners, self.xyl, self.target = corners, corners.xyl, target
        self.poly = list(corners.ring)
        self._span = None  # |target - source|, read by the cuts only
        self._cut: dict[tuple[int, int], float] = {}
        poly = self.poly
        self.cuts = [self._blocking_cut(a, b) for a, b in zip(poly, poly[1:] + poly[:1])]

    def _blocking_cut(self, a: int, b: int) -> float | None:
        """The cut of edge ``(a, b)`` if it blocks ``target`` (away from it,
        ``(target, a, b)`` not CCW), else ``None``."""
        target = self.target
        if a == target or b == target or orient_ids(self.xyl, target, a, b) > 0:
            return None
        return self._crossing(a, b)

    def cut(self, a: int, b: int) -> float:
        """Distance from target to where line ``(a, b)`` crosses source -> target:
        how much removing ``(a, b)`` from the polygon elongates its kernel
        (``0`` when ``(target, a, b)`` is CCW)."""
        hit = self._cut.get((a, b))
        if hit is not None:
            return hit
        if orient_ids(self.xyl, self.target, a, b) > 0:
            self._cut[(a, b)] = 0.0
            return 0.0
        return self._crossing(a, b)

    def _crossing(self, a: int, b: int) -> float:
        """:meth:`cut` of an edge ``(a, b)`` known not CCW from ``target``."""
        hit = self._cut.get((a, b))
        if hit is not None:
            return hit
        # Python floats: the same double arithmetic as on the array, without
        # NumPy's per-scalar overhead.
        xyl = self.xyl
        (ax, ay), (bx, by) = xyl[a], xyl[b]
        (sx, sy), (tx, ty) = xyl[self.corners.source], xyl[self.target]
        ex, ey = bx - ax, by - ay
        da = ex * (sy - ay) - ey * (sx - ax)
        db = ex * (ty - ay) - ey * (tx - ax)
        s = da / (da - db) if da != db else 1.0
        if self._span is None:
            self._span = float(np.hypot(tx - sx, ty - sy))
        out = self._cut[(a, b)] = (1.0 - min(max(s, 0.0), 1.0)) * self._span
        return out

    def is_ear(self, j: int, with_source: bool) -> bool:
        """Whether polygon vertex ``j`` may leave the polygon: by the paper's
        flip (``with_source``: quadrilateral ``(source, c, a, b)`` convex) or
        as an ear (convex corner, no other polygon vertex in the triangle)."""
        poly = self.poly
        c, a, b = poly[j - 1], poly[j], poly[(j + 1) % len(poly)]
        if a == self.target:
            return False
        return self.corners.flips(c, a, b) if with_source else self.corners.clips(c, a, b, poly)

    def next_clip(self) -> int | None:
        """The polygon vertex to take out next, or ``None`` once nothing blocks.

        By decreasing cut (then polygon order), the first blocking edge with
        an endpoint the paper's flip can take out (the one leaving the
        smaller cut); else one an ear clip can; else any ear.
        """
        blocking = sorted([(-cut, k) for k, cut in enumerate(self.cuts) if cut is not None])
        if not blocking:
            return None
        poly, n, target, corners = self.poly, len(self.poly), self.target, self.corners
        for with_source in (True, False):
            for _, k in blocking:
                best = None
                for j in (k, (k + 1) % n):
                    # is_ear, inline: this loop runs once per clip and target.
                    c, a, b = poly[j - 1], poly[j], poly[(j + 1) % n]
                    if a != target and (corners.flips(c, a, b) if with_source else corners.clips(c, a, b, poly)):
                        option = (self.cut(c, b), j)
                        if best is None or option < best:
                            best = option
                if best is not None:
                    return best[1]
        return next(j for j in range(n) if self.is_ear(j, False))

    def clip(self, j: int) -> tuple[int, int, int]:
        """Takes polygon vertex ``j`` out; returns its ear ``(c, a, b)``."""
        poly, cuts = self.poly, self.cuts
        c, a, b = poly[j - 1], poly[j], poly[(j + 1) % len(poly)]
        del poly[j]
        del cuts[j]
        # Edges j - 1 and j became one, now at j - 1 (the last when j was 0).
        cuts[j - 1] = self._blocking_cut(c, b)
        return (c, a, b)


class Flips(NamedTuple):
    """The flip part of a collapse plan: what depends on the star of the
    source alone (its ring's positions included), not on the target's.

    Attributes:
      ring, star: as in :class:`CollapsePlan`.
      clipped, flipped_out, fan: as in :class:`CollapsePlan`.
      polygon: the one-ring polygon left once the flips are made (CCW).
    """

    ring: tuple[int, ...]
    star: tuple[int, ...]
    clipped: tuple[int, ...]
    flipped_out: tuple[tuple[int, int, int], ...]
    polygon: tuple[int, ...]
    fan: tuple[tuple[int, int, int], ...]


def plan_collapse(tri, source: int, target: int) -> CollapsePlan | None:
    """How to collapse ``source`` onto ``target`` of ``tri`` without a fold-over.

    While some edge ``(a, b)`` of the one-ring polygon of ``source`` blocks
    ``target`` (triangle ``(target, a, b)`` not CCW), take the blocking edges
    by decreasing cut ``D`` (how far from ``target`` their supporting line
    crosses ``source -> target``) and flip away the spoke of one endpoint,
    preferring the flip that leaves the smaller cut. A flip of spoke
    ``(source, a)`` pushes the ear ``(c, a, b)`` out of the star and removes
    ``a`` from the polygon.

    The paper states that the top blocking edge always has a flippable spoke;
    near-collinear rings disprove it (a flip is only legal when the
    quadrilateral around the spoke is convex, which involves ``source``).
    Since ``source`` disappears anyway, otjax then clips any valid ear of the
    polygon (convex corner, no other polygon vertex in the closed triangle).
    A simple polygon with four or more vertices always has two ears with
    distinct tips, so one is not ``target``; every step removes a vertex; a
    triangle never blocks. The procedure therefore always terminates with a
    collapsible half-edge, in at most ``deg - 3`` steps.

    Args:
      tri: the :class:`~otjax.curves.triangulation.Triangulation` (read only).
      source, target: vertex ids.

    Returns:
      The plan, or ``None`` if an end is pinned, the vertices are not
      adjacent, or the link condition fails after the flips.
    """
    flips = plan_flips(tri, source, target)
    return None if flips is None else plan_from_flips(tri, source, target, flips)


def plan_flips(tri, source: int, target: int) -> Flips | None:
    """The flips of :func:`plan_collapse`, before its link condition.

    They depend on the star of ``source`` and the positions of its ring
    only, so a cache may keep them while the target's star changes
    (:func:`plan_from_flips` then checks the link condition again).

    Returns:
      The :class:`Flips`, or ``None`` if an end is pinned or the vertices
      are not adjacent.
    """
    return plan_flips_from(tri, source, (target,))[0]


def plan_flips_from(tri, source: int, targets) -> list[Flips | None]:
    """:func:`plan_flips` of ``(source, t)`` for each of ``targets``.

    The half-edges leaving a vertex are planned together: its star and the
    coordinates of its ring edges are read once for all of them.
    """
    xyl, pinned = tri.xy_list, tri.pinned
    if pinned[source] or all(pinned[t] for t in targets):
        return [None] * len(targets)
    ring, star = tri.star(source)
    edges = [(a, b, *xyl[a], *xyl[b]) for a, b in zip(ring, ring[1:] + ring[:1])]
    corners = None  # made at the first target that needs flips
    out = []
    for target in targets:
        if pinned[target] or target not in ring:
            out.append(None)
            continue
        fan = _visible_fan(xyl[target], target, edges)
        if fan is not None:
            out.append(Flips(ring, star, (), (), ring, fan))
            continue
        if corners is None:
            corners = _Corners(xyl, source, ring)
        out.append(_clipped_flips(corners, target, star))
    return out


def _clipped_flips(corners: _Corners, target: int, star) -> Flips:
    """The flips of :func:`plan_collapse` when some ring edge may block ``target``."""
    polygon = _Ring(corners, target)
    clipped: list[int] = []
    flipped_out: list[tuple[int, int, int]] = []
    while (chosen := polygon.next_clip()) is not None:
        ear = polygon.clip(chosen)
        flipped_out.append(ear)
        clipped.append(ear[1])
    poly = polygon.poly
    return Flips(tuple(corners.ring), tuple(star), tuple(clipped), tuple(flipped_out), tuple(poly), _fan(target, poly))


def _fan(target: int, poly) -> tuple[tuple[int, int, int], ...]:
    """The triangles ``(target, u, w)`` over the polygon edges away from ``target``."""
    n = len(poly)
    return tuple((target, poly[k], poly[(k + 1) % n]) for k in range(n) if target not in (poly[k], poly[(k + 1) % n]))


def _visible_fan(target_xy, target: int, edges) -> tuple[tuple[int, int, int], ...] | None:
    """:func:`_fan` of the ring, when every ring edge away from ``target``
    is certainly CCW seen from it (the float filter of
    :func:`~otjax.predicates.orient_scalar`); ``None`` when unsure (the full
    planning decides). Most collapses need no flip: this answers them
    without the planning machinery.

    Args:
      target_xy: ``[x, y]`` of ``target``.
      edges: ``(a, b, ax, ay, bx, by)`` of each ring edge, in ring order.
    """
    tx, ty = target_xy
    fan = []
    for a, b, ax, ay, bx, by in edges:
        if a == target or b == target:
            continue
        left = (ax - tx) * (by - ty)
        right = (ay - ty) * (bx - tx)
        det = left - right
        if not det > ORIENT_ERR * (abs(left) + abs(right)):
            return None
        fan.append((target, a, b))
    return tuple(fan)


def plan_from_flips(tri, source: int, target: int, flips: Flips) -> CollapsePlan | None:
    """The :class:`CollapsePlan` of ``flips`` (from :func:`plan_flips` of
    the same half-edge, its source's star unchanged since), or ``None`` if
    the link condition fails after the flips."""
    if not link_condition(tri, target, flips):
        return None
    return CollapsePlan(source, target, flips.ring, flips.star, flips.clipped, flips.flipped_out, flips.fan)


def link_condition(tri, target: int, flips: Flips) -> bool:
    """The link condition of the collapse of ``flips`` onto ``target``, at
    the current star of ``target``."""
    return _link_after_flips(tri, target, flips.polygon, flips.flipped_out)


def _link_after_flips(tri, target: int, poly, flipped_out) -> bool:
    """The link condition of ``(source, target)`` once the flips are made."""
    nb = tri.interior_neighbors(target)
    for c, _, b in flipped_out:  # the new diagonal (c, b)
        if c == target:
            nb.add(b)
        elif b == target:
            nb.add(c)
    k = poly.index(target)
    return nb.intersection(poly) == {poly[k - 1], poly[(k + 1) % len(poly)]}
