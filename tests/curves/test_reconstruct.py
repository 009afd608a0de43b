"""``reconstruct_curve`` on small inputs: determinism, scaling, masses,
tolerance mode, filters, refinement, image input, parameter errors.

The acceptance cases on shapes with known truth have a file each:
``test_reconstruct_{clean_star,star,skyline,junctions,outliers}.py``.
"""

import json

import numpy as np
import pytest

import otjax
from otjax import datasets, metrics


def small_case(seed=0, n=200):
    pts, _ = datasets.star(n, noise=0.01, seed=seed)
    return pts


@pytest.mark.parametrize("seed", [4, 5])
def test_refinement_never_increases_cost(seed):
    """200 points: the refinement step is taken or refused after any run, and
    the two runs per seed only need a curve for L-BFGS to move."""
    pts = small_case(seed, n=200)
    closed_form = otjax.reconstruct_curve(pts, n_vertices=10)
    refined = otjax.reconstruct_curve(pts, n_vertices=10, refine=True)
    assert refined.total_cost <= closed_form.total_cost
    info = refined.history["refine"]
    assert info["values"][-1] < info["values"][0]  # L-BFGS lowered its own objective
    assert info["accepted"] == (refined.total_cost < closed_form.total_cost)


def test_same_seed_gives_identical_bytes(tmp_path):
    pts = small_case()
    a = otjax.reconstruct_curve(pts, n_vertices=10, seed=7)
    b = otjax.reconstruct_curve(pts, n_vertices=10, seed=7)
    for ext in ("svg", "json"):
        a.save(tmp_path / f"a.{ext}")
        b.save(tmp_path / f"b.{ext}")
    assert (tmp_path / "a.svg").read_bytes() == (tmp_path / "b.svg").read_bytes()
    # The JSON records the wall time, the one field that may differ.
    ja, jb = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    ja.pop("seconds"), jb.pop("seconds")
    assert json.dumps(ja) == json.dumps(jb)


def test_scaling_all_masses_scales_cost_only():
    # A power of two scales every cost exactly in floating point, so the greedy
    # makes the same decisions bit for bit (with a factor 3, rounding can swap
    # two candidates whose costs agree to 1e-16, and the paths diverge).
    pts = small_case(1)
    one = otjax.reconstruct_curve(pts, n_vertices=10)
    four = otjax.reconstruct_curve(pts, np.full(len(pts), 4.0), n_vertices=10)
    np.testing.assert_array_equal(four.vertices, one.vertices)
    np.testing.assert_array_equal(four.edges, one.edges)
    np.testing.assert_allclose(four.total_cost, 4 * one.total_cost, rtol=1e-12)
    np.testing.assert_allclose(four.edge_mass, 4 * one.edge_mass, rtol=1e-12)
    np.testing.assert_allclose(four.edge_relevance, one.edge_relevance, rtol=1e-12)


def test_masses_weight_the_fit():
    # Two parallel strokes, one with 20x the mass: a single edge must sit
    # much closer to the heavy one.
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, 400)
    pts = np.concatenate([np.c_[x[:200], np.zeros(200)], np.c_[x[200:], np.full(200, 0.1)]])
    mass = np.concatenate([np.full(200, 20.0), np.ones(200)])
    result = otjax.reconstruct_curve(pts, mass, n_vertices=2)
    assert len(result.edges) == 1
    assert np.abs(result.vertices[:, 1]).max() < 0.02


def test_tolerance_mode_bounds_the_error_and_is_monotone():
    pts = small_case(2)
    loose = otjax.reconstruct_curve(pts, tolerance=0.05)
    tight = otjax.reconstruct_curve(pts, tolerance=0.02)
    assert len(tight.vertices) > len(loose.vertices) >= 10
    for r, tol in ((loose, 0.05), (tight, 0.02)):
        length2 = ((r.vertices[r.edges[:, 0]] - r.vertices[r.edges[:, 1]]) ** 2).sum(1)
        rms = np.sqrt(length2 / r.edge_relevance)  # sqrt((N + T) / M) per kept edge
        assert np.all(rms <= np.sqrt(2) * tol * (1 + 1e-9))


def test_filters_only_remove_edges_and_match_after_the_fact():
    pts = small_case(3)
    full = otjax.reconstruct_curve(pts, n_vertices=14)
    cut = float(np.median(full.edge_relevance))
    kept = otjax.reconstruct_curve(pts, n_vertices=14, relevance=cut, density=0.5)
    dens = full.edge_density()
    expect = (full.edge_relevance >= cut) & (dens >= 0.5 * dens.max())
    assert 0 < len(kept.edges) == int(expect.sum()) < len(full.edges)
    assert np.all(kept.edge_relevance >= cut)
    assert kept.total_cost == full.total_cost  # filtering is after the transport
    later = full.filtered(relevance=cut, density=0.5)
    np.testing.assert_array_equal(later.vertices[later.edges], kept.vertices[kept.edges])


def test_image_input_recovers_the_drawing():
    image, truth = datasets.drawing(size=64, shape="star")
    pts, mass = otjax.image_to_points(image, invert=True, threshold=0.05)
    result = otjax.reconstruct_curve(pts, mass, n_vertices=10)
    err = metrics.corner_errors(result.vertices, truth["corners"])
    assert err.max() <= 3.0, f"corner errors in pixels {err}"


@pytest.mark.parametrize("bad, message", [
    ({"n_vertices": 0}, "n_vertices"),
    ({"n_vertices": 10**6}, "n_vertices"),
    ({"n_vertices": 10, "relevance": -1.0}, "relevance"),
    ({"n_vertices": 10, "tolerance": 0.0}, "tolerance"),
    ({"n_vertices": 10, "relocation": 2.5}, "relocation"),
    ({}, "n_vertices"),
])
def test_bad_parameters_are_named(bad, message):
    with pytest.raises(ValueError, match=message):
        otjax.reconstruct_curve(small_case(), **bad)


@pytest.mark.parametrize("queue", ["exhaustive", "parallel"])
def test_a_vertex_whose_points_sit_on_edges_to_the_box_is_reported(queue):
    """Three points decimated to one vertex: their mass goes onto edges towards the pinned box
    corners (scaffolding, never output); the vertex at their end must still be in the result."""
    points = np.array([[0.0, 0.0], [0.0, 4.0], [1.0, 2.0]])
    r = otjax.reconstruct_curve(points, n_vertices=1, queue=queue, background="none")
    assert len(r.vertices) == 1 and r.isolated.tolist() == [0] and len(r.edges) == 0
    diameter = np.linalg.norm(points.max(0) - points.min(0))
    assert np.linalg.norm(r.vertices[0] - points.mean(0)) < diameter  # near the points, not a box corner
