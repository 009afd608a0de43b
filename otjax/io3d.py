"""Reading 3D point sets and triangle meshes.

Point sets (:func:`read_points3d`):

* text, ``.xyz``, ``.csv``, ``.txt``: one point per line, laid out as for
  :func:`otjax.io.read_points` (whitespace or commas, ``#`` comments, one
  header line in a ``.csv``), with 3 columns ``x y z``, 4 ``x y z mass``,
  6 ``x y z nx ny nz`` or 7 ``x y z nx ny nz mass``. Normals are read and
  ignored: the transport needs none. (In the 2D reader ``.xyz`` means
  ``x y mass``; this module is the 3D one.)
* ``.ply``: the ``vertex`` element's ``x y z``, and its ``mass`` property
  when there is one; every other element (faces of a mesh) and property
  (normals, colours) is ignored.

Meshes (:func:`read_mesh`), for feature recovery: ``.ply`` (``vertex`` and
``face`` elements, faces as ``vertex_indices`` or ``vertex_index``, and an
optional ``edge`` element of ``vertex1 vertex2``), ``.obj`` (``v``, ``f``
and ``l`` statements; texture and normal indices ``f 1/2/3`` and negative,
relative indices allowed; other statements ignored) and ``.off`` (``OFF``,
``COFF``, ``NOFF``, ``CNOFF``, ``STOFF`` headers; extra vertex columns and
face colours ignored). A polygon of ``k > 3`` corners becomes ``k - 2``
triangles fanned from its first corner.

PLY goes through ``plyfile`` (binary and ASCII, either byte order;
docs/decisions.md#mesh_reader); OBJ and OFF are plain text read here. Every
failure to read is a :class:`ValueError` naming the file.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import NamedTuple

import numpy as np

from otjax.io import parse_row, read_table, read_text

POINT_EXTENSIONS = (".xyz", ".csv", ".txt", ".ply")
MESH_EXTENSIONS = (".ply", ".obj", ".off")
#: Column counts of a text point file and what they hold.
TEXT_LAYOUTS = {3: "x y z", 4: "x y z mass", 6: "x y z nx ny nz", 7: "x y z nx ny nz mass"}

_NO_EDGES = np.zeros((0, 2), np.int64)
_OFF_HEADER = re.compile(r"^(ST)?C?N?OFF$")


class Mesh(NamedTuple):
    """A triangle mesh.

    Attributes:
      vertices: ``(V, 3)`` float64 positions.
      triangles: ``(T, 3)`` int64 rows into ``vertices``.
      edges: ``(E, 2)`` int64 rows into ``vertices``: edges stated on their
        own (PLY ``edge`` element, OBJ ``l`` lines); empty for OFF.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    edges: np.ndarray = _NO_EDGES


def read_points3d(path) -> tuple[np.ndarray, np.ndarray | None]:
    """Reads a 3D point set (see the module doc for the formats).

    Returns:
      ``(points, masses)``: ``(n, 3)`` float64 and ``(n,)`` float64, or
      ``None`` when the file has no mass column (unit masses). Values are
      finite but not validated further; see :func:`otjax.validation.check_points`
      with ``dim=3``.

    Raises:
      ValueError: unknown extension, unreadable file, malformed line or PLY
        data, a non-finite value; the message names the file.

    Example:
      >>> points, masses = read_points3d("scan.ply")  # doctest: +SKIP
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in POINT_EXTENSIONS:
        raise ValueError(f"{path}: unknown point set extension {ext!r}; expected one of {', '.join(POINT_EXTENSIONS)}")
    try:
        if ext == ".ply":
            ply = _read_ply(path)
            points = _ply_xyz(path, ply)
            mass = _ply_scalar(path, ply["vertex"], "mass") if "mass" in _names(ply["vertex"]) else None
            return points, mass
        table = read_table(path, read_text(path), TEXT_LAYOUTS, header_allowed=ext == ".csv")
    except OSError as err:
        raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
    return table[:, :3].copy(), (table[:, -1].copy() if table.shape[1] in (4, 7) else None)


def read_mesh(path) -> Mesh:
    """Reads a triangle mesh from ``.ply``, ``.obj`` or ``.off``.

    Raises:
      ValueError: unknown extension, unreadable or malformed file, no
        vertices, no faces, an index out of range, a face with fewer than 3
        corners or a repeated corner, a non-finite coordinate; the message
        names the file.

    Example:
      >>> mesh = read_mesh("poisson.off")  # doctest: +SKIP
      >>> mesh.vertices.shape, mesh.triangles.shape  # doctest: +SKIP
      ((1538, 3), (3072, 3))
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in MESH_EXTENSIONS:
        raise ValueError(f"{path}: unknown mesh extension {ext!r}; expected one of {', '.join(MESH_EXTENSIONS)}")
    try:
        if ext == ".ply":
            vertices, faces, edges = _ply_mesh(path)
        elif ext == ".obj":
            vertices, faces, edges = _obj_mesh(path, read_text(path))
        else:
            vertices, faces, edges = _off_mesh(path, read_text(path))
    except OSError as err:
        raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
    return _checked_mesh(path, vertices, faces, edges)


