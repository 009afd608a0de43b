"""otjax's surface reconstruction against screened Poisson + QEM decimation,
on the same generated inputs, to the same vertex budget, in one run.

Inputs (:mod:`otjax.datasets3d`, one per seed of ``--seeds``): a staircase without noise and
with Gaussian noise of 1% of the bounding-box diagonal D, an open cylinder
with 10% uniform outliers, two crossing squares, the cube. Each goes through

* ``otjax``: :func:`otjax.surfaces.reconstruct_surface` at its defaults to
  the vertex budget, then facet filtering by relative mass density
  (``--density-threshold``, a multiple of the mean density);
* ``poisson``: Open3D normals (k nearest neighbours), oriented by a
  consistent tangent plane, screened Poisson (octree depth ``--depth``);
  its vertices farther than ``--trim`` point spacings from the input are cut
  away, which opens the surface where there are no points (``--trim 0``
  keeps Poisson's closed surface); then pymeshlab's quadric edge collapse
  (QEM, the filter's defaults) down to the vertex budget.

Metrics, against the clean shape, in % of D: symmetric Chamfer and
Hausdorff distance (:func:`otjax.metrics3d.surface_distances`), the
farthest point of the output (its kept facets, edges and isolated
vertices) from the shape, crease error
(mean distance from the true creases to the output's edges sharper than
30 degrees) and boundary error (from the true open borders to the output's
boundary edges, a fold's two triangles counted as one sheet); "folded", the
triangles lying over another on one of their edges (0 on a mesh without
folds); and the wall time of each method. It prints a markdown
table of the means over the seeds (Poisson + QEM is not deterministic:
means over seeds compare better than one run); ``--json`` writes every
run's numbers, ``--renders DIR`` one PNG per input of the first seed
(points, otjax, Poisson + QEM side by side).

Open3D and pymeshlab are the optional extra ``compare``
(``pip install 'otjax[compare]'``, and on Debian ``apt-get install
libusb-1.0-0`` for Open3D); the library never imports them. Without them
the script says so and exits 1.

    python scripts/compare_surfaces.py --methods poisson              # 5000 points, Poisson side only
    python scripts/compare_surfaces.py --methods poisson --trim 0     # Poisson's closed surfaces
    python scripts/compare_surfaces.py --points 1500 --vertices 100   # both sides
    python scripts/compare_surfaces.py --kinds cube staircase-1 --json out.json --renders renders/
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

METHODS = ("otjax", "poisson")
#: Pieces of the trimmed Poisson mesh with fewer than this share of its triangles are dropped.
SMALL_PIECE = 0.01
INSTALL = ("compare_surfaces: the Poisson + QEM side needs Open3D and pymeshlab: "
           "pip install 'otjax[compare]' (or pip install open3d pymeshlab); on Debian Open3D also needs "
           "apt-get install libusb-1.0-0.")


class Kind(NamedTuple):
    """One input: a dataset of :data:`otjax.datasets3d.SURFACES`, its noise
    (a fraction of D) and outliers (a fraction of the shape's points)."""

    name: str
    dataset: str
    noise: float
    outliers: float
    describe: str


KINDS = (
    Kind("staircase", "staircase", 0.0, 0.0, "three-step staircase, no noise"),
    Kind("staircase-1", "staircase", 0.01, 0.0, "staircase, sigma 1% D"),
    Kind("cylinder-outliers", "cylinder", 0.0, 0.1, "open cylinder + 10% uniform outliers"),
    Kind("crossing", "crossing", 0.0, 0.0, "two squares crossing at a line"),
    Kind("cube", "cube", 0.0, 0.0, "the unit cube's surface"),
)


class Output(NamedTuple):
    """A method's reconstruction: triangles, plus the dangling edges and
    isolated vertices a complex may have (empty for a mesh)."""

    vertices: np.ndarray
    triangles: np.ndarray
    edges: np.ndarray
    isolated: np.ndarray
    seconds: float
    note: str


def load_compare_extra():
    """``(open3d, pymeshlab)``, or ``None`` after printing what to install."""
    try:
        import open3d
        import pymeshlab
    except ImportError as err:  # also OSError-free: a missing libusb surfaces as ImportError here
        print(f"{INSTALL}\n(import failed: {err})", file=sys.stderr)
        return None
    return open3d, pymeshlab


def generate(kind: Kind, n: int, seed: int):
    """``(points, truth)`` of ``kind`` with ``n`` shape points (outliers on top)."""
    from otjax import datasets3d

    return datasets3d.SURFACES[kind.dataset](n, noise=kind.noise, n_outliers=round(kind.outliers * n),
                                             seed=seed)


def run_otjax(points: np.ndarray, n_vertices: int, threshold: float, seed: int, bin_density: float | None) -> Output:
    """:func:`otjax.surfaces.reconstruct_surface` at its defaults (or with
    ``bin_density``), then facets below ``threshold`` times the mean density dropped."""
    from otjax.surfaces import reconstruct_surface

    t0 = time.perf_counter()
    extra = {} if bin_density is None else {"bin_density": bin_density}
    run = reconstruct_surface(points, n_vertices=n_vertices, seed=seed, **extra)
    result = run.to_result().filtered(threshold)
    seconds = time.perf_counter() - t0
    note = (f"{len(run.triangles)} -> {len(result.triangles)} facets at density {threshold:g}; "
            f"{len(result.edges)} edges, {len(result.isolated)} isolated")
    return Output(result.vertices, result.triangles, result.edges, result.isolated, seconds, note)


def decimate_to_vertices(pymeshlab, vertices: np.ndarray, triangles: np.ndarray, n_vertices: int,
                         tries: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """QEM (pymeshlab's quadric edge collapse) of a mesh to about ``n_vertices``.

    The filter takes a face count, not a vertex count; the face count is
    corrected from the vertices each try gave (``F / V`` is nearly constant
    under decimation: about 2 on a closed mesh, less with boundaries), each
    try from the undecimated mesh, and the try nearest the budget is kept.
    """
    best = None
    faces = max(4, 2 * n_vertices)
    for _ in range(tries):
        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertices, triangles))
        # The filter's defaults otherwise: a boundary is weighted, not frozen (Poisson's open border would
        # hold every one of its vertices).
        ms.meshing_decimation_quadric_edge_collapse(targetfacenum=int(faces), autoclean=True)
        ms.meshing_remove_unreferenced_vertices()
        m = ms.current_mesh()
        v, f = m.vertex_matrix().copy(), m.face_matrix().astype(np.int64)
        if best is None or abs(len(v) - n_vertices) < abs(len(best[0]) - n_vertices):
            best = (v, f)
        if len(v) == n_vertices or len(v) == 0:
            break
        faces = max(4, round(faces * n_vertices / len(v)))
    return best


