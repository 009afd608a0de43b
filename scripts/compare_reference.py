"""otjax against the C++ reference (CGAL's Optimal_transportation_reconstruction_2),
both at their defaults, on the same generated inputs, in one run.

The reference is built on the fly from Debian's header-only ``libcgal-dev``
with a small driver of this project's (``scripts/otr2_driver.cpp``); without
``g++`` or the headers the script says so and exits. Each case (six kinds of
input, several seeds) runs the reference, then otjax's command line as a user
would (``otjax curve FILE -n N --seed S``, persistent compilation cache warm),
alternating; ``--cold`` adds a cold otjax process (no compilation cache) per
case. Quality, against the clean shape, in % of its bounding-box diagonal D:
corner error (each true corner to its nearest output vertex, mean / max),
Hausdorff distance between the output (edges and isolated vertices) and the
truth, F1 of the length recall and precision within 2% D, and the number of
triangles (3-cycles of output edges, which none of these shapes has).

Speed by size: a noisy star (sigma 1% D) of 1k, 3k, 10k and 20k points to
10 vertices (50 at 20k), both tools on the same file: the median of
``SMALL_REPEATS`` alternating runs each up to ``SMALL_POINTS`` points (runs
of a few seconds, where the machine's noise is a large part of the
difference), one run each above.

"Cache warm" means that the compilation cache holds the kernel shapes the
command needs: one untimed otjax run on each kind's first input and on each
size's input fills it, as an earlier run on similar data would.

    python scripts/compare_reference.py                        # 6 kinds x 3 seeds, then the sizes
    python scripts/compare_reference.py --seeds 0 --kinds star-2 skyline --cold --no-sizes
    python scripts/compare_reference.py --sizes                # only the sizes
    python scripts/compare_reference.py --json docs/bench/reference.json --markdown table.md
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

HERE = Path(__file__).resolve().parent
DRIVER_SOURCE = HERE / "otr2_driver.cpp"
HEADER = Path("/usr/include/CGAL/Optimal_transportation_reconstruction_2.h")


class Kind(NamedTuple):
    """One kind of input: a generator of ``(points, truth)`` and a target."""

    name: str
    n_vertices: int
    make: object  # (seed) -> (points, truth)
    describe: str


def _kinds():
    from otjax import datasets

    def star(noise):
        return lambda seed: datasets.star(3000, noise=noise, seed=seed)

    def star_outliers(seed):
        pts, truth = datasets.star(3000, noise=0.02, seed=seed)
        return datasets.with_outliers(pts, truth, 3000, margin=0.2, seed=seed + 1000)

    return [
        Kind("star-clean", 10, star(0.0), "noise-free star, 3k points"),
        Kind("star-1", 10, star(0.01), "star, sigma 1% D, 3k"),
        Kind("star-2", 10, star(0.02), "star, sigma 2% D, 3k"),
        Kind("star-2-outliers", 10, star_outliers, "star, sigma 2% D + as many uniform outliers, 6k"),
        Kind("skyline", 18, lambda seed: datasets.skyline(2000, noise=0.01, seed=seed), "skyline, sigma 1% D, 2k"),
        Kind("junctions", 9, lambda seed: datasets.junctions(2000, noise=0.005, seed=seed),
             "X crossing and T junction, sigma 0.5% D, 2k"),
    ]


def build_driver(build_dir: Path, header: Path = HEADER) -> Path | None:
    """Compiles the reference driver; ``None`` (with a message) if it cannot be."""
    compiler = shutil.which("g++")
    if compiler is None or not header.exists():
        missing = "g++" if compiler is None else f"the CGAL headers ({header})"
        print(f"compare_reference: {missing} not found; install Debian's g++ and libcgal-dev to run the "
              "reference. Nothing was compared.", file=sys.stderr)
        return None
    exe = build_dir / "otr2_driver"
    if not exe.exists() or exe.stat().st_mtime < DRIVER_SOURCE.stat().st_mtime:
        cmd = [compiler, "-O2", "-DNDEBUG", "-std=c++17", "-o", str(exe), str(DRIVER_SOURCE), "-lgmp", "-lmpfr"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            print(f"compare_reference: building the driver failed:\n{done.stderr[-2000:]}", file=sys.stderr)
            return None
    return exe


def run_reference(exe: Path, points_file: Path, out: Path, n_vertices: int) -> dict:
    t0 = time.perf_counter()
    subprocess.run([str(exe), str(points_file), str(out), str(n_vertices)], check=True)
    wall = time.perf_counter() - t0
    lines = out.read_text().split("\n")
    seconds = float(lines[0].split()[1])
    nv = int(lines[1].split()[1])
    vertices = np.array([[float(x) for x in line.split()] for line in lines[2:2 + nv]]).reshape(-1, 2)
    ne = int(lines[2 + nv].split()[1])
    edges = np.array([[int(x) for x in line.split()] for line in lines[3 + nv:3 + nv + ne]], np.int64).reshape(-1, 2)
    ni = int(lines[3 + nv + ne].split()[1])
    isolated = np.array([int(x) for x in lines[4 + nv + ne:4 + nv + ne + ni]], np.int64)
    return {"vertices": vertices, "edges": edges, "isolated": isolated, "wall": wall, "inner": seconds}


def run_otjax(points_file: Path, out: Path, n_vertices: int, seed: int, cache: Path | None) -> dict:
    cmd = [sys.executable, "-m", "otjax", "curve", str(points_file), "-n", str(n_vertices), "--seed", str(seed),
           "-o", str(out)]
    cmd += ["--compile-cache", str(cache)] if cache is not None else ["--no-compile-cache"]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True)
    wall = time.perf_counter() - t0
    r = json.loads(out.read_text())
    return {"vertices": np.asarray(r["vertices"], float).reshape(-1, 2),
            "edges": np.asarray(r["edges"], np.int64).reshape(-1, 2),
            "isolated": np.asarray(r["isolated"], np.int64), "wall": wall, "inner": r["seconds"]}


def triangles(edges: np.ndarray) -> int:
    """Number of 3-cycles of the graph ``edges (m, 2)``."""
    nbr: dict[int, set] = {}
    for a, b in edges.tolist():
        if a != b:
            nbr.setdefault(a, set()).add(b)
            nbr.setdefault(b, set()).add(a)
    return sum(1 for a, b in edges.tolist() for c in nbr.get(a, set()) & nbr.get(b, set()) if c > max(a, b))


def quality(result: dict, truth: dict) -> dict:
    """Corner errors, Hausdorff, F1@2% and triangles, lengths in % of D."""
    from otjax import metrics

    d = truth["diagonal"]
    segs = metrics.edges_to_segments(result["vertices"], result["edges"])
    iso = result["vertices"][result["isolated"]]
    shown = np.concatenate([segs, np.stack([iso, iso], 1)]) if len(iso) else segs
    corners = metrics.corner_errors(result["vertices"], truth["corners"]) if len(truth["corners"]) else np.zeros(1)
    recall = metrics.length_within(truth["segments"], segs, 0.02 * d) if len(segs) else 0.0
    precision = metrics.length_within(segs, truth["segments"], 0.02 * d) if len(segs) else 0.0
    f1 = 2 * recall * precision / (recall + precision) if recall + precision > 0 else 0.0
    return {"corner_mean": 100 * float(corners.mean()) / d, "corner_max": 100 * float(corners.max()) / d,
            "hausdorff": 100 * metrics.hausdorff(shown, truth["segments"]) / d, "recall": recall,
            "precision": precision, "f1": f1, "triangles": triangles(result["edges"]),
            "vertices": len(result["vertices"]), "edges": len(result["edges"])}


def compare(kinds, seeds, exe: Path, cold: bool, work: Path, cache: Path) -> list[dict]:
    from otjax.io import write_points

    rows = []
    for kind in kinds:
        for seed in seeds:
            points, truth = kind.make(seed)
            points_file = work / f"{kind.name}-{seed}.xy"
            write_points(points_file, points)
            row = {"kind": kind.name, "seed": seed, "n_points": len(points), "n_vertices": kind.n_vertices}
            if seed == seeds[0]:
                run_otjax(points_file, work / "warm.json", kind.n_vertices, seed, cache)
            ref = run_reference(exe, points_file, work / "ref.txt", kind.n_vertices)
            row["reference"] = {**quality(ref, truth), "seconds": ref["wall"], "inner_seconds": ref["inner"]}
            ours = run_otjax(points_file, work / "otjax.json", kind.n_vertices, seed, cache)
            row["otjax"] = {**quality(ours, truth), "seconds": ours["wall"], "inner_seconds": ours["inner"]}
            if cold and seed == seeds[0]:
                row["otjax_cold_seconds"] = run_otjax(points_file, work / "cold.json", kind.n_vertices, seed,
                                                      None)["wall"]
            rows.append(row)
            r, o = row["reference"], row["otjax"]
            print(f"{kind.name:16s} seed {seed}: reference corners {r['corner_mean']:.2f}/{r['corner_max']:.2f} "
                  f"H {r['hausdorff']:.2f} F1 {r['f1']:.2f} tri {r['triangles']} {r['seconds']:.1f} s | otjax "
                  f"{o['corner_mean']:.2f}/{o['corner_max']:.2f} H {o['hausdorff']:.2f} F1 {o['f1']:.2f} "
                  f"tri {o['triangles']} {o['seconds']:.1f} s", flush=True)
    return rows


SIZES = ((1000, 10), (3000, 10), (10000, 10), (20000, 50))
SMALL_POINTS, SMALL_REPEATS = 3000, 5


def compare_sizes(sizes, exe: Path, work: Path, cache: Path, cold: bool) -> list[dict]:
    """Wall seconds of both tools on a noisy star per ``(points, target)``."""
    from otjax import datasets
    from otjax.io import write_points

    rows = []
    for n, target in sizes:
        points, truth = datasets.star(n, noise=0.01, seed=0)
        points_file = work / f"star-{n}.xy"
        write_points(points_file, points)
        run_otjax(points_file, work / "warm.json", target, 0, cache)
        ref_walls, our_walls = [], []
        for _ in range(SMALL_REPEATS if n <= SMALL_POINTS else 1):
            ref = run_reference(exe, points_file, work / "ref.txt", target)
            ours = run_otjax(points_file, work / "otjax.json", target, 0, cache)
            ref_walls.append(ref["wall"])
            our_walls.append(ours["wall"])
        row = {"n_points": n, "n_vertices": target, "reference_seconds": float(np.median(ref_walls)),
               "otjax_seconds": float(np.median(our_walls)), "reference_runs": ref_walls, "otjax_runs": our_walls,
               "otjax_inner_seconds": ours["inner"],
               "reference_corner_mean": quality(ref, truth)["corner_mean"],
               "otjax_corner_mean": quality(ours, truth)["corner_mean"]}
        if cold:
            row["otjax_cold_seconds"] = run_otjax(points_file, work / "cold.json", target, 0, None)["wall"]
        rows.append(row)
        print(f"star {n} -> {target}: reference {row['reference_seconds']:.1f} s | otjax "
              f"{row['otjax_seconds']:.1f} s ({len(ref_walls)} runs each, median)", flush=True)
    return rows


def size_table(rows: list[dict]) -> str:
    """Markdown: wall seconds per size, both tools."""
    out = ["| noisy star, points → V | reference s | otjax s (warm cache) | otjax s (cold) | "
           "corner error mean, seed 0, reference / otjax (% D) |", "| --- | --- | --- | --- | --- |"]
    for r in rows:
        cold = f"{r['otjax_cold_seconds']:.1f}" if "otjax_cold_seconds" in r else ""
        out.append(f"| {r['n_points']} → {r['n_vertices']} | {r['reference_seconds']:.2f} | "
                   f"{r['otjax_seconds']:.2f} | {cold} | {r['reference_corner_mean']:.2f} / "
                   f"{r['otjax_corner_mean']:.2f} |")
    return "\n".join(out)


def table(rows: list[dict]) -> str:
    """Markdown: per kind, the mean over seeds of each figure, both tools."""
    out = ["| input | points → V | tool | corner error mean / max (% D) | Hausdorff (% D) | F1@2% | "
           "triangles | seconds |", "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for kind in dict.fromkeys(r["kind"] for r in rows):
        mine = [r for r in rows if r["kind"] == kind]
        for tool in ("reference", "otjax"):
            q = {k: float(np.mean([r[tool][k] for r in mine])) for k in
                 ("corner_mean", "corner_max", "hausdorff", "f1", "triangles", "seconds")}
            secs = f"{q['seconds']:.2f}"
            cold = [r["otjax_cold_seconds"] for r in mine if "otjax_cold_seconds" in r]
            if tool == "otjax" and cold:
                secs += f" (cold {cold[0]:.1f})"
            out.append(f"| {kind} | {mine[0]['n_points']} → {mine[0]['n_vertices']} | {tool} | "
                       f"{q['corner_mean']:.2f} / {q['corner_max']:.2f} | {q['hausdorff']:.2f} | {q['f1']:.2f} | "
                       f"{q['triangles']:.1f} | {secs} |")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    names = [k.name for k in _kinds()]
    ap.add_argument("--kinds", nargs="+", choices=names, default=names)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--cold", action="store_true", help="also time one cold otjax process per kind")
    ap.add_argument("--sizes", action="store_true", help="only the speed-by-size table")
    ap.add_argument("--no-sizes", action="store_true", help="only the quality table")
    ap.add_argument("--build-dir", type=Path, help="where the driver is built (default: a temporary directory)")
    ap.add_argument("--json", type=Path, help="write every row here")
    ap.add_argument("--markdown", type=Path, help="write the table here")
    args = ap.parse_args(argv)
    for path in (args.json, args.markdown):
        if path is not None and not path.parent.is_dir():
            ap.error(f"{path.parent} is not a directory")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        build = args.build_dir or tmp
        build.mkdir(parents=True, exist_ok=True)
        exe = build_driver(build)
        if exe is None:
            return 1
        cache = tmp / "jax-cache"
        kinds = [k for k in _kinds() if k.name in args.kinds]
        rows = [] if args.sizes else compare(kinds, args.seeds, exe, args.cold, tmp, cache)
        by_size = [] if args.no_sizes else compare_sizes(SIZES, exe, tmp, cache, args.cold)
    text = "\n\n".join(t for t in (table(rows) if rows else "", size_table(by_size) if by_size else "") if t)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, {platform.python_version()}"
    print(f"\nmachine: {machine}\n{text}")
    if args.markdown:
        args.markdown.write_text(text + "\n")
    if args.json:
        args.json.write_text(json.dumps({"machine": machine, "rows": rows, "sizes": by_size}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
