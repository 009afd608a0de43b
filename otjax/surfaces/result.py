"""The result of a surface reconstruction: arrays, density filtering, files, a picture.

The JSON layout is DESIGN.md's "Surface result JSON" plus the vertex
masses, described by the JSON Schema shipped next to this module
(``surface_result.schema.json``, :func:`json_schema`). The schema checks
types; :meth:`SurfaceResult.from_dict` also checks what a schema cannot
(index ranges, matching lengths, densities that match the masses).
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from otjax.io import check_output_paths, write_files
from otjax.result_fields import check_json_keys, float_array, index_array, load_json, plain_json
from otjax.surfaces import mesh_files
from otjax.surfaces.filtering import check_threshold, facet_density, filter_facets

SAVE_EXTENSIONS = (".json",) + mesh_files.MESH_EXTENSIONS
JSON_KEYS = ("vertices", "triangles", "edges", "isolated", "vertex_mass", "triangle_mass", "triangle_density",
             "total_cost", "params", "seconds")


def json_schema() -> dict:
    """The JSON Schema (draft 2020-12) of :meth:`SurfaceResult.to_dict`."""
    text = resources.files("otjax.surfaces").joinpath("surface_result.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


@dataclass(eq=False)
class SurfaceResult:
    """A reconstructed surface: a complex of triangles, dangling edges and isolated vertices.

    Attributes:
      vertices: ``(V, 3)`` float64 positions.
      triangles: ``(T, 3)`` int64 facets, rows into ``vertices``.
      edges: ``(E, 2)`` int64 dangling edges (of no facet); a reconstruction
        has none, since edges carry no transported mass.
      isolated: ``(I,)`` int64 vertices of no facet or edge that carry mass.
      triangle_mass: ``(T,)`` mass transported onto each facet, ``>= 0``.
      vertex_mass: ``(V,)`` mass transported onto each vertex (``>= 0``), or
        ``None`` when not known.
      total_cost: squared W2 transport cost of the input onto the complex.
      params: the parameters used (JSON-serialisable values).
      seconds: wall time of the reconstruction.
      points, masses: ``(n, 3)`` and ``(n,)`` input, or ``None``; for plots, not saved.
      stats: anything else about the run; not saved.

    Derived on construction: ``triangle_area``, ``triangle_density``
    (``mass / area``) and ``density`` (the :class:`~otjax.surfaces.filtering.FacetDensity`,
    with the sorted relative densities a threshold slider needs).

    Example:
      >>> r = SurfaceResult(vertices=np.eye(3), triangles=[[0, 1, 2]], triangle_mass=[2.0])
      >>> SurfaceResult.from_dict(r.to_dict()).triangles.tolist()
      [[0, 1, 2]]
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_mass: np.ndarray
    edges: np.ndarray | None = None
    isolated: np.ndarray | None = None
    vertex_mass: np.ndarray | None = None
    total_cost: float = 0.0
    params: dict | None = None
    seconds: float = 0.0
    points: np.ndarray | None = None
    masses: np.ndarray | None = None
    stats: object = None

    def __post_init__(self):
        self.vertices = float_array(self.vertices, "vertices", (-1, 3))
        n = len(self.vertices)
        self.triangles = index_array(self.triangles, "triangles", (-1, 3), n)
        if self.triangles.size and np.any(np.diff(np.sort(self.triangles, axis=1), axis=1) == 0):
            raise ValueError("triangles must have three different vertices")
        self.edges = index_array(self.edges, "edges", (-1, 2), n)
        if self.edges.size and np.any(self.edges[:, 0] == self.edges[:, 1]):
            raise ValueError("edges must join two different vertices")
        self.isolated = index_array(self.isolated, "isolated", (-1,), n)
        self.triangle_mass = float_array(self.triangle_mass, "triangle_mass", (len(self.triangles),))
        if self.vertex_mass is not None:
            self.vertex_mass = float_array(self.vertex_mass, "vertex_mass", (n,))
        for name in ("triangle_mass", "vertex_mass"):
            value = getattr(self, name)
            if value is not None and np.any(value < 0):
                raise ValueError(f"{name} must be >= 0")
        for name in ("total_cost", "seconds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
            setattr(self, name, float(value))
        self.params = {} if self.params is None else self.params
        if not isinstance(self.params, dict):
            raise ValueError(f"params must be a dict, got {type(self.params).__name__}")  # noqa: TRY004
        if self.points is not None:
            self.points = float_array(self.points, "points", (-1, 3))
        if self.masses is not None:
            self.masses = float_array(self.masses, "masses", (-1 if self.points is None else len(self.points),))
        self.density = facet_density(self.vertices, self.triangles, self.triangle_mass)
        self.triangle_area = self.density.area
        self.triangle_density = self.density.density

    @classmethod
    def from_arrays(cls, vertices, triangles, triangle_mass, **fields) -> SurfaceResult:
        """The result of plain arrays; ``fields`` are the other attributes by name.

        Example:
          >>> SurfaceResult.from_arrays(np.eye(3), [[0, 1, 2]], [1.0], total_cost=0.5).total_cost
          0.5
        """
        return cls(vertices=vertices, triangles=triangles, triangle_mass=triangle_mass, **fields)

    # --- filtering ----------------------------------------------------------

    @property
    def sorted_density(self) -> np.ndarray:
        """``(T,)`` relative facet densities, decreasing: the thresholds of :meth:`filtered`."""
        return self.density.sorted

    def filtered(self, threshold: float) -> SurfaceResult:
        """A copy keeping the facets of relative density ``>= threshold``
        (:mod:`otjax.surfaces.filtering`: a multiple of the mean density; what
        happens to edges and vertices is described there)."""
        threshold = check_threshold(threshold)
        f = filter_facets(self.vertices, self.triangles, self.triangle_mass, threshold, self.edges, self.isolated,
                          self.vertex_mass)
        keep_v = f.vertex_index >= 0
        return SurfaceResult(
            vertices=f.vertices, triangles=f.triangles, triangle_mass=self.triangle_mass[f.triangle_keep],
            edges=f.edges, isolated=f.isolated,
            vertex_mass=None if self.vertex_mass is None else self.vertex_mass[keep_v],
            total_cost=self.total_cost, params={**self.params, "threshold": threshold}, seconds=self.seconds,
            points=self.points, masses=self.masses, stats=self.stats)

    # --- JSON -------------------------------------------------------------

    def to_dict(self) -> dict:
        """The JSON layout (module doc), with plain Python lists, ints and floats."""
        return {
            "vertices": self.vertices.tolist(), "triangles": self.triangles.tolist(), "edges": self.edges.tolist(),
            "isolated": self.isolated.tolist(),
            "vertex_mass": None if self.vertex_mass is None else self.vertex_mass.tolist(),
            "triangle_mass": self.triangle_mass.tolist(), "triangle_density": self.triangle_density.tolist(),
            "total_cost": self.total_cost, "params": plain_json(self.params, "params"), "seconds": self.seconds,
        }

    def to_json(self, indent: int | None = None) -> str:
        """:meth:`to_dict` as strict JSON (no NaN or inf)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, d: dict) -> SurfaceResult:
        """A result from :meth:`to_dict`'s layout, checked.

        Raises:
          ValueError: a key missing or unknown, a wrong type or shape, an index
            out of range, lengths that differ, densities that do not match
            ``triangle_mass / area``.
        """
        check_json_keys(d, JSON_KEYS, "surface result")
        result = cls(**{k: d[k] for k in JSON_KEYS if k != "triangle_density"})
        stored = float_array(d["triangle_density"], "triangle_density", (len(result.triangles),))
        if not np.allclose(stored, result.triangle_density, rtol=1e-9, atol=0):
            raise ValueError("triangle_density does not match triangle_mass / triangle area")
        return result

    @classmethod
    def load(cls, path) -> SurfaceResult:
        """Reads a result saved as ``.json``; ``ValueError`` naming the file if unreadable or malformed."""
        return load_json(path, cls.from_dict)

    # --- files ------------------------------------------------------------

    def render(self, path) -> str | bytes:
        """The content of a file at ``path`` (by extension: ``.json``, ``.ply``, ``.obj``, ``.off``)."""
        ext = Path(path).suffix.lower()
        if ext == ".json":
            return self.to_json(indent=1) + "\n"
        if ext == ".ply":
            return mesh_files.to_ply(self.vertices, self.triangles, self.edges, self.triangle_mass,
                                 self.triangle_density, self.vertex_mass)
        if ext == ".obj":
            return mesh_files.to_obj(self.vertices, self.triangles, self.edges, self.isolated)
        if ext == ".off":
            return mesh_files.to_off(self.vertices, self.triangles)
        raise ValueError(f"{path}: unknown output extension {ext!r}; expected one of {', '.join(SAVE_EXTENSIONS)}")

    def save(self, *paths, mkdir: bool = False) -> None:
        """Writes the result to one or more files, all or nothing.

        Every path is checked first (extension, directory, no path twice;
        :func:`otjax.io.check_output_paths`), every file is made in memory,
        then all are written atomically (:func:`otjax.io.write_files`): a bad
        path or a failure leaves nothing new on disk.

        Example:
          >>> result.save("out.json", "out.ply")  # doctest: +SKIP
        """
        checked = check_output_paths(paths, SAVE_EXTENSIONS, mkdir=mkdir)
        write_files([(p, self.render(p)) for p in checked], mkdir=mkdir)

    def plot(self, ax=None, *, show_points: bool = True, plan=None, highlight=None):
        """Draws the result on 3D axes (:func:`otjax.surfaces.plot.plot_complex`), facets
        coloured by density; returns the axes."""
        from otjax.surfaces.plot import plot_complex

        return plot_complex(self.vertices, self.triangles, self.edges, self.isolated, density=self.triangle_density,
                            points=self.points if show_points else None, plan=plan, highlight=highlight, ax=ax)

    def summary(self) -> str:
        """One line: counts, cost and time."""
        return (f"{len(self.vertices)} vertices, {len(self.triangles)} triangles, {len(self.edges)} edges, "
                f"{len(self.isolated)} isolated, total cost (W2^2) {self.total_cost:.6g}, {self.seconds:.2f} s")