def trim_far(o3d, mesh, points: np.ndarray, factor: float) -> None:
    """Removes, in place, the vertices of ``mesh`` farther than ``factor``
    times the input's median nearest-neighbour spacing from every input
    point (the sheets Poisson adds where there are no points), then the
    connected pieces of fewer than :data:`SMALL_PIECE` of the triangles
    (QEM cannot reduce a piece below a triangle or so, so fragments would
    hold the vertex count above the budget)."""
    from scipy.spatial import cKDTree

    tree = cKDTree(points)
    spacing = float(np.median(tree.query(points, 2)[0][:, 1]))
    far = tree.query(np.asarray(mesh.vertices))[0] > factor * spacing
    mesh.remove_vertices_by_mask(far)
    piece, sizes, _ = mesh.cluster_connected_triangles()
    sizes = np.asarray(sizes)
    mesh.remove_triangles_by_mask(sizes[np.asarray(piece)] < SMALL_PIECE * max(1, len(mesh.triangles)))
    mesh.remove_unreferenced_vertices()


def run_poisson(o3d, pymeshlab, points: np.ndarray, n_vertices: int, depth: int, trim: float,
                neighbours: int) -> Output:
    """Screened Poisson with estimated, oriented normals, optionally
    trimmed (:func:`trim_far`, ``trim > 0``), QEM to ``n_vertices``."""
    t0 = time.perf_counter()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points, np.float64)))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(neighbours))
    # Poisson needs normals pointing one way across the surface; PCA alone gives a random sign per point.
    cloud.orient_normals_consistent_tangent_plane(neighbours)
    mesh, _ = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=depth)
    full = len(mesh.vertices)
    if trim > 0:
        trim_far(o3d, mesh, points, trim)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.triangles, np.int64)
    trimmed = f", {len(v)} after the trim" if trim > 0 else ""
    v, f = decimate_to_vertices(pymeshlab, v, f, n_vertices)
    seconds = time.perf_counter() - t0
    return Output(v, f, np.zeros((0, 2), np.int64), np.zeros(0, np.int64), seconds,
                  f"Poisson {full} vertices{trimmed}, QEM to {len(v)}")


