"""Lattice inputs against random inputs of the same size.

Every pixel of an image is a point of a square lattice: exactly collinear
and cocircular points everywhere, which sends most predicate evaluations to
their exact fallback. This compares the wall time of ``reconstruct_curve``
at its defaults on an ``m x m`` lattice (unit masses, what an all-white image
gives) with ``m * m`` uniform random points in the same square.

Each run is a fresh process reading its kernels from a shared persistent
compilation cache (filled by an untimed run of each case first, as the
command line's cache would be); the reported time is the median of the
repeats of ``reconstruct_curve`` alone, the cases alternating.

    python scripts/bench_lattice.py                       # 32x32 and 100x100, 3 repeats
    python scripts/bench_lattice.py --sides 32 --repeats 1 --json out.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile

import numpy as np

CHILD = r"""
import json, sys, time
import numpy as np
import otjax
side, kind, n_vertices, cache = int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), sys.argv[4]
otjax.enable_compilation_cache(cache)
if kind == "lattice":
    g = np.arange(side, dtype=np.float64)
    points = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
else:
    points = np.random.default_rng(0).uniform(0, side - 1, size=(side * side, 2))
t = time.perf_counter()
r = otjax.reconstruct_curve(points, n_vertices=n_vertices, seed=0)
print(json.dumps({"seconds": time.perf_counter() - t, "vertices": len(r.vertices), "edges": len(r.edges)}))
"""


def run(side: int, kind: str, n_vertices: int, cache: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(side), kind, str(n_vertices), cache],
                         check=True, capture_output=True, text=True, env=dict(os.environ, JAX_PLATFORMS="cpu"))
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sides", type=int, nargs="+", default=[32, 100])
    ap.add_argument("--n-vertices", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        for side in args.sides:
            for kind in ("random", "lattice"):
                run(side, kind, args.n_vertices, cache)  # fills the compilation cache
            times = {"random": [], "lattice": []}
            for _ in range(args.repeats):
                for kind in times:
                    times[kind].append(run(side, kind, args.n_vertices, cache)["seconds"])
            med = {k: float(np.median(v)) for k, v in times.items()}
            rows.append({"side": side, "points": side * side, "n_vertices": args.n_vertices,
                         "random_s": med["random"], "lattice_s": med["lattice"],
                         "ratio": med["lattice"] / med["random"], "runs": times})
            r = rows[-1]
            print(f"{side}x{side} ({r['points']} points -> {args.n_vertices}): random {r['random_s']:.2f} s, "
                  f"lattice {r['lattice_s']:.2f} s, ratio {r['ratio']:.2f}", flush=True)
    print("\n| input | points | random (s) | lattice (s) | lattice / random |")
    print("| --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['side']}x{r['side']} | {r['points']} | {r['random_s']:.2f} | {r['lattice_s']:.2f} "
              f"| {r['ratio']:.2f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": platform.platform(), "processor": platform.processor(),
                       "python": platform.python_version(), "rows": rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
