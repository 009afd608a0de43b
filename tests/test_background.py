"""The background-noise estimate (otjax.background) against known mixtures."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from otjax import datasets, datasets3d
from otjax.background import estimate_background, flat_noise, near_shape, shape_weights
from otjax.metrics3d import point_triangle_distance


def uneven_star(n=3000, noise=0.01, seed=0):
    """A star whose right half is sampled ten times more sparsely than its left."""
    pts, truth = datasets.star(n, noise=noise, seed=seed)
    keep = (pts[:, 0] < 0) | (np.random.default_rng(seed + 7).random(len(pts)) < 0.1)
    return pts[keep], truth


@pytest.mark.parametrize("n_shape, n_outliers", [(600, 600), (3000, 3000), (3000, 1000)])
def test_recovers_the_density_of_uniform_outliers(n_shape, n_outliers):
    pts, truth = datasets.star(n_shape, noise=0.02, seed=3)
    mixed, _ = datasets.with_outliers(pts, truth, n_outliers, margin=0.2, seed=4)
    est = estimate_background(mixed)
    # The outliers fill the bounding box of the mixture: that is the truth.
    area = float(np.prod(mixed.max(0) - mixed.min(0)))
    assert est.found
    assert est.density == pytest.approx(n_outliers / area, rel=0.15)
    assert est.fraction == pytest.approx(n_outliers / len(mixed), rel=0.15)
    # The shape's points are mostly shape, the outliers mostly background.
    p = est.probability
    assert p[:n_shape].mean() < 0.35 < 0.6 < p[n_shape:].mean()


@pytest.mark.parametrize("make", [
    lambda: datasets.star(3000, noise=0.0, seed=0)[0],
    lambda: datasets.star(3000, noise=0.01, seed=1)[0],
    lambda: datasets.star(3000, noise=0.02, seed=2)[0],
    lambda: uneven_star()[0],
    lambda: datasets.skyline(2000, noise=0.01, seed=0)[0],
    lambda: datasets.circle(200, noise=0.01, seed=0)[0],
    lambda: datasets.junctions(2000, noise=0.005, seed=0)[0],
], ids=["clean", "noise-1", "noise-2", "uneven", "skyline", "sparse-circle", "junctions"])
def test_a_shape_without_outliers_has_no_background(make):
    est = estimate_background(make())
    assert not est.found and est.fraction == 0 and not est.probability.any()


def test_does_not_depend_on_units():
    pts, truth = datasets.star(1500, noise=0.02, seed=5)
    mixed, _ = datasets.with_outliers(pts, truth, 1500, margin=0.2, seed=6)
    a = estimate_background(mixed)
    b = estimate_background(mixed * 1000.0 + 5.0)
    assert b.fraction == pytest.approx(a.fraction, rel=1e-9)
    assert b.density == pytest.approx(a.density / 1e6, rel=1e-9)
    np.testing.assert_allclose(b.probability, a.probability, rtol=1e-9, atol=1e-12)


def test_too_few_points_or_a_flat_box():
    assert not estimate_background(np.random.default_rng(0).random((20, 2))).found
    line = np.stack([np.linspace(0, 1, 500), np.zeros(500)], 1)
    assert not estimate_background(line).found


def test_fills_a_box_in_3d_too():
    rng = np.random.default_rng(8)
    plane = np.c_[rng.random((4000, 2)), 0.5 + 0.002 * rng.standard_normal(4000)]
    noise = rng.random((1000, 3))
    est = estimate_background(np.vstack([plane, noise]))
    assert est.found and est.fraction == pytest.approx(1000 / 5000, rel=0.25)
    assert not estimate_background(plane).found


@pytest.mark.parametrize("n_outliers", [300, 900])
def test_finds_outliers_around_a_shape_that_fills_its_box(n_outliers):
    """An open cylinder touches its box on every side, so most outliers have
    its points among their neighbours and read denser than the background:
    the count must be taken where the density reads as background. (Those
    near the surface keep a low probability: the estimate is local.)"""
    pts = datasets3d.cylinder(3000, n_outliers=n_outliers, seed=1).points
    est = estimate_background(pts)
    assert est.found
    assert est.fraction == pytest.approx(n_outliers / len(pts), rel=0.2)
    shape, outliers = est.probability[:3000].mean(), est.probability[3000:].mean()
    assert shape < 0.1 and outliers > 5 * shape


@pytest.mark.parametrize("name, noise", [("cylinder", 0.0), ("cylinder", 0.01), ("staircase", 0.01), ("cube", 0.0),
                                         ("crossing", 0.0)])
def test_a_surface_without_outliers_has_no_background(name, noise):
    assert not estimate_background(datasets3d.SURFACES[name](3000, noise=noise, seed=2).points).found


def test_shape_weights_give_background_points_almost_nothing_and_the_shape_most():
    """A dense line over uniform noise: the noise keeps a few percent of its
    mass in all (where ``1 - beta / rho`` would leave it a sizeable share:
    k-NN estimates of a uniform field scatter about 25% around it), the
    line's points most of theirs."""
    rng = np.random.default_rng(5)
    noise = rng.random((3000, 2))
    t = rng.random(3000)
    line = np.stack([t, 0.5 + 0.002 * rng.standard_normal(3000)], 1)
    est = estimate_background(np.concatenate([line, noise]))
    assert est.found
    w = shape_weights(est)
    far = np.abs(noise[:, 1] - 0.5) > 0.05
    naive = 1.0 - est.probability[3000:][far]
    assert w[3000:][far].mean() < 0.05 < naive.mean()
    assert np.median(w[:3000]) > 0.8
    assert ((w >= 0) & (w <= 1)).all()
    no_background = estimate_background(line)
    assert not no_background.found and (shape_weights(no_background) == 1).all()


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), noise=st.sampled_from([0.0, 1e-3, 1e-2]),
       scale=st.floats(1e-3, 1e3), fold=st.floats(30.0, 150.0))
