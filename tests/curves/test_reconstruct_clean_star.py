"""Acceptance of ``reconstruct_curve`` on a noise-free star (2000 points, 10
vertices): its corners are recovered. Distances are relative to the
bounding-box diagonal ``D``."""

import numpy as np

import otjax
from otjax import datasets
from tests.curves.reconstruct_cases import STAR_POINTS, assert_one_closed_cycle


def test_noise_free_star_recovers_its_corners():
    pts, truth = datasets.star(STAR_POINTS, noise=0.0, seed=1)
    result = otjax.reconstruct_curve(pts, n_vertices=10)
    d = truth["diagonal"]
    assert_one_closed_cycle(result, 10)
    # Each output vertex is near a distinct true corner (a bijection).
    dist = np.linalg.norm(result.vertices[:, None] - truth["corners"][None], axis=-1)
    assert len(set(dist.argmin(1))) == 10
    assert dist.min(1).max() <= 0.003 * d, f"worst vertex {dist.min(1).max() / d:.4%} of D"
