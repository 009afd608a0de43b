"""reconstruct_surface end to end on shapes with a known surface (small, HiGHS)."""

import json

import numpy as np
import pytest

from otjax.surfaces.reconstruct import SurfaceReconstruction, reconstruct_surface
from tests.surfaces.shapes import CROSS, CUBE, SQUARE, diagonal, fit

def run(shape, n, n_vertices, seed=0, **kw):
    pts = shape.sample(n, np.random.default_rng(seed))
    kw = {"solver": "exact", "choices": 10, "max_sweeps": 1, **kw}
    return pts, reconstruct_surface(pts, n_vertices=n_vertices, seed=seed, **kw)


def test_cube_is_fitted_and_the_masses_are_all_transported():
    pts, r = run(CUBE, 500, 30, seed=1)
    d = diagonal(pts)
    assert isinstance(r, SurfaceReconstruction) and len(r.vertices) == 30
    f = fit(CUBE, r.vertices, r.triangles, d, samples=4000)
    assert f.chamfer <= 0.01 and f.coverage >= 0.7, f
    on_vertices = sum(r.plan.simplex_mass(int(v)) for v in r.vertex_ids)
    assert r.triangle_mass.sum() + on_vertices == pytest.approx(len(pts), rel=1e-9)
    assert np.isfinite(r.total_cost) and r.total_cost > 0 and r.cost_exponent == 0
    assert np.all(r.triangle_area > 0) and r.stats.collapses == len(r.plan.complex.alive) - 30


def test_open_square_keeps_its_boundary_under_collapses_alone():
    # Collapses keep input points as vertices, so every facet lies on the square.
    pts, r = run(SQUARE, 300, 16, seed=2, relocation=0, final_relocations=0, fit_features=False)
    d = diagonal(pts)
    f = fit(SQUARE, r.vertices, r.triangles, d, samples=4000)
    assert f.to_surface <= 0.01 and f.coverage >= 0.8, f
    # vertices on every side of the square (the boundary is kept, not shrunk)
    for axis in (0, 1):
        assert r.vertices[:, axis].min() <= 0.06 and r.vertices[:, axis].max() >= 0.94


def test_crossing_planes_keep_both_planes():
    pts, r = run(CROSS, 400, 20, seed=3)
    d = diagonal(pts)
    centres = r.vertices[r.triangles].mean(axis=1)
    on_z = np.abs(centres[:, 2] - 0.5) < 0.02
    on_y = np.abs(centres[:, 1] - 0.5) < 0.02
    area = r.triangle_area
    assert area[on_z].sum() > 0.6 and area[on_y].sum() > 0.6  # each unit square mostly covered
    assert fit(CROSS, r.vertices, r.triangles, d, samples=4000).chamfer <= 0.01


def test_results_are_in_user_units():
    pts, r = run(SQUARE, 150, 8, seed=4, fraction=0.2)
    # a power-of-two scale maps to the same canonical input (otjax.frame): the same run, scaled
    scale = 2.0**10
    r2 = reconstruct_surface(pts * scale, n_vertices=8, solver="exact", choices=10, max_sweeps=1, seed=4,
                             fraction=0.2)
    np.testing.assert_array_equal(r2.triangles, r.triangles)
    np.testing.assert_allclose(r2.vertices, r.vertices * scale, rtol=1e-15)
    assert r2.total_cost == pytest.approx(r.total_cost * scale**2, rel=1e-12)
    np.testing.assert_allclose(r2.triangle_area, r.triangle_area * scale**2, rtol=1e-12)
    np.testing.assert_allclose(r2.triangle_mass, r.triangle_mass, rtol=1e-12)
    assert r.total_cost > 0


def test_same_seed_writes_the_same_bytes_and_another_seed_differs(tmp_path):
    pts = SQUARE.sample(150, np.random.default_rng(4))
    kw = {"n_vertices": 8, "solver": "exact", "choices": 10, "max_sweeps": 1, "fraction": 0.2}
    meshes = ("r.ply", "r.obj", "r.off")
    for run_dir, seed in (("a", 3), ("b", 3), ("c", 4)):
        result = reconstruct_surface(pts, seed=seed, **kw).to_result({"seed": seed})
        (tmp_path / run_dir).mkdir()
        for name in meshes + ("r.json",):
            result.save(tmp_path / run_dir / name)
    for name in meshes:
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    # The JSON records the wall time, the one field that may differ.
    ja, jb = (json.loads((tmp_path / d / "r.json").read_text()) for d in "ab")
    assert ja.pop("seconds") > 0 and jb.pop("seconds") > 0
    assert json.dumps(ja) == json.dumps(jb)
    assert (tmp_path / "a" / "r.ply").read_bytes() != (tmp_path / "c" / "r.ply").read_bytes()