def measure(out: Output, truth, samples: int) -> dict:
    """Chamfer, Hausdorff, farthest output point, crease and boundary error in % of D (``None``
    where the truth has no crease or no boundary), time, sizes."""
    from otjax import metrics3d

    dist = metrics3d.surface_distances(out.vertices, out.triangles, out.edges, out.isolated, truth=truth,
                                       samples=samples)
    crease = metrics3d.crease_error(out.vertices, out.triangles, truth.creases)
    boundary = metrics3d.boundary_error(out.vertices, out.triangles, truth.boundaries)
    sharp = metrics3d.edge_sharpness(out.vertices, out.triangles)
    d = truth.diagonal / 100
    # None where the truth has no such feature (the metric would read 0 whatever the output).
    return {"chamfer": dist.chamfer / d, "hausdorff": dist.hausdorff / d, "farthest": dist.to_truth_max / d,
            "crease": crease.mean / d if len(truth.creases) else None,
            "boundary": boundary.mean / d if len(truth.boundaries) else None, "seconds": out.seconds, "vertices": len(out.vertices),
            # triangles on an edge that lie over another one there (0 on a mesh without folds)
            "folded": int(np.sum(sharp.n_triangles - np.maximum(sharp.layers, 1))),
            "triangles": len(out.triangles), "note": out.note}


