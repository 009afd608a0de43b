"""Render the curve acceptance cases (``tests/curves/test_reconstruct_*.py``) as PNG pictures.

    python scripts/gallery.py [--out docs/gallery] [--seed 0] [--small] [--cases NAME ...]

Each case is reconstructed with the same data and parameters as the
acceptance tests, drawn (input points light grey, edges dark, vertices red,
isolated vertices as hollow red squares) and saved as ``OUT/NAME.png``. The
measured numbers go to ``OUT/gallery.json`` (merged with the cases already
there, so ``--cases`` refreshes only the named ones) and are printed as a
table. Distances are in percent of ``D``, the bounding-box diagonal of the
clean shape; ``seconds`` is the reconstruction's own wall time
(``CurveResult.seconds``, JIT compilation included).

``--seed S`` is added to every data seed of the tests (so 0 gives exactly
the tests' point sets) and passed to ``reconstruct_curve`` as its ``seed``.
``--small`` divides every point count by 4 for a quick check (the
``drawing`` case is an image and keeps its size). Every file is written
atomically: a temporary file in the same directory, then ``os.replace``.

Only the public API of ``otjax`` is used.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass, field

import jax
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

import otjax
from otjax import datasets, metrics

POINT_COLOR = "0.8"  # light grey, lighter than CurveResult.plot's own points
TOL = 0.03  # recall / precision tolerance, fraction of D (as in the outlier test)
NEAR = 0.02  # junction / end search radius, fraction of D (as in the junction test)


# --- running and measuring ---------------------------------------------------


@dataclass
class Run:
    """One reconstruction drawn in one panel, with its numbers."""

    label: str
    result: otjax.CurveResult
    points: np.ndarray
    numbers: dict = field(default_factory=dict)


@dataclass
class Case:
    """A rendered case: its runs (one per panel) and case-level numbers."""

    name: str
    description: str
    runs: list
    truth: dict
    numbers: dict = field(default_factory=dict)
    layout: tuple = (1, 1)  # (rows, cols) of panels
    panel_size: tuple = (6.0, 6.4)  # inches, titles included


def _pct(x: float) -> float | None:
    """A fraction of D as a percentage; ``None`` when not finite (no vertices, no edges)."""
    x = float(x)
    return 100.0 * x if math.isfinite(x) else None


def measure(result: otjax.CurveResult, truth: dict, features: np.ndarray) -> dict:
    """Counts, corner errors and Hausdorff distance (percent of D), cost and time of one result."""
    d = truth["diagonal"]
    err = metrics.corner_errors(result.vertices, features) / d
    out = metrics.edges_to_segments(result.vertices, result.edges)
    return {
        "vertices": len(result.vertices),
        "edges": len(result.edges),
        "isolated": len(result.isolated),
        "corner_mean_pct": _pct(err.mean()) if err.size else None,
        "corner_max_pct": _pct(err.max()) if err.size else None,
        "hausdorff_pct": _pct(metrics.hausdorff(truth["segments"], out) / d),
        "total_cost": result.total_cost,
        "seconds": result.seconds,
    }


def recall_precision(result: otjax.CurveResult, truth: dict) -> dict:
    """Share of the true length within TOL * D of the edges, and of the edges' length near the truth."""
    kept = metrics.edges_to_segments(result.vertices, result.edges)
    tol = TOL * truth["diagonal"]
    return {
        "recall": metrics.length_within(truth["segments"], kept, tol),
        "precision": metrics.length_within(kept, truth["segments"], tol),
    }


def degrees(result: otjax.CurveResult) -> np.ndarray:
    return np.bincount(result.edges.ravel(), minlength=len(result.vertices))


def near_degrees(result: otjax.CurveResult, where: np.ndarray, radius: float) -> list:
    """For each point of ``where``: the degrees of the output vertices within ``radius`` (sorted)."""
    deg = degrees(result)
    out = []
    for p in where:
        near = np.linalg.norm(result.vertices - p, axis=1) <= radius
        out.append(sorted(int(k) for k in deg[near]))
    return out


def reconstruct(points, masses=None, **kwargs) -> otjax.CurveResult:
    return otjax.reconstruct_curve(points, masses, **kwargs)


