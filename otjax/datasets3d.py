"""Synthetic surfaces with known ground truth (3D).

A surface is a union of *patches*, each of which can be sampled exactly by
area and has an exact distance function:

* rectangles ``o + s u + t v`` with ``s, t`` in ``[0, 1]`` and ``u ⊥ v``;
* surfaces of revolution about the z axis of a segment ``(r0, z0)-(r1, z1)``
  of the half plane ``r >= 0`` (a cylinder, a cone, an annulus). The
  nearest point of such a surface lies in the meridian half plane of the
  query point, so its distance is the 2D distance from ``(|xy|, z)`` to
  the segment.

A :class:`SurfaceTruth` holds the patches and the features a reconstruction
must find, as segment arrays ``(s, 2, 3)`` like the 2D truth's: ``creases``
(sharp edges, including lines where sheets cross), ``boundaries`` (open
borders; circles as inscribed 360-gons, within ``1 - cos(pi / 360)`` ~
``4e-5`` of the radius) and ``corners`` (points where feature lines end,
meet or bend, and cone tips).

Generators return ``(points, truth)`` (:class:`SurfaceSample`) or, for
feature recovery, ``(points, truth, mesh)`` (:class:`RecoverySample`), where
``mesh`` is a smooth :class:`otjax.io3d.Mesh` that misses the truth's
features. Points are drawn uniformly by area, then moved by isotropic
Gaussian noise of standard deviation ``noise * D`` (``D`` the diagonal of
the clean shape's bounding box; ``noise=0.01`` is 1% of ``D``), then
``n_outliers`` uniform outliers in :func:`outlier_box` are appended. A seed
fixes everything; the noise is drawn after the clean samples, so for a
fixed seed the noisy points minus the clean ones is exactly the noise.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.io3d import Mesh

_NO = np.zeros((0, 2, 3))
# Entries of one (points x patches) block in the distance function: about 8 MiB per float64 temporary.
_BLOCK = 1 << 20
#: Vertices around a circle in a truth's mesh and boundary polylines.
CIRCLE_SEGMENTS = 360


class SurfaceTruth(NamedTuple):
    """A surface with exact area sampling and distance (see the module doc).

    Attributes:
      rectangles: ``(R, 3, 3)`` rows ``o, u, v`` of each rectangle.
      revolutions: ``(Q, 4)`` rows ``r0, z0, r1, z1`` of each revolved segment.
      creases: ``(c, 2, 3)`` sharp edges as segments.
      boundaries: ``(b, 2, 3)`` open borders as segments.
      corners: ``(k, 3)`` feature points.
      diagonal: bounding-box diagonal ``D`` of the surface.
      mesh: a triangulation of the surface: exact on rectangles, an inscribed
        :data:`CIRCLE_SEGMENTS`-gon on surfaces of revolution (within
        ``4e-5`` of the radius); patches may meet at T-junctions (the box
        pair's), so not every crease is an edge of it.
    """

    rectangles: np.ndarray
    revolutions: np.ndarray
    creases: np.ndarray
    boundaries: np.ndarray
    corners: np.ndarray
    diagonal: float
    mesh: Mesh

    def areas(self) -> np.ndarray:
        """``(R + Q,)`` area of each patch, rectangles first."""
        rect = np.linalg.norm(self.rectangles[:, 1], axis=1) * np.linalg.norm(self.rectangles[:, 2], axis=1)
        r0, z0, r1, z1 = self.revolutions.T
        return np.concatenate([rect, np.pi * (r0 + r1) * np.hypot(r1 - r0, z1 - z0)])

    @property
    def area(self) -> float:
        """Total area."""
        return float(self.areas().sum())

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, 3)`` points uniform by area on the surface.

        Draws, in order: the patch of each point, then two uniforms per point.
        """
        area = self.areas()
        which = rng.choice(len(area), size=n, p=area / area.sum())
        u = rng.random((n, 2))
        out = np.empty((n, 3))
        n_rect = len(self.rectangles)
        rect = which < n_rect
        o, a, b = (self.rectangles[which[rect], i] for i in range(3))
        out[rect] = o + u[rect, :1] * a + u[rect, 1:] * b
        r0, z0, r1, z1 = self.revolutions[which[~rect] - n_rect].T
        # The area density along the segment is proportional to the radius r0 + (r1 - r0) t:
        # invert its CDF, a t^2 + r0 t = c, in the form that is stable for a = 0 and r0 = 0.
        half = 0.5 * (r1 - r0)
        c = u[~rect, 1] * 0.5 * (r0 + r1)
        t = 2 * c / (r0 + np.sqrt(r0 * r0 + 4 * half * c))
        r, z, theta = r0 + (r1 - r0) * t, z0 + (z1 - z0) * t, 2 * np.pi * u[~rect, 0]
        out[~rect] = np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)
        return out

    def distance(self, x) -> np.ndarray:
        """``(m,)`` exact distance of points ``x (m, 3)`` to the surface."""
        x = np.asarray(x, np.float64).reshape(-1, 3)
        out = np.empty(len(x))
        step = max(1, _BLOCK // max(1, len(self.rectangles) + len(self.revolutions)))
        for lo in range(0, len(x), step):
            out[lo:lo + step] = self._distance(x[lo:lo + step])
        return out

    def _distance(self, x: np.ndarray) -> np.ndarray:
        best = np.full(len(x), np.inf)
        if len(self.rectangles):
            o, u, v = (self.rectangles[None, :, i] for i in range(3))
            d = x[:, None] - o  # (m, R, 3)
            # u and v are orthogonal, so the nearest point clamps each coordinate on its own.
            s = np.clip(np.sum(d * u, -1) / np.sum(u * u, -1), 0.0, 1.0)
            t = np.clip(np.sum(d * v, -1) / np.sum(v * v, -1), 0.0, 1.0)
            off = d - s[..., None] * u - t[..., None] * v
            best = np.minimum(best, np.sqrt(np.sum(off * off, -1)).min(1))
        if len(self.revolutions):
            q = np.stack([np.hypot(x[:, 0], x[:, 1]), x[:, 2]], 1)[:, None]  # (m, 1, 2)
            a, b = self.revolutions[None, :, :2], self.revolutions[None, :, 2:]
            ab = b - a
            t = np.clip(np.sum((q - a) * ab, -1) / np.sum(ab * ab, -1), 0.0, 1.0)
            off = q - a - t[..., None] * ab
            best = np.minimum(best, np.sqrt(np.sum(off * off, -1)).min(1))
        return best


class SurfaceSample(NamedTuple):
    """Points ``(N, 3)`` (shape samples, then outliers) and their :class:`SurfaceTruth`."""

    points: np.ndarray
    truth: SurfaceTruth


class RecoverySample(NamedTuple):
    """A feature recovery input: points ``(N, 3)`` on the truth, the truth,
    and a smooth :class:`~otjax.io3d.Mesh` that rounds or covers its features."""

    points: np.ndarray
    truth: SurfaceTruth
    mesh: Mesh


# ------------------------------------------------------------------ building


def _rect(o, u, v) -> np.ndarray:
    return np.array([o, u, v], np.float64)


def _box_rects(lo, hi, top: bool = True) -> list[np.ndarray]:
    """The faces of the box ``[lo, hi]`` (without its top when ``top`` is false)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ex, ey, ez = np.diag(hi - lo)
    rects = [_rect(lo, ex, ey), _rect(lo, ex, ez), _rect(lo, ey, ez),
             _rect(lo + ey, ex, ez), _rect(lo + ex, ey, ez)]
    return rects + ([_rect(lo + ez, ex, ey)] if top else [])


def _holed_rects(lo, hi, hole_lo, hole_hi, z: float) -> list[np.ndarray]:
    """The rectangle ``[lo, hi]`` at height ``z`` minus ``[hole_lo, hole_hi]``: the 8
    rectangles of the 3 x 3 grid they span, without the middle one."""
    xs, ys = (np.array([lo[k], hole_lo[k], hole_hi[k], hi[k]], float) for k in range(2))
    return [_rect((xs[i], ys[j], z), (xs[i + 1] - xs[i], 0, 0), (0, ys[j + 1] - ys[j], 0))
            for i in range(3) for j in range(3) if (i, j) != (1, 1)]


def _box_edges(lo, hi) -> np.ndarray:
    """``(12, 2, 3)`` edges of the box ``[lo, hi]``."""
    corners = np.array([[[lo, hi][i >> k & 1][k] for k in range(3)] for i in range(8)], float)
    pairs = [(i, i | 1 << k) for i in range(8) for k in range(3) if not i >> k & 1]
    return corners[np.array(pairs)]


def _loop(points) -> np.ndarray:
    p = np.asarray(points, np.float64)
    return np.stack([p, np.roll(p, -1, 0)], 1)


def _circle(radius: float, z: float) -> np.ndarray:
    a = np.arange(CIRCLE_SEGMENTS) * (2 * np.pi / CIRCLE_SEGMENTS)
    return _loop(np.stack([radius * np.cos(a), radius * np.sin(a), np.full_like(a, z)], 1))


def _revolution_mesh(r0, z0, r1, z1) -> tuple[np.ndarray, np.ndarray]:
    k = CIRCLE_SEGMENTS
    a = np.arange(k) * (2 * np.pi / k)
    rings = [np.zeros((1, 3)) + [0, 0, z] if r == 0 else np.stack([r * np.cos(a), r * np.sin(a), np.full(k, z)], 1)
             for r, z in ((r0, z0), (r1, z1))]
    i = np.arange(k)
    j = (i + 1) % k
    if r0 == 0:
        tris = np.stack([np.zeros(k, int), 1 + i, 1 + j], 1)
    elif r1 == 0:
        tris = np.stack([i, j, np.full(k, k)], 1)
    else:
        tris = np.concatenate([np.stack([i, j, k + i], 1), np.stack([j, k + j, k + i], 1)])
    return np.concatenate(rings), tris


def _merge(vertices: np.ndarray, triangles: np.ndarray, diagonal: float) -> Mesh:
    """The mesh with vertices equal to 1e-12 D merged (patch meshes share their borders)."""
    key = np.round(vertices / diagonal * 1e12)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return Mesh(vertices[first], inverse.reshape(-1)[triangles])


def _truth(rects, revolutions=(), creases=_NO, boundaries=_NO, corners=()) -> SurfaceTruth:
    rects = np.asarray(rects, np.float64).reshape(-1, 3, 3)
    revolutions = np.asarray(revolutions, np.float64).reshape(-1, 4)
    parts = [(np.stack([o, o + u, o + u + v, o + v]), np.array([[0, 1, 2], [0, 2, 3]])) for o, u, v in rects]
    parts += [_revolution_mesh(*row) for row in revolutions]
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    vertices = np.concatenate([v for v, _ in parts])
    triangles = np.concatenate([t + off for (_, t), off in zip(parts, offsets)])
    diagonal = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    return SurfaceTruth(rects, revolutions, np.asarray(creases, np.float64).reshape(-1, 2, 3),
                        np.asarray(boundaries, np.float64).reshape(-1, 2, 3),
                        np.asarray(corners, np.float64).reshape(-1, 3), diagonal,
                        _merge(vertices, triangles, diagonal))


def _box_corners(lo, hi) -> np.ndarray:
    return np.array([[[lo, hi][i >> k & 1][k] for k in range(3)] for i in range(8)], float)


def staircase_truth(steps: int = 3) -> SurfaceTruth:
    """``steps`` risers and treads of ``1 / steps``, extruded over ``y`` in ``[0, 1]``; open."""
    s = 1.0 / steps
    ey = np.array([0.0, 1.0, 0.0])
    profile = [(0.0, 0.0)]
    for k in range(steps):
        profile += [(k * s, (k + 1) * s), ((k + 1) * s, (k + 1) * s)]
    profile = np.array([(x, 0.0, z) for x, z in profile])  # (2 steps + 1, 3) at y = 0
    rects = [_rect(profile[k], ey, profile[k + 1] - profile[k]) for k in range(len(profile) - 1)]
    creases = np.stack([profile[1:-1], profile[1:-1] + ey], 1)
    sides = [np.stack([profile[:-1] + y, profile[1:] + y], 1) for y in (0 * ey, ey)]
    ends = np.stack([profile[[0, -1]], profile[[0, -1]] + ey], 1)
    return _truth(rects, creases=creases, boundaries=np.concatenate(sides + [ends]),
                  corners=np.concatenate([profile, profile + ey]))


def cylinder_truth(radius: float = 0.5, height: float = 1.0) -> SurfaceTruth:
    """The side of a cylinder about the z axis, ``z`` in ``[0, height]``; open at both ends."""
    return _truth([], [(radius, 0.0, radius, height)],
                  boundaries=np.concatenate([_circle(radius, 0.0), _circle(radius, height)]))


def cone_truth(radius: float = 0.5, height: float = 1.0) -> SurfaceTruth:
    """The side of a cone, tip at ``(0, 0, height)``, open base circle of ``radius`` at ``z = 0``."""
    return _truth([], [(0.0, height, radius, 0.0)], boundaries=_circle(radius, 0.0),
                  corners=[(0.0, 0.0, height)])


def cube_truth() -> SurfaceTruth:
    """The surface of the unit cube ``[0, 1]^3``: 12 creases, 8 corners, closed."""
    lo, hi = np.zeros(3), np.ones(3)
    return _truth(_box_rects(lo, hi), creases=_box_edges(lo, hi), corners=_box_corners(lo, hi))


def crossing_truth() -> SurfaceTruth:
    """Two unit squares crossing at a line: ``z = 1/2`` and ``y = 1/2`` over ``[0, 1]^2``.

    The crossing line is the one crease (four sheets meet there at right
    angles); each square's border is boundary; corners: the 8 square
    corners and the 2 ends of the crossing line.
    """
    a = _rect((0, 0, 0.5), (1, 0, 0), (0, 1, 0))
    b = _rect((0, 0.5, 0), (1, 0, 0), (0, 0, 1))
    loops = [np.array([o, o + u, o + u + v, o + v]) for o, u, v in (a, b)]
    # Each square as two halves meeting at the crossing line, so the truth's mesh has that line as an edge.
    halves = [_rect(o + k * v / 2, u, v / 2) for o, u, v in (a, b) for k in (0, 1)]
    return _truth(halves, creases=[[(0, 0.5, 0.5), (1, 0.5, 0.5)]],
                  boundaries=np.concatenate([_loop(p) for p in loops]),
                  corners=np.concatenate(loops + [[(0, 0.5, 0.5), (1, 0.5, 0.5)]]))


def box_pair_truth() -> SurfaceTruth:
    """A box ``[1/4, 3/4]^2 x [0.4, 0.8]`` standing on the box ``[0, 1]^2 x [0, 0.4]``: the
    surface of their union, closed, with 20 convex creases and 4 concave ones where
    they meet; corners: the 8 of the lower box and the 8 of the upper one."""
    lo1, hi1 = np.zeros(3), np.array([1.0, 1.0, 0.4])
    lo2, hi2 = np.array([0.25, 0.25, 0.4]), np.array([0.75, 0.75, 0.8])
    rects = _box_rects(lo1, hi1, top=False) + _holed_rects(lo1[:2], hi1[:2], lo2[:2], hi2[:2], 0.4)
    rects += [r for r in _box_rects(lo2, hi2) if not (r[0][2] == 0.4 and r[1][2] == 0 and r[2][2] == 0)]
    creases = np.concatenate([_box_edges(lo1, hi1), _box_edges(lo2, hi2)])
    return _truth(rects, creases=creases, corners=np.concatenate([_box_corners(lo1, hi1), _box_corners(lo2, hi2)]))


def holed_square_truth(hole: tuple[float, float] = (0.35, 0.65)) -> SurfaceTruth:
    """The unit square at ``z = 0`` minus the square ``hole^2``: boundary outside and around the hole."""
    a, b = hole
    outer = np.array([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], float)
    inner = np.array([(a, a, 0), (b, a, 0), (b, b, 0), (a, b, 0)], float)
    return _truth(_holed_rects((0, 0), (1, 1), (a, a), (b, b), 0.0),
                  boundaries=np.concatenate([_loop(outer), _loop(inner)]), corners=np.concatenate([outer, inner]))


# ---------------------------------------------------------------- sampling


def outlier_box(truth: SurfaceTruth, scale: float = 1.2) -> np.ndarray:
    """``(2, 3)`` lower and upper corner of the truth's bounding box scaled by
    ``scale`` about its centre; an axis where the shape is flat gets a width of
    ``(scale - 1) D``."""
    v = truth.mesh.vertices
    lo, hi = v.min(0), v.max(0)
    half = 0.5 * np.where(hi > lo, scale * (hi - lo), (scale - 1) * truth.diagonal)
    return np.stack([(lo + hi) / 2 - half, (lo + hi) / 2 + half])


def sample_surface(truth: SurfaceTruth, n: int, noise: float = 0.0, n_outliers: int = 0,
                   seed: int = 0) -> np.ndarray:
    """``(n + n_outliers, 3)`` points: ``n`` uniform by area on ``truth``, Gaussian
    noise of standard deviation ``noise * D``, then ``n_outliers`` uniform in
    :func:`outlier_box`.

    Example:
      >>> sample_surface(cube_truth(), 100, noise=0.01, n_outliers=10).shape
      (110, 3)
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"n must be an integer >= 1, got {n!r}")
    if not (isinstance(n_outliers, (int, np.integer)) and n_outliers >= 0):
        raise ValueError(f"n_outliers must be an integer >= 0, got {n_outliers!r}")
    if not (np.isfinite(noise) and noise >= 0):
        raise ValueError(f"noise must be a finite number >= 0, got {noise!r}")
    rng = np.random.default_rng(seed)
    points = truth.sample(n, rng)
    points = points + noise * truth.diagonal * rng.standard_normal(points.shape)
    # The outliers' own stream: changing n_outliers leaves the shape's samples as they are.
    box = outlier_box(truth)
    outliers = np.random.default_rng(np.random.SeedSequence([seed, 1])).uniform(box[0], box[1], (n_outliers, 3))
    return np.concatenate([points, outliers])


