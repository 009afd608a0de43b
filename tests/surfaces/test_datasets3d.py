"""The 3D ground-truth surfaces: samples on the surface, exact distances,
area-uniform sampling, seeded noise and outliers, recovery meshes."""

import numpy as np
import pytest
from scipy import stats

from otjax import datasets, datasets3d
from otjax.datasets3d import RECOVERY, SURFACES
from tests.surfaces.shapes import point_triangle_distance as oracle_distance

ALL = {**SURFACES, **RECOVERY}
POLYHEDRAL = ["staircase", "cube", "crossing", "box_pair"]


@pytest.mark.parametrize("name", sorted(ALL))
def test_clean_samples_and_features_lie_on_the_truth(name):
    points, truth = ALL[name](3000, seed=3)[:2]
    assert points.shape == (3000, 3)
    assert truth.distance(points).max() <= 1e-12 * truth.diagonal
    for feature in (truth.creases.reshape(-1, 3), truth.boundaries.reshape(-1, 3), truth.corners):
        if len(feature):
            assert truth.distance(feature).max() <= 1e-12
    v = truth.mesh.vertices
    assert truth.diagonal == pytest.approx(np.linalg.norm(v.max(0) - v.min(0)))


@pytest.mark.parametrize("name", POLYHEDRAL + ["holed_square"])
def test_distance_matches_brute_force_on_the_exact_mesh(name):
    truth = ALL[name](10)[1]
    rng = np.random.default_rng(0)
    x = rng.uniform(-0.3, 1.3, (400, 3))
    near = truth.sample(200, rng) + 0.01 * rng.standard_normal((200, 3))
    x = np.concatenate([x, near])
    want = oracle_distance(x, truth.mesh.vertices[truth.mesh.triangles])
    np.testing.assert_allclose(truth.distance(x), want, rtol=1e-12, atol=1e-12)
    # The exact mesh has the truth's area.
    t = truth.mesh.vertices[truth.mesh.triangles]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()
    assert area == pytest.approx(truth.area, rel=1e-12)


def test_revolution_distances_match_closed_forms():
    rng = np.random.default_rng(1)
    x = rng.uniform(-1, 1.5, (500, 3))
    rho, z = np.hypot(x[:, 0], x[:, 1]), x[:, 2]
    cyl = datasets3d.cylinder_truth(radius=0.5, height=1.0)
    np.testing.assert_allclose(cyl.distance(x), np.hypot(rho - 0.5, z - np.clip(z, 0, 1)), atol=1e-14)
    # Cone: brute force over a fine grid of its generatrix in the point's own meridian plane.
    cone = datasets3d.cone_truth(radius=0.5, height=1.0)
    t = np.linspace(0, 1, 20001)
    gen = np.stack([0.5 * t, 1.0 - t], 1)  # (r, z) from the tip to the base
    want = np.min(np.hypot(rho[:, None] - gen[None, :, 0], z[:, None] - gen[None, :, 1]), axis=1)
    np.testing.assert_allclose(cone.distance(x), want, atol=1e-4)
    assert cone.area == pytest.approx(np.pi * 0.5 * np.hypot(0.5, 1.0))


@pytest.mark.parametrize("name", POLYHEDRAL + ["holed_square"])
def test_patch_counts_follow_area(name):
    points, truth = ALL[name](20000, seed=5)[:2]
    o, u, v = truth.rectangles[:, 0], truth.rectangles[:, 1], truth.rectangles[:, 2]
    d = points[:, None] - o[None]
    s = np.sum(d * u, -1) / np.sum(u * u, -1)
    t = np.sum(d * v, -1) / np.sum(v * v, -1)
    off = d - s[..., None] * u - t[..., None] * v
    inside = (np.abs(off).max(-1) < 1e-12) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    # A point on a shared border is in two patches: count it in the first only.
    owner = np.argmax(inside, axis=1)
    assert inside.any(axis=1).all()
    counts = np.bincount(owner, minlength=len(o))
    area = truth.areas()
    assert stats.chisquare(counts, area / area.sum() * len(points)).pvalue > 1e-3
    # Within the largest patch, both coordinates are uniform.
    k = int(np.argmax(area))
    mine = owner == k
    assert stats.kstest(s[mine, k], "uniform").pvalue > 1e-3
    assert stats.kstest(t[mine, k], "uniform").pvalue > 1e-3