def test_bin_density_sets_the_bins_of_large_facets():
    """Four times the density: facets of the same area get about four times
    the bins (each facet's count is that of its area when it was made, between 1 and 32)."""
    kw = {"n_vertices": 8, "fraction": 0.2, "relocation": 0, "final_relocations": 0, "final_density_factor": 1}
    _, coarse = run(SQUARE, 150, seed=4, **kw)
    _, fine = run(SQUARE, 150, seed=4, bin_density=600.0, **kw)
    bins = lambda r: np.array([len(r.plan.bins[t].capacity) for t in r.plan.facet_entries])  # noqa: E731
    assert fine.plan.settings.density == 4 * coarse.plan.settings.density == 600
    assert bins(fine).sum() > 2 * bins(coarse).sum()


def test_the_final_finer_bins_sharpen_the_creases_of_a_staircase():
    """The final passes on bins four times as dense (the default) bring the
    creases and the surface closer to the truth than the decimation's bins
    (the feature fit, which comes after them, left out)."""
    from otjax.datasets3d import staircase
    from otjax.metrics3d import chamfer, crease_error

    pts, truth = staircase(300, noise=0.0, seed=5)
    kw = {"n_vertices": 20, "seed": 5, "solver": "exact", "choices": 10, "max_sweeps": 1, "fraction": 0.2,
          "fit_features": False}
    coarse = reconstruct_surface(pts, final_density_factor=1, **kw)
    fine = reconstruct_surface(pts, **kw)
    assert fine.plan.settings.density == 4 * coarse.plan.settings.density
    bins = lambda r: sum(len(r.plan.bins[t].capacity) for t in r.plan.facet_entries)  # noqa: E731
    assert bins(fine) > 2 * bins(coarse)  # the final facets were re-binned, not the decimation's bins kept
    errors = [(crease_error(r.vertices, r.triangles, truth.creases).mean,
               chamfer(r.vertices, r.triangles, r.edges, r.isolated, truth=truth)) for r in (coarse, fine)]
    assert errors[1][0] < 0.8 * errors[0][0] and errors[1][1] < 0.9 * errors[0][1]


def test_the_feature_fit_puts_the_crease_vertices_of_a_staircase_on_its_creases():
    """The last step (the default) moves crease vertices onto the planes of
    the points: the creases come closer to the truth, the surface no farther."""
    from otjax.datasets3d import staircase
    from otjax.metrics3d import chamfer, crease_error

    pts, truth = staircase(900, noise=0.0, seed=6)
    kw = {"n_vertices": 40, "seed": 6, "solver": "exact", "choices": 10, "max_sweeps": 1, "fraction": 0.2}
    plain = reconstruct_surface(pts, fit_features=False, **kw)
    fitted = reconstruct_surface(pts, **kw)
    assert fitted.stats.relocations > plain.stats.relocations
    errors = [(crease_error(r.vertices, r.triangles, truth.creases).mean,
               chamfer(r.vertices, r.triangles, r.edges, r.isolated, truth=truth)) for r in (plain, fitted)]
    assert errors[1][0] < 0.8 * errors[0][0] and errors[1][1] <= 1.05 * errors[0][1], errors
    assert np.all(fitted.triangle_area > 0)