def case_star_clean(scale: int, seed: int) -> Case:
    pts, truth = datasets.star(3000 // scale, noise=0.0, seed=1 + seed)
    r = reconstruct(pts, n_vertices=10, seed=seed)
    run = Run("n_vertices=10", r, pts, measure(r, truth, truth["corners"]))
    return Case("star-clean", "clean five-pointed star", [run], truth)


def case_star_noisy(scale: int, seed: int) -> Case:
    pts, truth = datasets.star(3000 // scale, noise=0.01, seed=2 + seed)
    r = reconstruct(pts, n_vertices=10, seed=seed)
    run = Run("n_vertices=10", r, pts, measure(r, truth, truth["corners"]))
    return Case("star-noisy", "five-pointed star, noise 1% D", [run], truth)


def case_star_outliers(scale: int, seed: int) -> Case:
    n = 1500 // scale
    pts, truth = datasets.star(n, noise=0.02, seed=3 + seed)
    pts, truth = datasets.with_outliers(pts, truth, n, seed=4 + seed)
    # As in the acceptance test: 4x the star's corners, every solid edge kept (the
    # automatic filters off), then the density filter (the paper's relevance cannot
    # separate the outlier edges, see README).
    full = reconstruct(pts, n_vertices=40, seed=seed, background="none", chords=False)
    runs = []
    for label, kept in (("all solid edges", full), ("relevance >= 100 (paper)", full.filtered(relevance=100.0)),
                        ("density >= 0.4 (otjax)", full.filtered(density=0.4))):
        numbers = measure(kept, truth, truth["corners"])
        numbers.update(recall_precision(kept, truth))
        runs.append(Run(label, kept, pts, numbers))
    consistent = all(r.result.total_cost == full.total_cost for r in runs)
    desc = f"star, noise 2% D, {n} shape points + {n} uniform outliers, 40 vertices"
    return Case("star-outliers", desc, runs, truth, {"filter_consistent": consistent}, (1, 3), (5.0, 5.4))


def case_junctions(scale: int, seed: int) -> Case:
    pts, truth = datasets.junctions(2000 // scale, noise=0.0, seed=5 + seed)
    n = len(truth["corners"])
    r = reconstruct(pts, n_vertices=n, seed=seed)
    run = Run(f"n_vertices={n}", r, pts, measure(r, truth, truth["corners"]))
    radius = NEAR * truth["diagonal"]
    near_j = near_degrees(r, truth["junctions"], radius)
    near_e = near_degrees(r, truth["ends"], radius)
    numbers = {
        "junction_degree_wanted": truth["junction_degree"].tolist(),
        "junction_degrees_near": near_j,
        "junctions_found": sum(
            int(want) in got for want, got in zip(truth["junction_degree"], near_j)
        ),
        "ends_found": sum(1 in got for got in near_e),
        "ends": len(truth["ends"]),
    }
    desc = "X-crossing (degree 4), T-junction (degree 3), bend, 5 open ends"
    return Case("junctions", desc, [run], truth, numbers, (1, 1), (8.0, 5.0))


def case_skyline(scale: int, seed: int) -> Case:
    pts, truth = datasets.skyline(1500 // scale, noise=0.005, seed=6 + seed)
    features = np.concatenate([truth["corners"], truth["ends"]])
    n = len(features)
    runs = []
    for label, reloc, final in (("relocation=0, final_relocations=0", 0, 0),
                                ("relocation=100, final_relocations=1", 100, 1)):
        r = reconstruct(pts, n_vertices=n, relocation=reloc, final_relocations=final, seed=seed)
        runs.append(Run(label, r, pts, measure(r, truth, features)))
    without, with_ = (run.numbers for run in runs)
    ratio = None
    if with_["corner_mean_pct"] is not None and without["corner_mean_pct"]:
        ratio = with_["corner_mean_pct"] / without["corner_mean_pct"]
    numbers = {"corner_mean_ratio": ratio, "cost_lower_with_relocation": with_["total_cost"] < without["total_cost"]}
    return Case("skyline", f"open skyline, noise 0.5% D, {n} vertices (12 corners + 2 ends)", runs, truth,
                numbers, (2, 1), (10.0, 5.0))


def case_drawing(scale: int, seed: int) -> Case:
    del scale  # an image: the pixel count is fixed by its size
    image, truth = datasets.drawing(size=64, shape="star")
    pts, mass = otjax.image_to_points(image, invert=True, threshold=0.05)
    r = reconstruct(pts, mass, n_vertices=10, seed=seed)
    run = Run("n_vertices=10", r, pts, measure(r, truth, truth["corners"]))
    err = metrics.corner_errors(r.vertices, truth["corners"])
    numbers = {"corner_max_px": float(err.max()), "image_size": 64}
    return Case("drawing", "64x64 raster of a star, pixel darkness as mass", [run], truth, numbers)


CASES = {
    "star-clean": case_star_clean,
    "star-noisy": case_star_noisy,
    "star-outliers": case_star_outliers,
    "junctions": case_junctions,
    "skyline": case_skyline,
    "drawing": case_drawing,
}


# --- drawing and writing ---------------------------------------------------------


def _fmt_pct(x) -> str:
    return "-" if x is None else f"{x:.2f}%"


def panel_title(run: Run) -> str:
    n = run.numbers
    line2 = f"corner error mean {_fmt_pct(n['corner_mean_pct'])}, max {_fmt_pct(n['corner_max_pct'])} of D"
    if "recall" in n:
        line2 += f"\nrecall {n['recall']:.3f}, precision {n['precision']:.3f} (within {TOL:.0%} D)"
    else:
        line2 += f", Hausdorff {_fmt_pct(n['hausdorff_pct'])}"
    counts = f"{n['vertices']} vertices, {n['edges']} edges"
    if n["isolated"]:
        counts += f", {n['isolated']} isolated"
    return f"{run.label}\n{counts}, {n['seconds']:.1f} s\n{line2}"


def render(case: Case) -> bytes:
    """The case's figure as PNG bytes, drawn on a private Figure with an Agg canvas."""
    rows, cols = case.layout
    width, height = case.panel_size
    fig = Figure(figsize=(width * cols, height * rows), dpi=100)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax, run in zip(axes, case.runs):
        ax.scatter(*run.points.T, s=3, c=POINT_COLOR, linewidths=0, zorder=0)
        run.result.plot(ax, show_points=False)
        ax.set_title(panel_title(run), fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    title = f"{case.name}: {case.description}"
    if len(case.runs) == 1:
        axes[0].set_title(f"{title}\n{axes[0].get_title()}", fontsize=9)
    else:
        fig.suptitle(title, fontsize=11)
    # Keep a strip of about 0.35 inch at the top for the suptitle; tight_layout packs the panels below it.
    top = 1.0 if len(case.runs) == 1 else 1.0 - 0.35 / (height * rows)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, top))
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def write_atomic(path: str, data: bytes) -> None:
    """Write ``data`` to a temporary file next to ``path``, then rename it over ``path``."""
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{os.path.basename(path)}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes it owner-only
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _jsonable(value):
    """NumPy scalars to Python ones, non-finite floats to None (strict JSON)."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def case_record(case: Case, small: bool, seed: int) -> dict:
    return {
        "description": case.description,
        "small": small,
        "seed": seed,
        "n_points": len(case.runs[0].points),
        "diagonal": case.truth["diagonal"],
        "png": f"{case.name}.png",
        "runs": [dict(run.numbers, label=run.label, params=run.result.params) for run in case.runs],
        **case.numbers,
    }


def load_existing(path: str) -> dict:
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, ValueError):
        return {}
    return doc.get("cases", {}) if isinstance(doc, dict) else {}


def table(records: dict) -> str:
    head = ("case", "run", "points", "verts", "edges", "isol", "mean%D", "max%D", "haus%D", "rec", "prec", "s")
    rows = []
    for name, rec in records.items():
        for run in rec["runs"]:
            rows.append((
                name,
                run["label"],
                str(rec["n_points"]),
                str(run["vertices"]),
                str(run["edges"]),
                str(run["isolated"]),
                _fmt_pct(run["corner_mean_pct"]).rstrip("%"),
                _fmt_pct(run["corner_max_pct"]).rstrip("%"),
                _fmt_pct(run["hausdorff_pct"]).rstrip("%"),
                f"{run['recall']:.3f}" if "recall" in run else "",
                f"{run['precision']:.3f}" if "precision" in run else "",
                f"{run['seconds']:.1f}",
            ))
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) if i < 2 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
             for r in [head, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def extras(records: dict) -> list:
    """Case-level numbers that do not fit the table, one line per case."""
    lines = []
    for name, rec in records.items():
        skip = {"description", "small", "seed", "n_points", "diagonal", "png", "runs"}
        rest = {k: v for k, v in rec.items() if k not in skip}
        if rest:
            lines.append(f"{name}: " + ", ".join(f"{k}={v}" for k, v in rest.items()))
    return lines


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--out", default="docs/gallery", help="output directory (default: docs/gallery)")
    p.add_argument("--seed", type=int, default=0, help="added to every data seed; 0 = the tests' data")
    p.add_argument("--small", action="store_true", help="divide point counts by 4 for a quick check")
    p.add_argument("--cases", nargs="+", choices=list(CASES), metavar="NAME",
                   help=f"cases to render (default: all): {', '.join(CASES)}")
    return p.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    names = args.cases or list(CASES)
    scale = 4 if args.small else 1
    json_path = os.path.join(args.out, "gallery.json")
    records = load_existing(json_path)
    done = {}
    for name in names:
        print(f"[gallery] {name} ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        case = CASES[name](scale, args.seed)
        png = os.path.join(args.out, f"{name}.png")
        write_atomic(png, render(case))
        done[name] = records[name] = _jsonable(case_record(case, args.small, args.seed))
        print(f"[gallery] {name}: {time.perf_counter() - t0:.1f} s wall -> {png}", file=sys.stderr, flush=True)
    doc = {
        "about": "numbers behind the PNGs; distances in percent of the clean shape's diagonal D",
        "generated_by": "scripts/gallery.py",
        "otjax_version": otjax.__version__,
        "jax_version": jax.__version__,
        "python": platform.python_version(),
        "machine": f"{platform.machine()}, {os.cpu_count()} CPUs",
        "cases": {name: records[name] for name in CASES if name in records},
    }
    write_atomic(json_path, (json.dumps(_jsonable(doc), indent=1, allow_nan=False) + "\n").encode())
    print(table(done))
    for line in extras(done):
        print(line)
    print(f"wrote {', '.join(os.path.join(args.out, n + '.png') for n in done)} and {json_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