# ----------------------------------------------------------------- text points


# ------------------------------------------------------------------------ PLY


def _declared_rows_fit(path: Path, data: bytes) -> None:
    """Refuses a header whose element counts cannot fit the bytes after it.

    ``plyfile`` allocates every element's table before reading its rows, so
    a few bytes declaring 10^12 vertices would ask for terabytes. Every row
    takes at least one byte in every PLY format, which bounds the counts.
    """
    end = data.find(b"end_header")
    if end < 0:
        return  # plyfile reports the missing end of the header
    body = len(data) - end - len(b"end_header")
    for line in data[:end].splitlines():
        fields = line.split()
        if len(fields) == 3 and fields[0] == b"element" and fields[2].isdigit() and int(fields[2]) > body:
            name = fields[1].decode("ascii", "replace")
            raise ValueError(f"{path}: the header declares {int(fields[2])} {name} rows but only {body} bytes follow it")


def _read_ply(path: Path):
    from plyfile import PlyData, PlyParseError

    data = path.read_bytes()
    _declared_rows_fit(path, data)
    import io

    try:
        return PlyData.read(io.BytesIO(data), mmap=False)
    except PlyParseError as err:
        raise ValueError(f"{path}: not a readable PLY file ({err})") from None
    except Exception as err:  # noqa: BLE001  plyfile reports some corrupt data as ValueError, TypeError, ...
        raise ValueError(f"{path}: not a readable PLY file ({type(err).__name__}: {err})") from None


def _names(element) -> list[str]:
    return [p.name for p in element.properties]


def _ply_scalar(path: Path, element, name: str) -> np.ndarray:
    """A scalar numeric property of a PLY element as finite float64."""
    prop = element.ply_property(name)
    if hasattr(prop, "len_dtype"):
        raise ValueError(f"{path}: PLY property {element.name}.{name} must be a number, not a list")
    values = np.asarray(element[name], dtype=np.float64)
    bad = ~np.isfinite(values)
    if bad.any():
        raise ValueError(f"{path}: PLY property {element.name}.{name} holds NaN or inf (row {int(np.argmax(bad))})")
    return values


def _ply_xyz(path: Path, ply) -> np.ndarray:
    if "vertex" not in ply:
        raise ValueError(f"{path}: PLY file has no 'vertex' element")
    vertex = ply["vertex"]
    missing = [c for c in "xyz" if c not in _names(vertex)]
    if missing:
        raise ValueError(f"{path}: PLY vertex element lacks property {', '.join(missing)}")
    if vertex.count == 0:
        raise ValueError(f"{path}: no points (the PLY vertex element is empty)")
    return np.stack([_ply_scalar(path, vertex, c) for c in "xyz"], axis=1)


def _ply_mesh(path: Path):
    ply = _read_ply(path)
    vertices = _ply_xyz(path, ply)
    faces: list = []
    if "face" in ply:
        face = ply["face"]
        name = next((n for n in ("vertex_indices", "vertex_index") if n in _names(face)), None)
        if name is None:
            raise ValueError(f"{path}: PLY face element has no vertex_indices property")
        prop = face.ply_property(name)
        if not hasattr(prop, "len_dtype") or np.dtype(prop.val_dtype).kind not in "iu":
            raise ValueError(f"{path}: PLY property face.{name} must be a list of integers")
        faces = list(face[name])
    edges = _NO_EDGES
    if "edge" in ply:
        edge = ply["edge"]
        if not {"vertex1", "vertex2"} <= set(_names(edge)):
            raise ValueError(f"{path}: PLY edge element needs vertex1 and vertex2 properties")
        if any(np.dtype(edge.ply_property(n).val_dtype).kind not in "iu" for n in ("vertex1", "vertex2")):
            raise ValueError(f"{path}: PLY properties edge.vertex1 and edge.vertex2 must be integers")
        edges = np.stack([_ply_scalar(path, edge, "vertex1"), _ply_scalar(path, edge, "vertex2")], axis=1)
    return vertices, faces, edges


# ------------------------------------------------------------------ OBJ, OFF


def _obj_index(path: Path, number: int, token: str, n_vertices: int) -> int:
    """A 0-based vertex index from an OBJ corner ``i``, ``i/t``, ``i//n``, ``i/t/n`` (negative: relative)."""
    head = token.split("/", 1)[0]
    try:
        i = int(head)
    except ValueError:
        raise ValueError(f"{path}:{number}: not a vertex index: {token[:40]!r}") from None
    if i == 0:
        raise ValueError(f"{path}:{number}: OBJ vertex indices start at 1, got 0")
    if abs(i) > 2**62:  # would overflow int64 on the way to the range check
        raise ValueError(f"{path}:{number}: vertex index out of range: {token[:40]!r}")
    return i - 1 if i > 0 else n_vertices + i  # out of range is caught with the others


