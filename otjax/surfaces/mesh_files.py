"""A surface result as mesh files: PLY, OBJ, OFF.

Each writer makes the whole file in memory from arrays, so that saving can
check everything first and write atomically (:mod:`otjax.io`). Numbers are
written so that :func:`otjax.io3d.read_mesh` reads back the same float64
values (PLY binary doubles; OBJ and OFF the shortest decimal that round-trips),
and the same arrays always give the same bytes.

* PLY (binary little endian): ``vertex`` with ``x y z`` (and ``mass`` when
  vertex masses are known), ``face`` with ``vertex_indices``, ``mass`` and
  ``density``, and ``edge`` with ``vertex1 vertex2`` for the dangling edges.
* OBJ: ``v`` lines, ``f`` lines (1-based), ``l`` lines for the dangling
  edges and one ``p`` line listing the isolated vertices.
* OFF: vertices and triangles only; the format has no edges or points.
"""

from __future__ import annotations

import io

import numpy as np

MESH_EXTENSIONS = (".ply", ".obj", ".off")


def _number(x: float) -> str:
    return repr(float(x))  # the shortest decimal that reads back as the same float64


def _lines(rows, prefix: str, offset: int = 0) -> list[str]:
    return [prefix + " ".join(str(int(i) + offset) for i in row) for row in np.asarray(rows).tolist()]


def to_ply(vertices, triangles, edges, triangle_mass, triangle_density, vertex_mass=None) -> bytes:
    """The complex as a binary little-endian PLY file (module doc).

    Args:
      vertices: ``(V, 3)``; triangles: ``(T, 3)``; edges: ``(E, 2)`` dangling edges.
      triangle_mass, triangle_density: ``(T,)`` per-face properties.
      vertex_mass: ``(V,)`` or ``None`` (no vertex property then).
    """
    from plyfile import PlyData, PlyElement

    vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")] + ([("mass", "<f8")] if vertex_mass is not None else [])
    vert = np.empty(len(vertices), dtype=fields)
    for k, name in enumerate("xyz"):
        vert[name] = vertices[:, k]
    if vertex_mass is not None:
        vert["mass"] = vertex_mass
    triangles = np.asarray(triangles, np.int64).reshape(-1, 3)
    face = np.empty(len(triangles), dtype=[("vertex_indices", "<i4", (3,)), ("mass", "<f8"), ("density", "<f8")])
    face["vertex_indices"] = triangles
    face["mass"] = triangle_mass
    face["density"] = triangle_density
    edges = np.asarray(edges, np.int64).reshape(-1, 2)
    edge = np.empty(len(edges), dtype=[("vertex1", "<i4"), ("vertex2", "<i4")])
    edge["vertex1"], edge["vertex2"] = edges[:, 0], edges[:, 1]
    elements = [PlyElement.describe(vert, "vertex"),
                PlyElement.describe(face, "face", len_types={"vertex_indices": "u1"}),
                PlyElement.describe(edge, "edge")]
    buffer = io.BytesIO()
    PlyData(elements, text=False, byte_order="<", comments=["otjax surface result"]).write(buffer)
    return buffer.getvalue()


def to_obj(vertices, triangles, edges, isolated) -> str:
    """The complex as Wavefront OBJ text (module doc)."""
    vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
    out = ["# otjax surface result"]
    out += ["v " + " ".join(_number(x) for x in row) for row in vertices.tolist()]
    out += _lines(np.asarray(triangles).reshape(-1, 3), "f ", 1)
    out += _lines(np.asarray(edges).reshape(-1, 2), "l ", 1)
    isolated = np.asarray(isolated).reshape(-1)
    if len(isolated):
        out += _lines(isolated[None], "p ", 1)
    return "\n".join(out) + "\n"


def to_off(vertices, triangles) -> str:
    """The vertices and triangles as OFF text (module doc)."""
    vertices = np.asarray(vertices, np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles).reshape(-1, 3)
    out = ["OFF", f"{len(vertices)} {len(triangles)} 0"]
    out += [" ".join(_number(x) for x in row) for row in vertices.tolist()]
    out += _lines(triangles, "3 ")
    return "\n".join(out) + "\n"
