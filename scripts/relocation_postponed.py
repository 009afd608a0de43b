"""Does postponing relocation to the last K collapses (paper §3.5) keep quality?

Runs the noisy skyline and the noisy star with relocation during the last K
collapses for several K (K = every collapse is the unpostponed variant) and
prints corner error (% of the diagonal), total cost and wall time; writes JSON.

    python scripts/relocation_postponed.py --json docs/relocation_postponed.json
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import otjax
from otjax import datasets, metrics


def cases():
    pts, truth = datasets.skyline(1500, noise=0.005, seed=6)
    yield "skyline", pts, truth, len(truth["corners"]) + len(truth["ends"]), np.concatenate(
        [truth["corners"], truth["ends"]])
    pts, truth = datasets.star(3000, noise=0.01, seed=2)
    yield "star", pts, truth, 10, truth["corners"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ks", type=int, nargs="+", default=[0, 100, 1_000_000])
    ap.add_argument("--queue", default="exhaustive")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args(argv)
    rows = []
    print("| case | K | corner error mean / max (% D) | total cost | seconds |")
    print("| --- | --- | --- | --- | --- |")
    for name, pts, truth, n, corners in cases():
        for k in args.ks:
            t0 = time.perf_counter()
            r = otjax.reconstruct_curve(pts, n_vertices=n, relocation=k, queue=args.queue)
            sec = time.perf_counter() - t0
            err = metrics.corner_errors(r.vertices, corners) / truth["diagonal"] * 100
            rows.append({"case": name, "K": k, "corner_mean": float(err.mean()), "corner_max": float(err.max()),
                         "total_cost": r.total_cost, "seconds": sec, "relocations": r.history["relocations"]})
            label = "every collapse" if k >= 1_000_000 else str(k)
            print(f"| {name} | {label} | {err.mean():.2f} / {err.max():.2f} | {r.total_cost:.5g} | {sec:.1f} |",
                  flush=True)
    if args.json:
        tmp = args.json.with_suffix(".tmp")
        tmp.write_text(json.dumps(rows, indent=1))
        os.replace(tmp, args.json)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
