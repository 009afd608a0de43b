"""The benchmark script works (at its smallest size; benchmarks are not timed tests)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "bench_curves.py"


def test_bench_curves_smallest_size(tmp_path):
    """The smallest size the script accepts: each of its four cold runs (one per queue) still
    compiles its kernels and collapses down to the target, which is all the
    rows' fields need; a larger input only adds collapses."""
    out = tmp_path / "bench.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--sizes", "100", "--repeats", "1", "--json", str(out)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "| n | queue |" in proc.stdout
    doc = json.loads(out.read_text())
    rows = doc["rows"]
    assert {r["queue"] for r in rows} == {"exhaustive", "multiple-choice", "parallel", "lazy"}
    for r in rows:
        assert r["n"] == 100 and r["n_vertices"] >= 1
        assert r["collapses"] == r["initial_vertices"] - r["target"]
        assert 1 <= r["rounds"] <= r["collapses"]
        assert sum(r["split"].values()) <= r["seconds"]
        assert 0 < r["compile_seconds"] < r["seconds"]
        assert 1 <= r["compiled_shapes"] <= 12
        assert r["peak_rss_mib"] > 0 and r["total_cost"] > 0
        assert r["compile_cache"] == "cold"  # every run compiles unless --compile-cache is given
        assert r["machine_check"]["numpy_ms"] > 0 and r["machine_check"]["kernel_ms"] > 0
    assert doc["fit_10k_1M"] == {"exhaustive": None, "multiple-choice": None, "parallel": None, "lazy": None}


def test_bench_curves_rejects_bad_arguments():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--sizes", "10"], capture_output=True, text=True,
                          timeout=60, check=False)
    assert proc.returncode == 2 and "sizes must be >= 100" in proc.stderr


def _compare_reference():
    import importlib.util

    path = SCRIPT.parent / "compare_reference.py"
    spec = importlib.util.spec_from_file_location("compare_reference", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_reference_comparison_counts_triangles_of_the_output_graph():
    triangles = _compare_reference().triangles
    k4 = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
    assert triangles(np.array(k4)) == 4
    square_with_diagonal = [[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]]
    assert triangles(np.array(square_with_diagonal)) == 2
    path = [[0, 1], [1, 2], [2, 3]]
    assert triangles(np.array(path)) == 0
    assert triangles(np.zeros((0, 2), np.int64)) == 0


def test_reference_comparison_scores_an_exact_output_as_perfect():
    """The truth itself as output: zero errors, F1 1, no triangle; one edge
    moved by 5% D: that much Hausdorff, and the length off it leaves the F1."""
    from otjax import datasets

    quality = _compare_reference().quality
    _, truth = datasets.skyline(200, seed=0)
    segs = truth["segments"]
    vertices = segs.reshape(-1, 2)
    edges = np.arange(len(vertices)).reshape(-1, 2)
    exact = quality({"vertices": vertices, "edges": edges, "isolated": np.zeros(0, np.int64)}, truth)
    assert exact["corner_mean"] == 0 and exact["hausdorff"] < 0.1 and exact["f1"] == 1 and exact["triangles"] == 0
    shifted = vertices.copy()
    shifted[edges[0]] += [0.0, 0.05 * truth["diagonal"]]
    off = quality({"vertices": shifted, "edges": edges, "isolated": np.zeros(0, np.int64)}, truth)
    assert 4.9 < off["hausdorff"] < 5.1 and off["precision"] < 1 and off["f1"] < 1


def test_reference_comparison_without_the_headers_says_so(tmp_path, capsys):
    assert _compare_reference().build_driver(tmp_path, header=tmp_path / "missing.h") is None
    assert "libcgal-dev" in capsys.readouterr().err
