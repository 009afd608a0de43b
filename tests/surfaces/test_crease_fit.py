"""Crease fitting (otjax.surfaces.crease_fit) against the exact creases and
corners of the surfaces the points were sampled from."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from otjax.surfaces.crease_fit import _crease_end, fit_creases


def folded_sheets(rows: int, opening: float, width: float):
    """Two sheets meeting at the z axis (``0 <= z <= 1``) at ``opening``
    radians, each ``width`` wide: a grid mesh of five columns (two a sheet
    and the crease in the middle) and ``rows`` rows, two triangles a cell.
    Returns ``(vertices, triangles, crease_rows, directions)``."""
    u = {1: np.array([1.0, 0, 0]), -1: np.array([np.cos(opening), np.sin(opening), 0])}
    z = np.linspace(0, 1, rows)
    columns = (-2, -1, 0, 1, 2)
    vertices = []
    for i in range(rows):
        for c in columns:
            side = u[np.sign(c)] if c else np.zeros(3)
            vertices.append(np.array([0, 0, z[i]]) + abs(c) * width / 2 * side)
    tri = []
    for i in range(rows - 1):
        for j in range(len(columns) - 1):
            a, b = i * 5 + j, i * 5 + j + 1
            c, d = a + 5, b + 5
            tri += [(a, b, d), (a, d, c)]
    crease = np.array([i * 5 + 2 for i in range(rows)])
    return np.array(vertices), np.array(tri), crease, u


def sample_sheets(u: dict, width: float, n: int, rng) -> np.ndarray:
    """``2 n`` points uniform on the two sheets (a little wider than the mesh)."""
    out = []
    for side in (1, -1):
        t, z = rng.random(n) * width * 1.05, rng.random(n)
        out.append(t[:, None] * u[side] + np.c_[np.zeros(n), np.zeros(n), z])
    return np.concatenate(out)


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), rows=st.integers(4, 6), opening=st.floats(50, 100),
       scale_exp=st.floats(-3, 3))
def test_crease_vertices_move_onto_the_crease_in_any_frame(seed, rows, opening, scale_exp):
    rng = np.random.default_rng(seed)
    width = 0.6
    vertices, triangles, crease, u = folded_sheets(rows, np.radians(opening), width)
    points = sample_sheets(u, width, 1500, rng)
    # An opening up to 100 degrees keeps the displaced crease edges sharper than 60 degrees. The
    # crease's end vertices, on one sharp edge at the open border, slide along it to its points' ends.
    inner, ends = crease[1:-1], crease[[0, -1]]
    shifted = vertices.copy()
    shifted[inner] += rng.uniform(-0.03, 0.03, (len(inner), 3))
    rotation, scale, shift = Rotation.random(random_state=seed % 2**32), 10.0 ** scale_exp, rng.normal(size=3)

    def to_frame(x):
        return rotation.apply(x) * scale + shift

    fit = fit_creases(to_frame(shifted), triangles, to_frame(points))

    assert fit.moved.tolist() == crease.tolist()
    back = rotation.inv().apply((fit.vertices - shift) / scale)
    # Onto the z axis, at the height of its nearest point there; the ends at the points' ends.
    assert np.allclose(back[crease, :2], 0, atol=1e-3)
    assert np.allclose(back[inner, 2], shifted[inner, 2], atol=1e-3)
    assert np.allclose(back[ends, 2], [0, 1], atol=0.1)
    others = np.setdiff1d(np.arange(len(vertices)), crease)
    assert np.array_equal(fit.vertices[others], to_frame(shifted)[others])


@pytest.mark.parametrize("noise", [0.0, 0.003, 0.01])
def test_a_crease_end_on_one_sharp_edge_moves_between_planes_as_thin_as_the_noise(noise):
    # r is about 0.3 here: noise of 0.01 (0.03 r) makes the planes thicker than THIN * r, but no
    # thicker than the points' noise everywhere.
    rng = np.random.default_rng(11)
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), 0.6)
    points = sample_sheets(u, 0.6, 3000, rng)
    points[:, :2] += rng.normal(0, noise, (len(points), 2))  # off both sheets (x = 0 and y = 0)
    shifted = vertices.copy()
    shifted[crease] += [0.02, -0.01, 0.01]  # every crease vertex off the crease
    moved = fit_creases(shifted, triangles, points).moved
    assert np.isin(crease, moved).all()
    assert np.isin(moved, crease).all()


def test_a_crease_end_on_one_sharp_edge_stays_between_planes_thicker_than_the_noise():
    # Sheets 0.03 thick (root mean square residual 0.1 r) at both ends of the crease and exact
    # elsewhere: the planes at the ends are thick for these points, whose noise is 0 (THIN), while
    # the vertices on two sharp edges still move.
    rng = np.random.default_rng(11)
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), 0.6)
    points = sample_sheets(u, 0.6, 3000, rng)
    ends = (points[:, 2] < 0.2) | (points[:, 2] > 0.8)
    points[ends, :2] += rng.normal(0, 0.03, (ends.sum(), 2))
    shifted = vertices.copy()
    shifted[crease] += [0.02, -0.01, 0.01]
    moved = fit_creases(shifted, triangles, points).moved
    assert np.isin(crease[1:-1], moved).all()
    assert not np.isin(crease[[0, -1]], moved).any()
    assert np.isin(moved, crease).all()


def corner_faces(step: float = 0.25, k: int = 3):
    """The three faces of the unit cube at the origin, each a ``k x k`` grid
    of spacing ``step`` (two triangles a cell), shared vertices merged.
    Returns ``(vertices, triangles, corner_row)``."""
    g = np.arange(k) * step
    index, vertices, tri = {}, [], []

    def vid(p):
        key = tuple(np.round(p, 9))
        if key not in index:
            index[key] = len(vertices)
            vertices.append(np.array(p, float))
        return index[key]

    for axis in range(3):
        a, b = [x for x in range(3) if x != axis]
        for i in range(k - 1):
            for j in range(k - 1):
                ids = []
                for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)):
                    p = np.zeros(3)
                    p[a], p[b] = g[i + di], g[j + dj]
                    ids.append(vid(p))
                tri += [(ids[0], ids[1], ids[2]), (ids[0], ids[2], ids[3])]
    return np.array(vertices), np.array(tri), index[(0.0, 0.0, 0.0)]


def test_a_corner_vertex_moves_to_the_corner():
    rng = np.random.default_rng(3)
    vertices, triangles, corner = corner_faces()
    points = []
    for axis in range(3):
        p = rng.random((1500, 3)) * 0.55
        p[:, axis] = 0
        points.append(p)
    points = np.concatenate(points)
    shifted = vertices.copy()
    shifted[corner] = [0.02, -0.015, 0.01]

    fit = fit_creases(shifted, triangles, points)

    assert corner in fit.moved.tolist()
    assert np.linalg.norm(fit.vertices[corner]) < 1e-6


def test_a_corner_of_one_exact_face_and_two_noisy_ones_moves_to_the_corner():
    # Planes thin by different amounts are still three planes: the thinnest being exact must not
    # make the others too thick to count.
    rng = np.random.default_rng(8)
    vertices, triangles, corner = corner_faces()
    points = []
    for axis, noise in ((0, 0.0), (1, 0.002), (2, 0.002)):
        p = rng.random((1500, 3)) * 0.55
        p[:, axis] = rng.normal(0.0, noise, 1500) if noise else 0.0
        points.append(p)
    shifted = vertices.copy()
    shifted[corner] = [0.02, -0.015, 0.01]

    fit = fit_creases(shifted, triangles, np.concatenate(points))

    assert corner in fit.moved.tolist()
    assert np.linalg.norm(fit.vertices[corner]) < 1e-3


def test_a_fold_the_points_do_not_have_moves_nothing():
    # The mesh folds at a right angle; the points lie on one of its sheets and the plane beyond the crease.
    rng = np.random.default_rng(4)
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), 0.6)
    shifted = vertices.copy()
    shifted[crease[1:-1]] += [0.02, 0.02, 0]
    points = np.c_[rng.uniform(-0.6, 0.6, 3000), np.zeros(3000), rng.random(3000)]

    fit = fit_creases(shifted, triangles, points)

    assert len(fit.moved) == 0
    assert np.array_equal(fit.vertices, shifted)


def test_sheets_whose_points_stop_short_of_their_line_move_nothing():
    # The points' planes meet at the z axis, but no point comes within a third of an edge of it.
    rng = np.random.default_rng(5)
    width = 0.6
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), width)
    points = sample_sheets(u, width, 3000, rng)
    points = points[np.linalg.norm(points[:, :2], axis=1) > 0.11]  # edges here are 0.25 and 0.3 long
    shifted = vertices.copy()
    shifted[crease[1:-1]] += [0.02, 0.02, 0]

    fit = fit_creases(shifted, triangles, points)

    assert len(fit.moved) == 0


def test_a_facet_across_a_crease_end_makes_no_corner_of_other_faces():
    # A crease ends at the open border z = 0, where a facet of the complex lies across it in the
    # border's plane, so the end vertex has three groups of facets. Within its reach stand two more
    # faces, parallel to the sheets (a staircase's next riser and tread), whose points no sheet's
    # plane takes: the plane of the facet across, fitted to them, is far thicker than the sheets'
    # and must not make the end a corner (the corner of three planes lies up the crease or nowhere).
    rng = np.random.default_rng(7)
    width = 0.6
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), width)
    end = crease[0]
    triangles = np.vstack([triangles, [end, end - 1, end + 1]])
    faces = [np.c_[rng.random(3000) * width, np.full(3000, 0.25), rng.random(3000)],
             np.c_[np.full(3000, 0.25), rng.random(3000) * width, rng.random(3000)]]
    points = np.concatenate([sample_sheets(u, width, 3000, rng), *faces])
    shifted = vertices.copy()
    shifted[end] = [0.01, -0.02, 0.005]

    fit = fit_creases(shifted, triangles, points)

    assert end in fit.moved.tolist()
    assert np.allclose(fit.vertices[end], [0, 0, 0.005], atol=1e-3)


@pytest.mark.parametrize("extra", [[[0, 1, -1], [0, 1, 4]], [[0, 1, -1], [0, 1, 4], [0, -1, 6]]])
def test_facets_across_a_crease_whose_points_are_the_sheets_own_are_no_planes(extra):
    # An inner crease vertex has, besides the two sheets' facets, a facet across the crease at its
    # own height (normal along the crease) and one or two across it diagonally. In the noise their
    # planes each take a band of the sheets' points and survive the fit, four or five planes in
    # all (no crease of two or corner of three); their points lie on the sheets' planes, and
    # dropped, they leave the two sheets: the vertex moves onto the crease.
    rng = np.random.default_rng(3)
    width, noise = 0.6, 0.005
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), width)
    v = crease[2]
    triangles = np.vstack([triangles, v + np.array(extra)])
    points = sample_sheets(u, width, 3000, rng)
    points += noise * rng.standard_normal(points.shape)
    shifted = vertices.copy()
    shifted[v] += [0.02, 0.015, 0.01]

    fit = fit_creases(shifted, triangles, points)

    assert v in fit.moved.tolist()
    assert np.allclose(fit.vertices[v], [0, 0, shifted[v, 2]], atol=noise / 2)


def test_a_vertex_whose_planes_needed_pruning_stays_between_planes_thicker_than_the_noise():
    # The facets of the test above, but the points are thick (0.02) only around the vertex and
    # exact elsewhere: the points' noise reads 0, the two planes left after the pruning are far
    # thicker than it and than THIN * r, and a crease found among pruned planes must be thin.
    rng = np.random.default_rng(3)
    width = 0.6
    vertices, triangles, crease, u = folded_sheets(5, np.radians(90), width)
    v = crease[2]
    triangles = np.vstack([triangles, v + np.array([[0, 1, -1], [0, 1, 4]])])
    points = sample_sheets(u, width, 3000, rng)
    close = np.linalg.norm(points - vertices[v], axis=1) < 0.4
    points[close] += 0.02 * rng.standard_normal((close.sum(), 3))
    shifted = vertices.copy()
    shifted[v] += [0.02, 0.015, 0.01]

    assert v not in fit_creases(shifted, triangles, points).moved.tolist()


@pytest.mark.parametrize("neighbours, slides", [
    ([[0, 0, 0.3]], True),  # the crease goes on behind the vertex only: an end
    ([[0, 0, 0.3], [0, 0, 0.05]], False),  # and on beyond it, on the line: no end (two vertices on one end)
    ([[0, 0, 0.3], [0.15, 0.15, 0.05]], True),  # beyond it but off the line (across the border): an end
    ([[0.15, 0.15, 0.3]], False),  # no crease edge of the vertex along the line: not its crease
])
def test_only_the_last_vertex_of_a_crease_slides_to_its_end(neighbours, slides):
    # Two right-angled sheets meet at the z axis; their points end at z = 0. The border vertex at
    # z = 0.1, its facets above it, slides down the axis to the last point there if a crease edge
    # of it runs up the axis and none goes on below it.
    rng = np.random.default_rng(9)
    a, b = rng.random((2, 4000))
    points = np.concatenate([np.c_[a * 0.5, np.zeros(4000), b], np.c_[np.zeros(4000), a * 0.5, b]])
    target = np.array([0.0, 0.0, 0.1])

    out = _crease_end(target, np.eye(3)[:2], np.array(neighbours, float), np.array([0.1, 0.1, 0.4]),
                      points[np.linalg.norm(points - target, axis=1) <= 0.3], 0.3)

    if slides:
        # the points within 0.03 of the axis, in the ball of 0.3 around the target, end past the
        # lowest of them by their mean spacing along it
        near = points[np.linalg.norm(points - target, axis=1) <= 0.3]
        z = near[np.linalg.norm(near[:, :2], axis=1) <= 0.03, 2]
        assert np.allclose(out, [0, 0, z.min() - np.ptp(z) / (len(z) - 1)], atol=1e-12)
        assert abs(out[2]) < 0.01
    else:
        assert np.array_equal(out, target)


def test_nothing_moves_without_triangles_or_points():
    vertices, triangles, _, u = folded_sheets(4, np.radians(90), 0.6)
    assert len(fit_creases(vertices, np.zeros((0, 3), int), np.ones((5, 3))).moved) == 0
    assert len(fit_creases(vertices, triangles, np.zeros((0, 3))).moved) == 0


@pytest.mark.parametrize("change, message", [
    ({"vertices": np.ones((4, 2))}, "vertices must be"),
    ({"points": np.full((3, 3), np.nan)}, "points must be"),
    ({"triangles": np.array([[0, 1, 9]])}, "triangles index"),
    ({"triangles": np.ones((2, 3))}, "integer"),
    ({"sharp_angle": 90}, "sharp_angle"),
    ({"sharp_angle": True}, "sharp_angle"),
])
def test_bad_input_is_named(change, message):
    args = {"vertices": np.eye(3) + 1, "triangles": np.array([[0, 1, 2]]), "points": np.ones((4, 3)),
            **change}
    with pytest.raises(ValueError, match=message):
        fit_creases(**args)
