"""Benchmarks the initial complex (§4.1): time per step and fit to the true surface.

Noise-free points on a cube's surface (or an open square, or two crossing
planes); for each size the initial complex is built with the exact solver
(HiGHS, closed form where it is exact) and reported with

* the seconds of each step: Delaunay of the subset, the plan with the bins
  of every Delaunay facet, the relaxation, the filter (and their total);
* the relaxation's sweeps, local LPs solved, how many of those needed HiGHS
  (in the JSON also the stencils ruled out unbuilt, and built but bounded);
* the kept facets' fit (``tests/surfaces/shapes.py``): coverage, the share
  of the true surface within 1% (and 2%) of the bbox diagonal ``D`` of a
  kept facet; symmetric Chamfer distance and the largest distance of a kept
  facet to the surface, in ``D``.

Example::

    python scripts/bench_initial_complex.py --sizes 1000 5000
    python scripts/bench_initial_complex.py --sizes 10000 30000 --no-fit --json docs/bench/initial_complex.json
"""

from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

from bench_surface_lp import machine, write_json  # noqa: E402  (scripts/ is on the path)
from otjax.surfaces.initial_complex import FRACTION, initial_complex  # noqa: E402
from otjax.surfaces.plan import BinSettings  # noqa: E402
from otjax.surfaces.solvers import LocalSolver  # noqa: E402
from tests.surfaces.shapes import CROSS, CUBE, SQUARE, diagonal, fit  # noqa: E402

SHAPES = {"cube": CUBE, "square": SQUARE, "cross": CROSS}


def run(shape_name: str, n: int, seed: int, min_bins: int | None, fraction: float, with_fit: bool) -> dict:
    shape = SHAPES[shape_name]
    points = shape.sample(n, np.random.default_rng(seed))
    d = diagonal(points)
    settings = None if min_bins is None else BinSettings(diagonal=d, min_bins=min_bins, seed=seed)
    solver = LocalSolver("exact")
    t = time.perf_counter()
    ic = initial_complex(points, np.ones(n), solver, fraction=fraction, settings=settings, seed=seed)
    total = time.perf_counter() - t
    arrays = ic.plan.complex.to_arrays()
    row = {"shape": shape_name, "points": n, "seed": seed, "fraction": fraction,
           "min_bins": ic.plan.settings.min_bins, "seconds": total, "steps": ic.seconds,
           "delaunay_facets": ic.delaunay_facets, "kept_facets": int(len(arrays.triangles)),
           "sweeps": ic.relaxation.sweeps, "solves": solver.solved, "highs": solver.solved - solver.closed_form,
           "ruled_out": ic.relaxation.ruled_out, "bounded": ic.relaxation.bounded,
           "cost_first": ic.relaxation.costs[0], "cost_last": ic.relaxation.costs[-1],
           "vertex_mass_share": float(sum(e.mass.sum() for e in ic.plan.vertex_entries.values()) / n)}
    if with_fit:
        f1 = fit(shape, arrays.vertices, arrays.triangles, d, within=0.01, samples=10000)
        f2 = fit(shape, arrays.vertices, arrays.triangles, d, within=0.02, samples=10000)
        row.update(coverage_1pct=f1.coverage, coverage_2pct=f2.coverage, chamfer=f1.chamfer,
                   to_surface=f1.to_surface)
    return row


HEADER = (f"{'shape':>6} {'points':>7} {'total s':>8} {'delaunay':>8} {'bins':>6} {'relax':>7} {'filter':>6} "
          f"{'sweeps':>6} {'solves':>7} {'highs':>6} {'facets':>7} {'kept':>6} {'cov1%':>6} {'cov2%':>6} "
          f"{'chamfer':>8} {'to_surf':>8}")


def print_row(r: dict) -> None:
    s = r["steps"]
    fit_cols = (f"{r['coverage_1pct']:>6.3f} {r['coverage_2pct']:>6.3f} {r['chamfer']:>8.4f} {r['to_surface']:>8.4f}"
                if "coverage_1pct" in r else "")
    print(f"{r['shape']:>6} {r['points']:>7} {r['seconds']:>8.1f} {s['delaunay']:>8.2f} {s['bins']:>6.1f} "
          f"{s['relaxation']:>7.1f} {s['filter']:>6.2f} {r['sweeps']:>6} {r['solves']:>7} {r['highs']:>6} "
          f"{r['delaunay_facets']:>7} {r['kept_facets']:>6} {fit_cols}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shape", choices=sorted(SHAPES), default="cube")
    parser.add_argument("--sizes", nargs="+", type=int, default=[1000, 5000, 10000])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--min-bins", type=int, default=None, help="default: the initial complex's own")
    parser.add_argument("--fraction", type=float, default=FRACTION)
    parser.add_argument("--no-fit", action="store_true", help="skip the (slow) distances to the surface")
    parser.add_argument("--json", default=None, help="also write the rows here")
    args = parser.parse_args()
    info = machine()
    print(f"{info['cpu']}, {info['cores']} cores, load {info['load_average']}")
    print(HEADER)
    rows = []
    for n in args.sizes:
        rows.append(run(args.shape, n, args.seed, args.min_bins, args.fraction, not args.no_fit))
        print_row(rows[-1])
    if args.json:
        out = {"machine": info, "rows": rows,
               "command": "python scripts/bench_initial_complex.py " + " ".join(sys.argv[1:])}
        write_json(args.json, out)


if __name__ == "__main__":
    main()