# A border point with 5 of its 16 neighbours on the other sheet, beside two crease points.
@example(seed=27517, noise=0.0, scale=1.0, fold=30.0)
def test_near_shape_drops_points_off_a_folded_sheet_and_keeps_the_sheet(seed, noise, scale, fold):
    """Two half-planes meeting at ``fold`` degrees on the y axis (a crease),
    noise of standard deviation ``noise`` (side 1), rotated, scaled and
    shifted: the sheet is kept, crease points included (at most 2 of its
    1,500 points go: a corner of the crease and a noise tail at the border
    can stand off every flat of their neighbours), and points
    ten to fifteen standard deviations (at least 0.05) off the sheet, away
    from the crease, the other sheet and each other, are dropped."""
    rng = np.random.default_rng(seed)
    n = 1500
    u, y = rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    a = np.radians(fold)
    side = rng.random(n) < 0.5
    sheet = np.where(side[:, None], np.c_[u, y, 0 * u], np.c_[u * np.cos(a), y, u * np.sin(a)])
    sheet = sheet + noise * rng.standard_normal(sheet.shape)
    # Off the first half-plane over a 3 x 3 grid, 0.25 apart (a neighbourhood spans about 0.1 here).
    grid = np.stack(np.meshgrid([0.35, 0.6, 0.85], [0.25, 0.5, 0.75]), -1).reshape(-1, 2)
    m = len(grid)
    off = np.c_[grid + rng.uniform(-0.02, 0.02, (m, 2)),
                -max(10 * noise, 0.05) * rng.uniform(1, 1.5, m)]  # the side away from the other sheet
    points = np.concatenate([sheet, off]) @ np.linalg.qr(rng.standard_normal((3, 3)))[0] * scale + rng.uniform(-1, 1, 3) * scale
    near = near_shape(points, np.ones(len(points)))
    assert np.count_nonzero(~near[:n]) <= 2, f"sheet points dropped: {np.flatnonzero(~near[:n])[:5]}"
    assert not near[n:].any(), f"{int(near[n:].sum())} off-sheet points kept"


