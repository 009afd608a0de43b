"""The result of a curve reconstruction: arrays, JSON, SVG/PNG pictures.

The JSON layout is the one of ``DESIGN.md`` ("Curve result JSON") and is
described by the JSON Schema shipped next to this module
(``curve_result.schema.json``, see :func:`json_schema`). The schema checks
types; :meth:`CurveResult.from_dict` also checks what a schema cannot (index
ranges, matching lengths).
"""

from __future__ import annotations

import io
import json
import math
import numbers
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from otjax.io import atomic_write
from otjax.result_fields import check_json_keys, float_array, index_array, load_json, plain_json

# A wrong type is a ValueError too, not a TypeError (the noqa: TRY004 below): DESIGN.md
# promises one exception type for bad input, which is what the CLI catches.

SAVE_EXTENSIONS = (".json", ".svg", ".png")
JSON_KEYS = (
    "vertices",
    "edges",
    "isolated",
    "edge_mass",
    "edge_relevance",
    "total_cost",
    "params",
    "seconds",
)


def json_schema() -> dict:
    """The JSON Schema (draft 2020-12) of :meth:`CurveResult.to_dict`."""
    text = resources.files("otjax.curves").joinpath("curve_result.schema.json").read_text(encoding="utf-8")
    return json.loads(text)


def check_save_path(path) -> Path:
    """``path`` as a :class:`Path` if :meth:`CurveResult.save` can write it, else ``ValueError``.

    Lets a caller (the CLI) reject every output name before any work is done.
    """
    path = Path(path)
    if path.suffix.lower() not in SAVE_EXTENSIONS:
        raise ValueError(
            f"{path}: unknown output extension {path.suffix!r}; expected one of {', '.join(SAVE_EXTENSIONS)}"
        )
    return path