def test_surfaces_of_revolution_are_sampled_uniformly_by_area():
    points, _ = datasets3d.cylinder(20000, seed=2)
    theta = np.arctan2(points[:, 1], points[:, 0])
    assert stats.kstest((theta + np.pi) / (2 * np.pi), "uniform").pvalue > 1e-3
    assert stats.kstest(points[:, 2], "uniform").pvalue > 1e-3
    points, _ = datasets3d.cone(20000, seed=2)
    # The area within slant distance s of the tip grows as s^2.
    slant = np.linalg.norm(points - [0, 0, 1], axis=1) / np.hypot(0.5, 1.0)
    assert stats.kstest(slant, lambda x: np.clip(x, 0, 1) ** 2).pvalue > 1e-3
    theta = np.arctan2(points[:, 1], points[:, 0])
    assert stats.kstest((theta + np.pi) / (2 * np.pi), "uniform").pvalue > 1e-3


def test_seeded_noise_and_outliers():
    clean, truth = datasets3d.staircase(2000, seed=7)
    again, _ = datasets3d.staircase(2000, seed=7)
    np.testing.assert_array_equal(clean, again)
    assert not np.array_equal(clean, datasets3d.staircase(2000, seed=8)[0])
    noisy, _ = datasets3d.staircase(2000, noise=0.02, seed=7)
    moved = noisy - clean
    assert moved.std() == pytest.approx(0.02 * truth.diagonal, rel=0.05)
    with_out, _ = datasets3d.staircase(2000, noise=0.02, n_outliers=500, seed=7)
    np.testing.assert_array_equal(with_out[:2000], noisy)  # outliers come last, the shape unchanged
    box = datasets3d.outlier_box(truth)
    lo, hi = truth.mesh.vertices.min(0), truth.mesh.vertices.max(0)
    np.testing.assert_allclose(box[1] - box[0], 1.2 * (hi - lo))
    np.testing.assert_allclose(box.mean(0), (lo + hi) / 2)
    out = with_out[2000:]
    assert np.all((out >= box[0]) & (out <= box[1]))
    assert out.std(axis=0) == pytest.approx((box[1] - box[0]) / np.sqrt(12), rel=0.1)  # uniform in the box


def test_flat_shape_gets_an_outlier_slab():
    truth = datasets3d.holed_square_truth()
    box = datasets3d.outlier_box(truth)
    assert box[1, 2] - box[0, 2] == pytest.approx(0.2 * truth.diagonal)


@pytest.mark.parametrize("bad", [{"n": 0}, {"n": 2.5}, {"noise": -0.1}, {"noise": np.nan}, {"n_outliers": -1}])
def test_bad_arguments_are_value_errors(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        datasets3d.cube(**{"n": 10, **bad})


def test_rounded_box_mesh_is_a_closed_smooth_surface_near_the_cube():
    points, truth, mesh = datasets3d.rounded_box(500, seed=0, exponent=8.0, resolution=8)
    q = 2 * mesh.vertices - 1
    np.testing.assert_allclose(np.sum(np.abs(q) ** 8, axis=1), 1.0, rtol=1e-12)
    tri = np.sort(mesh.triangles, axis=1)
    edges, count = np.unique(np.concatenate([tri[:, [0, 1]], tri[:, [0, 2]], tri[:, [1, 2]]]), axis=0,
                             return_counts=True)
    assert np.all(count == 2)  # closed, every edge on two triangles
    assert len(mesh.vertices) - len(edges) + len(tri) == 2  # a sphere
    # It rounds the corners by (1 - 3^(-1/8)) / 2 along each axis, and stays within the cube.
    cut = (1 - 3 ** (-1 / 8)) / 2
    assert truth.distance(mesh.vertices).max() == pytest.approx(cut, rel=1e-9)  # the corner vertex, to a face
    assert np.all((mesh.vertices >= 0) & (mesh.vertices <= 1))
    assert truth.distance(points).max() < 1e-12


def test_holed_square_mesh_covers_the_hole():
    points, truth, mesh = datasets3d.holed_square(2000, hole=(0.35, 0.65), resolution=16)
    centre = mesh.vertices[mesh.triangles].mean(axis=1)
    in_hole = np.all((centre[:, :2] > 0.35) & (centre[:, :2] < 0.65), axis=1)
    assert in_hole.sum() >= 4 * 4 * 2  # at least the grid cells wholly inside the hole
    assert not np.any(np.all((points[:, :2] > 0.35) & (points[:, :2] < 0.65), axis=1))
    grid = np.unique(mesh.vertices[:, 0])
    assert not np.any(np.isclose(grid, 0.35) | np.isclose(grid, 0.65))  # no grid line on the hole's border
    assert len(truth.boundaries) == 8


def test_generators_are_reexported_from_datasets():
    assert datasets.cube is datasets3d.cube and datasets.SURFACES is SURFACES
    assert datasets.star is not None  # the 2D ones are still there
