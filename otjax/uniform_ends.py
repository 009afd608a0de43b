"""Where a uniformly sampled interval ends, from its samples: the fits of
curve ends and of surface borders and crease ends move a vertex there."""

from __future__ import annotations

import math

import numpy as np


def uniform_end(x: np.ndarray, noise: float = 0.0) -> float:
    """Where samples ``x (k,)``, ``k >= 2``, of a uniform spread end: past
    the largest by their mean spacing, since the last of ``k`` uniform
    samples of an interval falls short of its end by ``1 / (k + 1)`` of it
    on average.

    With Gaussian noise of standard deviation ``noise`` on the samples, a
    share ``noise / (sqrt(2 pi) L)`` of them (``L`` their range) lies past
    the end: the quantile below that share stands for the largest.

    Example:
      >>> x = np.random.default_rng(0).random(2000)  # uniform on [0, 1]
      >>> noisy = x + 0.02 * np.random.default_rng(1).normal(size=2000)
      >>> [round(uniform_end(x), 3), round(uniform_end(noisy), 3), round(uniform_end(noisy, 0.02), 3)]
      [1.0, 1.033, 0.999]
    """
    spread = float(np.ptp(x))
    share = min(noise / (math.sqrt(2 * math.pi) * spread), 0.5) if noise > 0 and spread > 0 else 0.0
    return float(np.quantile(x, 1.0 - share) + spread / (len(x) - 1))
