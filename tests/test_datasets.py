"""Synthetic shapes: samples on the truth, features consistent with the segment graph, noise level."""

import importlib.util
import json
import pathlib
from collections import Counter

import numpy as np
import pytest

from otjax import datasets
from otjax.datasets import EXAMPLES, circle, drawing, junctions, load_example, skyline, star, with_outliers

GENERATORS = {"star": star, "skyline": skyline, "junctions": junctions, "circle": circle}


def _distance_to_segments(p, segs):
    """Independent of otjax.metrics: clamp-project every point on every segment, keep the nearest."""
    a, b = segs[:, 0], segs[:, 1]
    ab = b - a
    t = np.clip(((p[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    return np.linalg.norm(p[:, None] - (a + t[..., None] * ab), axis=-1).min(1)


def _degree(segments):
    """Endpoint -> number of segment ends there (exact coordinates: truths share vertex arrays)."""
    return Counter(tuple(p) for p in segments.reshape(-1, 2).tolist())


@pytest.mark.parametrize("name", GENERATORS)
class TestGenerators:
    def test_clean_samples_on_truth(self, name):
        pts, truth = GENERATORS[name](500, seed=3)
        assert pts.shape == (500, 2) and pts.dtype == np.float64
        assert _distance_to_segments(pts, truth["segments"]).max() < 1e-12

    def test_truth_keys_and_shapes(self, name):
        _, truth = GENERATORS[name](10)
        assert truth["segments"].ndim == 3 and truth["segments"].shape[1:] == (2, 2)
        for key in ("corners", "junctions", "ends"):
            assert truth[key].ndim == 2 and truth[key].shape[1] == 2
        assert truth["junction_degree"].shape == (len(truth["junctions"]),)
        flat = truth["segments"].reshape(-1, 2)
        assert truth["diagonal"] == pytest.approx(np.hypot(*np.ptp(flat, axis=0)))

    def test_features_match_segment_graph(self, name):
        _, truth = GENERATORS[name](10)
        degree = _degree(truth["segments"])
        for p in truth["ends"].tolist():
            assert degree[tuple(p)] == 1
        for p, k in zip(truth["junctions"].tolist(), truth["junction_degree"]):
            assert degree[tuple(p)] == k >= 3
        for p in truth["corners"].tolist():
            assert tuple(p) in degree
        # Conversely every vertex that is not a plain pass-through is listed.
        listed = {tuple(p) for key in ("ends", "junctions") for p in truth[key].tolist()}
        assert {p for p, k in degree.items() if k != 2} == listed

    def test_deterministic_for_a_seed(self, name):
        a, _ = GENERATORS[name](200, noise=0.01, seed=7)
        b, _ = GENERATORS[name](200, noise=0.01, seed=7)
        c, _ = GENERATORS[name](200, noise=0.01, seed=8)
        np.testing.assert_array_equal(a, b)
        assert not np.allclose(a, c)

    def test_noise_std(self, name):
        # The noise is drawn last, so for one seed noisy minus clean is exactly the noise.
        clean, truth = GENERATORS[name](20_000, seed=1)
        noisy, _ = GENERATORS[name](20_000, noise=0.02, seed=1)
        assert np.std(noisy - clean) == pytest.approx(0.02 * truth["diagonal"], rel=0.1)

    def test_rejects_bad_arguments(self, name):
        with pytest.raises(ValueError, match="n must"):
            GENERATORS[name](0)
        with pytest.raises(ValueError, match="noise"):
            GENERATORS[name](10, noise=-0.1)


def test_star_corners_alternate_tip_and_notch():
    _, truth = star(10, points=4, inner=0.5)
    radius = np.linalg.norm(truth["corners"], axis=1)
    np.testing.assert_allclose(radius, [1.0, 0.5] * 4)
    assert len(truth["segments"]) == 8


def test_skyline_is_axis_aligned_with_right_angle_corners():
    _, truth = skyline(10, steps=6)
    d = truth["segments"][:, 1] - truth["segments"][:, 0]
    assert np.all((d[:, 0] == 0) ^ (d[:, 1] == 0))  # each piece horizontal or vertical, none empty
    assert np.all(d[:-1, 0] * d[1:, 0] == 0)  # consecutive pieces alternate: every vertex turns
    assert len(truth["corners"]) == 12 and len(truth["ends"]) == 2
    np.testing.assert_array_equal(truth["ends"][:, 1], [0.0, 0.0])


def test_junctions_geometry_supports_a_two_percent_test():
    _, truth = junctions(10)
    diag = truth["diagonal"]
    assert sorted(truth["junction_degree"].tolist()) == [3, 4]
    assert np.linalg.norm(truth["junctions"][0] - truth["junctions"][1]) >= 0.25 * diag
    lengths = np.linalg.norm(truth["segments"][:, 1] - truth["segments"][:, 0], axis=1)
    assert lengths.min() >= 0.15 * diag
    # Every vertex of the shape is a corner, and corners are far apart compared with 2% of D.
    assert {tuple(p) for p in truth["corners"].tolist()} == set(_degree(truth["segments"]))
    c = truth["corners"]
    gaps = np.linalg.norm(c[:, None] - c[None], axis=2) + np.eye(len(c)) * diag
    assert gaps.min() >= 0.15 * diag


def test_circle_polygon():
    pts, truth = circle(300, radius=2.0)
    assert truth["segments"].shape == (720, 2, 2) and truth["corners"].shape == (0, 2)
    np.testing.assert_allclose(np.linalg.norm(truth["segments"][:, 0], axis=1), 2.0)
    assert np.abs(np.linalg.norm(pts, axis=1) - 2.0).max() <= 2.0 * (1 - np.cos(np.pi / 720)) + 1e-12


class TestOutliers:
    def test_count_box_and_untouched_inliers(self):
        pts, truth = skyline(500, seed=2)
        out, t2 = with_outliers(pts, truth, 400, seed=5)
        assert out.shape == (900, 2) and t2["n_outliers"] == 400
        np.testing.assert_array_equal(out[:500], pts)
        flat = truth["segments"].reshape(-1, 2)
        lo, hi = flat.min(0), flat.max(0)
        np.testing.assert_allclose(t2["outlier_box"], [lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo)])
        extra = out[500:]
        assert np.all((extra >= t2["outlier_box"][0]) & (extra <= t2["outlier_box"][1]))
        # Uniform, so they spread to the box's margins rather than hugging the shape.
        assert np.any(extra[:, 1] < lo[1]) and np.any(extra[:, 0] > hi[0])
        assert "n_outliers" not in truth

    def test_rejects_negative_count(self):
        with pytest.raises(ValueError):
            with_outliers(*star(10), -1)


@pytest.mark.parametrize("shape", ["star", "skyline", "junctions", "circle"])
def test_drawing_ink_lies_on_truth(shape):
    size, width = 80, 2.0
    img, truth = drawing(size, shape, line_width=width)
    assert img.shape == (size, size) and img.min() == 0.0 and img.max() == 1.0
    rows, cols = np.nonzero(img < 0.5)
    centres = np.stack([cols + 0.5, size - rows - 0.5], 1)
    assert _distance_to_segments(centres, truth["segments"]).max() <= width
    # And the stroke follows the whole shape: every point of the truth is near a dark pixel.
    t = np.linspace(0, 1, 20)[:, None, None]
    along = (truth["segments"][None, :, 0] * (1 - t) + truth["segments"][None, :, 1] * t).reshape(-1, 2)
    gap = np.linalg.norm(along[:, None] - centres[None], axis=2).min(1)
    assert gap.max() <= 1.0
    # Truth stays inside the image.
    assert truth["segments"].min() > 0 and truth["segments"].max() < size


def test_drawing_orientation_is_y_up():
    # The skyline is not symmetric under y -> -y: a flipped image would leave its roof corners white.
    size = 64
    img, truth = drawing(size, "skyline")
    x, y = truth["corners"].T
    rows, cols = (size - y).astype(int), x.astype(int)  # the pixel whose square contains each corner
    assert img[rows, cols].max() < 0.5


@pytest.mark.parametrize("name", EXAMPLES)
def test_load_example(name):
    pts, masses, truth, defaults = load_example(name, n=300)
    assert isinstance(EXAMPLES[name], str) and EXAMPLES[name]
    assert pts.ndim == 2 and pts.shape[1] == 2 and np.all(np.isfinite(pts))
    np.testing.assert_array_equal(masses, np.ones(len(pts)))
    assert isinstance(defaults["n_vertices"], int) and isinstance(defaults["relevance"], float)
    assert len(pts) == 300 + truth.get("n_outliers", 0)
    if name in ("skyline", "junctions"):
        vertices = {tuple(p) for key in ("corners", "ends") for p in truth[key].tolist()}
        assert defaults["n_vertices"] == len(vertices)


def test_example_settings():
    pts, _, truth, defaults = load_example("star-outliers")
    assert len(pts) == 6000 and truth["n_outliers"] == 3000 and defaults["n_vertices"] == 10
    pts, _, truth, _ = load_example("noisy-star")
    assert len(pts) == 3000 and truth["params"]["noise"] == 0.01
    a = load_example("skyline", seed=4)[0]
    np.testing.assert_array_equal(a, load_example("skyline", seed=4)[0])


def test_unknown_example_lists_names():
    with pytest.raises(ValueError, match="noisy-star.*circle|circle.*noisy-star"):
        load_example("nope")


def _make_data_module():
    path = pathlib.Path(__file__).parent.parent / "scripts" / "make_data.py"
    spec = importlib.util.spec_from_file_location("make_data", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_make_data_script(tmp_path):
    make_data = _make_data_module()
    out = tmp_path / "s.xy"
    assert make_data.main(["junctions", "-n", "50", "--outliers", "5", "--seed", "2", "-o", str(out)]) == 0
    rows = np.loadtxt(out)
    assert rows.shape == (55, 3) and np.all(rows[:, 2] == 1)
    expected, truth = datasets.generate("junctions", n=50, n_outliers=5, seed=2)
    np.testing.assert_array_equal(rows[:, :2], expected)  # %.17g round-trips float64
    saved = json.loads((tmp_path / "s.truth.json").read_text())
    np.testing.assert_array_equal(saved["segments"], truth["segments"])
    assert saved["n_outliers"] == 5 and saved["params"]["seed"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.truth.json", "s.xy"]  # no temp files left


@pytest.mark.parametrize("argv", [["nope", "-o", "x.xy"], ["star", "-n", "0", "-o", "x.xy"], ["star"]])
def test_make_data_script_rejects_bad_arguments(argv, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as err:
        _make_data_module().main(argv)
    assert err.value.code == 2
    assert not list(tmp_path.iterdir())