@pytest.mark.parametrize("dim", [2, 3])
def test_near_shape_keeps_every_point_of_an_exact_flat(dim):
    """No point off any flat: every point stays (nothing left for the second chance)."""
    rng = np.random.default_rng(dim)
    points = np.c_[rng.random((400, dim - 1)), np.zeros(400)]
    assert near_shape(points, np.ones(400)).all()


def test_near_shape_in_2d_keeps_a_noisy_line_and_drops_points_off_it():
    rng = np.random.default_rng(3)
    line = np.c_[rng.uniform(0, 1, 800), 0.002 * rng.standard_normal(800)]
    x = np.linspace(0.2, 0.8, 5)  # 0.15 apart: no off point among another's neighbours
    off = np.c_[x, rng.choice([-1, 1], 5) * rng.uniform(0.03, 0.05, 5)]
    near = near_shape(np.concatenate([line, off]), np.ones(805))
    assert np.count_nonzero(~near[:800]) <= 2
    assert not near[800:].any()


def test_near_shape_leaves_the_surface_and_drops_most_outliers_around_a_cylinder():
    """The outliers that :func:`shape_weights` leaves mass to are those near the
    cylinder; most of them stand off its tangent planes and go."""
    truth = datasets3d.cylinder_truth()
    points = datasets3d.sample_surface(truth, 3000, n_outliers=300, seed=4)
    w = shape_weights(estimate_background(points))
    near = near_shape(points, w)
    assert near[:3000].all()
    kept_before = w[3000:].sum()
    assert kept_before > 100  # the premise: density alone leaves the outliers real mass
    assert (w[3000:] * near[3000:]).sum() < 0.5 * kept_before


@pytest.mark.parametrize("shape", ["cylinder", "staircase", "crossing"])
def test_near_shape_drops_outliers_whose_neighbourhood_is_wider_than_their_neighbours(shape):
    """Noise-free shapes with 10% uniform outliers: of the mass that density
    alone leaves to outliers more than 3% D off the shape, under a third
    stays (an own-flat test alone keeps 40-65% of it: an outlier's
    neighbourhood is a wide patch of the surface with a flat tilted towards
    it), and no point of the shape goes (crease and border points are as
    thick as their neighbours)."""
    truth = getattr(datasets3d, f"{shape}_truth")()
    diagonal = float(np.linalg.norm(np.ptp(truth.mesh.vertices, 0)))
    points = datasets3d.sample_surface(truth, 3000, n_outliers=300, seed=4)
    w = shape_weights(estimate_background(points))
    near = near_shape(points, w)
    assert near[:3000].all()
    far = point_triangle_distance(points[3000:], truth.mesh.vertices[truth.mesh.triangles]) > 0.03 * diagonal
    assert (w[3000:] * near[3000:])[far].sum() < (1 / 3) * w[3000:][far].sum()


@pytest.mark.parametrize("sigma", [0.0, 0.002, 0.005])
@pytest.mark.parametrize("fold", [None, 60.0])
def test_flat_noise_reads_the_noise_of_a_sheet_with_or_without_a_crease(sigma, fold):
    """Gaussian noise across a unit square (or two half squares folded at a
    crease), rotated and scaled: the estimate is the standard deviation to
    within 10% (noise a tenth of the neighbourhoods' width), 0 when exact."""
    rng = np.random.default_rng(int(sigma * 1e4 + (fold or 0)))
    u, y = rng.random(4000), rng.random(4000)
    a = np.radians(fold or 180.0)
    folded = np.c_[0.5 - (u - 0.5) * np.cos(a), y, (u - 0.5) * np.sin(a)]
    sheet = np.where((u < 0.5)[:, None], np.c_[u, y, 0 * u], folded)
    points = sheet + sigma * rng.standard_normal((4000, 3))
    rotation = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    got = flat_noise(points @ rotation * 7.0 + 3.0) / 7.0
    if sigma == 0:
        assert got < 1e-9
    else:
        assert abs(got - sigma) <= 0.1 * sigma
