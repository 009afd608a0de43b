"""Crease vertices moved onto the planes of the points around them (not in the paper).

The transport cost settles a vertex on a crease a little off it: its
facets are fitted to the points by bins, a coarse quadrature, and a
vertex's own bin takes the points nearest to it. :func:`fit_creases` fits
a plane to the points on each side of a crease vertex and moves the vertex
to where those planes meet: onto their line (two planes) or their common
point (three planes, a corner), if each plane has points next to that
target: a crease of the points, not of the complex alone.

Which side a point is on is decided the way k-means decides a cluster:
the planes start as the facets' (facets grouped by normal), each point
joins the nearest, each plane is refitted to its points (least squares),
and points farther from their plane than :data:`TRIM` times its residual
leave it, so points of a third surface nearby (the next face of a box,
the other end of a crease) fall away from the fit. A third plane is
kept only if it is about as thin as the other two: where a facet of the
complex lies across a crease's end, its plane can only gather the points
of other faces, and taken for a corner it would slide the vertex along
the crease. A crease vertex on the open border also slides along its
crease to where the points along it end (a vertex on one sharp edge
only between thin planes): the transport leaves a border vertex short of
the last points, as :mod:`otjax.surfaces.border_fit`
says of flat ones. Every decision is taken on the positions given; the
vertices move together. All lengths are relative to the vertex's own
edges, so scaling, rotating or translating the input moves the result
with it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from otjax.metrics3d import edge_sharpness
from otjax.surfaces.fit_input import (VertexFit, checked, points_noise, unit_normals,
                                      vertex_facets, without_flattening)
from otjax.uniform_ends import uniform_end

#: Dihedral sharpness, in degrees, above which an edge is a crease
#: (docs/decisions.md#feature_fit).
SHARP_ANGLE = 60.0
#: Facets or planes whose normals are within this many degrees are one
#: plane; the fitted planes a vertex moves to are farther apart.
PLANE_ANGLE = 30.0
#: A point joins a plane's first fit within this many times ``r`` (the
#: vertex's median edge length) of it.
NEAR = 0.2
#: A target farther than this many times ``r`` from the nearest point of
#: one of its planes is no crease of the points (docs/decisions.md#feature_fit).
GAP = 0.3
#: Fewest points a plane is fitted to.
MIN_POINTS = 5
#: Points farther from their plane than this many times its root mean
#: square residual leave its fit.
TRIM = 3.0
#: Rounds of assigning points to planes and refitting them.
ROUNDS = 4
#: Of three or more fitted planes, one whose members lie within another's
#: tolerance for more than this share is no plane of its own and drops
#: (docs/decisions.md#feature_fit).
REDUNDANT = 0.5
#: Of three fitted planes, one whose root mean square residual exceeds this
#: many times the least of them (or :data:`FLOOR` ``* r``, if larger) is no
#: plane and drops (docs/decisions.md#feature_fit).
THICK = 3.0
#: The least residual :data:`THICK` compares with, in units of ``r``.
FLOOR = 0.01
#: A crease's end slides along its line to where the points within this
#: many times ``r`` of the line end (docs/decisions.md#feature_fit).
TUBE = 0.1
#: A border vertex on one sharp edge moves only where the root mean square
#: residual of each of its two fitted planes is at most this many times ``r``,
#: or :data:`NOISE_MARGIN` times the points' noise if that is more
#: (docs/decisions.md#feature_fit).
THIN = 0.03
#: Planes as thick as the points' noise (:func:`otjax.background.flat_noise`)
#: times this are thin.
NOISE_MARGIN = 1.5


#: What :func:`fit_creases` returns: the positions after the fit and the rows that moved.
CreaseFit = VertexFit


class _Planes(NamedTuple):
    """Planes ``normal . x = offset``: ``normal (k, 3)`` unit, ``offset (k,)``;
    a point within ``tolerance (k,)`` of its nearest plane belongs to it."""

    normal: np.ndarray
    offset: np.ndarray
    tolerance: np.ndarray


def fit_creases(vertices, triangles, points, sharp_angle: float = SHARP_ANGLE,
                noise: float | None = None) -> CreaseFit:
    """Moves the crease vertices of a complex onto the planes of the points.

    A vertex on at least two edges sharper than ``sharp_angle`` (edges of
    two or more triangles: :func:`otjax.metrics3d.edge_sharpness`) is a
    crease vertex, and so is a vertex of the open border on one (where a
    crease ends), if its two fitted planes are thin (root mean square
    residual at most :data:`THIN` ``* r``, or :data:`NOISE_MARGIN` times
    the points' noise, :func:`~otjax.background.flat_noise`, if that is
    more). Its facets are grouped by
    normal (within :data:`PLANE_ANGLE`, in increasing row order); with
    ``r`` the median length of its edges, the points within ``r`` of it are
    shared among the groups' planes and the planes refitted (module doc;
    planes that come within :data:`PLANE_ANGLE` of one another merge,
    planes with fewer than :data:`MIN_POINTS` points drop, and of three or
    more, one whose points lie within its own tolerance of another plane
    (more than :data:`REDUNDANT` of them) drops, once a round: a facet
    across a crease or across the border; where one did, the two or three
    planes left must be thin as above). With two planes more than
    :data:`PLANE_ANGLE` apart the target is the nearest point of their line
    (for a vertex on the open border, an edge of one triangle, slid along it
    to where the points within :data:`TUBE` ``* r`` of it end, if the vertex
    ends a crease edge along it: :func:`_crease_end`); with three (pairwise
    so), their common point, unless one of them is more than :data:`THICK`
    times as thick (root mean square residual) as the thinnest: then it
    drops and the other two decide (if two are, the vertex stays). The
    vertex moves there if the move is at most ``r / 2`` and every plane has
    a point of its own within :data:`GAP` ``* r`` of the target.
    Moves that would flatten a triangle are undone
    (:func:`~otjax.surfaces.fit_input.without_flattening`).

    Args:
      vertices: ``(V, 3)`` vertex positions.
      triangles: ``(T, 3)`` int rows into ``vertices``.
      points: ``(n, 3)`` the points the complex was reconstructed from.
      sharp_angle: degrees, in ``(0, 90)``.
      noise: the points' standard deviation about their surface, if known
        (else :func:`~otjax.background.flat_noise` of ``points``).

    Returns:
      :class:`CreaseFit`.

    Raises:
      ValueError: arrays of the wrong shape, non-finite values, indices out
        of range, ``sharp_angle`` outside ``(0, 90)``.
    """
    if isinstance(sharp_angle, bool) or not np.isscalar(sharp_angle) or not 0 < float(sharp_angle) < 90:
        raise ValueError(f"sharp_angle must be a number of degrees in (0, 90), got {sharp_angle!r}")
    vertices, triangles, points = checked(vertices, triangles, points)
    out = vertices.copy()
    if not len(triangles) or not len(points):
        return VertexFit(out, np.zeros(0, np.int64))
    sharp = edge_sharpness(vertices, triangles)
    creases = sharp.edges[(sharp.n_triangles > 1) & (sharp.angle > np.radians(sharp_angle))]
    count = np.bincount(creases.ravel(), minlength=len(vertices))
    border = np.zeros(len(vertices), bool)
    border[sharp.edges[sharp.n_triangles == 1].ravel()] = True
    along = [[] for _ in range(len(vertices))]
    for a, b in creases.tolist():
        along[a].append(b)
        along[b].append(a)
    normal = unit_normals(vertices, triangles)
    facets = vertex_facets(triangles)
    tree = cKDTree(points)
    min_cos = np.cos(np.radians(PLANE_ANGLE))
    noise = points_noise(points, noise)
    moved = []
    for v in np.flatnonzero((count >= 2) | ((count == 1) & border)).tolist():
        own = np.array([f for f in facets[v] if np.any(normal[f])], np.int64)
        target = _target(v, own, vertices, triangles, normal, points, tree, min_cos, np.radians(sharp_angle),
                         np.array(along[v], np.int64) if border[v] else None, noise)
        if target is not None:
            out[v] = target
            moved.append(v)
    return without_flattening(vertices, out, triangles, np.asarray(moved, np.int64))


def _target(v, own, vertices, triangles, normal, points, tree, min_cos, sharp,
            end_of: np.ndarray | None, noise: float) -> np.ndarray | None:
    """Where crease vertex ``v`` (facets ``own``) moves, or ``None`` if it
    stays; ``end_of``: where ``v`` is on the open border, its neighbours
    along crease edges (:func:`_crease_end`), else ``None``; ``noise``: the
    points' standard deviation about their surface."""
    ring = np.setdiff1d(triangles[own], [v])
    lengths = np.linalg.norm(vertices[ring] - vertices[v], axis=1)
    if not len(lengths) or not lengths.min() > 0:
        return None
    reach = float(np.median(lengths))
    near = points[tree.query_ball_point(vertices[v], reach)]
    fit = _fitted(_facet_planes(own, vertices, triangles, normal), near, reach)
    if fit is None or len(fit.planes.normal) not in (2, 3):
        return None
    planes = fit.planes
    n, c, tolerance = planes
    if np.any(np.abs(n @ n.T)[np.triu_indices(len(n), 1)] > min_cos):
        return None
    # One sharp edge is weaker evidence of a crease than two, and planes left
    # after pruning may be a bevel: a plane fitted across two faces tilts and
    # moves the vertex far, so both need thin planes.
    if np.any(tolerance / TRIM > max(THIN * reach, NOISE_MARGIN * noise)) and (
            fit.pruned or (end_of is not None and len(end_of) == 1)):
        return None
    if len(n) == 2:  # the nearest point of the line n x = c
        target = vertices[v] - n.T @ np.linalg.solve(n @ n.T, n @ vertices[v] - c)
    else:
        target = np.linalg.solve(n, c)
    if end_of is not None and len(n) == 2:
        centre = vertices[triangles[own]].mean(axis=(0, 1))
        target = _crease_end(target, n, vertices[end_of], centre, near, reach, noise)
    if np.linalg.norm(target - vertices[v]) > reach / 2 or _gap(planes, near, target) > GAP * reach:
        return None
    if _least_sharpness(planes, near, target) <= sharp:
        return None
    return target


