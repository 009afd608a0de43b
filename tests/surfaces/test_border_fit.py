"""Border fitting (otjax.surfaces.border_fit) against its rule written out in
the frame of a square: which vertices move, and where."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.surfaces.border_fit import fit_border


def grid_square(k: int, margin: float):
    """``k x k`` vertices over ``[margin, 1 - margin]^2`` in the plane z = 0, two triangles a cell."""
    g = np.linspace(margin, 1 - margin, k)
    x, y = np.meshgrid(g, g, indexing="ij")
    vertices = np.c_[x.ravel(), y.ravel(), np.zeros(k * k)]
    tri = []
    for i in range(k - 1):
        for j in range(k - 1):
            a, b, c, d = i * k + j, (i + 1) * k + j, (i + 1) * k + j + 1, i * k + j + 1
            tri += [(a, b, c), (a, c, d)]
    return vertices, np.array(tri)


def _strip_end(d, along, across, t_range, step):
    """Past the farthest of the points ``d`` (from the vertex) in the strip
    ``t_range`` along, a tenth of ``step`` off the plane and ``step`` across,
    by their mean spacing, across."""
    t, h, o = d @ along, d[:, 2], d @ across
    strip = (t >= t_range[0]) & (t <= t_range[1]) & (np.abs(h) <= step / 10) & (np.abs(o) <= step)
    assert strip.sum() >= 5  # premise: every border vertex moves
    return o[strip].max() + np.ptp(o[strip]) / (strip.sum() - 1)


def expected_square(vertices, points, k, margin):
    """The rule in the square's frame: a side vertex moves across its border
    to where the points of the strip beside it end: past the farthest by
    their mean spacing; at a corner each border edge moves out across
    itself to where the points of a strip beside it end, and the corner to
    where the two lines meet, if a point lies within a quarter step of
    there; else it moves as a side vertex, along the diagonal."""
    out = vertices.copy()
    step = (1 - 2 * margin) / (k - 1)
    x, y = np.eye(3)[0], np.eye(3)[1]
    for v in range(k * k):
        i, j = divmod(v, k)
        side_x = -1 if i == 0 else 1 if i == k - 1 else 0
        side_y = -1 if j == 0 else 1 if j == k - 1 else 0
        d = points - vertices[v]
        if side_x and side_y:  # the edge along y moves out along x, the edge along x along y
            move = (_strip_end(d, -side_y * y, side_x * x, (step / 4, step), step) * side_x * x
                    + _strip_end(d, -side_x * x, side_y * y, (step / 4, step), step) * side_y * y)
            if np.linalg.norm(d - move, axis=1).min() <= step / 4:
                out[v] = vertices[v] + move
                continue
        if side_x or side_y:
            across = (side_x * x + side_y * y) / np.hypot(side_x, side_y)
            along = np.array([-across[1], across[0], 0.0])
            out[v] = vertices[v] + _strip_end(d, along, across, (-step / 2, step / 2), step) * across
    return out


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), k=st.integers(3, 5), margin=st.floats(0.01, 0.06),
       n=st.integers(800, 2000), scale_exp=st.floats(-3, 3))
def test_square_border_vertices_move_to_the_end_of_their_strip_in_any_frame(seed, k, margin, n, scale_exp):
    rng = np.random.default_rng(seed)
    vertices, triangles = grid_square(k, margin)
    points = np.c_[rng.random((n, 2)), np.zeros(n)]
    # A second sheet, beyond the square's borders but off its plane: it must not count.
    off = np.c_[rng.uniform(-0.2, 1.2, (200, 2)), rng.choice([-0.2, 0.2], 200)]
    points = np.concatenate([points, off])
    want = expected_square(vertices, points, k, margin)
    rot, scale, shift = random_rotation(rng), 10.0**scale_exp, rng.normal(size=3) * 10.0**scale_exp
    frame = lambda x: scale * x @ rot.T + shift  # noqa: E731
    fit = fit_border(frame(vertices), triangles, frame(points))
    border = np.flatnonzero(np.any(want != vertices, axis=1) | np.isin(np.arange(k * k), fit.moved))
    interior = np.setdiff1d(np.arange(k * k), border)
    np.testing.assert_array_equal(fit.moved, np.sort(border))
    assert len(border) == 4 * (k - 1)
    np.testing.assert_allclose(fit.vertices, frame(want), rtol=0, atol=1e-9 * scale)
    np.testing.assert_array_equal(fit.vertices[interior], frame(vertices)[interior])
    # Each side vertex ends where the points of its strip end: at most their spacing past the square.
    assert np.all((want[:, :2] >= -0.02) & (want[:, :2] <= 1.02))


def test_vertices_on_a_crease_stay_and_the_others_move_out():
    # Two sheets folded at a right angle along the x axis: y >= 0 at z = 0 and z >= 0 at y = 0.
    rng = np.random.default_rng(0)
    k, margin = 4, 0.05
    flat, triangles = grid_square(k, margin)
    flat[:, 1] -= margin  # the crease row at y = 0
    standing = flat[:, [0, 2, 1]]  # the same grid in the plane y = 0
    on_crease = np.arange(k * k) % k == 0  # rows i * k + j with j = 0
    vertices = np.concatenate([flat, standing[~on_crease]])  # the crease row shared
    index = np.where(on_crease, np.arange(k * k), k * k + np.cumsum(~on_crease) - 1)
    triangles = np.concatenate([triangles, index[triangles]])
    u = rng.random((3000, 2))
    points = np.concatenate([np.c_[u[:1500, 0], u[:1500, 1], np.zeros(1500)],
                             np.c_[u[1500:, 0], np.zeros(1500), u[1500:, 1]]])
    fit = fit_border(vertices, triangles, points)
    crease = np.flatnonzero((vertices[:, 1] == 0) & (vertices[:, 2] == 0))
    assert len(crease) == k and not np.isin(crease, fit.moved).any()
    np.testing.assert_array_equal(fit.vertices[crease], vertices[crease])
    # The far borders (y or z near 1) move out to the last points, off the crease.
    far = np.flatnonzero(np.maximum(vertices[:, 1], vertices[:, 2]) > 0.9)
    assert np.isin(far, fit.moved).all()
    assert np.all(np.maximum(fit.vertices[far, 1], fit.vertices[far, 2]) > np.maximum(vertices[far, 1],
                                                                                         vertices[far, 2]))


def test_the_strip_reaches_its_corners_and_no_further():
    v, t = grid_square(3, 0.1)  # step 0.4: vertex 3 at (0.5, 0.1) has the strip |x - 0.5| <= 0.2, 0 <= 0.1 - y <= 0.4
    g = np.linspace(0.1, 0.9, 17) + 0.001  # off the strip's edges, so that membership is plain
    inside = np.c_[np.stack(np.meshgrid(g, g), -1).reshape(-1, 2), np.zeros(17 * 17)]  # ends at the mesh's border
    corner = [0.5 + 0.19, 0.1 - 0.39, 0.0]  # in the strip, near its far corner
    beside = [0.5 + 0.21, 0.1 - 0.395, 0.0]  # just outside it along the border
    above = [0.5, 0.1 - 0.395, 0.041]  # just outside it off the plane
    fit = fit_border(v, t, np.concatenate([inside, [corner, beside, above]]))
    # the strip: the grid points with |x - 0.5| < 0.2 and 0.1 - y > -0.4, and the corner point
    rows = inside[(np.abs(inside[:, 0] - 0.5) < 0.2) & (inside[:, 1] < 0.5)]
    across = np.r_[0.1 - rows[:, 1], 0.39]  # distances out across the border (-y)
    end = across.max() + (across.max() - across.min()) / (len(across) - 1)
    np.testing.assert_allclose(fit.vertices[3], [0.5, 0.1 - end, 0.0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("inside, moves", [(0.15, True), (0.25, False)])
def test_a_vertex_moves_inward_by_at_most_half_its_edge(inside, moves):
    # Vertex 3 at (0.5, 0.1), border edges 0.4 long; the points stop ``inside`` above the border
    # (y >= 0.1 + inside), the strip keeps some: the vertex moves up to their end only within 0.2.
    v, t = grid_square(3, 0.1)
    g = np.linspace(0.0, 1.0, 81)
    grid = np.c_[np.stack(np.meshgrid(g, g), -1).reshape(-1, 2), np.zeros(81 * 81)]
    points = grid[grid[:, 1] >= 0.1 + inside]
    fit = fit_border(v, t, points)
    assert (3 in fit.moved) == moves
    if moves:
        assert abs(fit.vertices[3, 1] - (0.1 + inside)) < 0.02
    else:
        np.testing.assert_array_equal(fit.vertices[3], v[3])


def test_side_vertices_end_at_the_border_of_noisy_points():
    # Gaussian noise of sigma = 0.01 in every direction spreads the points past the square's sides:
    # the farthest of a strip stands about two sigmas out. The side vertices (not the corners) land
    # on the true border on average, to within half a sigma, and no farther than two sigmas off.
    rng = np.random.default_rng(5)
    k, margin, sigma, n = 5, 0.05, 0.01, 20000
    vertices, triangles = grid_square(k, margin)
    points = np.c_[rng.random((n, 2)), np.zeros(n)] + sigma * rng.normal(size=(n, 3))
    fit = fit_border(vertices, triangles, points)
    i, j = np.divmod(np.arange(k * k), k)
    side = ((i == 0) | (i == k - 1)) ^ ((j == 0) | (j == k - 1))
    moved = fit.vertices[side]
    # Distance past the nearest side of the unit square (negative: inside).
    past = np.where(i[side] == 0, -moved[:, 0], np.where(i[side] == k - 1, moved[:, 0] - 1,
                    np.where(j[side] == 0, -moved[:, 1], moved[:, 1] - 1)))
    assert abs(past.mean()) < sigma / 2
    assert np.abs(past).max() < 2 * sigma


def test_nothing_moves_without_triangles_or_points():
    v, t = grid_square(3, 0.1)
    assert fit_border(v, t, np.zeros((0, 3))).moved.size == 0
    fit = fit_border(v, np.zeros((0, 3), np.int64), np.random.default_rng(0).random((50, 3)))
    assert fit.moved.size == 0 and np.array_equal(fit.vertices, v)


@pytest.mark.parametrize("change, message", [
    ({"vertices": np.zeros((4, 2))}, "vertices"),
    ({"points": np.full((3, 3), np.nan)}, "points"),
    ({"triangles": [[0, 1, 9]]}, "triangles"),
    ({"triangles": [[0.0, 1.0, 2.0]]}, "triangles"),
    ({"flat_angle": 90}, "flat_angle"),
    ({"flat_angle": True}, "flat_angle"),
])
def test_bad_input_is_named(change, message):
    v, t = grid_square(3, 0.1)
    args = {"vertices": v, "triangles": t, "points": np.random.default_rng(0).random((50, 3)), **change}
    with pytest.raises(ValueError, match=message):
        fit_border(**args)