def render(path: Path, kind: Kind, points: np.ndarray, outputs: dict, rows: dict) -> None:
    """Input points and each method's output side by side, one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    panels = [("input", None)] + list(outputs.items())
    fig = plt.figure(figsize=(4.5 * len(panels), 4.6))
    lo, hi = points.min(0), points.max(0)
    for k, (name, out) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1, projection="3d")
        if out is None:
            ax.scatter(*points.T, s=0.5, c="0.3", linewidths=0, depthshade=False)
            ax.set_title(f"{kind.name}: {len(points)} points", fontsize=10)
        else:
            ax.add_collection3d(Poly3DCollection(out.vertices[out.triangles], facecolor="tab:blue",
                                                 edgecolor="0.15", linewidths=0.25, alpha=0.8))
            if len(out.edges):
                ax.add_collection3d(Line3DCollection(out.vertices[out.edges], colors="k", linewidths=1.0))
            r = rows[name]
            ax.set_title(f"{name}: {r['vertices']} vertices, {r['triangles']} triangles\n"
                         f"Chamfer {r['chamfer']:.2f}%, Hausdorff {r['hausdorff']:.1f}% D", fontsize=9)
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
        ax.set_box_aspect(np.maximum(hi - lo, 1e-3))
        ax.view_init(25, 35)
        ax.set_axis_off()
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.86, wspace=0)
    fig.savefig(path, dpi=110)
    plt.close(fig)


MEAN_FIELDS = ("vertices", "triangles", "folded", "chamfer", "hausdorff", "farthest", "crease", "boundary",
               "seconds")


def mean_rows(rows: list[dict]) -> list[dict]:
    """One row per input and method (first-seen order): the mean of each of
    :data:`MEAN_FIELDS` over its seeds (``None`` stays ``None``), ``seeds`` their count."""
    groups: dict = {}
    for r in rows:
        groups.setdefault((r["kind"], r["method"]), []).append(r)
    out = []
    for (kind, method), rs in groups.items():
        row = {"kind": kind, "method": method, "seeds": len(rs)}
        for f in MEAN_FIELDS:
            row[f] = None if rs[0][f] is None else float(np.mean([r[f] for r in rs]))
        out.append(row)
    return out


def markdown(rows: list[dict]) -> str:
    """The table: one row per input and method (means over seeds)."""
    lines = [("| input | method | vertices | triangles | folded | Chamfer % D | Hausdorff % D | farthest % D "
              "| crease % D | boundary % D | time s |"),
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    def cell(x):
        return "-" if x is None else f"{x:.3f}"

    for r in rows:
        lines.append(f"| {r['kind']} | {r['method']} | {r['vertices']:.0f} | {r['triangles']:.0f} | {r['folded']:.0f} | "
                     f"{r['chamfer']:.3f} | "
                     f"{r['hausdorff']:.2f} | {r['farthest']:.2f} | {cell(r['crease'])} | {cell(r['boundary'])} "
                     f"| {r['seconds']:.1f} |")
    return "\n".join(lines)


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--points", type=int, default=5000, help="points sampled on each shape (outliers on top)")
    p.add_argument("--vertices", type=int, default=100, help="vertex budget of both methods")
    p.add_argument("--kinds", nargs="+", choices=[k.name for k in KINDS], default=[k.name for k in KINDS])
    p.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS))
    p.add_argument("--seeds", type=int, nargs="+", default=[0], help="one input of each kind per seed")
    p.add_argument("--density-threshold", type=float, default=0.1,
                   help="otjax: drop facets below this multiple of the mean density (0: keep all with mass)")
    p.add_argument("--bin-density", type=float, help="otjax: facet bins per squared diagonal (default: its own)")
    p.add_argument("--depth", type=int, default=8, help="Poisson octree depth")
    p.add_argument("--trim", type=float, default=3.0,
                   help="Poisson: drop vertices farther than this many point spacings from the input (0: keep all)")
    p.add_argument("--neighbours", type=int, default=20, help="normals: nearest neighbours (fit and orientation)")
    p.add_argument("--samples", type=int, default=20000, help="truth samples of the distance metrics")
    p.add_argument("--json", type=Path, help="write every number here")
    p.add_argument("--renders", type=Path, help="write one PNG per input into this folder")
    args = p.parse_args(argv)
    if args.points < 10 or args.vertices < 4:
        p.error("need --points >= 10 and --vertices >= 4")
    if not args.trim >= 0:
        p.error("--trim must be >= 0")
    return args


def main(argv=None) -> int:
    args = parse(argv)
    # Checked before any work, even for --methods otjax: one table always has both columns.
    extra = load_compare_extra()
    if extra is None:
        return 1
    o3d, pymeshlab = extra
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    if args.renders:
        args.renders.mkdir(parents=True, exist_ok=True)
    rows = []
    for kind in (k for k in KINDS if k.name in args.kinds):
        for seed in args.seeds:
            points, truth = generate(kind, args.points, seed)
            outputs, by_method = {}, {}
            for method in args.methods:
                if method == "otjax":
                    out = run_otjax(points, args.vertices, args.density_threshold, seed, args.bin_density)
                else:
                    out = run_poisson(o3d, pymeshlab, points, args.vertices, args.depth, args.trim, args.neighbours)
                outputs[method] = out
                row = {"kind": kind.name, "describe": kind.describe, "seed": seed, "points": len(points),
                       "method": method, **measure(out, truth, args.samples)}
                by_method[method] = row
                rows.append(row)
                print(f"{kind.name:18s} seed {seed} {method:8s} {row['seconds']:7.1f} s  {out.note}", file=sys.stderr,
                      flush=True)
            if args.renders and seed == args.seeds[0]:
                render(args.renders / f"{kind.name}.png", kind, points, outputs, by_method)
    print(markdown(mean_rows(rows)))
    if args.json:
        info = {"command": "python scripts/compare_surfaces.py " + " ".join(sys.argv[1:] if argv is None else argv),
                "machine": {"python": platform.python_version(), "machine": platform.machine(),
                            "cpus": os.cpu_count()},
                "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
                "rows": rows}
        args.json.write_text(json.dumps(info, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
