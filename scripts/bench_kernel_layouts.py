"""Kernel time of whole curve runs in each scoring layout (edges per row).

Each input is reconstructed once per layout (``reconstruct_curve`` at its
defaults, seed 0) while every ``--every``-th kernel call's packed buffers
are kept; the kept calls of all layouts are then replayed in one process,
interleaved call by call, ``--passes`` times, so that the machine's drift
falls on every layout alike. Reported: calls of each run, and the kernel
time of a run estimated as ``every x`` the replayed time (seconds). The
reconstructions are the same in every layout (checked here: vertices and
edges bitwise), so each layout scores the same candidates.

    python scripts/bench_kernel_layouts.py
    python scripts/bench_kernel_layouts.py --inputs star:0.01:1000:10 --every 2 --json out.json

Layouts: ``R/4`` and ``R/2`` edges a call of ``R`` rows (the run's budget and
shapes as its defaults give them); the default picks by
:func:`otjax.curves.scoring.layout_for` (docs/decisions.md#EDGES_PER_ROW).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from typing import NamedTuple

import numpy as np

INPUTS = ("star:0.01:1000:10", "skyline:0.01:2000:18", "star:0.01:3000:10", "star:0:3000:10",
          "star:0.01:10000:10", "star:0.01:20000:50")
# Points-per-vertex thresholds that force each layout (see scoring.layout_for).
FORCE = {"R/4": 0, "R/2": 1 << 30}


class KeptCall(NamedTuple):
    """One recorded kernel call: its packed buffers and static arguments."""

    floats: np.ndarray
    ints: np.ndarray
    rows: int
    static: dict


def record(spec: str, dense: int, every: int):
    """``(result, kept)`` of one run with ``scoring.DENSE_VERTICES = dense``;
    ``kept``: the :class:`KeptCall` of every ``every``-th kernel call."""
    import otjax
    from otjax import datasets
    from otjax.batch import pipeline
    from otjax.curves import scoring

    kind, noise, n, nv = spec.split(":")
    pts, _ = getattr(datasets, kind)(n=int(n), noise=float(noise), seed=0)
    kept, count = [], [0]
    dispatch = pipeline.KernelPipeline.dispatch

    def keep(self, values, need):
        handle = dispatch(self, values, need)
        count[0] += 1
        if count[0] % every == 0:
            b = handle.buffers
            kept.append(KeptCall(np.array(b.floats), np.array(b.ints), b.r, dict(self.static)))
        return handle

    saved = scoring.DENSE_VERTICES
    pipeline.KernelPipeline.dispatch = keep
    scoring.DENSE_VERTICES = dense
    try:
        result = otjax.reconstruct_curve(pts, n_vertices=int(nv), seed=0)
    finally:
        pipeline.KernelPipeline.dispatch = dispatch
        scoring.DENSE_VERTICES = saved
    return result, kept


def replay(kept: dict, passes: int) -> dict:
    """Seconds of each layout's kept calls, interleaved call by call (mean over passes)."""
    import jax

    from otjax.curves import scoring

    def call(c: KeptCall):
        jax.block_until_ready(scoring.score_packed(c.floats, c.ints, rows=c.rows, **c.static))

    for calls in kept.values():  # every shape compiled before timing
        for c in {c.rows: c for c in calls}.values():
            call(c)
    total = dict.fromkeys(kept, 0.0)
    longest = max(len(c) for c in kept.values())
    for _ in range(passes):
        for j in range(longest):
            for name, calls in kept.items():
                if j < len(calls):
                    t0 = time.perf_counter()
                    call(calls[j])
                    total[name] += time.perf_counter() - t0
    return {name: t / passes for name, t in total.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--inputs", nargs="+", default=list(INPUTS), help="kind:noise:points:vertices")
    parser.add_argument("--every", type=int, default=4, help="keep every this many-th kernel call")
    parser.add_argument("--passes", type=int, default=3)
    parser.add_argument("--json", help="write the rows here")
    args = parser.parse_args(argv)
    import jax

    from otjax.curves import scoring

    jax.config.update("jax_enable_x64", True)
    rows = []
    machine = f"{platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__} ({jax.default_backend()})"
    print("machine:", machine)
    print("| input | calls R/4 / R/2 | kernel s R/4 | kernel s R/2 | default |")
    print("| --- | --- | --- | --- | --- |")
    for spec in args.inputs:
        runs = {name: record(spec, dense, args.every) for name, dense in FORCE.items()}
        first = runs["R/4"][0]
        for name, (res, _) in runs.items():
            if not (np.array_equal(res.vertices, first.vertices) and np.array_equal(res.edges, first.edges)):
                raise SystemExit(f"{spec}: layout {name} changed the reconstruction")
        seconds = replay({name: kept for name, (_, kept) in runs.items()}, args.passes)
        n = int(spec.split(":")[2])
        default = f"R/{scoring.layout_for(n, first.params['initial_vertices']).edges_per_row}"
        row = {"input": spec, "calls": {k: res.history["kernel_calls"] for k, (res, _) in runs.items()},
               "kernel_seconds": {k: args.every * v for k, v in seconds.items()}, "default": default}
        rows.append(row)
        print(f"| {spec} | {row['calls']['R/4']} / {row['calls']['R/2']} | {row['kernel_seconds']['R/4']:.2f} | "
              f"{row['kernel_seconds']['R/2']:.2f} | {default} |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"machine": machine, "every": args.every, "passes": args.passes, "rows": rows},
                      f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
