"""Synthetic shapes with known ground truth (segments and corners).

Every generator returns ``(points, truth)``: ``points`` is ``(n, 2)`` float64,
``truth`` is a dict with ``corners (k, 2)`` and ``segments (s, 2, 2)``. Noise is
Gaussian with standard deviation ``noise`` times the bounding-box diagonal of
the clean shape. Generators are deterministic for a given ``seed``.
"""

from __future__ import annotations

import numpy as np


def _sample_segments(segments: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniform in arc length over ``(s, 2, 2)`` segments."""
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    which = rng.choice(len(segments), size=n, p=length / length.sum())
    t = rng.random(n)[:, None]
    return segments[which, 0] * (1 - t) + segments[which, 1] * t


def star(n: int = 3000, noise: float = 0.0, points: int = 5, inner: float = 0.4, seed: int = 0):
    """A closed star polygon with ``2 * points`` sharp corners.

    Example:
      >>> p, truth = star(100, noise=0.01)
      >>> p.shape, truth["corners"].shape
      ((100, 2), (10, 2))
    """
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if noise < 0:
        raise ValueError(f"noise must be >= 0, got {noise}")
    rng = np.random.default_rng(seed)
    k = 2 * points
    angle = np.pi / 2 + np.arange(k) * 2 * np.pi / k
    radius = np.where(np.arange(k) % 2 == 0, 1.0, inner)
    corners = np.stack([radius * np.cos(angle), radius * np.sin(angle)], 1)
    segments = np.stack([corners, np.roll(corners, -1, 0)], 1)
    pts = _sample_segments(segments, n, rng)
    diag = float(np.linalg.norm(corners.max(0) - corners.min(0)))
    pts = pts + noise * diag * rng.standard_normal(pts.shape)
    return pts, {"corners": corners, "segments": segments}
