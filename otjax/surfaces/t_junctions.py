"""T-junctions left by the decimation, and closing them; slivers, and removing them.

Half-edge collapses on a non-manifold complex can leave two sheets that
meet along a line without sharing its edges: one ends on an edge ``(a, b)``,
the other on two edges ``(a, v)`` and ``(v, b)`` with ``v`` on the segment
``ab``. No edge then carries both sheets, so the line is a crack rather
than a crease, however close the vertices lie to it. Closing a T-junction
splits every facet ``(a, b, c)`` of that edge at ``v`` into ``(a, v, c)`` and
``(v, b, c)`` (:meth:`~otjax.surfaces.complex.SimplicialComplex.split_edge`):
where ``v`` is on the segment, the surface is the same and the sheets share
the edges ``(a, v)`` and ``(v, b)``. A split that would make a sliver is
not made (:func:`is_t_junction`; docs/decisions.md#t_junctions).

A facet whose three corners lie on one line, as a fit that moves
vertices onto a crease can leave, is removed the same way: its long edge
is split at its middle corner (:func:`split_slivers`).

The transport plan follows: a split facet's mass goes to the half its bin
lies in, spread over that half's bins by capacity, which keeps the plan
feasible; the mass of a dropped sliver ``(a, v, b)`` goes to the nearest of
its vertices. The caller re-bins and relaxes the plan afterwards.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.surfaces.complex import SimplicialComplex, Triangle
from otjax.surfaces.plan import Entries, SurfacePlan

#: ``v`` lies on ``ab`` when the angle ``a v b`` is at least 180 degrees minus this.
T_JUNCTION_ANGLE = 5.0
#: Rounds of :func:`close_t_junctions` at most: a split adds edges, which in
#: a complex that is not embedded can make new T-junctions, even cycles.
MAX_ROUNDS = 8


class TJunction(NamedTuple):
    """A vertex ``v`` joined to both ends of the edge ``(a, b)``, lying on it,
    and not a corner of every facet of that edge."""

    a: int
    b: int
    v: int


def find_t_junctions(complex_: SimplicialComplex, angle: float = T_JUNCTION_ANGLE) -> list[TJunction]:
    """The T-junctions of ``complex_``, one per edge (the ``v`` of the widest
    angle ``a v b``, ties by id), in edge order. ``angle`` in degrees."""
    x = complex_.positions
    found = []
    for (a, b), facets in sorted(complex_.edges.items()):
        common = set(complex_.neighbors(a)) & set(complex_.neighbors(b))
        open_ = sorted(v for v in common if any(v not in t for t in facets))
        if open_:
            j = TJunction(a, b, min(open_, key=lambda v: _cosine(x, a, v, b)))  # the widest angle, ties by id
            if is_t_junction(complex_, j, angle):
                found.append(j)
    return found


def is_t_junction(complex_: SimplicialComplex, j: TJunction, angle: float = T_JUNCTION_ANGLE) -> bool:
    """Whether ``v`` is joined to both ends of the edge ``(a, b)``, is not a
    corner of one of its facets at least, sees ``ab`` under an angle of at
    least ``180 - angle`` degrees, and splitting there makes no sliver (a
    half with such an angle itself, as when the facet's third corner is on
    the line too): those stay, since splitting them could undo another split."""
    c = complex_
    if not (c.has_edge(j.a, j.b) and c.has_edge(j.a, j.v) and c.has_edge(j.v, j.b)):
        return False
    facets = [t for t in c.edge_triangles(j.a, j.b) if j.v not in t]
    if not facets or not _flat(c.positions, j.a, j.v, j.b, angle):
        return False
    return not _halves_flat(c.positions, j, facets, angle)


def _halves_flat(x: np.ndarray, j: TJunction, facets, angle: float) -> bool:
    """Whether splitting one of ``facets`` (on the edge ``(a, b)``, without
    ``v``) at ``v`` makes a half flat at one of its corners."""
    for t in facets:
        (o,) = set(t) - {j.a, j.b}
        for half in ((j.a, j.v, o), (j.v, j.b, o)):
            if any(_flat(x, half[k - 1], half[k], half[(k + 1) % 3], angle) for k in range(3)):
                return True
    return False


def _cosine(x: np.ndarray, a: int, v: int, b: int) -> float:
    """Cosine of the angle ``a v b`` (-1 where it is undefined: a zero-length side)."""
    u, w = x[a] - x[v], x[b] - x[v]
    norms = float(np.linalg.norm(u) * np.linalg.norm(w))
    return float(u @ w) / norms if norms > 0 else -1.0


def _flat(x: np.ndarray, a: int, v: int, b: int, angle: float) -> bool:
    """Whether the angle ``a v b`` is at least ``180 - angle`` degrees (or undefined)."""
    return _cosine(x, a, v, b) <= -np.cos(np.radians(angle))


def close_t_junctions(plan: SurfacePlan, angle: float = T_JUNCTION_ANGLE) -> int:
    """Closes the T-junctions of ``plan.complex`` in place (module doc),
    moving the plan's entries with the facets, in rounds (each closes those
    found at its start) until none is left or after :data:`MAX_ROUNDS`;
    returns how many edges were split."""
    splits = 0
    for _ in range(MAX_ROUNDS):
        todo = find_t_junctions(plan.complex, angle)
        if not todo:
            break
        for j in todo:
            if is_t_junction(plan.complex, j, angle):  # an earlier split of the round may have undone it
                _split(plan, j)
                splits += 1
    return splits


def split_slivers(plan: SurfacePlan, angle: float = T_JUNCTION_ANGLE) -> int:
    """Removes the slivers of ``plan.complex`` in place: a facet with a
    corner ``v`` that sees the opposite edge ``(a, b)`` under at least ``180
    - angle`` degrees (its widest) lies on that edge, as when a fit has put
    its three corners on one crease line. Splitting ``(a, b)`` at ``v``
    drops it and splits every other facet of that edge in two, as a
    T-junction is closed; the plan's entries follow (module doc). A sliver
    stays where a half would be a sliver again (another facet of ``(a, b)``
    has its third corner on that line too: four corners on one line, which
    splitting would only shuffle). Returns how many edges were split."""
    total = 0
    while True:  # each split removes a sliver and makes none, so this ends
        splits = 0
        for j in _slivers(plan.complex, angle):
            if _splittable(plan.complex, j, angle):  # an earlier split may have removed it
                _split(plan, j)
                splits += 1
        if not splits:
            return total
        total += splits


def _splittable(complex_: SimplicialComplex, j: TJunction, angle: float) -> bool:
    """Whether ``(a, v, b)`` is still a sliver of ``complex_`` whose split at
    ``v`` leaves no half flat at a corner."""
    c = complex_
    if not (c.has_edge(j.a, j.b) and c.has_edge(j.a, j.v) and c.has_edge(j.v, j.b)
            and _flat(c.positions, j.a, j.v, j.b, angle)):
        return False
    return not _halves_flat(c.positions, j, [t for t in c.edge_triangles(j.a, j.b) if j.v not in t], angle)


def _slivers(complex_: SimplicialComplex, angle: float) -> list[TJunction]:
    """One :class:`TJunction` ``(a, b, v)`` per facet flat at its widest corner ``v``, in facet order."""
    x = complex_.positions
    found = []
    flat = -np.cos(np.radians(angle))  # the cosine bound of _flat
    for t in sorted(complex_.triangles):
        cosines = [_cosine(x, t[i - 1], t[i], t[(i + 1) % 3]) for i in range(3)]
        k = int(np.argmin(cosines))  # the widest corner (the first of equals)
        if cosines[k] <= flat:
            found.append(TJunction(t[k - 1], t[(k + 1) % 3], t[k]))
    return found


def _split(plan: SurfacePlan, j: TJunction) -> None:
    """Splits ``(a, b)`` at ``v`` and hands each removed facet's entries on."""
    x = plan.complex.positions
    old_bins = {t: plan.bins.pop(t) for t in plan.complex.edge_triangles(j.a, j.b)}
    change = plan.complex.split_edge(j.a, j.b, j.v)
    plan.ensure_bins(change.added_triangles)
    ab = x[j.b] - x[j.a]
    # Where v falls along ab; where a and b coincide (and v with them) any
    # fraction names the same place.
    at = float((x[j.v] - x[j.a]) @ ab / (ab @ ab)) if ab @ ab > 0 else 0.5
    for t in change.removed_triangles:
        e = plan.facet_entries.pop(t, None)
        if e is None:
            continue
        lam = old_bins[t].barycentric[e.bin]  # weights of t's corners, in key order
        (c,) = set(t) - {j.a, j.b}
        if c == j.v:  # the sliver (a, v, b)
            to_nearest_corners(plan, t, e, lam)
            continue
        wa, wb = lam[:, t.index(j.a)], lam[:, t.index(j.b)]
        low = wb < at * (wa + wb)  # on a's side of the segment (v, c)
        for half, pick in (((j.a, j.v, c), low), ((j.v, j.b, c), ~low)):
            key = tuple(sorted(half))
            cap = plan.bins[key].capacity
            k = len(cap)
            _add(plan.facet_entries, key, np.repeat(e.point[pick], k), np.tile(np.arange(k), int(pick.sum())),
                 np.outer(e.mass[pick], cap).ravel())


