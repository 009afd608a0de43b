"""How thick a 2D point set is across its own local direction.

Exact samples of a curve (a polyline's points, a noise-free generator's)
have neighbourhoods that are segments: no thickness away from the corners.
Noisy samples have neighbourhoods as wide as the noise, which, once it
spans a few point spacings, makes them nearly round. The defaults tell the
two apart with this measure (docs/decisions.md#default_initial_vertices).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

NEIGHBOURS = 8


def local_thickness(points: np.ndarray, neighbours: int = NEIGHBOURS) -> float:
    """The median over the points of their neighbourhood's thickness.

    A point's neighbourhood is it and its ``neighbours - 1`` nearest
    points; its thickness is ``sqrt(l_min / l_max)`` of their covariance's
    eigenvalues: 0 on a line, 1 for an isotropic cloud. Independent of the
    input's units, position and orientation; a neighbourhood of coincident
    points counts as 0.

    Args:
      points: ``(n, 2)`` finite points, ``n >= 2``.
      neighbours: neighbourhood size, at least 3 (capped at ``n``).

    Returns:
      The median thickness, in ``[0, 1]``.
    """
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 2 or len(points) < 2:
        raise ValueError(f"points must be (n >= 2, 2), got shape {points.shape}")
    if neighbours < 3:
        raise ValueError(f"neighbours must be at least 3, got {neighbours}")
    k = min(neighbours, len(points))
    # Unit scale, so that squares neither overflow nor underflow at any input units.
    centred = points - (points.max(0) / 2 + points.min(0) / 2)
    extent = np.abs(centred).max()
    if extent > 0:
        centred = centred / extent
    _, nearest = cKDTree(centred).query(centred, k)
    local = centred[nearest]
    local = local - local.mean(1, keepdims=True)
    cov = np.einsum("nki,nkj->nij", local, local)
    # Eigenvalues of a symmetric 2x2: half trace plus or minus the distance from it.
    half_trace = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1])
    gap = np.hypot(0.5 * (cov[:, 0, 0] - cov[:, 1, 1]), cov[:, 0, 1])
    largest = half_trace + gap
    smallest = np.maximum(half_trace - gap, 0.0)
    ratio = np.divide(smallest, largest, out=np.zeros_like(largest), where=largest > 0)
    return float(np.median(np.sqrt(ratio)))