def _crease_end(target, normals, neighbours, centre, near, reach, noise: float = 0.0) -> np.ndarray:
    """``target``, on the line of the planes ``normals (2, 3)``, slid along
    it away from ``centre`` (of the vertex's facets) to where the points
    ``near`` within :data:`TUBE` ``* reach`` of the line end
    (:func:`~otjax.uniform_ends.uniform_end`, with the points'
    standard deviation ``noise``): a border vertex
    ending its crease goes where the crease of the points ends.
    Only where its crease neighbours ``(k, 3)`` within :data:`GAP` ``*
    reach`` of the line all lie behind it, and one does: the complex's
    crease runs along this line and ends there. Unchanged too where the
    tube holds fewer than :data:`MIN_POINTS` points or the slide exceeds
    ``reach / 2``."""
    line = np.cross(normals[0], normals[1])
    line /= np.linalg.norm(line)
    if (centre - target) @ line > 0:
        line = -line

    def split(x):  # (along the line, off it) for points x (k, 3)
        d = x - target
        a = d @ line
        return a, np.linalg.norm(d - a[:, None] * line, axis=1)

    a, off = split(neighbours)
    on_line = off <= GAP * reach
    if np.any((a > 0) & on_line) or not np.any((a < 0) & on_line):
        return target
    a, off = split(near)
    tube = off <= TUBE * reach
    if tube.sum() < MIN_POINTS:
        return target
    step = uniform_end(a[tube], noise)
    return target + step * line if abs(step) <= reach / 2 else target


