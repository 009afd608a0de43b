"""The acceptance cases of ``reconstruct_curve`` and their checks, shared by
the ``tests/curves/test_reconstruct_*.py`` files.

A helper module, not a test file: each acceptance case has its own test file
(one expensive reconstruction per file and configuration), so that the
suite's workers (``--dist loadfile``) run them side by side. Distances are
relative to the bounding-box diagonal ``D`` of the clean shape.
"""

from __future__ import annotations

import numpy as np

import otjax
from otjax import datasets, metrics


def components(n_vertices: int, edges: np.ndarray) -> int:
    parent = list(range(n_vertices))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in edges:
        parent[find(a)] = find(b)
    return len({find(i) for i in range(n_vertices)})


def assert_one_closed_cycle(result, n: int) -> None:
    deg = np.bincount(result.edges.ravel(), minlength=len(result.vertices))
    assert len(result.vertices) == n, f"{len(result.vertices)} vertices, expected {n}"
    assert len(result.edges) == n
    assert np.all(deg == 2), f"degrees {deg}"
    assert components(n, result.edges) == 1
    assert len(result.isolated) == 0


# The acceptance cases: (points, input size) -> (result(s), truth).

STAR_POINTS = 2000
SKYLINE_POINTS = 750
JUNCTION_POINTS = 2000


def noisy_star_case(**mode):
    pts, truth = datasets.star(STAR_POINTS, noise=0.01, seed=2)
    return otjax.reconstruct_curve(pts, n_vertices=10, **mode), truth


def check_noisy_star(result, truth):
    d = truth["diagonal"]
    assert_one_closed_cycle(result, 10)
    err = metrics.corner_errors(result.vertices, truth["corners"]) / d
    assert err.mean() <= 0.01, f"mean corner error {err.mean():.3%}"
    assert err.max() <= 0.02, f"max corner error {err.max():.3%}"
    h = metrics.hausdorff(metrics.edges_to_segments(result.vertices, result.edges), truth["segments"]) / d
    assert h <= 0.025, f"Hausdorff {h:.3%}"


def junction_case(**mode):
    pts, truth = datasets.junctions(JUNCTION_POINTS, noise=0.0, seed=5)
    return otjax.reconstruct_curve(pts, n_vertices=len(truth["corners"]), **mode), truth


def check_junctions(result, truth):
    d = truth["diagonal"]
    deg = np.bincount(result.edges.ravel(), minlength=len(result.vertices))
    for where, want in zip(truth["junctions"], truth["junction_degree"]):
        near = np.linalg.norm(result.vertices - where, axis=1) <= 0.02 * d
        assert np.any(near & (deg == want)), f"no degree-{want} vertex within 2% D of {where}"
    for end in truth["ends"]:
        near = np.linalg.norm(result.vertices - end, axis=1) <= 0.02 * d
        assert np.any(near & (deg == 1)), f"open end {end} lost"


def _skyline():
    pts, truth = datasets.skyline(SKYLINE_POINTS, noise=0.005, seed=6)
    return pts, truth, len(truth["corners"]) + len(truth["ends"])


def skyline_run(**mode):
    """The skyline reconstructed with relocation (as in :func:`skyline_case`)."""
    pts, _, n = _skyline()
    return otjax.reconstruct_curve(pts, n_vertices=n, relocation=100, final_relocations=1, **mode)


def skyline_case(**mode):
    pts, truth, n = _skyline()
    without = otjax.reconstruct_curve(pts, n_vertices=n, relocation=0, final_relocations=0, **mode)
    return skyline_run(**mode), without, truth


def check_skyline(with_reloc, without, truth):
    corners = np.concatenate([truth["corners"], truth["ends"]])
    e_with = metrics.corner_errors(with_reloc.vertices, corners).mean()
    e_without = metrics.corner_errors(without.vertices, corners).mean()
    assert e_with <= 0.7 * e_without, f"with {e_with:.4g} vs without {e_without:.4g}"
    assert with_reloc.total_cost < without.total_cost


# The other queues and the random-subset initialisation pass the same
# acceptance checks. "subset" is the configuration for large inputs: the
# multiple-choice queue on a triangulation of half of the points.
MODES = {
    "multiple-choice": {"queue": "multiple-choice"},
    "subset": {"queue": "multiple-choice", "initial_vertices": "half"},
    "parallel": {"queue": "parallel"},
}


def mode_args(name: str, n_points: int) -> dict:
    args = dict(MODES[name])
    if args.get("initial_vertices") == "half":
        args["initial_vertices"] = n_points // 2
    return args


def check_parallel_against_sequential(case: str, par, seq) -> None:
    """The parallel queue costs at most 3% more than the sequential greedy,
    with as many collapses in at least 5x fewer rounds."""
    assert par.total_cost <= 1.03 * seq.total_cost, (
        f"{case}: parallel {par.total_cost:.6g} vs sequential {seq.total_cost:.6g}")
    h = par.history
    assert h["collapses"] == seq.history["collapses"]
    assert 5 * h["rounds"] <= h["collapses"], f"{case}: {h['rounds']} rounds, {h['collapses']} collapses"
