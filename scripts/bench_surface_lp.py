"""Benchmarks the local transport LP solvers: batched JAX Newton against a HiGHS loop.

Synthetic 1-ring stencils: ``F`` triangles around a centre vertex (slightly
out of plane), facet bins on a jittered barycentric grid of each triangle
(capacities: jittered, summing to 1 per facet), one vertex bin per vertex,
points sampled on the triangles with 1% noise and 5% outliers. For each
stencil size (points x bins) and batch size it reports

* ``batched``: ``solve_batched`` on one padded batch, seconds per stencil of
  a second call (compilation excluded; the first call's extra time is the
  compile column), its steps, converged fraction, and the rounded cost's
  gap to the HiGHS optimum on the stencils HiGHS solved;
* ``highs``: ``solve_member`` (scipy's HiGHS) on up to ``--exact`` stencils,
  seconds per stencil.

Example::

    python scripts/bench_surface_lp.py --quick
    python scripts/bench_surface_lp.py --sizes 256x80 512x128 --batches 1 16 64 256 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)  # script-local: the float64 runs need it

import numpy as np

from otjax.lp.batched import NewtonOptions, solve_batched
from otjax.lp.exact import solve_member
from otjax.lp.problem import CONVERGED, LocalLP, pack

QUICK_SIZES = ("32x32", "128x64", "256x80", "512x128", "2048x512")
QUICK_BATCHES = (1, 16, 64, 256)


def fan_stencil(rng: np.random.Generator, n_points: int, n_bins: int, n_facets: int = 6) -> LocalLP:
    """A 1-ring of ``n_facets`` triangles with ``n_bins`` bins in all (vertex bins included)."""
    angles = np.linspace(0, 2 * np.pi, n_facets, endpoint=False) + rng.uniform(-0.2, 0.2, n_facets)
    ring = np.stack([np.cos(angles), np.sin(angles), rng.normal(0, 0.15, n_facets)], axis=1)
    verts = np.concatenate([[[0.0, 0.0, rng.normal(0, 0.1)]], ring])
    tris = np.stack([np.zeros(n_facets, int), 1 + np.arange(n_facets), 1 + (np.arange(n_facets) + 1) % n_facets], 1)
    per_facet = np.full(n_facets, (n_bins - len(verts)) // n_facets)
    per_facet[: (n_bins - len(verts)) % n_facets] += 1
    bins, capacity, simplex = [], [], []
    for f, n in enumerate(per_facet):
        bary = rng.dirichlet(np.full(3, 4.0), n)  # spread inside the triangle, away from its edges
        bins.append(bary @ verts[tris[f]])
        cap = rng.uniform(0.8, 1.2, n)
        capacity.append(cap / cap.sum())
        simplex.append(np.full(n, f))
    bins.append(verts)
    capacity.append(np.zeros(len(verts)))
    simplex.append(n_facets + np.arange(len(verts)))
    host = rng.integers(0, n_facets, n_points)
    points = np.einsum("nc,ncd->nd", rng.dirichlet(np.ones(3), n_points), verts[tris[host]])
    points += rng.normal(0, 0.01, points.shape)
    outliers = rng.random(n_points) < 0.05
    points[outliers] = rng.uniform(-1.2, 1.2, (outliers.sum(), 3))
    bins = np.concatenate(bins)
    cost = ((points[:, None, :] - bins[None, :, :]) ** 2).sum(-1)
    is_vertex = np.arange(len(bins)) >= len(bins) - len(verts)
    return LocalLP(cost, rng.uniform(0.5, 1.5, n_points), np.concatenate(capacity),
                   np.concatenate(simplex).astype(np.int32), is_vertex)


def machine() -> dict:
    model = platform.processor()
    try:
        with open("/proc/cpuinfo") as f:
            model = next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    return {"cpu": model, "cores": os.cpu_count(), "jax": jax.__version__, "backend": jax.default_backend(),
            "platform": platform.platform(), "load_average": os.getloadavg()}


def write_json(path: str, doc: dict) -> None:
    """Writes a benchmark's rows (creating the folder) and says where."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path, "w") as f:
        json.dump(doc, f, indent=1)
    print(f"wrote {path}")


def bench_highs(stencils) -> tuple[float, np.ndarray]:
    """Seconds per stencil and the optimal costs."""
    t = time.perf_counter()
    costs = np.array([solve_member(lp).cost for lp in stencils])
    return (time.perf_counter() - t) / len(stencils), costs


def bench_batched(stencils, options: NewtonOptions, dtype) -> dict:
    p, k = stencils[0].cost.shape
    batch = pack(stencils, dtype=dtype, shape=(p, k, max(4, stencils[0].n_simplices)), batch=len(stencils))
    t = time.perf_counter()
    jax.block_until_ready(solve_batched(batch, options, dtype))
    first = time.perf_counter() - t
    t = time.perf_counter()
    sol = jax.device_get(solve_batched(batch, options, dtype))
    run = time.perf_counter() - t
    return {"seconds_per_stencil": run / len(stencils), "compile_seconds": max(first - run, 0.0),
            "cost": np.asarray(sol.cost, float), "status": np.asarray(sol.status),
            "steps": np.asarray(sol.iterations)}