@pytest.mark.parametrize("kw, match", [
    ({"points": np.zeros((10, 2))}, "shape"),
    ({"points": np.r_[np.random.default_rng(0).random((9, 3)), [[np.nan, 0, 0]]]}, "NaN"),
    ({"masses": -np.ones(10)}, "masses"),
    ({"masses": np.r_[np.ones(9), 0.0]}, "masses must be > 0"),
    ({"n_vertices": 3}, "at least 4"),
    ({"n_vertices": 11}, "cannot exceed"),
    ({"solver": "fast"}, "solver"),
    ({"queue": "lifo"}, "queue"),
    ({"bin_density": 0.0}, "bin_density must be > 0"),
    ({"bin_density": float("nan")}, "bin_density"),
    ({"final_density_factor": 0.5}, "final_density_factor"),
    ({"final_density_factor": float("inf")}, "final_density_factor"),
])
def test_bad_input_is_one_clear_value_error(kw, match):
    args = {"points": np.random.default_rng(0).random((10, 3)), "masses": None, "n_vertices": 5, **kw}
    with pytest.raises(ValueError, match=match):
        reconstruct_surface(args.pop("points"), args.pop("masses"), args.pop("n_vertices"), **args)


@pytest.fixture(scope="module")
def noisy_staircase_runs():
    """The noisy staircase (1% D noise) at 20 vertices, with and without relocation."""
    from otjax.datasets3d import staircase

    pts, truth = staircase(250, noise=0.01, seed=5)
    kw = {"n_vertices": 20, "seed": 5, "solver": "exact", "choices": 10, "max_sweeps": 1, "fraction": 0.2}
    return (pts, reconstruct_surface(pts, **kw),
            reconstruct_surface(pts, relocation=0, final_relocations=0, fit_features=False, **kw))


def test_relocation_lowers_the_final_cost_on_the_noisy_staircase(noisy_staircase_runs):
    pts, moved, fixed = noisy_staircase_runs
    assert moved.stats.relocations > 0 and fixed.stats.relocations == 0
    assert len(moved.vertices) == len(fixed.vertices) == 20
    assert moved.total_cost < fixed.total_cost
    # collapses alone keep input points as vertices (up to the frame's rounding); relocation moves them
    gap = lambda v: np.min(np.linalg.norm(v[:, None] - pts[None], axis=2), axis=1)  # noqa: E731
    assert gap(fixed.vertices).max() < 1e-12 and gap(moved.vertices).max() > 1e-3


def test_edges_of_no_triangle_are_left_out_and_their_vertices_with_mass_are_isolated(noisy_staircase_runs):
    """Edges carry no mass (no edge bins): the complex's edges of no triangle
    are not in the result, and each vertex of no triangle that carries mass
    is an isolated vertex of it, whether on such an edge or on none."""
    _, *runs = noisy_staircase_runs
    dangling = 0
    for r in runs:
        arrays = r.complex.to_arrays()
        dangling += int(arrays.dangling.sum())
        on_triangles = set(r.triangles.ravel().tolist())
        carrying = {row for row, v in enumerate(r.vertex_ids) if r.plan.simplex_mass(int(v)) > 0}
        assert r.edges.shape == (0, 2)
        assert set(r.isolated.tolist()) == carrying - on_triangles
        on_dangling = set(arrays.edges[arrays.dangling].ravel().tolist()) - on_triangles
        assert on_dangling & carrying <= set(r.isolated.tolist())
    assert dangling > 0  # the premise: the decimation leaves edges of no triangle


def test_background_noise_is_discounted_and_clean_input_left_as_it_is():
    rng = np.random.default_rng(0)
    square = SQUARE.sample(400, rng)
    outliers = rng.uniform([0, 0, 0.1], [1, 1, 0.9], (100, 3))
    pts = np.vstack([square, outliers])
    kw = {"solver": "exact", "choices": 10, "max_sweeps": 1, "seed": 5, "final_density_factor": 1.0}
    auto = reconstruct_surface(pts, n_vertices=10, **kw)
    none = reconstruct_surface(pts, n_vertices=10, background="none", **kw)
    # The plan holds the transported points and masses: the outliers lost most of theirs.
    assert none.plan.masses.sum() == len(pts)
    assert auto.plan.masses.sum() < len(pts) - 0.5 * len(outliers)
    off = lambda r: np.abs(r.vertices[:, 2] - 0.5).max()  # noqa: E731
    assert off(auto) < 0.5 * off(none)
    cube = CUBE.sample(400, rng)
    clean_auto = reconstruct_surface(cube, n_vertices=10, **kw)
    clean_none = reconstruct_surface(cube, n_vertices=10, background="none", **kw)
    np.testing.assert_array_equal(clean_auto.vertices, clean_none.vertices)
    np.testing.assert_array_equal(clean_auto.triangles, clean_none.triangles)
