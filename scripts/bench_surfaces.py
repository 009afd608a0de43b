"""Benchmarks surface reconstruction (:func:`otjax.surfaces.reconstruct_surface`) at its defaults.

For each size, in a fresh process (so that peak memory and JAX compilation
are those of a cold run), noisy samples of a shape of
:data:`otjax.datasets3d.SURFACES` (default: the staircase, Gaussian noise
of 1% of the bounding-box diagonal D) go to ``--vertices`` vertices. It
reports:

- the wall time and its split: ``init`` (Delaunay of the subset, bins,
  relaxation), ``scoring`` (building and solving the candidate collapses),
  ``collapse`` (applying them), ``relocation`` (during the decimation and
  the final passes), the rest (drawing half-edges, bookkeeping);
- the local LPs solved: by collapse scoring and by everything else
  (relaxation, relocation), in closed form or not, and their sizes
  (points x bins: median, 90% quantile, largest);
- the batched solver's compiled shapes (0 where HiGHS solves everything);
- the process's peak resident memory, the final transport cost (input
  units), and the Chamfer and crease error to the clean shape (% of D).

It prints a markdown table and, with ``--json``, writes every number with
the machine's description.

    python scripts/bench_surfaces.py                                   # 10k and 30k points -> 200 vertices
    python scripts/bench_surfaces.py --points 3000 --vertices 100 --solver batched
    python scripts/bench_surfaces.py --json docs/bench/surfaces.json
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np


def sizes_of(problems) -> list[tuple[int, int]]:
    return [tuple(int(x) for x in np.shape(lp.cost)) for lp in problems]


class Recorder:
    """Counts the local LPs each surface step hands to a solver, and the
    shapes the batched solver compiles, by wrapping the calls in place."""

    def __init__(self):
        self.scoring: list[tuple[int, int]] = []
        self.other: list[tuple[int, int]] = []
        self.closed_form = 0
        self.shapes: set[tuple[int, ...]] = set()
        solve = importlib.import_module("otjax.lp.solve")  # the package exports a function of that name
        scoring = importlib.import_module("otjax.surfaces.collapse_scoring")
        solvers = importlib.import_module("otjax.surfaces.solvers")
        batched, members, call = solve.solve_batched, scoring.solve_members, solvers.LocalSolver.__call__
        recorder = self

        def solve_batched(problem, *args, **kwargs):
            recorder.shapes.add(tuple(int(x) for x in np.shape(problem.cost)) + (int(problem.simplex_mask.shape[-1]),))
            return batched(problem, *args, **kwargs)

        def scoring_members(problems, *args, **kwargs):
            recorder.scoring += sizes_of(problems)
            got = members(problems, *args, **kwargs)
            recorder.closed_form += sum(bool(getattr(s, "closed_form", False)) for s in got.solutions)
            return got

        def local_call(self, problems):
            recorder.other += sizes_of(problems)
            before = self.closed_form
            out = call(self, problems)
            recorder.closed_form += self.closed_form - before
            return out

        solve.solve_batched = solve_batched
        scoring.solve_members = scoring_members
        solvers.LocalSolver.__call__ = local_call

    def summary(self) -> dict:
        variables = np.array([p * k for p, k in self.scoring + self.other] or [0])
        largest = max(self.scoring + self.other, key=lambda s: s[0] * s[1], default=(0, 0))
        return {"lp_scoring": len(self.scoring), "lp_other": len(self.other), "lp_closed_form": self.closed_form,
                "lp_variables_median": float(np.median(variables)),
                "lp_variables_q90": float(np.quantile(variables, 0.9)), "lp_largest": list(largest),
                "compiled_shapes": len(self.shapes)}


def run_one(args) -> dict:
    """One size in this process: the row of the table."""
    import jax

    from otjax import datasets3d, metrics3d
    from otjax.surfaces import reconstruct_surface
    from otjax.surfaces.reconstruct import surface_solver

    recorder = Recorder()
    sample = datasets3d.SURFACES[args.shape](args.points[0], noise=args.noise, seed=args.seed)
    t0 = time.perf_counter()
    run = reconstruct_surface(sample.points, n_vertices=args.vertices, queue=args.queue, solver=args.solver,
                              seed=args.seed, progress=args.progress)
    wall = time.perf_counter() - t0
    d = sample.truth.diagonal / 100
    dist = metrics3d.surface_distances(run.vertices, run.triangles, run.edges, run.isolated, truth=sample.truth)
    crease = metrics3d.crease_error(run.vertices, run.triangles, sample.truth.creases)
    st = run.stats.seconds
    split = {"init": run.seconds["initial"] + run.seconds["rebin"], "scoring": st["export"] + st["score"],
             "collapse": st["apply"], "relocation": st["relocate"] + run.seconds["final_relocation"] + run.seconds["feature_fit"]}
    split["other"] = wall - sum(split.values())
    return {"shape": args.shape, "noise": args.noise, "points": args.points[0], "vertices": len(run.vertices),
            "initial_vertices": len(run.complex.alive), "queue": args.queue, "solver": surface_solver(args.solver),
            "seconds": wall, "split": split, "collapses": run.stats.collapses, "relocations": run.stats.relocations,
            "scored": run.stats.scored, **recorder.summary(),
            "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "final_cost": run.total_cost,
            "chamfer": dist.chamfer / d,
            "crease": crease.mean / d if len(sample.truth.creases) and np.isfinite(crease.mean) else None,
            "backend": jax.default_backend()}


def markdown(rows: list[dict]) -> str:
    lines = ["| points | V0 -> V | s | init / scoring / collapse / relocation / other s | LPs scoring / other "
             "(closed form) | LP vars median / q90, largest P x K | compiled shapes | peak MB | final cost "
             "| Chamfer / crease % D |",
             "| ---: | --- | ---: | --- | --- | --- | ---: | ---: | ---: | --- |"]
    for r in rows:
        s = r["split"]
        crease = "-" if r["crease"] is None else f"{r['crease']:.2f}"
        lines.append(
            f"| {r['points']:,} | {r['initial_vertices']:,} -> {r['vertices']} | {r['seconds']:.1f} | "
            f"{s['init']:.1f} / {s['scoring']:.1f} / {s['collapse']:.1f} / {s['relocation']:.1f} / {s['other']:.1f} | "
            f"{r['lp_scoring']:,} / {r['lp_other']:,} ({r['lp_closed_form']:,}) | "
            f"{r['lp_variables_median']:,.0f} / {r['lp_variables_q90']:,.0f}, "
            f"{r['lp_largest'][0]} x {r['lp_largest'][1]} | {r['compiled_shapes']} | {r['peak_mb']:,.0f} | "
            f"{r['final_cost']:.4g} | {r['chamfer']:.2f} / {crease} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--points", type=int, nargs="+", default=[10000, 30000])
    p.add_argument("--vertices", type=int, default=200)
    p.add_argument("--shape", default="staircase", help="a dataset of otjax.datasets3d.SURFACES")
    p.add_argument("--noise", type=float, default=0.01, help="Gaussian noise, a fraction of D")
    p.add_argument("--queue", default="multiple-choice")
    p.add_argument("--solver", choices=("batched", "exact"), help="default: reconstruct_surface's")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--progress", action="store_true")
    p.add_argument("--json", help="write the rows and the machine here")
    p.add_argument("--one", action="store_true", help=argparse.SUPPRESS)  # a child process: one size, JSON out
    args = p.parse_args(argv)
    if args.one:
        import jax

        jax.config.update("jax_enable_x64", True)
        print(json.dumps(run_one(args)))
        return 0
    rows = []
    for n in args.points:
        child = [sys.executable, os.path.abspath(__file__), "--one", "--points", str(n), "--vertices",
                 str(args.vertices), "--shape", args.shape, "--noise", repr(args.noise), "--queue", args.queue,
                 "--seed", str(args.seed)] + (["--solver", args.solver] if args.solver else []) + \
            (["--progress"] if args.progress else [])
        got = subprocess.run(child, stdout=subprocess.PIPE, text=True, check=True)
        row = json.loads(got.stdout.strip().splitlines()[-1])
        row["load_average_after"] = os.getloadavg()
        rows.append(row)
        print(markdown(rows[-1:]).splitlines()[-1] if len(rows) > 1 else markdown(rows), flush=True)
    if args.json:
        from bench_surface_lp import machine, write_json

        write_json(args.json, {"machine": machine(), "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
