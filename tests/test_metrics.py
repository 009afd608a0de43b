"""Metrics against hand-checkable geometry and a brute-force loop oracle."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax import metrics
from otjax.metrics import (
    corner_errors,
    edges_to_segments,
    hausdorff,
    length_within,
    point_segment_distance,
    sample_segments,
)


def _loop_distance(p, segs):
    """Oracle: distance from each point to each segment by the textbook clamp, one pair at a time."""
    out = []
    for px, py in p:
        best = math.inf
        for (ax, ay), (bx, by) in segs:
            dx, dy = bx - ax, by - ay
            len2 = dx * dx + dy * dy
            t = 0.0 if len2 == 0 else min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / len2))
            best = min(best, math.hypot(px - ax - t * dx, py - ay - t * dy))
        out.append(best)
    return np.array(out)


coord = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
point = st.tuples(coord, coord)


@st.composite
def segment(draw):
    a = draw(point)
    # One segment in four is degenerate: a point is a valid (zero-length) segment.
    b = a if draw(st.integers(0, 3)) == 0 else draw(point)
    return (a, b)


class TestPointSegmentDistance:
    @settings(max_examples=60, deadline=None)
    @given(st.lists(point, min_size=1, max_size=12), st.lists(segment(), min_size=1, max_size=8))
    def test_matches_loop_oracle(self, pts, segs):
        got = point_segment_distance(np.array(pts), np.array(segs))
        np.testing.assert_allclose(got, _loop_distance(pts, segs), rtol=1e-9, atol=1e-9)

    def test_blocks_do_not_change_the_result(self, rng, monkeypatch):
        p = rng.normal(size=(300, 2))
        segs = rng.normal(size=(40, 2, 2))
        whole = point_segment_distance(p, segs)
        monkeypatch.setattr(metrics, "_BLOCK", 7)  # blocks of a single point
        np.testing.assert_array_equal(point_segment_distance(p, segs), whole)

    def test_hand_values(self):
        seg = [[[0.0, 0.0], [2.0, 0.0]]]
        got = point_segment_distance([[1.0, 3.0], [-3.0, 4.0], [2.0, 0.0]], seg)
        np.testing.assert_allclose(got, [3.0, 5.0, 0.0])

    def test_no_segments_is_infinite(self):
        assert np.all(np.isinf(point_segment_distance(np.zeros((3, 2)), np.zeros((0, 2, 2)))))

    def test_bad_shapes(self):
        with pytest.raises(ValueError, match="segs"):
            point_segment_distance(np.zeros((3, 2)), np.zeros((3, 2)))
        with pytest.raises(ValueError, match="3-D"):
            point_segment_distance(np.zeros((3, 2)), np.zeros((1, 2, 3)))


class TestCornerErrors:
    def test_hand_values(self):
        vertices = [[0.0, 0.0], [4.0, 0.0]]
        corners = [[3.0, 4.0], [0.0, -1.0], [4.0, 0.0]]
        # (3, 4) is 5 from the origin and sqrt(1 + 16) from (4, 0).
        np.testing.assert_allclose(corner_errors(vertices, corners), [math.sqrt(17), 1.0, 0.0])

    def test_empty(self):
        assert np.all(np.isinf(corner_errors(np.zeros((0, 2)), [[1.0, 2.0]])))
        assert corner_errors([[0.0, 0.0]], np.zeros((0, 2))).shape == (0,)


class TestSampleSegments:
    def test_spacing_weights_and_cover(self, rng):
        segs = rng.normal(size=(5, 2, 2))
        step = 0.05
        pts, w = sample_segments(segs, step)
        lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
        assert w.sum() == pytest.approx(lengths.sum(), rel=1e-12)
        assert w.max() <= step
        # Every point of every segment is within step / 2 of a sample.
        t = np.linspace(0, 1, 101)[:, None, None]
        dense = (segs[None, :, 0] * (1 - t) + segs[None, :, 1] * t).reshape(-1, 2)
        gap = np.linalg.norm(dense[:, None] - pts[None], axis=2).min(1)
        assert gap.max() <= step / 2 + 1e-12

    def test_degenerate_segment_gives_one_weightless_sample(self):
        pts, w = sample_segments([[[1.0, 2.0], [1.0, 2.0]]], 0.1)
        np.testing.assert_array_equal(pts, [[1.0, 2.0]])
        np.testing.assert_array_equal(w, [0.0])

    def test_step_must_be_positive(self):
        with pytest.raises(ValueError, match="step"):
            sample_segments([[[0.0, 0.0], [1.0, 0.0]]], 0.0)


class TestHausdorff:
    @pytest.mark.parametrize("d", [0.0, 0.01, 0.3, 2.0])
    def test_parallel_unit_segments(self, d):
        a = [[[0.0, 0.0], [1.0, 0.0]]]
        b = [[[0.0, d], [1.0, d]]]
        assert hausdorff(a, b) == pytest.approx(d, abs=1e-12)

    def test_segment_against_itself(self, rng):
        segs = rng.normal(size=(6, 2, 2))
        # Samples are interpolated, so they sit on their segment only up to rounding.
        assert hausdorff(segs, segs) == pytest.approx(0.0, abs=1e-12)

    def test_error_is_at_most_half_a_step(self):
        # The farthest point of A from B is its endpoint (1, 0), at distance 0.5 from B's end (0.5, 0).
        a = [[[0.0, 0.0], [1.0, 0.0]]]
        b = [[[0.0, 0.0], [0.5, 0.0]]]
        for step in (0.3, 0.01):
            h = hausdorff(a, b, step=step)
            assert 0.5 - step / 2 - 1e-12 <= h <= 0.5 + 1e-12
            assert hausdorff(b, a, step=step) == h

    def test_empty_sets(self):
        seg = [[[0.0, 0.0], [1.0, 0.0]]]
        assert hausdorff(np.zeros((0, 2, 2)), np.zeros((0, 2, 2))) == 0.0
        assert hausdorff(seg, np.zeros((0, 2, 2))) == math.inf


class TestLengthWithin:
    @pytest.mark.parametrize("step", [None, 0.1, 0.013])
    def test_half_of_a_segment(self, step):
        # B is the vertical unit-half-length segment at x = 1; points of A = [0, 2] x {0} within 0.5
        # of it are exactly those with 0.5 <= x <= 1.5, half of A.
        a = [[[0.0, 0.0], [2.0, 0.0]]]
        b = [[[1.0, -1.0], [1.0, 1.0]]]
        tol_step = 1e-3 * math.hypot(2.0, 2.0) if step is None else step
        assert length_within(a, b, tol=0.5, step=step) == pytest.approx(0.5, abs=tol_step)

    def test_recall_and_precision(self):
        truth = [[[0.0, 0.0], [1.0, 0.0]], [[1.0, 0.0], [1.0, 1.0]]]
        output = [[[0.0, 0.0], [1.0, 0.0]]]  # the first half of the truth only
        assert length_within(truth, output, tol=1e-9) == pytest.approx(0.5, abs=2e-3)
        assert length_within(output, truth, tol=1e-9) == 1.0

    def test_no_length(self):
        point = [[[1.0, 1.0], [1.0, 1.0]]]
        assert length_within(point, [[[0.0, 0.0], [1.0, 0.0]]], tol=5.0) == 0.0
        assert length_within(np.zeros((0, 2, 2)), [[[0.0, 0.0], [1.0, 0.0]]], tol=5.0) == 0.0


class TestEdgesToSegments:
    def test_gathers_endpoints(self):
        v = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
        segs = edges_to_segments(v, [[0, 1], [2, 0]])
        np.testing.assert_array_equal(segs, [[v[0], v[1]], [v[2], v[0]]])
        assert edges_to_segments(v, np.zeros((0, 2), int)).shape == (0, 2, 2)

    def test_bad_indices(self):
        with pytest.raises(ValueError, match="indices"):
            edges_to_segments(np.zeros((3, 2)), [[0, 3]])
        with pytest.raises(ValueError, match="integer"):
            edges_to_segments(np.zeros((3, 2)), [[0.0, 1.0]])
