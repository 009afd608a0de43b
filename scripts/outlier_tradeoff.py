"""Recall/precision of outlier filtering: the paper's relevance vs otjax's density.

Case: a star (σ = 2% of the diagonal D) plus as many uniform outliers as shape
points in a box 20% larger. For each vertex budget the reconstruction runs once
and keeps every solid edge; the filters are then applied after the fact
(``CurveResult.filtered``). Recall = fraction of the truth's length within 3% D
of a kept edge; precision = fraction of the kept length within 3% D of the
truth. Prints a table and writes JSON.

    python scripts/outlier_tradeoff.py --points 1500 --budgets 20 30 40 60 --seeds 3 --json out/tradeoff.json
"""

from __future__ import annotations

import argparse
import json
import os
import time

import otjax
from otjax import datasets, metrics

RELEVANCE = (0, 25, 50, 75, 100, 150, 200)
DENSITY = (0.2, 0.3, 0.35, 0.4, 0.45, 0.5, 0.6)


def sweep(points: int, budgets, seed: int) -> list[dict]:
    pts, truth = datasets.star(points, noise=0.02, seed=seed)
    pts, truth = datasets.with_outliers(pts, truth, points, seed=seed + 1)
    tol = 0.03 * truth["diagonal"]
    rows = []
    for budget in budgets:
        t0 = time.perf_counter()
        # Every solid edge: the automatic background discount and filters off.
        result = otjax.reconstruct_curve(pts, n_vertices=budget, background="none", chords=False)
        seconds = time.perf_counter() - t0
        filters = [("relevance", v, result.filtered(relevance=v)) for v in RELEVANCE]
        filters += [("density", v, result.filtered(density=v)) for v in DENSITY]
        for kind, value, kept in filters:
            segs = metrics.edges_to_segments(kept.vertices, kept.edges)
            rows.append({"seed": seed, "budget": budget, "filter": kind, "threshold": value,
                         "edges": len(kept.edges),
                         "recall": metrics.length_within(truth["segments"], segs, tol),
                         "precision": metrics.length_within(segs, truth["segments"], tol),
                         "seconds": seconds})
            r = rows[-1]
            print(f"{seed:>4} {budget:>6} {kind:>9} {value:>9} {r['edges']:>5} "
                  f"{r['recall']:>7.3f} {r['precision']:>9.3f}", flush=True)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=1500, help="shape points (as many outliers are added)")
    ap.add_argument("--budgets", type=int, nargs="+", default=[20, 30, 40, 60])
    ap.add_argument("--seeds", type=int, nargs="+", default=[3])
    ap.add_argument("--json", default=None, help="write the rows here (atomically)")
    args = ap.parse_args(argv)
    print(f"{'seed':>4} {'budget':>6} {'filter':>9} {'threshold':>9} {'edges':>5} {'recall':>7} {'precision':>9}")
    rows = [r for s in args.seeds for r in sweep(args.points, args.budgets, s)]
    if args.json:
        os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
        tmp = args.json + ".tmp"
        with open(tmp, "w") as f:
            json.dump(rows, f, indent=1)
        os.replace(tmp, args.json)


if __name__ == "__main__":
    main()
