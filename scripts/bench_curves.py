"""Benchmark of curve reconstruction at scale: time, its split, memory, cost.

Input (seeded): a noisy five-pointed star (sigma = 1% of the diagonal) with 10%
of the points replaced by uniform outliers in the enlarged bounding box. Every
(size, queue) pair runs in a fresh Python process, so each run pays its own
compilation and reports its own peak resident memory, as a user's would.

    python scripts/bench_curves.py                          # every size, every queue
    python scripts/bench_curves.py --sizes 1000 --repeats 1 --json out.json
    python scripts/bench_curves.py --queues multiple-choice --plot docs/bench_curves.png
    python scripts/bench_curves.py --from-json docs/bench/*.json --plot docs/bench/time_vs_n.png
    python scripts/bench_curves.py --sizes 50000 --queues multiple-choice --compile-cache /tmp/cache

Runs are cold by default: every process compiles its kernels. With
``--compile-cache DIR`` each (size, queue) first runs once untimed to fill the
persistent compilation cache in DIR (what the command line keeps in
~/.cache/otjax), and the timed runs then read their kernels from it.

Each row ends with a machine check (:func:`machine_check`, NumPy / XLA
milliseconds of two fixed workloads, run after the timed run): the machine's
speed when the row was measured.

Prints a table and the fit ``time ~ n^k`` between 10k and 1M points, and writes
JSON (``--json``). Runs of sizes up to ``--median-up-to`` are repeated
``--repeats`` times and the median run is reported.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

SIZES = (1_000, 3_000, 10_000, 50_000, 200_000, 1_000_000)
QUEUES = ("exhaustive", "multiple-choice", "parallel", "lazy")
OUTLIER_FRACTION = 0.1


def target_for(n: int) -> int:
    """Target vertex count: 10 up to 50k points (the star's corners), 100 above."""
    return 10 if n <= 50_000 else 100


def make_input(n: int, seed: int):
    """``(points, truth)``: the noisy star with uniform outliers, ``n`` points."""
    from otjax import datasets

    n_out = round(OUTLIER_FRACTION * n)
    pts, truth = datasets.star(n - n_out, noise=0.01, seed=seed)
    return datasets.with_outliers(pts, truth, n_out, seed=seed + 1)


def run_one(n: int, queue: str, seed: int, cache: str | None = None) -> dict:
    """One reconstruction in this process; returns its measurements."""
    import resource
    import time

    import jax

    import otjax
    from otjax import metrics

    if cache:
        otjax.enable_compilation_cache(cache)

    compile_s = [0.0]

    def listen(event: str, seconds: float, **_kw) -> None:
        if event.endswith("backend_compile_duration"):
            compile_s[0] += seconds

    jax.monitoring.register_event_duration_secs_listener(listen)
    points, truth = make_input(n, seed)
    target = target_for(n)
    t0 = time.perf_counter()
    result = otjax.reconstruct_curve(points, n_vertices=target, queue=queue, seed=seed)
    wall = time.perf_counter() - t0
    compiled_in_run = compile_s[0]
    check = machine_check()
    h = result.history
    s = h["seconds"]
    corner = metrics.corner_errors(result.vertices, truth["corners"]) / truth["diagonal"] if len(
        result.vertices) else np.array([np.inf])
    return {
        "n": n, "queue": queue, "target": target, "seed": seed,
        "initial_vertices": result.params["initial_vertices"],
        "seconds": wall,
        "split": {
            "init": s.get("init", 0.0),
            "scoring": s.get("score", 0.0),
            "topology": s.get("export", 0.0) + s.get("apply", 0.0) + s.get("sample", 0.0),
            "relocation": s.get("relocate", 0.0) + s.get("final_relocation", 0.0),
        },
        "collapses": h["collapses"],
        "collapses_per_second": h["collapses"] / wall,
        "rounds": h["rounds"],
        "kernel_calls": h["kernel_calls"],
        "compiled_shapes": h["compiled_shapes"],
        "compile_seconds": compiled_in_run,
        "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "total_cost": result.total_cost,
        "n_vertices": len(result.vertices), "n_edges": len(result.edges),
        "corner_error_mean": float(np.mean(corner)) if len(truth["corners"]) <= len(result.vertices) else None,
        "backend": jax.default_backend(),
        "compile_cache": "warm" if cache else "cold",
        "machine_check": check,
    }


def machine_check() -> dict:
    """Milliseconds of two fixed workloads, run after the timed run: the
    machine's speed at the time of the row, to compare rows of a shared
    machine whose speed drifts (the benchmark VM: 10-20% within an hour).

    ``numpy_ms``: sorting 2^20 seeded random floats (one core, NumPy);
    ``kernel_ms``: one scoring-kernel call on an empty 32768-row batch (XLA,
    both cores; the shape every run above a few thousand points compiles).
    Each is the median of 15 runs. The kernel's inputs are plain (unaligned)
    NumPy zeros, not the library's reused aligned buffers
    (``PackedBuffers``), so the call includes copying them; every row in
    ``docs/bench/`` is measured this way, so checks stay comparable.
    """
    import time

    import jax

    from otjax.curves import scoring

    x = np.random.default_rng(0).random(1 << 20)
    r = 1 << 15
    floats, ints = (np.zeros(k) for k in scoring.FIELDS[4].layout(r)[1])
    ints = ints.astype(np.int32)

    def kernel():
        with jax.enable_x64(True):
            jax.block_until_ready(scoring.score_packed(floats, ints, rows=r, dtype=np.float64))

    def median_ms(f) -> float:
        f()
        times = []
        for _ in range(15):
            t0 = time.perf_counter()
            f()
            times.append(time.perf_counter() - t0)
        return 1e3 * float(np.median(times))

    return {"numpy_ms": median_ms(lambda: np.sort(x)), "kernel_ms": median_ms(kernel)}


def run_child(n: int, queue: str, seed: int, timeout: float, cache: str | None = None) -> dict:
    """Runs :func:`run_one` in a fresh interpreter (own compile, own peak RSS)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.json"
        cmd = [sys.executable, __file__, "--child", str(n), queue, str(seed), str(out), cache or ""]
        try:
            # A cold run is cold whatever cache the caller's environment names.
            env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False, env=env)
        except subprocess.TimeoutExpired:
            return {"n": n, "queue": queue, "error": f"timed out after {timeout:.0f} s"}
        if proc.returncode != 0 or not out.exists():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            return {"n": n, "queue": queue, "error": tail[0]}
        return json.loads(out.read_text())


def fit_exponent(rows: list[dict], lo: int = 10_000, hi: int = 1_000_000) -> float | None:
    """Least-squares slope of log(time) against log(n) for ``lo <= n <= hi``."""
    pts = [(r["n"], r["seconds"]) for r in rows if "seconds" in r and lo <= r["n"] <= hi]
    if len({n for n, _ in pts}) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def table(rows: list[dict]) -> str:
    head = ("| n | queue | target | initial vertices | seconds | init / scoring / topology / relocation | "
            "collapses/s | rounds | shapes | compile s | peak RSS MiB | total cost | machine check ms |")
    lines = [head, "|" + " --- |" * (head.count("|") - 1)]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['n']} | {r['queue']} | | | {r['error']} | | | | | | | | |")
            continue
        sp = r["split"]
        mc = r.get("machine_check")  # absent or None in rows written without one
        check = f"{mc['numpy_ms']:.1f} / {mc['kernel_ms']:.2f}" if mc else ""
        lines.append(
            f"| {r['n']} | {r['queue']}{' (warm cache)' if r.get('compile_cache') == 'warm' else ''} | {r['target']} | {r['initial_vertices']} | {r['seconds']:.2f} | "
            f"{sp['init']:.2f} / {sp['scoring']:.2f} / {sp['topology']:.2f} / {sp['relocation']:.2f} | "
            f"{r['collapses_per_second']:.0f} | {r['rounds']} | {r['compiled_shapes']} | "
            f"{r['compile_seconds']:.2f} | {r['peak_rss_mib']:.0f} | {r['total_cost']:.6g} | {check} |")
    return "\n".join(lines)


def plot(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for queue in QUEUES:
        pts = sorted((r["n"], r["seconds"]) for r in rows if r.get("queue") == queue and "seconds" in r)
        if pts:
            ax.loglog(*zip(*pts), "o-", label=queue)
    ax.set_xlabel("input points n")
    ax.set_ylabel("wall time (s)")
    ax.set_title("otjax curve reconstruction: time vs input size")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp" + path.suffix)
    fig.savefig(tmp, dpi=110)
    os.replace(tmp, path)


def main(argv=None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == "--child":
        n, queue, seed, out, cache = sys.argv[2:7]
        result = run_one(int(n), queue, int(seed), cache or None)
        Path(out).write_text(json.dumps(result))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--queues", nargs="+", choices=QUEUES, default=list(QUEUES))
    ap.add_argument("--repeats", type=int, default=3, help="runs per size up to --median-up-to (median kept)")
    ap.add_argument("--median-up-to", type=int, default=50_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per run")
    ap.add_argument("--compile-cache", metavar="DIR",
                    help="warm runs: fill a persistent compilation cache in DIR first (one untimed run)")
    ap.add_argument("--json", type=Path, help="write the rows here")
    ap.add_argument("--plot", type=Path, help="write a log-log plot of time vs n here")
    ap.add_argument("--from-json", type=Path, nargs="+", metavar="JSON",
                    help="run nothing: merge these earlier outputs, print the table and fits, plot")
    args = ap.parse_args(argv)
    if args.from_json:
        try:
            docs = [json.loads(p.read_text()) for p in args.from_json]
        except (OSError, ValueError) as err:
            ap.error(f"cannot read a benchmark JSON: {err}")
        rows = sorted((r for d in docs for r in d["rows"]), key=lambda r: (r["n"], QUEUES.index(r["queue"])))
        report(rows, sorted({r["queue"] for r in rows}, key=QUEUES.index), docs[0].get("machine"), args)
        return 0
    if any(n < 100 for n in args.sizes) or args.repeats < 1:
        ap.error("sizes must be >= 100 and repeats >= 1")
    rows = []
    for n in sorted(args.sizes):
        for queue in args.queues:
            reps = args.repeats if n <= args.median_up_to else 1
            if args.compile_cache:
                run_child(n, queue, args.seed, args.timeout, args.compile_cache)  # fills the cache
            runs = [run_child(n, queue, args.seed, args.timeout, args.compile_cache) for _ in range(reps)]
            ok = sorted((r for r in runs if "seconds" in r), key=lambda r: r["seconds"])
            row = ok[len(ok) // 2] if ok else runs[0]
            row["repeats"] = len(ok)
            rows.append(row)
            print(table([row]).splitlines()[-1], flush=True)
    print()
    report(rows, args.queues, {"platform": platform.platform(), "cores": os.cpu_count()}, args)
    return 0 if all("seconds" in r for r in rows) else 1


def report(rows: list[dict], queues, machine: dict | None, args) -> None:
    """Prints the table and the fits; writes the JSON and the plot if asked."""
    if machine:
        print(f"machine: {machine.get('cores')} cores, {machine.get('platform')}")
    print(table(rows))
    fits = {q: fit_exponent([r for r in rows if r.get("queue") == q]) for q in queues}
    for q, k in fits.items():
        if k is not None:
            print(f"fit {q}: time ~ n^{k:.2f} between 10k and 1M points")
    if args.json:
        payload = {"machine": machine, "rows": rows, "fit_10k_1M": fits}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.json.with_suffix(".tmp")
        tmp.write_text(json.dumps(payload, indent=1))
        os.replace(tmp, args.json)
    if args.plot:
        plot(rows, args.plot)


if __name__ == "__main__":
    sys.exit(main())
