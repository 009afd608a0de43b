"""Uniform background noise in a point set: its density and each point's share.

The model: the points are a mixture of a shape (curve or surface, dense near
itself) and uniform background noise over the bounding box, of density
``beta`` (points per unit area or volume). A k-nearest-neighbour estimate
gives the local density ``rho_i`` at each point; under the mixture the
probability that point ``i`` is background is ``min(1, beta / rho_i)``.

``beta`` is found from the points alone: starting from the density of a
box filled uniformly, it is repeatedly replaced by the median density of
the points below twice it, which settles on the lowest dense level of
the data. That level is background only if it explains about as many
points as it predicts where it is the density seen: random probes spread
uniformly over the box, their k-nearest-neighbour density taken among the
points, measure the share of the box where a probe would read below the
same cut, and background of density ``beta`` puts ``beta * volume * share``
points there (near a shape that fills its box, an outlier's neighbours are
the shape's points, so it reads denser: counting against the whole box
missed such backgrounds). The points must also fill space: the number of
neighbours within ``r`` of them grows as ``r^d`` (``d`` the dimension;
``r^(d-1)`` on a curve or surface). A sparse shape without outliers fails
one test or the other, gets ``beta = 0``, and every point keeps its full
mass (docs/decisions.md#background).

An outlier near the shape reads dense; :func:`near_shape` finds the points
that stand off the flat through their neighbours (surfaces leave them out).

NumPy and scipy only: the same estimate serves curves and surfaces.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

NEIGHBOURS = 16
LEVEL_FACTOR = 2.0
CONSISTENCY = 0.5
DIMENSION_MARGIN = 0.5
SHAPE_SIGMAS = 2.0
#: Fewer points than this many times ``k`` give no background: the k-NN
#: balls then span much of any shape, which reads as a uniform level.
MIN_POINTS_PER_NEIGHBOUR = 20
#: Probes per point for the share of the box where the density reads as background.
PROBES = 2
#: A point farther than this many residual scales from the flat through its
#: neighbours is off the shape (:func:`near_shape`).
FLAT_SIGMAS = 5.0
#: A point off the flat through its neighbours is still on the shape when it
#: lies on this many of its neighbours' thin flats: those whose residuals are
#: within ``THIN`` median scales (:func:`near_shape`, docs/decisions.md#background).
SUPPORTING_FLATS = 2
THIN = 2.0
#: A point whose shape weight is below ``DOUBT`` (the density leaves it a
#: fair chance of being background) passes the own-flat test only where its
#: neighbourhood is at most ``WIDER`` times as thick as its neighbours' own
#: (median of their scales): one off the shape reaches for a wide patch
#: (:func:`near_shape`, docs/decisions.md#background).
DOUBT = 0.9
WIDER = 2.0
#: Neighbours of the flats :func:`flat_noise` measures the noise about:
#: fewer follow the noise (docs/decisions.md#feature_fit).
NOISE_NEIGHBOURS = 32
#: A point's normal is reliable where its neighbours' median distance to their flat is at most this
#: many times the median of that over all points (:func:`point_normals`; docs/decisions.md#transverse) ...
RELIABLE = 2.0
#: ... plus this many times the points' median distance to their neighbours.
RELIABLE_FLOOR = 0.02
# Median absolute residual to standard deviation, for Gaussian residuals.
_MAD_TO_SIGMA = 1.4826


class Background(NamedTuple):
    """The background estimate of a point set.

    Attributes:
      density: ``beta``, background points per unit area (volume in 3D), in
        the units of the input; ``0`` when no background was found.
      fraction: ``beta * volume / n``, the estimated share of background points.
      probability: ``(n,)`` each point's probability of being background,
        ``min(1, beta / rho_i)`` (all zeros when ``density == 0``).
      local_density: ``(n,)`` the k-nearest-neighbour density ``rho_i``.
    """

    density: float
    fraction: float
    probability: np.ndarray
    local_density: np.ndarray

    @property
    def found(self) -> bool:
        return self.density > 0


def estimate_background(points: np.ndarray, neighbours: int = NEIGHBOURS) -> Background:
    """Estimates uniform background noise in ``points (n, d)`` (see the module doc).

    Args:
      points: ``(n, d)`` validated float64 points, ``d`` in 2 or 3, distinct.
      neighbours: ``k`` of the k-nearest-neighbour density.

    Returns:
      A :class:`Background`. Fewer than ``20 k`` points
      (:data:`MIN_POINTS_PER_NEIGHBOUR`), or a flat bounding box, give no background.
    """
    points = np.asarray(points, np.float64)
    n, dim = points.shape
    none = Background(0.0, 0.0, np.zeros(n), np.zeros(n))
    extent = points.max(0) - points.min(0) if n else np.zeros(dim)
    volume = float(np.prod(extent))
    if n < MIN_POINTS_PER_NEIGHBOUR * neighbours or not volume > 0:
        return none
    # Work in the frame of the box (unit diagonal), so that the result does not depend on units.
    scale = float(np.linalg.norm(extent))
    unit = (points - points.min(0)) / scale
    far = min(n - 1, 4 * neighbours)
    dist, _ = cKDTree(unit).query(unit, [neighbours + 1, far + 1])
    radius = dist[:, 0]
    ball = math.pi ** (dim / 2) / math.gamma(dim / 2 + 1)
    with np.errstate(divide="ignore"):
        rho = neighbours / (ball * radius**dim)
    unit_volume = volume / scale**dim
    beta = n / unit_volume
    for _ in range(100):
        below = rho < LEVEL_FACTOR * beta
        if not below.any():
            return none._replace(local_density=rho / scale**dim)
        level = float(np.median(rho[below]))
        if abs(level - beta) <= 1e-12 * beta:
            break
        beta = level
    below = rho < LEVEL_FACTOR * beta
    # A fixed seed: the probes are part of the estimator, not a random draw of the caller's.
    probes = np.random.default_rng(0).uniform(0.0, extent / scale, (PROBES * n, dim))
    probe_radius = cKDTree(unit).query(probes, [neighbours])[0][:, 0]
    with np.errstate(divide="ignore"):
        share = float(np.mean(neighbours / (ball * probe_radius**dim) < LEVEL_FACTOR * beta))
    # Background fills the box: around its points the neighbour count grows
    # as r^d. Points of a sparse shape grow as r^(d-1) and do not count.
    with np.errstate(divide="ignore", invalid="ignore"):
        growth = np.log(far / neighbours) / np.log(dist[below, 1] / radius[below])
    if (np.count_nonzero(below) < CONSISTENCY * beta * unit_volume * share
            or not np.median(growth) > dim - DIMENSION_MARGIN):
        return none._replace(local_density=rho / scale**dim)
    probability = np.minimum(1.0, beta / rho)
    return Background(beta / scale**dim, float(beta * unit_volume / n), probability, rho / scale**dim)


def shape_weights(background: Background, neighbours: int = NEIGHBOURS, sigmas: float = SHAPE_SIGMAS) -> np.ndarray:
    """The share of each point's mass that a reconstruction should transport.

    ``1 - min(1, c beta / rho_i)`` with ``c = 1 + sigmas / sqrt(k)``: the
    shape's share of the local density, counting only what stands
    ``sigmas`` standard errors of the k-nearest-neighbour estimate above
    the background level. With ``c = 1`` a background point whose estimate
    came out high by chance (a quarter of them are 25% high at ``k = 16``)
    would keep a fifth of its mass, enough in sum to pull vertices off the
    shape (docs/decisions.md#background).

    Returns:
      ``(n,)`` weights in ``[0, 1]``; all ones when no background was found.
    """
    if not background.found:
        return np.ones(len(background.probability))
    factor = 1.0 + sigmas / math.sqrt(neighbours)
    return 1.0 - np.minimum(1.0, factor * background.probability)


def _flats(near: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares flats of ``near (n, k, d)`` with weights ``w (n, k)``:
    ``(centre (n, d), normal (n, d))``."""
    w = w[..., None] + 1e-12  # a neighbourhood of weight-0 points still gets a flat
    centre = (w * near).sum(1) / w.sum(1)
    spread = near - centre[:, None]
    return centre, np.linalg.eigh(np.einsum("nki,nkj->nij", w * spread, spread))[1][:, :, 0]


class _LocalFlats(NamedTuple):
    """Per point, the flat of its neighbours: ``centre (n, d)``, unit
    ``normal (n, d)``, the neighbours' median distance to it ``local (n,)``
    and their rows ``idx (n, k)``."""

    centre: np.ndarray
    normal: np.ndarray
    local: np.ndarray
    idx: np.ndarray


def _local_flats(points: np.ndarray, weights: np.ndarray, neighbours: int) -> _LocalFlats:
    """Per point, the weighted least-squares flat of its ``neighbours``
    nearest points (itself left out) and their median distance to it."""
    idx = cKDTree(points).query(points, neighbours + 1)[1][:, 1:]
    near = points[idx]  # (n, k, d)
    centre, normal = _flats(near, weights[idx])
    local = np.median(np.abs(np.einsum("nkd,nd->nk", near - centre[:, None], normal)), axis=1)
    return _LocalFlats(centre, normal, local, idx)


def _near_a_neighbours_flat(points: np.ndarray, weights: np.ndarray, idx: np.ndarray, which: np.ndarray,
                            sigmas: float, floor_scale: float) -> np.ndarray:
    """For the points ``which (m,)``: whether at least :data:`SUPPORTING_FLATS`
    of their neighbours' flats, each refitted without the point itself and
    thin (its median residual within :data:`THIN` ``* floor_scale``), pass
    within ``sigmas`` scales of it (``floor_scale``, the median residual,
    as a standard deviation): ``(m,) bool``."""
    m, k = len(which), idx.shape[1]
    nbr = idx[which]  # (m, k)
    hood = idx[nbr]  # (m, k, k): each neighbour's own neighbours
    others = hood != which[:, None, None]  # the point itself left out
    near = points[hood].reshape(m * k, k, -1)
    centre, normal = _flats(near, (weights[hood] * others).reshape(m * k, k))
    resid = np.abs(np.einsum("nkd,nd->nk", near - centre[:, None], normal)).reshape(m, k, k)
    local = np.nanmedian(np.where(others, resid, np.nan), axis=2)
    gap = np.abs(np.einsum("mkd,mkd->mk", points[which][:, None] - centre.reshape(m, k, -1),
                           normal.reshape(m, k, -1)))
    tol = sigmas * _MAD_TO_SIGMA * floor_scale
    return np.count_nonzero((gap <= tol) & (local <= floor_scale * THIN), axis=1) >= SUPPORTING_FLATS


class PointNormals(NamedTuple):
    """Per point, the normal of the flat through its neighbours and whether
    it tells the surface's (:func:`point_normals`).

    Attributes:
      normal: ``(n, d)`` unit normals, unoriented.
      reliable: ``(n,)`` bool: the neighbours lie on their flat (false
        where they straddle a crease, a corner or a crossing).
    """

    normal: np.ndarray
    reliable: np.ndarray


def point_normals(points: np.ndarray, neighbours: int = NEIGHBOURS) -> PointNormals:
    """The unit normals of the flats (planes in 3D, lines in 2D) through
    each point's ``neighbours`` nearest points (itself left out), by least
    squares, and which of them to trust: those whose neighbours' median
    distance to their flat is at most :data:`RELIABLE` times the median of
    that over all points (the noise), plus :data:`RELIABLE_FLOOR` times the
    points' median distance to their neighbours (exact flats read 0).

    Args:
      points: ``(n, d)`` float64 points, ``d`` in 2 or 3, ``n > neighbours``.

    Example:
      >>> rng = np.random.default_rng(0)
      >>> u, v = rng.random((2, 400))
      >>> pts = np.r_[np.c_[u[:200], v[:200], np.zeros(200)], np.c_[np.zeros(200), v[200:], u[200:]]]
      >>> got = point_normals(pts)  # the planes z = 0 and x = 0, meeting at a crease along y
      >>> far = np.maximum(pts[:, 0], pts[:, 2]) > 0.3
      >>> bool(np.all(got.reliable[far])), bool(np.any(~got.reliable[~far]))
      (True, True)
      >>> bool(np.allclose(np.abs(got.normal[far & (pts[:, 2] == 0)][:, 2]), 1.0))
      True
    """
    points = np.asarray(points, np.float64)
    flats = _local_flats(points, np.ones(len(points)), neighbours)
    spacing = float(np.median(np.linalg.norm(points[flats.idx] - points[:, None], axis=-1)))
    bound = RELIABLE * float(np.median(flats.local)) + RELIABLE_FLOOR * spacing
    return PointNormals(flats.normal, flats.local <= bound)


def flat_noise(points: np.ndarray, neighbours: int = NOISE_NEIGHBOURS) -> float:
    """The standard deviation of the points about the shape they sample.

    The median over the points of their neighbours' median distance to
    the flat (a plane in 3D, a line in 2D) through them, scaled to a
    standard deviation for Gaussian residuals: about ``sigma`` for noise of
    standard deviation ``sigma`` well below the neighbourhoods' width (a
    flat through neighbours as thick as they are wide follows the noise,
    and the estimate falls short), unmoved by creases and corners (a
    minority of the points), 0 on exact flats.

    Args:
      points: ``(n, d)`` float64 points, ``d`` in 2 or 3, ``n > neighbours``.
    """
    points = np.asarray(points, np.float64)
    return _MAD_TO_SIGMA * float(np.median(_local_flats(points, np.ones(len(points)), neighbours).local))


def near_shape(points: np.ndarray, weights: np.ndarray, neighbours: int = NEIGHBOURS,
               sigmas: float = FLAT_SIGMAS) -> np.ndarray:
    """Which points lie on the flat (a plane in 3D, a line in 2D) through their neighbours.

    An outlier close to a surface reads dense, since its ``k`` nearest
    neighbours are the surface's points, and keeps much of its
    :func:`shape_weights`; it still stands off their plane. Each point's
    ``k`` neighbours (the point left out) get a least-squares flat, weighted
    by ``weights``, and a residual scale: the larger of their median
    distance to it and the median of that over all points, as a standard
    deviation. A point is near the shape when its distance to the flat is
    at most ``sigmas`` scales. Where one flat does not fit (a crease, a
    corner) the neighbours' own residuals are large, and so is the scale:
    the point stays. Outliers close together raise each other's scale and
    may stay. An outlier a few neighbourhood widths off a surface has the
    surface's points for neighbours, spread over a patch wider and more
    curved than theirs, and a flat tilted towards it: where its weight is
    below :data:`DOUBT`, it passes only if its neighbourhood's scale is at
    most :data:`WIDER` times the median of its neighbours' own (a point at
    a crease, whose neighbours straddle it too, is as thick as they are).
    A point off that flat still stays when it lies within
    ``sigmas`` median scales of at least :data:`SUPPORTING_FLATS` of its
    neighbours' own flats that are thin (residuals within :data:`THIN`
    median scales), each refitted without the point: a point of a sheet at
    a crease whose neighbours lean to the other sheet.

    Args:
      points: ``(n, d)`` float64 points, ``d`` in 2 or 3, ``n > k``.
      weights: ``(n,)`` shape weights in ``[0, 1]``, not all 0.

    Returns:
      ``(n,)`` bool, True where the point is near the shape.
    """
    points = np.asarray(points, np.float64)
    centre, normal, local, idx = _local_flats(points, weights, neighbours)
    # The floor: on exact flats every residual is a rounding error.
    floor = max(float(np.median(local[weights > 0])), 1e-9 * float(np.linalg.norm(np.ptp(points, axis=0))))
    gap = np.abs(np.einsum("nd,nd->n", points - centre, normal))
    near = gap <= sigmas * _MAD_TO_SIGMA * np.maximum(local, floor)
    doubt = weights < DOUBT
    near[doubt] &= local[doubt] <= WIDER * np.maximum(np.median(local[idx[doubt]], axis=1), floor)
    # Second chance where one flat does not fit: a point of a sheet at a
    # crease whose neighbours are mostly on the other sheet, or at a border
    # where they lean to one side, lies on some neighbour's flat.
    off = np.flatnonzero(~near)
    if len(off):
        near[off] = _near_a_neighbours_flat(points, weights, idx, off, sigmas, floor)
    return near