def run(sizes, batches, n_exact: int, options: NewtonOptions, dtypes, budget: float, max_batch_vars: int) -> list[dict]:
    rows = []
    for size in sizes:
        p, k = map(int, size.split("x"))
        rng = np.random.default_rng(p * 7919 + k)
        # Only as many stencils as the largest batch that will run: 4096 dense
        # cost matrices of the largest size would not fit in memory.
        runnable = [b for b in batches if b == 1 or p * k * b <= max_batch_vars]
        stencils = [fan_stencil(rng, p, k) for _ in range(max(runnable))]
        started = time.perf_counter()
        n_ex = min(n_exact, len(stencils)) if p * k < 200_000 else 1
        highs_s, optimum = bench_highs(stencils[:n_ex])
        rows.append({"points": p, "bins": k, "variables": p * k, "solver": "highs", "batch": 1,
                     "seconds_per_stencil": highs_s, "stencils": n_ex})
        print_row(rows[-1])
        for dtype in dtypes:
            for b in batches:
                # Large stencils only in small batches: larger ones exceed the time budget.
                if b not in runnable or (b > 1 and time.perf_counter() - started > budget):
                    continue
                res = bench_batched(stencils[:b], options, dtype)
                m = min(b, n_ex)
                gap = (res["cost"][:m] - optimum[:m]) / optimum[:m]
                rows.append({"points": p, "bins": k, "variables": p * k, "solver": "batched",
                             "dtype": np.dtype(dtype).name, "batch": b,
                             "seconds_per_stencil": res["seconds_per_stencil"],
                             "compile_seconds": res["compile_seconds"],
                             "speedup_vs_highs": highs_s / res["seconds_per_stencil"],
                             "converged": float(np.mean(res["status"] == CONVERGED)),
                             "steps_median": float(np.median(res["steps"])), "steps_max": int(res["steps"].max()),
                             "gap_median": float(np.median(gap)), "gap_max": float(gap.max()), "gap_stencils": m})
                print_row(rows[-1])
    return rows


HEADER = (f"{'points x bins':>14} {'vars':>8} {'solver':>8} {'dtype':>7} {'batch':>5} {'ms/stencil':>11} "
          f"{'compile s':>9} {'speedup':>7} {'conv':>5} {'steps':>7} {'gap med':>8} {'gap max':>8}")


def print_row(r: dict) -> None:
    if r["solver"] == "highs":
        print(f"{r['points']:>6} x {r['bins']:<5} {r['variables']:>8} {'highs':>8} {'f64':>7} {1:>5} "
              f"{1e3 * r['seconds_per_stencil']:>11.2f}   ({r['stencils']} stencils)", flush=True)
        return
    print(f"{r['points']:>6} x {r['bins']:<5} {r['variables']:>8} {'batched':>8} {'f' + r['dtype'][-2:]:>7} "
          f"{r['batch']:>5} {1e3 * r['seconds_per_stencil']:>11.2f} {r['compile_seconds']:>9.1f} "
          f"{r['speedup_vs_highs']:>6.1f}x {r['converged']:>5.2f} {r['steps_median']:>3.0f}/{r['steps_max']:<3d} "
          f"{r['gap_median']:>8.1e} {r['gap_max']:>8.1e}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", nargs="+", default=None, help="points x bins, e.g. 256x80")
    parser.add_argument("--batches", nargs="+", type=int, default=None)
    parser.add_argument("--exact", type=int, default=16, help="stencils HiGHS solves per size")
    parser.add_argument("--float32", action="store_true", help="also time float32 runs")
    parser.add_argument("--quick", action="store_true", help=f"sizes {QUICK_SIZES}, batches {QUICK_BATCHES}, "
                        "8 HiGHS stencils per size")
    parser.add_argument("--budget", type=float, default=120.0, help="seconds per size before larger batches are skipped")
    parser.add_argument("--max-batch-variables", type=int, default=1 << 23,
                        help="larger batches than this many LP variables in all are skipped (batch 1 always runs)")
    parser.add_argument("--json", default="docs/bench/surface_lp.json")
    args = parser.parse_args()
    sizes = args.sizes or (QUICK_SIZES if args.quick else ("32x32", "128x64", "256x80", "512x128", "1024x256",
                                                           "2048x512"))
    batches = args.batches or (QUICK_BATCHES if args.quick else (1, 16, 64, 256, 1024, 4096))
    n_exact = 8 if args.quick and args.exact == 16 else args.exact
    options = NewtonOptions()
    dtypes = (np.float64, np.float32) if args.float32 else (np.float64,)
    info = machine()
    print(f"{info['cpu']}, {info['cores']} cores, jax {info['jax']} ({info['backend']}), load {info['load_average']}")
    print(HEADER)
    rows = run(sizes, batches, n_exact, options, dtypes, args.budget, args.max_batch_variables)
    out = {"machine": info, "options": options._asdict(), "rows": rows,
           "command": "python scripts/bench_surface_lp.py " + " ".join(os.sys.argv[1:])}
    write_json(args.json, out)


if __name__ == "__main__":
    main()