def _facet_planes(own, vertices, triangles, normal) -> _Planes:
    """One plane per group of ``own`` facets with normals within
    :data:`PLANE_ANGLE` (unsigned; the first facet of a group leads it):
    the group's mean normal through its facets' mean corner."""
    group = _groups(normal[own])
    rows, offsets = [], []
    for g in range(group.max() + 1):
        n = normal[own[group == g]]
        n = n * np.where(n @ n[0] < 0, -1.0, 1.0)[:, None]  # facets carry no consistent orientation
        n = n.mean(0) / np.linalg.norm(n.mean(0))
        rows.append(n)
        offsets.append(vertices[triangles[own[group == g]]].mean(axis=(0, 1)) @ n)
    return _Planes(np.array(rows), np.array(offsets), np.full(len(rows), np.inf))


class _Fit(NamedTuple):
    """Planes fitted to the points around a vertex; ``pruned``: whether a
    plane dropped as redundant on the way (:func:`_without_redundant`)."""

    planes: _Planes
    pruned: bool


def _fitted(planes: _Planes, near: np.ndarray, reach: float) -> _Fit | None:
    """``planes`` refitted to the points ``near`` (:data:`ROUNDS` rounds:
    each point joins its nearest plane if within that plane's tolerance,
    first :data:`NEAR` ``* reach``, then :data:`TRIM` residuals), of
    three the ones :data:`THICK` times thicker than the thinnest dropped;
    ``None`` once fewer than two planes have points enough, or are thin.
    Each round, of three or more planes, one whose members are another's
    drops (:func:`_without_redundant`)."""
    planes = planes._replace(tolerance=np.full(len(planes.normal), NEAR * reach))
    pruned = False
    for _ in range(ROUNDS):
        nearest, within = _members(planes, near)
        rows, offsets, spread = [], [], []
        for g in range(len(planes.normal)):
            q = near[(nearest == g) & within]
            if len(q) < MIN_POINTS:
                continue
            centre = q.mean(0)
            n = np.linalg.eigh(np.cov((q - centre).T))[1][:, 0]  # the direction of least spread
            rows.append(n)
            offsets.append(n @ centre)
            spread.append(max(TRIM * np.sqrt(np.mean((q @ n - n @ centre) ** 2)), 1e-6 * reach))
        if len(rows) < 2:
            return None
        first = np.unique(_groups(np.array(rows)), return_index=True)[1]
        fitted = _Planes(np.array(rows)[first], np.array(offsets)[first], np.array(spread)[first])
        planes = _without_redundant(fitted, near)
        pruned |= len(planes.normal) < len(fitted.normal)
    if len(planes.normal) != 3:
        return _Fit(planes, pruned)
    # A corner needs three planes: one much thicker than the thinnest holds
    # the points of other faces that no plane took.
    flat = planes.tolerance <= THICK * max(planes.tolerance.min(), TRIM * FLOOR * reach)
    return _Fit(_Planes(*(x[flat] for x in planes)), pruned) if flat.sum() >= 2 else None