def remove_facets(plan: SurfacePlan, facets) -> int:
    """Removes ``facets`` from ``plan.complex`` (their edges no other facet
    has go too), each one's entries handed to its corners
    (:func:`to_nearest_corners`); returns how many. The caller relaxes the
    plan afterwards."""
    facets = list(facets)
    for t in facets:
        bins = plan.bins[t]
        entries = plan.drop_facet(t)
        plan.complex.remove_triangle(t)
        if entries is not None and len(entries.point):
            to_nearest_corners(plan, t, entries, bins.barycentric[entries.bin])
    return len(facets)


def to_nearest_corners(plan: SurfacePlan, t: Triangle, entries: Entries, lam: np.ndarray) -> None:
    """Hands the ``entries`` of a removed facet ``t`` to the vertex bins of its
    corners, each to the corner nearest its bin (``lam``: the bins' weights
    of ``t``'s corners, in key order)."""
    x = plan.complex.positions[list(t)]
    corner = np.asarray(t)[np.argmin((((lam @ x)[:, None] - x[None]) ** 2).sum(-1), axis=1)]
    for v in np.unique(corner).tolist():
        pick = corner == v
        _add(plan.vertex_entries, v, entries.point[pick], np.zeros(int(pick.sum()), np.int64),
             entries.mass[pick])


def _add(entries: dict, key, point: np.ndarray, bin_: np.ndarray, mass: np.ndarray) -> None:
    """Adds entries to ``entries[key]``, summing the mass of repeated (point, bin) pairs."""
    if not len(point):
        return
    old = entries.get(key)
    if old is not None:
        point, bin_, mass = (np.concatenate([o, n]) for o, n in zip(old, (point, bin_, mass)))
    pairs, inverse = np.unique(np.stack([point, bin_], axis=1), axis=0, return_inverse=True)
    entries[key] = Entries(pairs[:, 0].copy(), pairs[:, 1].copy(), np.bincount(inverse.ravel(), mass))
