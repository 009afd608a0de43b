"""Synthetic shapes with known ground truth.

This module holds the 2D curves; the 3D surfaces (:mod:`otjax.datasets3d`)
are re-exported at its end.

Every generator returns ``(points, truth)``: ``points`` is ``(n, 2)`` float64
and ``truth`` a dict that always holds the same keys (empty arrays where a
feature does not occur), so any consumer can read any shape:

- ``segments (s, 2, 2)``: the clean shape, as straight segments.
- ``corners (k, 2)``: sharp corners, where the direction changes; free ends
  are not corners (they are in ``ends``), except for :func:`junctions`, whose
  corners list every vertex of the shape (see there).
- ``junctions (j, 2)`` and ``junction_degree (j,) int``: points where three
  or more segments meet.
- ``ends (e, 2)``: free ends of open curves (degree-1 points).
- ``diagonal``: float, bounding-box diagonal ``D`` of the clean shape.

Points are drawn uniformly in arc length over the segments, then moved by
Gaussian noise of standard deviation ``noise * D``. Generators are
deterministic for a ``seed`` and draw the noise last, so for a fixed seed the
noisy points minus the clean ones is exactly the noise.

:func:`with_outliers` adds ``n_outliers`` and ``outlier_box``, :func:`generate`
adds ``params``. The built-in examples (:data:`EXAMPLES`, :func:`load_example`)
fix a shape, a sample size, a noise level, outliers and recommended
reconstruction parameters.
"""

from __future__ import annotations

from typing import NamedTuple

import inspect
from dataclasses import dataclass

import numpy as np

from otjax.metrics import point_segment_distance

_NO_POINTS = np.zeros((0, 2))


