"""Fuzzing the 3D readers: any bytes under any 3D extension give either a
result that keeps the reader's contract or one ValueError naming the file;
never another exception, never a warning, never a file left behind."""

import io
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from plyfile import PlyData, PlyElement

from otjax.io3d import MESH_EXTENSIONS, POINT_EXTENSIONS, read_mesh, read_points3d
from tests.fuzz.strategies import listing, mangled, number_text, text_rows, warnings_are_errors
from tests.profiles import examples


def read_or_refuse(data: bytes, ext: str, reader):
    """``reader`` on a file holding ``data``: its result, or ``None`` after a ValueError naming the file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"in put{ext}"
        path.write_bytes(data)
        try:
            with warnings_are_errors():
                result = reader(path)
        except ValueError as err:
            assert str(path) in str(err), f"the message does not name the file: {err}"
            result = None
        assert listing(tmp) == [path.name]
    return result


def check_points(result):
    if result is None:
        return
    points, masses = result
    assert points.dtype == np.float64 and points.ndim == 2 and points.shape[1] == 3 and len(points) >= 1
    assert np.isfinite(points).all()
    assert masses is None or (masses.shape == (len(points),) and np.isfinite(masses).all())


def check_mesh(mesh):
    if mesh is None:
        return
    nv = len(mesh.vertices)
    assert mesh.vertices.shape == (nv, 3) and np.isfinite(mesh.vertices).all() and nv >= 1
    assert mesh.triangles.dtype == np.int64 and mesh.triangles.shape[1:] == (3,) and len(mesh.triangles) >= 1
    assert mesh.triangles.min() >= 0 and mesh.triangles.max() < nv
    assert np.all(np.diff(np.sort(mesh.triangles, axis=1), axis=1) > 0)  # three different corners
    assert mesh.edges.dtype == np.int64 and mesh.edges.shape[1:] == (2,)
    if mesh.edges.size:
        assert mesh.edges.min() >= 0 and mesh.edges.max() < nv and np.all(mesh.edges[:, 0] != mesh.edges[:, 1])


@st.composite
def mesh_text(draw) -> bytes:
    """OBJ or OFF-like text: statements with odd numbers, indices out of range, ragged faces."""
    index = st.one_of(st.integers(-5, 8).map(str), st.sampled_from(["1/2/3", "2//1", "0", "x", "99999999999999999999"]))
    lines = []
    off = draw(st.booleans())
    if off:
        lines.append(draw(st.sampled_from(["OFF", "COFF", "NOFF", "4OFF", "OFF 3 1 0", ""])))
        lines.append(" ".join(draw(st.lists(st.integers(0, 6).map(str), min_size=0, max_size=3))))
    for _ in range(draw(st.integers(0, 12))):
        kind = draw(st.sampled_from(["v", "f", "l", "row", "junk"]))
        if kind == "v":
            lines.append("v " + " ".join(draw(st.lists(number_text, min_size=0, max_size=4))))
        elif kind in ("f", "l"):
            lines.append(kind + " " + " ".join(draw(st.lists(index, min_size=0, max_size=5))))
        elif kind == "row":
            lines.append(" ".join(draw(st.lists(st.one_of(number_text, index), min_size=0, max_size=6))))
        else:
            lines.append(draw(st.sampled_from(["# c", "", "vn 0 0 1", "usemtl m", "o x", "p 1"])))
    return "\n".join(lines).encode()


@st.composite
def ply_files(draw) -> bytes:
    """A valid small PLY point set or mesh (either encoding), possibly mangled."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(0, 6))
    fields = [("x", "f8")] + [(c, draw(st.sampled_from(["f4", "f8", "i2", "u1"]))) for c in "yz"]
    if draw(st.booleans()):
        fields.append(("mass", "f8"))
    vert = np.zeros(n, dtype=fields)
    for name, _ in fields:
        vert[name] = rng.integers(0, 5, n)
    if n and draw(st.booleans()):
        vert["x"][0] = draw(st.sampled_from([np.nan, np.inf, 1e300]))
    elements = [PlyElement.describe(vert, "vertex")]
    if draw(st.booleans()):
        k = draw(st.integers(1, 5))
        faces = np.empty(draw(st.integers(0, 4)), dtype=[("vertex_indices", "i4", (k,))])
        faces["vertex_indices"] = rng.integers(-1, n + 2, (len(faces), k))
        elements.append(PlyElement.describe(faces, "face"))
    if draw(st.booleans()):
        edges = np.empty(draw(st.integers(0, 3)), dtype=[("vertex1", "i4"), ("vertex2", "i4")])
        edges["vertex1"], edges["vertex2"] = rng.integers(0, n + 1, (2, len(edges)))
        elements.append(PlyElement.describe(edges, "edge"))
    buffer = io.BytesIO()
    with warnings_are_errors():
        PlyData(elements, text=draw(st.booleans()), byte_order=draw(st.sampled_from(["<", ">"]))).write(buffer)
    return draw(mangled(buffer.getvalue()))


any_bytes = st.one_of(st.binary(max_size=300), text_rows().map(lambda t: t.encode("utf-8")), mesh_text(),
                      mesh_text().flatmap(mangled))


@settings(max_examples=examples(200, 2000))
@given(data=any_bytes, ext=st.sampled_from(list(POINT_EXTENSIONS) + [".XYZ", ".obj", ""]))
def test_point_readers(data, ext):
    check_points(read_or_refuse(data, ext, read_points3d))


@settings(max_examples=examples(200, 2000))
@given(data=any_bytes, ext=st.sampled_from(list(MESH_EXTENSIONS) + [".OBJ", ".stl"]))
def test_mesh_readers(data, ext):
    check_mesh(read_or_refuse(data, ext, read_mesh))


@settings(max_examples=examples(200, 2000))
@given(data=ply_files())
def test_ply_files_valid_and_mangled(data):
    check_points(read_or_refuse(data, ".ply", read_points3d))
    check_mesh(read_or_refuse(data, ".ply", read_mesh))


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=examples(100, 1000))
@given(rows=st.sampled_from([3, 4, 6, 7]).flatmap(lambda k: st.lists(st.lists(finite, min_size=k, max_size=k),
                                                                     min_size=1, max_size=10)),
       sep=st.sampled_from([" ", "\t", ",", ", "]), ext=st.sampled_from([".xyz", ".csv", ".txt"]))
def test_valid_tables_read_back_exactly(rows, sep, ext):
    table = np.array(rows, np.float64)
    text = "\n".join(sep.join(repr(float(v)) for v in row) for row in table)
    got = read_or_refuse(text.encode(), ext, read_points3d)
    assert got is not None
    np.testing.assert_array_equal(got[0], table[:, :3])
    assert (got[1] is None) == (table.shape[1] in (3, 6))
    if got[1] is not None:
        np.testing.assert_array_equal(got[1], table[:, -1])