def _generator(make_truth, doc: str):
    def generate(n: int = 4000, noise: float = 0.0, n_outliers: int = 0, seed: int = 0) -> SurfaceSample:
        truth = make_truth()
        return SurfaceSample(sample_surface(truth, n, noise, n_outliers, seed), truth)

    generate.__doc__ = (f"``(points, truth)``: ``n`` samples of {doc} (see :func:`sample_surface` and "
                        f"the truth's own function for the shape).")
    return generate


staircase = _generator(staircase_truth, "a three-step staircase (5 creases, open)")
cylinder = _generator(cylinder_truth, "an open cylinder of radius 1/2 and height 1")
cone = _generator(cone_truth, "a cone with a tip and an open base")
cube = _generator(cube_truth, "the unit cube's surface")
crossing = _generator(crossing_truth, "two unit squares crossing at a line")
box_pair = _generator(box_pair_truth, "a box standing on a larger one")

SURFACES = {"staircase": staircase, "cylinder": cylinder, "cone": cone, "cube": cube, "crossing": crossing,
            "box_pair": box_pair}
"""Surface name -> generator ``f(n, noise=, n_outliers=, seed=) -> (points, truth)``."""


def _grid(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """A ``resolution`` x ``resolution`` grid of the unit square: ``(r+1)^2`` uv
    rows and ``2 r^2`` triangles."""
    i, j = np.meshgrid(np.arange(resolution + 1), np.arange(resolution + 1), indexing="ij")
    uv = np.stack([i.ravel(), j.ravel()], 1) / resolution
    a = (i[:-1, :-1] * (resolution + 1) + j[:-1, :-1]).ravel()
    b, c, d = a + resolution + 1, a + 1, a + resolution + 2
    return uv, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def rounded_cube_mesh(exponent: float = 8.0, resolution: int = 16) -> Mesh:
    """The superquadric ``|x|^p + |y|^p + |z|^p = 1`` mapped onto ``[0, 1]^3``: a
    smooth closed mesh that rounds the unit cube's creases and corners.

    Each face of the cube gets a ``resolution`` x ``resolution`` grid; every
    grid point moves along its ray from the centre onto the superquadric.
    With ``p = 8`` the corners are cut by ``(1 - 3^(-1/p)) / 2 ~ 0.064``
    along each axis.
    """
    if not exponent > 2 or resolution < 1:
        raise ValueError(f"need exponent > 2 and resolution >= 1, got {exponent}, {resolution}")
    uv, tris = _grid(resolution)
    faces, offset = [], 0
    for axis in range(3):
        others = [k for k in range(3) if k != axis]
        for side in (-1.0, 1.0):
            q = np.empty((len(uv), 3))
            q[:, axis] = side
            q[:, others] = 2 * uv - 1
            faces.append((q, tris + offset))
            offset += len(uv)
    q = np.concatenate([f[0] for f in faces])
    radius = np.sum(np.abs(q) ** exponent, axis=1) ** (1.0 / exponent)
    vertices = 0.5 + 0.5 * q / radius[:, None]
    return _merge(vertices, np.concatenate([f[1] for f in faces]), float(np.sqrt(3)))


def rounded_box(n: int = 4000, noise: float = 0.0, n_outliers: int = 0, seed: int = 0, exponent: float = 8.0,
                resolution: int = 16) -> RecoverySample:
    """Points on the unit cube and :func:`rounded_cube_mesh`, the smooth mesh a
    feature-lossy reconstruction would give: recovery must pull its vertices
    onto the cube's creases and corners."""
    truth = cube_truth()
    return RecoverySample(sample_surface(truth, n, noise, n_outliers, seed), truth,
                          rounded_cube_mesh(exponent, resolution))


def holed_square(n: int = 4000, noise: float = 0.0, n_outliers: int = 0, seed: int = 0,
                 hole: tuple[float, float] = (0.35, 0.65), resolution: int = 16) -> RecoverySample:
    """Points on the unit square minus a square hole, and a flat
    ``resolution`` x ``resolution`` grid mesh of the whole square covering the
    hole (as a hole-filling reconstruction gives): recovery must drop the
    facets over the hole and pull its border onto the hole's boundary. With
    the defaults no grid line lies on the hole's border."""
    if not 0 < hole[0] < hole[1] < 1:
        raise ValueError(f"hole must satisfy 0 < a < b < 1, got {hole}")
    truth = holed_square_truth(hole)
    uv, tris = _grid(resolution)
    mesh = Mesh(np.c_[uv, np.zeros(len(uv))], tris)
    return RecoverySample(sample_surface(truth, n, noise, n_outliers, seed), truth, mesh)


RECOVERY = {"rounded_box": rounded_box, "holed_square": holed_square}
"""Recovery example name -> generator ``f(n, noise=, n_outliers=, seed=) -> (points, truth, mesh)``."""
