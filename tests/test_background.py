"""The background-noise estimate (otjax.background) against known mixtures."""

import numpy as np
import pytest

from otjax import datasets, datasets3d
from otjax.background import estimate_background


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
    from otjax.background import shape_weights

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
