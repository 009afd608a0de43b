"""Benchmarks the batched edge-cost kernel: sort vs pairwise-rank vs NumPy.

For each points-per-stencil size P, batch size B and dtype, times

* ``jax-sort``: ``jit(vmap(stencil_cost))`` with the lexsort + segmented scan
  tangential part;
* ``jax-rank``: the same with the sort-free ``(P, P)`` rank tangential part;
* ``numpy``: a vectorised NumPy implementation (one global lexsort over all
  (stencil, edge) groups, cumsums and bincounts);

and reports the median over ``--repeat`` runs (after a warm-up call that also
compiles), as microseconds per call and nanoseconds per (padded) point.

Example::

    python scripts/bench_edge_cost.py --sizes 8 16 32 64 128 --batch 64 256 --json bench.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)  # script-local: float64 runs need it

import numpy as np

from otjax.curves import cost
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils


def random_stencil(rng: np.random.Generator, n_edges: int, n_points: int):
    """A stencil of ``n_edges`` edges sharing vertices and ``n_points`` points.

    Edges join nearby vertices of a jittered grid; each point lies near one
    edge and lists it with two other edges as candidates.
    """
    side = int(np.ceil(np.sqrt(n_edges))) + 1
    grid = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2).astype(float)
    verts = grid + rng.uniform(-0.3, 0.3, grid.shape)
    i = rng.integers(0, len(verts), n_edges)
    step = rng.choice([1, side, side + 1], n_edges)
    j = np.clip(i + step, 0, len(verts) - 1)
    j = np.where(j == i, (i + 1) % len(verts), j)
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    edges = np.stack([verts[lo], verts[hi]], axis=1)
    host = rng.integers(0, n_edges, n_points)
    s = rng.uniform(-0.1, 1.1, n_points)[:, None]
    points = edges[host, 0] + s * (edges[host, 1] - edges[host, 0]) + rng.normal(0, 0.05, (n_points, 2))
    cand = np.sort(
        np.stack([host, rng.integers(0, n_edges, n_points), rng.integers(0, n_edges, n_points)], 1), 1
    )
    mass = rng.uniform(0.5, 1.5, n_points)
    return edges, points, mass, cand.astype(np.int32)


# ----------------------------------------------------------------------------
# Vectorised NumPy reference (whole batch at once).


def _np_segment_sqdist(p, a, b):
    d, pa, pb = b - a, p - a, p - b
    along = np.einsum("...k,...k->...", pa, d)
    den = np.einsum("...k,...k->...", d, d)
    t = np.divide(along, den, out=np.zeros_like(along), where=den != 0)
    off = pa - t[..., None] * d
    da, db, dm = (np.einsum("...k,...k->...", v, v) for v in (pa, pb, off))
    return np.where(along <= 0, da, np.where(np.einsum("...k,...k->...", pb, d) >= 0, db, dm))


def numpy_batched_cost(s: EdgeStencil) -> dict:
    """Per-edge costs of a padded batch with NumPy; same conventions as JAX."""
    n_b, n_e, _ = s.shape
    rows = np.arange(n_b)[:, None]
    seg = s.edges[rows[..., None], s.cand]  # (B, P, 3, 2, 2)
    d2 = _np_segment_sqdist(s.points[:, :, None], seg[..., 0, :], seg[..., 1, :])
    assign = np.take_along_axis(s.cand, np.argmin(d2, axis=2)[..., None], axis=2)[..., 0]
    m = np.where(s.point_mask, s.mass, 0)
    group = np.where(s.point_mask, rows * n_e + assign, n_b * n_e).ravel()  # padding -> extra group

    e = s.edges[rows, assign]  # (B, P, 2, 2)
    a, b = e[..., 0, :], e[..., 1, :]
    d = b - a
    length = np.sqrt(np.einsum("...k,...k->...", d, d))
    u = d / np.where(length > 0, length, 1)[..., None]
    pa, pb = s.points - a, s.points - b
    t = np.einsum("...k,...k->...", pa, u).ravel()
    nrm2 = (u[..., 0] * pa[..., 1] - u[..., 1] * pa[..., 0]) ** 2
    vtx2 = np.minimum(np.einsum("...k,...k->...", pa, pa), np.einsum("...k,...k->...", pb, pb))
    m, length = m.ravel(), length.ravel()

    n_g = n_b * n_e + 1
    edge_mass = np.bincount(group, m, n_g)
    normal = np.bincount(group, m * nrm2.ravel(), n_g)
    vertex = np.bincount(group, m * vtx2.ravel(), n_g)

    # Mass before each point within its group: global lexsort by (group, t),
    # then cumsum minus the cumsum at the group start.
    order = np.lexsort((t, group))
    m_s, g_s = m[order], group[order]
    # float64 accumulation: a global float32 cumsum over B * P points would
    # lose the small per-group sums to cancellation.
    excl = np.cumsum(m_s, dtype=np.float64) - m_s
    start = np.r_[True, g_s[1:] != g_s[:-1]]
    before_s = excl - np.maximum.accumulate(np.where(start, excl, 0))
    before = np.empty_like(m)
    before[order] = before_s

    scale = np.divide(length, edge_mass[group], out=np.zeros_like(length), where=edge_mass[group] != 0)
    bin_len, centre = scale * m, scale * (before + 0.5 * m)
    tangential = np.bincount(group, m * (bin_len**2 / 12 + (t - centre) ** 2), n_g)

    edge_len = np.linalg.norm(s.edges[:, :, 1] - s.edges[:, :, 0], axis=-1).ravel()
    em = s.edge_mask.ravel()
    sums = {"edge_mass": edge_mass, "normal": normal, "tangential": tangential, "vertex": vertex}
    out = {k: v[:-1] for k, v in sums.items()}
    solid = (out["normal"] + out["tangential"] < out["vertex"]) & (out["edge_mass"] > 0) & (edge_len > 0) & em
    edge_cost = np.where(em, np.where(solid, out["normal"] + out["tangential"], out["vertex"]), 0)
    out = {k: v.reshape(n_b, n_e) for k, v in out.items()}
    out["edge_cost"] = edge_cost.reshape(n_b, n_e)
    out["total"] = out["edge_cost"].sum(axis=1)
    return out


# ----------------------------------------------------------------------------


def _check(got: np.ndarray, want: np.ndarray, dtype) -> None:
    """Sanity check against NumPy before timing anything.

    float64 must agree to 1e-9. In float32 a near-tie may flip one point's
    assignment (a genuine discontinuity), so only a few stencils may be off.
    """
    if dtype == np.float64:
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.abs(want).max())
        return
    off = np.abs(got - want) > 1e-3 * np.abs(want) + 1e-6
    assert off.mean() <= 0.01, f"{off.sum()} of {off.size} float32 stencils disagree with NumPy"


def _median_seconds(fn, repeat: int) -> float:
    fn()  # warm-up (and compile)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def bench(sizes, batches, repeat, seed, edges_per_stencil):
    rows = []
    for dtype in (np.float64, np.float32):
        for n_p in sizes:
            for n_b in batches:
                rng = np.random.default_rng(seed)
                n_e = edges_per_stencil or max(4, n_p // 2)
                stencils = [random_stencil(rng, n_e, n_p) for _ in range(n_b)]
                buckets = Buckets(min_edges=1, min_points=1, max_batch=n_b, point_budget=2**40, min_batch=n_b)
                host = pack_edge_stencils(stencils, buckets, dtype=dtype)
                dev = jax.device_put(host)
                ref = numpy_batched_cost(host)
                timings = {}
                for name, fn in (
                    ("jax-sort", cost.batched_stencil_cost_sort),
                    ("jax-rank", cost.batched_stencil_cost_rank),
                ):
                    _check(np.asarray(fn(dev).total), ref["total"], dtype)
                    timings[name] = _median_seconds(
                        lambda fn=fn, dev=dev: fn(dev).total.block_until_ready(), repeat
                    )
                timings["numpy"] = _median_seconds(lambda host=host: numpy_batched_cost(host), repeat)
                shape = host.shape
                for name, sec in timings.items():
                    rows.append(
                        {
                            "impl": name,
                            "dtype": np.dtype(dtype).name,
                            "B": shape[0],
                            "E": shape[1],
                            "P": shape[2],
                            "us_per_call": sec * 1e6,
                            "ns_per_point": sec * 1e9 / (shape[0] * shape[2]),
                        }
                    )
                    print(
                        f"{rows[-1]['dtype']} B={shape[0]} E={shape[1]} P={shape[2]} {name}: {sec * 1e6:.1f} us",
                        flush=True,
                    )
    return rows


def markdown(rows) -> str:
    impls = ["jax-sort", "jax-rank", "numpy"]
    head = "| dtype | B | E | P | " + " | ".join(f"{i} ns/pt (us/call)" for i in impls) + " | fastest |"
    lines = [head, "|" + "---|" * (5 + len(impls))]
    keys = sorted(
        {(r["dtype"], r["B"], r["E"], r["P"]) for r in rows}, key=lambda k: (k[0] != "float64", k[1], k[3])
    )
    for k in keys:
        by = {r["impl"]: r for r in rows if (r["dtype"], r["B"], r["E"], r["P"]) == k}
        cells = [f"{by[i]['ns_per_point']:.1f} ({by[i]['us_per_call']:.0f})" for i in impls]
        best = min(impls, key=lambda i: by[i]["ns_per_point"])
        lines.append(f"| {k[0]} | {k[1]} | {k[2]} | {k[3]} | " + " | ".join(cells) + f" | {best} |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 16, 32, 64, 128], help="points per stencil")
    ap.add_argument("--batch", type=int, nargs="+", default=[64, 256], help="stencils per call")
    ap.add_argument("--edges", type=int, default=0, help="edges per stencil (default max(4, P/2))")
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=str, default=None, help="write the results here")
    args = ap.parse_args(argv)
    rows = bench(args.sizes, args.batch, args.repeat, args.seed, args.edges)
    table = markdown(rows)
    print()
    print(table)
    if args.json:
        meta = {
            "jax": jax.__version__,
            "devices": [str(d) for d in jax.devices()],
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "args": vars(args),
        }
        with open(args.json, "w") as f:
            json.dump({"meta": meta, "rows": rows, "table": table}, f, indent=1)


if __name__ == "__main__":
    main()