def _obj_mesh(path: Path, text: str):
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    edges: list[list[int]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split("#", 1)[0].split()
        if not fields:
            continue
        key, args = fields[0], fields[1:]
        if key == "v":
            values = parse_row(args[:3]) if len(args) >= 3 else None
            if values is None:
                raise ValueError(f"{path}:{number}: a vertex needs 3 numbers: {line[:80]!r}")
            vertices.append(values)
        elif key in ("f", "l"):
            corners = [_obj_index(path, number, t, len(vertices)) for t in args]
            if key == "f":
                faces.append(corners)
            elif len(corners) < 2:
                raise ValueError(f"{path}:{number}: a line needs 2 or more vertices: {line[:80]!r}")
            else:
                edges += [corners[i:i + 2] for i in range(len(corners) - 1)]
    return _vertex_array(path, vertices), faces, np.array(edges, np.int64).reshape(-1, 2)


def _off_mesh(path: Path, text: str):
    lines = [(n, line.split("#", 1)[0].split()) for n, line in enumerate(text.splitlines(), start=1)]
    lines = [(n, f) for n, f in lines if f]
    if not lines or not _OFF_HEADER.match(lines[0][1][0]):
        raise ValueError(f"{path}: not an OFF file (the first line must be OFF, COFF, NOFF, CNOFF or STOFF)")
    first = lines[0][1][1:]  # the counts may follow the keyword on its line
    rest = lines[1:] if not first else [(lines[0][0], first)] + lines[1:]
    if not rest:
        raise ValueError(f"{path}: OFF file ends before its counts")
    number, counts = rest[0]
    if len(counts) < 2 or not all(c.isascii() and c.isdigit() for c in counts[:3]):
        raise ValueError(f"{path}:{number}: expected the counts 'vertices faces [edges]', got {' '.join(counts)[:80]!r}")
    nv, nf = int(counts[0]), int(counts[1])
    body = rest[1:]
    if len(body) < nv + nf:
        raise ValueError(f"{path}: OFF file declares {nv} vertices and {nf} faces but has {len(body)} lines after the counts")
    vertices = []
    for number, fields in body[:nv]:
        values = parse_row(fields[:3]) if len(fields) >= 3 else None
        if values is None:
            raise ValueError(f"{path}:{number}: a vertex needs 3 numbers: {' '.join(fields)[:80]!r}")
        vertices.append(values)
    faces = []
    for number, fields in body[nv:nv + nf]:
        try:
            k = int(fields[0])
            corners = [int(f) for f in fields[1:1 + k]]
        except ValueError:
            raise ValueError(f"{path}:{number}: not a face 'k i1 ... ik': {' '.join(fields)[:80]!r}") from None
        if k < 0 or len(corners) < k:
            raise ValueError(f"{path}:{number}: face declares {k} corners but lists {len(fields) - 1}")
        faces.append(corners)
    return _vertex_array(path, vertices), faces, _NO_EDGES


# -------------------------------------------------------------------- checks


def _vertex_array(path: Path, rows: list) -> np.ndarray:
    vertices = np.array(rows, np.float64).reshape(-1, 3)
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise ValueError(f"{path}: vertex {int(np.argmax(bad))} has a NaN or inf coordinate")
    return vertices


def _checked_mesh(path: Path, vertices: np.ndarray, faces, edges: np.ndarray) -> Mesh:
    """Faces fanned into triangles and every index checked."""
    nv = len(vertices)
    if nv == 0:
        raise ValueError(f"{path}: the mesh has no vertices")
    if not len(faces):
        raise ValueError(f"{path}: the mesh has no faces (a point set? read it with read_points3d)")
    triangles = []
    for i, face in enumerate(faces):
        if any(abs(int(c)) > nv for c in face):  # before int64: a huge text index would overflow it
            raise ValueError(f"{path}: face {i} has a vertex index out of range: indices must be in [0, {nv})")
        face = np.asarray(face, dtype=np.int64).ravel()
        if len(face) < 3:
            raise ValueError(f"{path}: face {i} has {len(face)} corner(s); a face needs 3 or more")
        if len(np.unique(face)) < len(face):
            raise ValueError(f"{path}: face {i} is degenerate: it repeats a vertex ({face.tolist()[:8]})")
        fan = np.stack([np.full(len(face) - 2, face[0]), face[1:-1], face[2:]], axis=1)
        triangles.append(fan)
    triangles = np.concatenate(triangles)
    for name, idx in (("face", triangles), ("edge", edges)):
        if idx.size and (idx.min() < 0 or idx.max() >= nv):
            raise ValueError(f"{path}: {name} vertex index out of range: indices must be in [0, {nv}), "
                             f"got {idx.min()}..{idx.max()}")
    edges = np.asarray(edges).astype(np.int64).reshape(-1, 2)
    if edges.size and np.any(edges[:, 0] == edges[:, 1]):
        raise ValueError(f"{path}: an edge joins a vertex to itself")
    return Mesh(vertices, triangles, edges)