@dataclass(eq=False)
class CurveResult:
    """A reconstructed curve.

    Attributes:
      vertices: ``(k, 2)`` float64 vertex positions.
      edges: ``(m, 2)`` int64 kept edges, as indices into ``vertices``.
      isolated: ``(i,)`` int64 vertices carrying mass but no kept edge.
      edge_mass: ``(m,)`` float64 mass transported to each edge.
      edge_relevance: ``(m,)`` float64 relevance of each edge.
      total_cost: squared W2 transport cost of the input onto the result.
      params: the parameters used (JSON-serialisable values).
      seconds: wall time of the reconstruction.
      points: ``(n, 2)`` input points, or ``None``; for plotting, not saved.
      masses: ``(n,)`` input masses, or ``None``; for plotting, not saved.
      history: optional per-step record of the run; not saved.

    Example:
      >>> r = CurveResult(vertices=[[0, 0], [1, 0]], edges=[[0, 1]], isolated=[],
      ...                 edge_mass=[2.0], edge_relevance=[1.0], total_cost=0.1,
      ...                 params={"n_vertices": 2}, seconds=0.5)
      >>> CurveResult.from_dict(r.to_dict()).edges.tolist()
      [[0, 1]]
    """

    vertices: np.ndarray
    edges: np.ndarray
    isolated: np.ndarray
    edge_mass: np.ndarray
    edge_relevance: np.ndarray
    total_cost: float
    params: dict
    seconds: float
    points: np.ndarray | None = None
    masses: np.ndarray | None = None
    history: dict | None = None

    def __post_init__(self):
        # Coerce and check once here, so that every result (built by the
        # library or loaded from a file) serialises without surprises.
        self.vertices = float_array(self.vertices, "vertices", (-1, 2))
        k = len(self.vertices)
        self.edges = index_array(self.edges, "edges", (-1, 2), k)
        if self.edges.size and np.any(self.edges[:, 0] == self.edges[:, 1]):
            raise ValueError("edges must join two different vertices")
        self.isolated = index_array(self.isolated, "isolated", (-1,), k)
        m = len(self.edges)
        self.edge_mass = float_array(self.edge_mass, "edge_mass", (m,))
        self.edge_relevance = float_array(self.edge_relevance, "edge_relevance", (m,))
        for name in ("total_cost", "seconds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            if value < 0:
                raise ValueError(f"{name} must be >= 0, got {value}")
            setattr(self, name, float(value))
        if not isinstance(self.params, dict):
            raise ValueError(f"params must be a dict, got {type(self.params).__name__}")  # noqa: TRY004
        if self.points is not None:
            self.points = float_array(self.points, "points", (-1, 2))
        if self.masses is not None:
            n = -1 if self.points is None else len(self.points)
            self.masses = float_array(self.masses, "masses", (n,))

    # --- filtering ----------------------------------------------------------

    def edge_density(self) -> np.ndarray:
        """``(m,)`` mass per unit length of each edge, ``M_e / |e|``."""
        length = np.linalg.norm(self.vertices[self.edges[:, 0]] - self.vertices[self.edges[:, 1]], axis=1)
        return self.edge_mass / np.where(length > 0, length, np.inf)

    def filtered(self, relevance: float = 0.0, density: float = 0.0) -> CurveResult:
        """A copy keeping the edges with relevance ``>= relevance`` and linear
        mass density ``>= density`` times the largest one.

        For exploring thresholds without reconstructing again. Vertices that
        lose all their edges are dropped (vertex masses are not stored in a
        result, so they are not turned into isolated vertices); isolated
        vertices stay. ``reconstruct_curve(..., relevance=, density=)`` gives
        the same edges.
        """
        if not (np.isfinite(relevance) and relevance >= 0):
            raise ValueError(f"relevance must be finite and >= 0, got {relevance!r}")
        if not (0 <= density <= 1):
            raise ValueError(f"density must be in [0, 1], got {density!r}")
        dens = self.edge_density()
        keep = self.edge_relevance >= relevance
        if len(dens):
            keep &= dens >= density * dens.max()
        used = np.unique(np.concatenate([self.edges[keep].ravel(), self.isolated]))
        index = np.full(len(self.vertices), -1, np.int64)
        index[used] = np.arange(len(used))
        return CurveResult(
            vertices=self.vertices[used], edges=index[self.edges[keep]].reshape(-1, 2),
            isolated=index[self.isolated], edge_mass=self.edge_mass[keep],
            edge_relevance=self.edge_relevance[keep], total_cost=self.total_cost,
            params={**self.params, "relevance": float(relevance), "density": float(density)},
            seconds=self.seconds, points=self.points, masses=self.masses, history=self.history)

    # --- JSON -------------------------------------------------------------

    def to_dict(self) -> dict:
        """The DESIGN.md JSON layout, with plain Python lists, ints and floats."""
        return {
            "vertices": self.vertices.tolist(),
            "edges": self.edges.tolist(),
            "isolated": self.isolated.tolist(),
            "edge_mass": self.edge_mass.tolist(),
            "edge_relevance": self.edge_relevance.tolist(),
            "total_cost": self.total_cost,
            "params": plain_json(self.params, "params"),
            "seconds": self.seconds,
        }

    def to_json(self, indent: int | None = None) -> str:
        """:meth:`to_dict` as a JSON string (strict JSON: no NaN or inf)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, d: dict) -> CurveResult:
        """Builds a result from :meth:`to_dict`'s layout, checking it.

        Raises:
          ValueError: a key missing or unknown, a wrong type or shape, an index
            out of range, or lengths that do not match.
        """
        check_json_keys(d, JSON_KEYS, "curve result")
        return cls(**{k: d[k] for k in JSON_KEYS})

    @classmethod
    def load(cls, path) -> CurveResult:
        """Reads a result saved as ``.json``; ``ValueError`` if unreadable or malformed."""
        return load_json(path, cls.from_dict)

    # --- files ------------------------------------------------------------

    def save(self, path) -> None:
        """Writes the result as ``.json``, ``.svg`` or ``.png`` (by extension), atomically.

        The whole file is produced in memory first, so an error (unknown
        extension, unserialisable params) leaves nothing on disk.
        """
        path = check_save_path(path)
        ext = path.suffix.lower()
        if ext == ".json":
            data, mode = self.to_json(indent=1) + "\n", "w"
        elif ext == ".svg":
            data, mode = self.to_svg(), "w"
        else:
            data, mode = self.to_png(), "wb"
        with atomic_write(path, mode) as f:
            f.write(data)

    def to_svg(self, width: int = 800) -> str:
        """A standalone SVG picture: input points (grey), edges (black), vertices (red).

        The view box is the bounding box of everything drawn plus a 5% margin;
        y points up as in the data. Isolated vertices are drawn as squares.
        """
        drawn = [self.vertices] + ([self.points] if self.points is not None else [])
        allxy = np.concatenate(drawn) if sum(len(a) for a in drawn) else np.zeros((1, 2))
        lo, hi = allxy.min(0), allxy.max(0)
        size = float(max(hi - lo)) or 1.0  # a single point still gets a visible box
        margin = 0.05 * size
        box_w, box_h = float(hi[0] - lo[0]) + 2 * margin, float(hi[1] - lo[1]) + 2 * margin

        def xy(p):  # data coordinates to SVG (y down) coordinates
            return p[..., 0] - lo[0] + margin, hi[1] - p[..., 1] + margin

        def f(v):
            return f"{v:.7g}"

        stroke = 0.004 * size
        radius = 0.008 * size
        out = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            (
                f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" '
                f'height="{round(width * box_h / box_w)}" viewBox="0 0 {f(box_w)} {f(box_h)}">'
            ),
            '<rect width="100%" height="100%" fill="white"/>',
        ]
        if self.points is not None and len(self.points):
            px, py = xy(self.points)
            out.append('<g id="points" fill="#bbbbbb">')
            out += [f'<circle cx="{f(a)}" cy="{f(b)}" r="{f(radius / 3)}"/>' for a, b in zip(px, py)]
            out.append("</g>")
        vx, vy = xy(self.vertices)
        out.append(f'<g id="edges" stroke="#202020" stroke-width="{f(stroke)}" stroke-linecap="round">')
        out += [
            f'<line x1="{f(vx[i])}" y1="{f(vy[i])}" x2="{f(vx[j])}" y2="{f(vy[j])}"/>' for i, j in self.edges
        ]
        out.append("</g>")
        isolated = np.zeros(len(self.vertices), bool)
        isolated[self.isolated] = True
        out.append('<g id="vertices" fill="#d62728">')
        out += [
            f'<circle cx="{f(vx[i])}" cy="{f(vy[i])}" r="{f(radius)}"/>' for i in np.flatnonzero(~isolated)
        ]
        out.append("</g>")
        out.append(f'<g id="isolated" fill="none" stroke="#d62728" stroke-width="{f(stroke)}">')
        out += [
            f'<rect x="{f(vx[i] - radius)}" y="{f(vy[i] - radius)}" width="{f(2 * radius)}" height="{f(2 * radius)}"/>'
            for i in np.flatnonzero(isolated)
        ]
        out.append("</g>")
        out.append("</svg>")
        return "\n".join(out) + "\n"

    def to_png(self, dpi: int = 100) -> bytes:
        """A PNG picture of :meth:`plot`, rendered off-screen (no pyplot, no global state)."""
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6, 6), dpi=dpi)
        FigureCanvasAgg(fig)  # attaches itself to fig
        self.plot(fig.add_subplot())
        fig.tight_layout()
        buffer = io.BytesIO()
        fig.savefig(buffer, format="png")
        return buffer.getvalue()

    def plot(self, ax=None, *, show_points: bool = True):
        """Draws the result with matplotlib.

        Args:
          ax: axes to draw on; ``None`` makes a new figure with pyplot (as
            plotting libraries usually do, so it shows in notebooks).
          show_points: also draw the input points, when the result holds them.

        Returns:
          The axes.
        """
        from matplotlib.collections import LineCollection

        if ax is None:
            import matplotlib.pyplot as plt

            _, ax = plt.subplots(figsize=(6, 6))
        if show_points and self.points is not None and len(self.points):
            ax.scatter(*self.points.T, s=4, c="0.65", linewidths=0, label="input points")
        if len(self.edges):
            ax.add_collection(
                LineCollection(self.vertices[self.edges], colors="0.1", linewidths=1.5, label="edges")
            )
        isolated = np.zeros(len(self.vertices), bool)
        isolated[self.isolated] = True
        if (~isolated).any():
            ax.scatter(*self.vertices[~isolated].T, s=18, c="tab:red", zorder=3, label="vertices")
        if isolated.any():
            ax.scatter(
                *self.vertices[isolated].T,
                s=30,
                marker="s",
                facecolors="none",
                edgecolors="tab:red",
                zorder=3,
                label="isolated vertices",
            )
        ax.set_aspect("equal")
        ax.autoscale_view()
        return ax

    def summary(self) -> str:
        """One line: counts, cost and time."""
        return (
            f"{len(self.vertices)} vertices, {len(self.edges)} edges, {len(self.isolated)} isolated, "
            f"total cost (W2^2) {self.total_cost:.6g}, {self.seconds:.2f} s"
        )
