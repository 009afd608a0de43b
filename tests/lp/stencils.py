"""Random local transport LPs with 3D geometry, for the LP tests."""

from __future__ import annotations

import numpy as np

from otjax.lp.problem import LocalLP


def random_stencil(rng: np.random.Generator, n_points: int, n_bins: int, n_facets: int,
                   n_vertices: int, noise: float = 0.05) -> LocalLP:
    """Points near random triangles, bins on them, vertex bins at corners.

    ``n_bins`` counts facet and vertex bins (each facet gets at least one);
    facet capacities are positive and sum to 1 per facet; 10% of the points
    are outliers in the unit box. Simplex ids: facets first, then vertices.
    """
    n_facet_bins = max(n_bins - n_vertices, n_facets)
    corners = rng.uniform(0, 1, (n_facets, 3, 3))
    owner = np.concatenate([np.arange(n_facets), rng.integers(0, n_facets, n_facet_bins - n_facets)])
    bary = rng.dirichlet(np.ones(3), n_facet_bins)
    facet_pos = np.einsum("nc,ncd->nd", bary, corners[owner])
    pick = rng.choice(3 * n_facets, n_vertices, replace=3 * n_facets < n_vertices)
    vertex_pos = corners.reshape(-1, 3)[pick]
    bins = np.concatenate([facet_pos, vertex_pos])
    capacity = rng.uniform(0.5, 1.5, n_facet_bins)
    capacity /= np.bincount(owner, capacity, n_facets)[owner]
    host = rng.integers(0, n_facets, n_points)
    on = np.einsum("nc,ncd->nd", rng.dirichlet(np.ones(3), n_points), corners[host])
    points = on + rng.normal(0, noise, on.shape)
    outliers = rng.random(n_points) < 0.1
    points[outliers] = rng.uniform(0, 1, (outliers.sum(), 3))
    cost = np.sum((points[:, None, :] - bins[None, :, :]) ** 2, axis=-1)
    return LocalLP(cost=cost, mass=rng.uniform(0.5, 1.5, n_points),
                   capacity=np.concatenate([capacity, np.zeros(n_vertices)]),
                   simplex=np.concatenate([owner, n_facets + np.arange(n_vertices)]).astype(np.int32),
                   is_vertex=np.concatenate([np.zeros(n_facet_bins, bool), np.ones(n_vertices, bool)]))


def random_mix(rng: np.random.Generator, count: int) -> list[LocalLP]:
    """``count`` stencils of mixed sizes: 8-200 points, 4-80 bins, 1-6 facets, 1-4 vertex bins."""
    out = []
    for _ in range(count):
        n_vertices = int(rng.integers(1, 5))
        n_facets = int(rng.integers(1, 7))
        n_bins = int(rng.integers(max(4, n_facets + n_vertices), 81))
        out.append(random_stencil(rng, int(rng.integers(8, 201)), n_bins, n_facets, n_vertices))
    return out
