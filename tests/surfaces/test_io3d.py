"""Reading 3D point sets (text, PLY) and meshes (PLY, OBJ, OFF)."""

import io

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from otjax.io import read_points
from otjax.io3d import read_mesh, read_points3d


def write(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data if isinstance(data, bytes) else data.encode())
    return path


def ply_bytes(vertices, faces=None, text=False, byte_order="<", extra=()):
    fields = [("x", "f8"), ("y", "f8"), ("z", "f8")] + [(name, "f4") for name in extra]
    vert = np.zeros(len(vertices), dtype=fields)
    for k, c in enumerate("xyz"):
        vert[c] = vertices[:, k]
    for name in extra:
        vert[name] = np.arange(len(vertices)) + 0.5
    elements = [PlyElement.describe(vert, "vertex")]
    if faces is not None:
        face = np.empty(len(faces), dtype=[("vertex_indices", "i4", (len(faces[0]),))])
        face["vertex_indices"] = faces
        elements.append(PlyElement.describe(face, "face"))
    buffer = io.BytesIO()
    PlyData(elements, text=text, byte_order=byte_order).write(buffer)
    return buffer.getvalue()


@pytest.mark.parametrize("columns, has_mass", [(3, False), (4, True), (6, False), (7, True)])
def test_text_point_layouts(tmp_path, columns, has_mass):
    table = np.random.default_rng(0).normal(size=(5, columns))
    text = "# x y z ...\n" + "\n".join(" ".join(repr(float(v)) for v in row) for row in table)
    points, masses = read_points3d(write(tmp_path, "p.xyz", text))
    np.testing.assert_array_equal(points, table[:, :3])
    if has_mass:
        np.testing.assert_array_equal(masses, table[:, -1])
    else:
        assert masses is None


def test_csv_header_and_commas(tmp_path):
    points, masses = read_points3d(write(tmp_path, "p.csv", "x,y,z,mass\n1,2,3,4\n5,6,7,8,\n"))
    assert points.tolist() == [[1, 2, 3], [5, 6, 7]] and masses.tolist() == [4, 8]


@pytest.mark.parametrize("text, message", [
    ("1 2\n", "expected 3 .x y z. or 4"), ("1 2 3 4 5\n", "got 5"), ("1 2 3\n1 2 3 4\n", ":2: expected 3 columns"),
    ("1 2 nan\n", "NaN or inf"), ("1 2 x\n", "not a row of numbers"), ("# nothing\n", "no points"),
    ("1,,2,3\n", "empty field"),
])
def test_bad_text_is_one_value_error_naming_the_file(tmp_path, text, message):
    path = write(tmp_path, "bad.txt", text)
    with pytest.raises(ValueError, match=message) as err:
        read_points3d(path)
    assert str(path) in str(err.value)


def test_2d_reader_still_reads_xyz_as_x_y_mass(tmp_path):
    points, masses = read_points(write(tmp_path, "p.xyz", "1 2 3\n4 5 6\n"))
    assert points.shape == (2, 2) and masses.tolist() == [3, 6]


@pytest.mark.parametrize("text, byte_order", [(False, "<"), (False, ">"), (True, "=")])
def test_ply_point_sets(tmp_path, text, byte_order):
    v = np.random.default_rng(1).normal(size=(6, 3))
    points, masses = read_points3d(write(tmp_path, "p.ply", ply_bytes(v, text=text, byte_order=byte_order,
                                                                      extra=("nx", "mass"))))
    np.testing.assert_array_equal(points, v)
    np.testing.assert_array_equal(masses, np.arange(6) + 0.5)
    points, masses = read_points3d(write(tmp_path, "q.ply", ply_bytes(v, faces=[[0, 1, 2]])))
    np.testing.assert_array_equal(points, v)  # a mesh read as points: its vertices
    assert masses is None


def test_ply_mesh_with_quads_is_fanned(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]], float)
    mesh = read_mesh(write(tmp_path, "m.ply", ply_bytes(v, faces=[[0, 1, 2, 3], [0, 1, 4, 3]])))
    np.testing.assert_array_equal(mesh.vertices, v)
    assert mesh.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [0, 1, 4], [0, 4, 3]]
    assert mesh.edges.shape == (0, 2)


def test_obj_mesh(tmp_path):
    text = """# a comment
o thing
v 0 0 0
v 1 0 0 1.0
v 1 1 0
vn 0 0 1
vt 0 0
v 0 1 0
f 1/1/1 2/1/1 3/1/1
f -4 -2 -1
l 1 2 3
usemtl x
"""
    mesh = read_mesh(write(tmp_path, "m.obj", text))
    assert mesh.vertices.shape == (4, 3) and mesh.vertices[1].tolist() == [1, 0, 0]
    assert mesh.triangles.tolist() == [[0, 1, 2], [0, 2, 3]]
    assert mesh.edges.tolist() == [[0, 1], [1, 2]]


def test_off_mesh(tmp_path):
    text = "COFF\n# comment\n4 2 0\n0 0 0 255 0 0 255\n1 0 0 1 1 1 1\n1 1 0 0 0 0 0\n0 1 0 0 0 0 0\n" \
           "3 0 1 2 255 0 0\n3 0 2 3\n"
    mesh = read_mesh(write(tmp_path, "m.off", text))
    assert mesh.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    assert mesh.triangles.tolist() == [[0, 1, 2], [0, 2, 3]]
    mesh = read_mesh(write(tmp_path, "n.off", "OFF 3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"))
    assert mesh.triangles.tolist() == [[0, 1, 2]]


@pytest.mark.parametrize("name, text, message", [
    ("a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
    ("b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n", "degenerate"),
    ("c.obj", "v 0 0 0\nv 1 0 0\n", "no faces"),
    ("d.obj", "v 0 0\nf 1 2 3\n", ":1: a vertex needs 3 numbers"),
    ("e.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "start at 1"),
    ("f.obj", "v 0 0 inf\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "NaN or inf"),
    ("g.off", "PLY\n", "not an OFF file"),
    ("h.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n", "declares 3 vertices"),
    ("i.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "1 corner|a face needs 3"),
    ("j.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n", "declares 4 corners"),
    ("k.ply", "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nend_header\n1\n", "declares"),
    ("l.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n", "lacks property y"),
    ("m.ply", "not a ply at all", "not a readable PLY"),
    ("n.stl", "solid", "unknown mesh extension"),
])
def test_bad_meshes_are_one_value_error_naming_the_file(tmp_path, name, text, message):
    path = write(tmp_path, name, text)
    with pytest.raises(ValueError, match=message) as err:
        read_mesh(path)
    assert str(path) in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match="cannot read"):
        read_mesh(tmp_path / "none.off")
    with pytest.raises(ValueError, match="cannot read"):
        read_points3d(tmp_path / "none.xyz")