def _without_redundant(planes: _Planes, near: np.ndarray) -> _Planes:
    """``planes`` less the one whose members lie most within its own
    tolerance of another plane, if more than :data:`REDUNDANT` of them do:
    a plane across a crease (the points along it) or across the open
    border (the points along the border) takes points that are other
    planes' own."""
    if len(planes.normal) < 3:
        return planes
    nearest, within = _members(planes, near)
    dist = np.abs(near @ planes.normal.T - planes.offset)  # (n, k)
    share = np.zeros(len(planes.normal))
    for g in range(len(planes.normal)):
        own = within & (nearest == g)
        if own.any():
            share[g] = (np.delete(dist[own], g, axis=1) < planes.tolerance[g]).any(axis=1).mean()
    if share.max() <= REDUNDANT:
        return planes
    keep = np.arange(len(planes.normal)) != share.argmax()
    return _Planes(*(x[keep] for x in planes))


def _members(planes: _Planes, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(nearest (n,), within (n,))``: each point's nearest plane and
    whether it is within that plane's tolerance."""
    dist = np.abs(points @ planes.normal.T - planes.offset)
    nearest = dist.argmin(1)
    return nearest, dist[np.arange(len(points)), nearest] < planes.tolerance[nearest]


def _least_sharpness(planes: _Planes, points: np.ndarray, target: np.ndarray) -> float:
    """The smallest, over pairs of planes, sharpness (radians, ``pi`` less
    the angle between the half planes) of the crease their members make
    at ``target``: each half plane leaves the pair's line towards the
    centre of its members (a curved sheet fitted by two planes opens wide,
    an acute fold narrow)."""
    nearest, within = _members(planes, points)
    least = np.pi
    for i, j in zip(*np.triu_indices(len(planes.normal), 1)):
        line = np.cross(planes.normal[i], planes.normal[j])
        line /= np.linalg.norm(line)
        sides = []
        for g in (i, j):
            w = points[within & (nearest == g)].mean(0) - target
            w -= (w @ line) * line + (w @ planes.normal[g]) * planes.normal[g]
            sides.append(w / max(np.linalg.norm(w), np.finfo(np.float64).tiny))
        least = min(least, np.pi - np.arccos(np.clip(sides[0] @ sides[1], -1.0, 1.0)))
    return float(least)


def _gap(planes: _Planes, points: np.ndarray, target: np.ndarray) -> float:
    """The largest, over the planes, distance from ``target`` to the
    plane's nearest member point: a crease of the points has points of
    each side next to it."""
    nearest, within = _members(planes, points)
    d = np.linalg.norm(points - target, axis=1)
    return max(float(d[within & (nearest == g)].min(initial=np.inf)) for g in range(len(planes.normal)))


def _groups(normals: np.ndarray) -> np.ndarray:
    """``(k,)`` group of each unit normal ``(k, 3)``: each joins the first
    group whose leading normal is within :data:`PLANE_ANGLE` of it
    (unsigned), or leads a new one; groups numbered in order of their leaders."""
    cos = np.cos(np.radians(PLANE_ANGLE))
    leaders: list[np.ndarray] = []
    group = np.empty(len(normals), np.int64)
    for i, n in enumerate(normals):
        hit = [g for g, lead in enumerate(leaders) if abs(n @ lead) >= cos]
        if hit:
            group[i] = hit[0]
        else:
            group[i] = len(leaders)
            leaders.append(n)
    return group

