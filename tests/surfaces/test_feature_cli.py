"""``otjax recover`` flags: ``--passes``, ``--density-threshold`` and ``--seed``
reach the run and change what it writes."""

import json

import numpy as np
import pytest

from otjax.cli import main
from otjax.datasets3d import holed_square

POINTS = 400


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """``flags -> the JSON written`` for a few flag sets on the holed square."""
    root = tmp_path_factory.mktemp("recover")
    out = {}
    for flags in [("--passes", "0"), ("--passes", "1"), ("--passes", "1", "--seed", "1"),
                  ("--passes", "1", "--density-threshold", "0"), ("--passes", "1", "--density-threshold", "0.5")]:
        path = root / f"{'_'.join(flags)}.json"
        argv = ["recover", "--example", "holed_square", "--points", str(POINTS), "--solver", "exact", "--quiet",
                *flags, "-o", str(path)]
        assert main(argv) == 0
        out[flags] = json.loads(path.read_text())
    return out


def test_passes(runs):
    mesh = holed_square(POINTS, seed=0).mesh  # the example's mesh (seed 0 is the default)
    still, moved = runs[("--passes", "0")], runs[("--passes", "1")]
    np.testing.assert_array_equal(still["vertices"], mesh.vertices)
    assert not np.array_equal(moved["vertices"], mesh.vertices)
    assert (still["params"]["passes"], moved["params"]["passes"]) == (0, 1)


def test_seed(runs):
    a, b = runs[("--passes", "1")], runs[("--passes", "1", "--seed", "1")]
    assert (a["params"]["seed"], b["params"]["seed"]) == (0, 1)
    assert not np.array_equal(a["vertices"], b["vertices"])


def test_density_threshold(runs):
    low = runs[("--passes", "1", "--density-threshold", "0")]
    high = runs[("--passes", "1", "--density-threshold", "0.5")]
    assert (low["params"]["density_threshold"], high["params"]["density_threshold"]) == (0.0, 0.5)
    np.testing.assert_array_equal(low["vertices"], high["vertices"])  # the filter comes after the moves
    kept_low = {tuple(t) for t in low["triangles"]}
    kept_high = {tuple(t) for t in high["triangles"]}
    assert kept_high < kept_low  # a higher threshold drops more, and only drops
    # what the higher threshold drops is the least dense: below half the mean density (the mass
    # over the area of every input face, those without mass included)
    v, tri = np.asarray(low["vertices"]), holed_square(POINTS, seed=0).mesh.triangles
    c = v[tri]
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1).sum()
    mean = sum(low["triangle_mass"]) / area
    density = dict(zip(map(tuple, low["triangles"]), low["triangle_density"]))
    assert all(density[t] < 0.5 * mean * (1 + 1e-9) for t in kept_low - kept_high)
    assert all(density[t] >= 0.5 * mean * (1 - 1e-9) for t in kept_high)
