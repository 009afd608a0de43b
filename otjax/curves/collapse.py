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
    """Exact orientation of the vertices ``a, b, c`` of ``xy`` (a list of ``[x, y]``)."""
    (ax, ay), (bx, by), (cx, cy) = xy[a], xy[b], xy[c]
    return orient_scalar(ax, ay, bx, by, cx, cy)


class _Ring:
    """The one-ring polygon of a collapse being planned, and its tests.

    Planning asks for the side of ``target`` against each polygon edge and
    for each edge's cut several times (once per clip); both depend on the
    edge alone, so they are computed once per edge.
    """

    def __init__(self, tri, source: int, target: int, ring):
        self.xy = tri.xy
        self.xyl = tri.xy_list
        self.source, self.target = source, target
        self.poly = list(ring)
        self._span = None  # |target - source|, read by cut only: most collapses need no flip
        self._side: dict[tuple[int, int], int] = {}
        self._cut: dict[tuple[int, int], float] = {}

    def side(self, a: int, b: int) -> int:
        """Exact orientation of ``(target, a, b)``."""
        hit = self._side.get((a, b))
        if hit is None:
            hit = self._side[(a, b)] = orient_ids(self.xyl, self.target, a, b)
        return hit

    def cut(self, a: int, b: int) -> float:
        """Distance from target to where line ``(a, b)`` crosses source -> target:
        how much removing ``(a, b)`` from the polygon elongates its kernel."""
        hit = self._cut.get((a, b))
        if hit is not None:
            return hit
        if self.side(a, b) > 0:
            self._cut[(a, b)] = 0.0
            return 0.0
        # Python floats: the same double arithmetic as on the array, without
        # NumPy's per-scalar overhead.
        xyl = self.xyl
        (ax, ay), (bx, by) = xyl[a], xyl[b]
        (sx, sy), (tx, ty) = xyl[self.source], xyl[self.target]
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
        poly, xyl = self.poly, self.xyl
        n = len(poly)
        c, a, b = poly[j - 1], poly[j], poly[(j + 1) % n]
        if a == self.target or orient_ids(xyl, c, a, b) <= 0:
            return False
        if with_source:
            return orient_ids(xyl, self.source, c, b) > 0
        # Scalar predicates with early exit: rings are short, and NumPy's
        # per-call overhead made this the hottest line on collinear data.
        for x in poly:
            if x in (c, a, b):
                continue
            if orient_ids(xyl, c, a, x) >= 0 and orient_ids(xyl, a, b, x) >= 0 and orient_ids(xyl, b, c, x) >= 0:
                return False
        return True

    def blocking(self) -> list[tuple[float, int]]:
        """``(cut, k)`` of the polygon edges ``k`` that block the target,
        by decreasing cut."""
        poly, target = self.poly, self.target
        # The caches read inline: blocking runs once per clip over every edge.
        sides, cuts = self._side, self._cut
        out = []
        for k, (a, b) in enumerate(zip(poly, poly[1:] + poly[:1])):
            if a == target or b == target:
                continue
            side = sides.get((a, b))
            if side is None:
                side = self.side(a, b)
            if side <= 0:
                cut = cuts.get((a, b))
                out.append((self.cut(a, b) if cut is None else cut, k))
        out.sort(key=lambda t: (-t[0], t[1]))
        return out

    def next_clip(self) -> int | None:
        """The polygon vertex to take out next, or ``None`` once nothing blocks.

        By decreasing cut, the first blocking edge with an endpoint the
        paper's flip can take out (the one leaving the smaller cut); else one
        an ear clip can; else any ear.
        """
        blocking = self.blocking()
        if not blocking:
            return None
        poly, n = self.poly, len(self.poly)
        for with_source in (True, False):
            for _, k in blocking:
                options = [(self.cut(poly[j - 1], poly[(j + 1) % n]), j)
                           for j in (k, (k + 1) % n) if self.is_ear(j, with_source)]
                if options:
                    return min(options)[1]
        return next(j for j in range(n) if self.is_ear(j, False))


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
    out = []
    for target in targets:
        if pinned[target] or target not in ring:
            out.append(None)
            continue
        fan = _visible_fan(xyl[target], target, edges)
        if fan is not None:
            out.append(Flips(ring, star, (), (), ring, fan))
        else:
            out.append(_clipped_flips(tri, source, target, ring, star))
    return out


def _clipped_flips(tri, source: int, target: int, ring, star) -> Flips:
    """The flips of :func:`plan_collapse` when some ring edge may block ``target``."""
    polygon = _Ring(tri, source, target, ring)
    poly = polygon.poly
    clipped: list[int] = []
    flipped_out: list[tuple[int, int, int]] = []
    while (chosen := polygon.next_clip()) is not None:
        n = len(poly)
        a = poly[chosen]
        flipped_out.append((poly[chosen - 1], a, poly[(chosen + 1) % n]))
        clipped.append(a)
        del poly[chosen]
    return Flips(tuple(ring), tuple(star), tuple(clipped), tuple(flipped_out), tuple(poly), _fan(target, poly))


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
