"""The benchmark script works (at its smallest size; benchmarks are not timed tests)."""

import json
import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent.parent / "scripts" / "bench_curves.py"


def test_bench_curves_smallest_size(tmp_path):
    out = tmp_path / "bench.json"
    proc = subprocess.run([sys.executable, str(SCRIPT), "--sizes", "1000", "--repeats", "1", "--json", str(out)],
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "| n | queue |" in proc.stdout
    doc = json.loads(out.read_text())
    rows = doc["rows"]
    assert {r["queue"] for r in rows} == {"exhaustive", "multiple-choice", "parallel"}
    for r in rows:
        assert r["n"] == 1000 and r["n_vertices"] >= 1
        assert r["collapses"] == r["initial_vertices"] - r["target"]
        assert 1 <= r["rounds"] <= r["collapses"]
        assert sum(r["split"].values()) <= r["seconds"]
        assert 0 < r["compile_seconds"] < r["seconds"]
        assert 1 <= r["compiled_shapes"] <= 12
        assert r["peak_rss_mib"] > 0 and r["total_cost"] > 0
        assert r["compile_cache"] == "cold"  # every run compiles unless --compile-cache is given
        assert r["machine_check"]["numpy_ms"] > 0 and r["machine_check"]["kernel_ms"] > 0
    assert doc["fit_10k_1M"] == {"exhaustive": None, "multiple-choice": None, "parallel": None}


def test_bench_curves_rejects_bad_arguments():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--sizes", "10"], capture_output=True, text=True,
                          timeout=60, check=False)
    assert proc.returncode == 2 and "sizes must be >= 100" in proc.stderr