def _sample_segments(segments: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` points uniform in arc length over ``(s, 2, 2)`` segments."""
    length = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    which = rng.choice(len(segments), size=n, p=length / length.sum())
    t = rng.random(n)[:, None]
    return segments[which, 0] * (1 - t) + segments[which, 1] * t


def _check_common(n: int, noise: float) -> None:
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    if not noise >= 0:
        raise ValueError(f"noise must be >= 0, got {noise}")


def _truth(segments, corners=_NO_POINTS, ends=_NO_POINTS, junctions=_NO_POINTS, degree=()) -> dict:
    """Assemble a truth dict with every key present and ``diagonal`` computed from the segments."""
    segments = np.asarray(segments, dtype=np.float64)
    flat = segments.reshape(-1, 2)
    return {
        "segments": segments,
        "corners": np.asarray(corners, dtype=np.float64).reshape(-1, 2),
        "junctions": np.asarray(junctions, dtype=np.float64).reshape(-1, 2),
        "junction_degree": np.asarray(degree, dtype=np.int64),
        "ends": np.asarray(ends, dtype=np.float64).reshape(-1, 2),
        "diagonal": float(np.linalg.norm(flat.max(0) - flat.min(0))),
    }


def _sample_truth(truth: dict, n: int, noise: float, rng: np.random.Generator) -> np.ndarray:
    """Sample the truth's segments and add noise; the draw order (which, t, noise) is fixed."""
    pts = _sample_segments(truth["segments"], n, rng)
    return pts + noise * truth["diagonal"] * rng.standard_normal(pts.shape)


def _polyline(vertices: np.ndarray) -> np.ndarray:
    """Segments ``(k-1, 2, 2)`` joining consecutive rows of ``vertices (k, 2)``."""
    return np.stack([vertices[:-1], vertices[1:]], axis=1)


def _star_truth(points: int, inner: float) -> dict:
    k = 2 * points
    angle = np.pi / 2 + np.arange(k) * 2 * np.pi / k
    radius = np.where(np.arange(k) % 2 == 0, 1.0, inner)
    corners = np.stack([radius * np.cos(angle), radius * np.sin(angle)], 1)
    return _truth(np.stack([corners, np.roll(corners, -1, 0)], 1), corners)


def star(n: int = 3000, noise: float = 0.0, points: int = 5, inner: float = 0.4, seed: int = 0):
    """A closed star polygon with ``2 * points`` sharp corners.

    Tips at radius 1, notches at radius ``inner``, one tip pointing up.

    Example:
      >>> p, truth = star(100, noise=0.01)
      >>> p.shape, truth["corners"].shape
      ((100, 2), (10, 2))
    """
    _check_common(n, noise)
    if points < 2 or not 0 < inner:
        raise ValueError(f"need points >= 2 and inner > 0, got points={points}, inner={inner}")
    truth = _star_truth(points, inner)
    return _sample_truth(truth, n, noise, np.random.default_rng(seed)), truth


def _skyline_truth(steps: int) -> dict:
    # Heights follow the golden-ratio sequence: consecutive heights always differ by at least
    # 0.38 * 0.6 ~ 0.23, so every vertical piece is long enough to be a visible corner pair.
    i = np.arange(steps)
    height = 0.3 + 0.6 * np.mod(0.5 + i * 0.6180339887, 1.0)
    width = 1.0 + 0.6 * np.mod(i * 0.4142135624, 1.0)
    x = np.concatenate([[0.0], np.cumsum(width)]) * (2.0 / width.sum())  # total width 2
    tops = np.stack([np.repeat(x, 2)[1:-1], np.repeat(height, 2)], 1)  # (2*steps, 2)
    vertices = np.concatenate([[[0.0, 0.0]], tops, [[x[-1], 0.0]]])
    return _truth(_polyline(vertices), corners=tops, ends=vertices[[0, -1]])


def skyline(n: int = 2000, noise: float = 0.0, steps: int = 6, seed: int = 0):
    """An open axis-aligned "city skyline" polyline (the paper's Fig. 8 shape).

    It rises from ``(0, 0)``, runs over ``steps`` flat roofs of varying width
    and height (between 0.3 and 0.9) and comes back down to ``(2, 0)``. The
    shape depends only on ``steps``; ``seed`` drives sampling and noise.
    ``corners`` holds the ``2 * steps`` right-angle bends, ``ends`` the two feet,
    so the polyline has ``2 * steps + 2`` vertices.

    Example:
      >>> p, truth = skyline(500, noise=0.005)
      >>> truth["corners"].shape, truth["ends"].shape
      ((12, 2), (2, 2))
    """
    _check_common(n, noise)
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    truth = _skyline_truth(steps)
    return _sample_truth(truth, n, noise, np.random.default_rng(seed)), truth


def _junctions_truth() -> dict:
    # A horizontal spine crossed by a diagonal line (X, degree 4) and, further right, a stem that
    # leaves it upwards (T, degree 3) and bends right. D ~ 4.83: every arm is >= 0.9 (18% of D),
    # X and T are 2 apart (41% of D), and no two feature points are closer than 0.9.
    x, t, bend = (0.0, 0.0), (2.0, 0.0), (2.0, 1.0)
    ends = np.array([(-1.2, 0.0), (3.2, 0.0), (-0.7, -1.0), (0.7, 1.0), (2.9, 1.0)])
    spine = [(ends[0], x), (x, t), (t, ends[1])]
    diagonal = [(ends[2], x), (x, ends[3])]
    stem = [(t, bend), (bend, ends[4])]
    segments = spine + diagonal + stem
    junctions = np.array([x, t])
    corners = np.concatenate([junctions, ends, [bend]])
    return _truth(np.array(segments), corners, ends, junctions, degree=[4, 3])


def junctions(n: int = 3000, noise: float = 0.0, seed: int = 0):
    """An open shape with an X-crossing (degree 4), a T-junction (degree 3) and a bend.

    Seven straight segments between eight vertices: the two junctions, five
    free ends and one right-angle bend. Here ``corners`` lists all eight (every
    vertex where a reconstruction must put a vertex), ``junctions`` the
    crossing then the T, ``ends`` the five free ends. The shape is fixed;
    ``seed`` drives sampling and noise.

    Example:
      >>> p, truth = junctions(500)
      >>> truth["junction_degree"].tolist(), len(truth["ends"]), len(truth["corners"])
      ([4, 3], 5, 8)
    """
    _check_common(n, noise)
    truth = _junctions_truth()
    return _sample_truth(truth, n, noise, np.random.default_rng(seed)), truth


def _circle_truth(radius: float) -> dict:
    angle = np.arange(720) * (2 * np.pi / 720)
    ring = radius * np.stack([np.cos(angle), np.sin(angle)], 1)
    return _truth(np.stack([ring, np.roll(ring, -1, 0)], 1))


def circle(n: int = 2000, noise: float = 0.0, radius: float = 1.0, seed: int = 0):
    """A circle centred at the origin: a smooth closed curve without corners.

    The truth (and the clean samples) is the inscribed regular 720-gon, which
    departs from the circle by at most ``radius * (1 - cos(pi / 720))``, about
    ``1e-5 * radius``; ``corners`` is empty.

    Example:
      >>> p, truth = circle(300, radius=2.0)
      >>> truth["segments"].shape, truth["corners"].shape
      ((720, 2, 2), (0, 2))
    """
    _check_common(n, noise)
    if not radius > 0:
        raise ValueError(f"radius must be > 0, got {radius}")
    truth = _circle_truth(radius)
    return _sample_truth(truth, n, noise, np.random.default_rng(seed)), truth


def with_outliers(points, truth: dict, n_outliers: int, margin: float = 0.2, seed: int = 0):
    """Append uniform outliers in the enlarged bounding box of the clean shape.

    The box is the bounding box of ``truth["segments"]``, grown on each side by
    ``margin`` times its extent along that axis (by ``margin * D`` along an
    axis where the shape is flat). The outliers come last in the returned points.

    Args:
      points: ``(n, 2)`` samples of the shape.
      truth: its truth dict; it is copied, not modified.
      n_outliers: number of outliers, ``>= 0``.
      margin: relative enlargement, ``>= 0``.
      seed: seed of the outliers' generator.

    Returns:
      ``points (n + n_outliers, 2)`` and a truth with ``n_outliers`` (int) and
      ``outlier_box (2, 2)`` (rows: lower corner, upper corner) added.

    Example:
      >>> p, t = with_outliers(*star(100), 50)
      >>> p.shape, t["n_outliers"]
      ((150, 2), 50)
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if n_outliers < 0 or not margin >= 0:
        raise ValueError(f"need n_outliers >= 0 and margin >= 0, got {n_outliers}, {margin}")
    flat = np.asarray(truth["segments"], dtype=np.float64).reshape(-1, 2)
    lo, hi = flat.min(0), flat.max(0)
    extent = hi - lo
    pad = margin * np.where(extent > 0, extent, np.linalg.norm(extent))
    box = np.stack([lo - pad, hi + pad])
    outliers = np.random.default_rng(seed).uniform(box[0], box[1], size=(n_outliers, 2))
    out = dict(truth, n_outliers=int(n_outliers), outlier_box=box)
    return np.concatenate([points, outliers]), out


_SHAPE_TRUTH = {
    "star": lambda: _star_truth(5, 0.4),
    "skyline": lambda: _skyline_truth(6),
    "junctions": _junctions_truth,
    "circle": lambda: _circle_truth(1.0),
}

SHAPES = {"star": star, "skyline": skyline, "junctions": junctions, "circle": circle}
"""Shape name -> generator ``f(n, noise=..., seed=...)``, all with their default parameters."""


def _fit_to_image(truth: dict, size: int, pad: float) -> dict:
    """Scale and translate every point-valued truth entry into ``[pad, size - pad]^2``, centred."""
    flat = truth["segments"].reshape(-1, 2)
    lo, hi = flat.min(0), flat.max(0)
    scale = (size - 2 * pad) / (hi - lo).max()
    shift = size / 2 - scale * (lo + hi) / 2
    out = dict(truth)
    for key in ("segments", "corners", "junctions", "ends"):
        out[key] = truth[key] * scale + shift
    out["diagonal"] = truth["diagonal"] * scale
    return out


def drawing(size: int = 64, shape: str = "star", line_width: float = 2.0):
    """A dark-on-white grayscale raster of a shape, as a scanned line drawing.

    Each pixel's darkness is the fraction of a ``line_width``-wide stroke
    covering it, approximated from its centre's distance ``r`` to the segments:
    ``clip(line_width / 2 + 0.5 - r, 0, 1)``. The shape is scaled to fill the
    image with a margin of ``line_width + 2`` pixels.

    Args:
      size: image height and width in pixels.
      shape: a name from :data:`SHAPES`, in its default parameters.
      line_width: stroke width in pixels, ``> 0``.

    Returns:
      ``image (size, size)`` float64 in ``[0, 1]`` (0 black, 1 white), and the
      truth in image point coordinates: pixel ``(row, col)`` has its centre at
      ``x = col + 0.5``, ``y = size - row - 0.5`` (y up).

    Example:
      >>> img, truth = drawing(32, "circle", line_width=1.5)
      >>> img.shape, float(img.min()), float(img.max())
      ((32, 32), 0.0, 1.0)
    """
    if shape not in _SHAPE_TRUTH:
        raise ValueError(f"unknown shape {shape!r}; valid shapes: {', '.join(sorted(_SHAPE_TRUTH))}")
    if not line_width > 0:
        raise ValueError(f"line_width must be > 0, got {line_width}")
    pad = line_width + 2.0
    if size < 2 * pad + 4:
        raise ValueError(f"size {size} is too small for line_width {line_width}: need >= {2 * pad + 4:g}")
    truth = _fit_to_image(_SHAPE_TRUTH[shape](), size, pad)
    col, row = np.meshgrid(np.arange(size), np.arange(size))
    centres = np.stack([col.ravel() + 0.5, size - row.ravel() - 0.5], 1)
    r = point_segment_distance(centres, truth["segments"]).reshape(size, size)
    ink = np.clip(line_width / 2 + 0.5 - r, 0.0, 1.0)
    return 1.0 - ink, truth


@dataclass(frozen=True)
class _Example:
    description: str
    shape: str
    n: int
    noise: float
    n_vertices: int
    n_outliers: int = 0
    relevance: float = 0.0


_EXAMPLES = {
    "star": _Example("clean five-pointed star, 3000 points, 10 corners", "star", 3000, 0.0, 10),
    "noisy-star": _Example("five-pointed star, 3000 points, 1% noise", "star", 3000, 0.01, 10),
    "star-outliers": _Example(
        "five-pointed star, 3000 points, 2% noise, plus 3000 uniform outliers",
        shape="star",
        n=3000,
        noise=0.02,
        n_vertices=10,
        n_outliers=3000,
    ),
    "skyline": _Example(
        "open city-skyline staircase, 2000 points, 0.5% noise, 12 right-angle corners and 2 ends",
        shape="skyline",
        n=2000,
        noise=0.005,
        n_vertices=14,
    ),
    "junctions": _Example(
        "open shape with an X-crossing, a T-junction and a bend, 3000 points, clean",
        shape="junctions",
        n=3000,
        noise=0.0,
        n_vertices=8,
    ),
    "circle": _Example("clean unit circle, 2000 points, no corners", "circle", 2000, 0.0, 50),
}

EXAMPLES: dict[str, str] = {name: ex.description for name, ex in _EXAMPLES.items()}
"""Built-in example name -> one-line description; load one with :func:`load_example`."""


def _outlier_seed(seed: int) -> int:
    """A seed for the outliers that is independent of the shape's own stream for the same ``seed``."""
    return int(np.random.SeedSequence([seed, 1]).generate_state(1)[0])


def generate(
    name: str, n: int | None = None, noise: float | None = None, n_outliers: int | None = None, seed: int = 0
):
    """Points and truth of a shape or built-in example, its settings overridden where given.

    A shape name (:data:`SHAPES`) defaults to the generator's own ``n``, no
    noise and no outliers; an example name (:data:`EXAMPLES`) to the example's
    settings. When only ``n`` is overridden, the outlier count keeps its share.

    Args:
      name: a key of :data:`SHAPES` or :data:`EXAMPLES`.
      n: number of shape samples (outliers not counted).
      noise: noise std as a fraction of the diagonal.
      n_outliers: number of uniform outliers, appended last (:func:`with_outliers`).
      seed: seed for sampling, noise and outliers.

    Returns:
      ``points (N, 2)`` and the truth dict, with the settings used under
      ``"params"`` (name, shape, n, noise, n_outliers, seed).

    Example:
      >>> pts, truth = generate("star-outliers", n=100)
      >>> pts.shape, truth["n_outliers"]
      ((200, 2), 100)
    """
    if name in _EXAMPLES:
        ex = _EXAMPLES[name]
        shape, base_n, base_noise, base_outliers = ex.shape, ex.n, ex.noise, ex.n_outliers
    elif name in SHAPES:
        shape, base_noise, base_outliers = name, 0.0, 0
        base_n = inspect.signature(SHAPES[name]).parameters["n"].default
    else:
        valid = sorted(set(SHAPES) | set(_EXAMPLES))
        raise ValueError(f"unknown shape or example {name!r}; valid names: {', '.join(valid)}")
    count = base_n if n is None else n
    noise = base_noise if noise is None else noise
    if n_outliers is None:
        n_outliers = round(base_outliers * count / base_n)
    points, truth = SHAPES[shape](count, noise=noise, seed=seed)
    if n_outliers:
        points, truth = with_outliers(points, truth, n_outliers, seed=_outlier_seed(seed))
    params = {
        "name": name,
        "shape": shape,
        "n": count,
        "noise": noise,
        "n_outliers": n_outliers,
        "seed": seed,
    }
    return points, dict(truth, params=params)


class LoadedExample(NamedTuple):
    """A built-in example, ready to run (unpacks as a 4-tuple)."""

    points: np.ndarray
    masses: np.ndarray
    truth: dict
    defaults: dict


def load_example(name: str, seed: int = 0, n: int | None = None) -> LoadedExample:
    """Points, unit masses, ground truth and recommended parameters of a built-in example.

    Args:
      name: a key of :data:`EXAMPLES`.
      seed: seed for sampling, noise and outliers.
      n: number of shape samples instead of the example's own; for
        ``"star-outliers"`` the outliers are scaled to keep their share.

    Returns:
      ``points (N, 2)``, ``masses (N,)`` ones, ``truth`` (see the module doc;
      plus ``n_outliers`` and ``outlier_box`` when the example has outliers),
      and ``defaults``: ``{"n_vertices": int, "relevance": float}``.

    Example:
      >>> pts, masses, truth, defaults = load_example("skyline", n=200)
      >>> pts.shape, defaults["n_vertices"]
      ((200, 2), 14)
    """
    if name not in _EXAMPLES:
        raise ValueError(f"unknown example {name!r}; valid names: {', '.join(_EXAMPLES)}")
    points, truth = generate(name, n=n, seed=seed)
    ex = _EXAMPLES[name]
    return LoadedExample(points, np.ones(len(points)), truth, {"n_vertices": ex.n_vertices, "relevance": ex.relevance})


# The 3D surfaces live in otjax.datasets3d (this module holds the 2D shapes); re-exported here.
from otjax.datasets3d import (  # noqa: F401
    RECOVERY,
    SURFACES,
    RecoverySample,
    SurfaceSample,
    SurfaceTruth,
    box_pair,
    box_pair_truth,
    cone,
    cone_truth,
    crossing,
    crossing_truth,
    cube,
    cube_truth,
    cylinder,
    cylinder_truth,
    holed_square,
    holed_square_truth,
    outlier_box,
    rounded_box,
    rounded_cube_mesh,
    sample_surface,
    staircase,
    staircase_truth,
)
