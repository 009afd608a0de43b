"""Benchmarks feature recovery (Algorithm 4): colour-batched passes against the paper's sequential order.

A rounded box (:func:`otjax.datasets3d.rounded_box`: the superquadric mesh that
rounds the unit cube, ``6 r^2 + 2`` vertices for grid resolution ``r``) and
noisy samples of the sharp cube (noise 0.5% of the diagonal). For each order
it reports the time (all of it, and the setup: checks, bins, relaxation),
the crease error and the Chamfer distance to the true cube before and after
(shares of the diagonal; the crease error is null where no edge is sharp
enough to measure), face flips, the kept share of the faces and the load
average (the machine is shared).

Example::

    python scripts/bench_features.py --points 200000 --resolution 58 --json docs/bench/features.json
    python scripts/bench_features.py --points 10000 --resolution 13
"""

from __future__ import annotations

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)  # script-local: the relocation kernels need float64

import numpy as np
from bench_surface_lp import machine, write_json

from otjax.datasets3d import rounded_box
from otjax.metrics3d import chamfer, crease_error
from otjax.surfaces.features import recover_features
from otjax.surfaces.solvers import default_solver


def quality(vertices, triangles, truth) -> dict:
    """Crease error (mean, max) and Chamfer distance, as shares of the diagonal."""
    d = truth.diagonal
    c = crease_error(vertices, triangles, truth.creases)
    # None (JSON null) where the mesh has no edge sharp enough to measure (the error is infinite)
    share = (lambda x: float(x / d) if np.isfinite(x) else None)
    return {"crease_mean": share(c.mean), "crease_max": share(c.max), "sharp_edges": c.n_edges,
            "chamfer": chamfer(vertices, triangles, truth=truth, samples=20000) / d}


def flips(before, after, triangles) -> int:
    """Faces whose normal turned by more than 90 degrees."""
    def normal(v):
        c = v[triangles]
        return np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    return int(np.sum(np.einsum("ij,ij->i", normal(before), normal(after)) <= 0))


def run(sample, order: str, passes: int, solver: str, seed: int) -> dict:
    mesh = sample.mesh
    t = time.perf_counter()
    got = recover_features(sample.points, mesh, passes=passes, order=order, solver=solver, seed=seed,
                           progress=True).stats
    seconds = time.perf_counter() - t
    row = {"order": order, "solver": solver or default_solver(), "passes": passes, "seconds": seconds,
           "setup_seconds": seconds - sum(p.seconds for p in got.passes),
           "pass_seconds": [p.seconds for p in got.passes], "solver_calls": [p.calls for p in got.passes],
           "accepted": [p.accepted for p in got.passes], "rejected": [p.rejected for p in got.passes],
           "shortened": [p.shortened for p in got.passes],
           "relaxation_sweeps": got.relaxation.sweeps, "relaxation_solves": got.relaxation.solves,
           "relaxation_bounded": got.relaxation.bounded, "pass_solves": [p.solves for p in got.passes],
           "cost_before": got.cost_before, "cost_after": got.cost_after,
           "flips": flips(mesh.vertices, got.vertices, mesh.triangles), "kept": float(got.keep.mean())}
    row.update({f"after_{k}": v for k, v in quality(got.vertices, mesh.triangles, sample.truth).items()})
    row["load_average"] = list(os.getloadavg())  # the VM is shared: read times against it
    return row


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=200_000)
    ap.add_argument("--resolution", type=int, default=58, help="grid per cube face: 6 r^2 + 2 vertices")
    ap.add_argument("--passes", type=int, default=3)
    ap.add_argument("--solver", default=None, choices=("exact", "batched", "auto"),
                    help="default: recover_features' own (HiGHS on a CPU)")
    ap.add_argument("--orders", nargs="+", default=["colouring", "sequential"])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json")
    args = ap.parse_args(argv)
    sample = rounded_box(args.points, noise=0.005, seed=args.seed, resolution=args.resolution)
    mesh = sample.mesh
    before = quality(mesh.vertices, mesh.triangles, sample.truth)
    print(f"{len(sample.points)} points, mesh {len(mesh.vertices)} vertices / {len(mesh.triangles)} faces; "
          f"before: crease {before['crease_mean'] or float('inf'):.4%} of D, Chamfer {before['chamfer']:.4%} of D")
    rows = [run(sample, order, args.passes, args.solver, args.seed) for order in args.orders]
    print(f"{'order':<11}{'seconds':>9}{'setup':>8}{'calls/pass':>12}{'crease %D':>11}{'Chamfer %D':>12}"
          f"{'flips':>7}{'kept':>7}{'load':>7}")
    for r in rows:
        print(f"{r['order']:<11}{r['seconds']:>9.1f}{r['setup_seconds']:>8.1f}{int(np.mean(r['solver_calls'])):>12d}"
              f"{100 * r['after_crease_mean']:>11.3f}{100 * r['after_chamfer']:>12.4f}{r['flips']:>7d}"
              f"{r['kept']:>7.3f}{r['load_average'][0]:>7.1f}")
    if args.json:
        write_json(args.json, {"benchmark": "features", "machine": machine(), "points": len(sample.points),
                               "vertices": len(mesh.vertices), "faces": len(mesh.triangles), "noise": 0.005,
                               "before": before, "rows": rows})


if __name__ == "__main__":
    main()
