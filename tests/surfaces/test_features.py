"""Feature recovery (Algorithm 4): creases of a rounded cube, a covered hole,
the colouring that batches the passes, the cost over a pass, bad input."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.datasets3d import holed_square, rounded_box
from otjax.metrics3d import chamfer, crease_error, triangle_samples
from otjax.surfaces.star_plan import surface_plan
from otjax.surfaces.features import (
    initial_plan,
    recover_features,
    relocation_pass,
    star_colouring,
    validate_input,
)


def normals(vertices, triangles):
    c = vertices[triangles]
    return np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])


@pytest.fixture(scope="module")
def cube():
    sample = rounded_box(1500, noise=0.005, seed=3, resolution=6)
    got = recover_features(sample.points, sample.mesh, passes=2, solver="exact").stats
    return sample, got


@pytest.fixture(scope="module")
def hole():
    sample = holed_square(1500, noise=0.005, seed=4, resolution=10)
    # four passes: the hole's border vertices need them to reach the border on this coarse grid
    got = recover_features(sample.points, sample.mesh, passes=4, solver="exact").stats
    return sample, got


# ---------------------------------------------------------------- acceptance
def test_cube_creases_are_recovered(cube):
    sample, got = cube
    tri, creases = sample.mesh.triangles, sample.truth.creases
    before = crease_error(sample.mesh.vertices, tri, creases).mean
    after = crease_error(got.vertices, tri, creases).mean
    assert after <= 0.5 * before, (before, after)


def test_cube_chamfer_does_not_grow(cube):
    sample, got = cube
    tri = sample.mesh.triangles
    before = chamfer(sample.mesh.vertices, tri, truth=sample.truth, samples=4000)
    after = chamfer(got.vertices, tri, truth=sample.truth, samples=4000)
    assert after <= before, (before, after)


def test_cube_no_face_flips_and_closed_surface_kept(cube):
    sample, got = cube
    tri = sample.mesh.triangles
    dots = np.einsum("ij,ij->i", normals(sample.mesh.vertices, tri), normals(got.vertices, tri))
    assert np.all(dots > 0)
    assert got.keep.mean() >= 0.95  # a closed, fully sampled surface loses (almost) nothing


def covered(points_xy, vertices, triangles):
    """``(n,)`` bool: the point lies under one of the triangles (xy projection)."""
    c = vertices[triangles][:, :, :2]
    a, b, d = c[:, 0], c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    det = b[:, 0] * d[:, 1] - b[:, 1] * d[:, 0]
    rel = points_xy[:, None, :] - a[None]
    u = (rel[..., 0] * d[:, 1] - rel[..., 1] * d[:, 0]) / det
    w = (b[:, 0] * rel[..., 1] - b[:, 1] * rel[..., 0]) / det
    return np.any((u >= -1e-12) & (w >= -1e-12) & (u + w <= 1 + 1e-12), axis=1)


def test_hole_reopened_and_surface_kept(hole):
    sample, got = hole
    lo, hi = 0.35, 0.65
    pts, w = triangle_samples(got.vertices, got.triangles, 0.01)
    inside = np.all((pts[:, :2] > lo) & (pts[:, :2] < hi), axis=1)
    left = float(w[inside].sum()) / (hi - lo) ** 2  # the input grid covers the hole once
    assert left <= 0.2, left
    truth = sample.truth.sample(3000, np.random.default_rng(0))
    kept = covered(truth[:, :2], got.vertices, got.triangles).mean()
    assert kept >= 0.95, kept
    # the measure itself: the unfiltered input covers the whole truth
    assert covered(truth[:, :2], sample.mesh.vertices, sample.mesh.triangles).all()


def test_result_fields(hole):
    sample, got = hole
    assert got.vertices.shape == sample.mesh.vertices.shape
    np.testing.assert_array_equal(got.triangles, sample.mesh.triangles[got.keep])
    assert np.all(np.diff(got.sorted_density) <= 0)
    assert got.triangle_mass.sum() == pytest.approx(len(sample.points), rel=1e-9)  # unit masses, all on faces
    assert got.cost_after <= got.cost_before
    assert [p.cost_before for p in got.passes[1:]] == [p.cost_after for p in got.passes[:-1]]


# ----------------------------------------------------------------- colouring
@st.composite
def small_meshes(draw):
    n = draw(st.integers(4, 30))
    seed = draw(st.integers(0, 2**31 - 1))
    rng = np.random.default_rng(seed)
    tri = np.sort(rng.integers(0, n, (draw(st.integers(1, 3 * n)), 3)), axis=1)
    tri = tri[(tri[:, 0] < tri[:, 1]) & (tri[:, 1] < tri[:, 2])]
    order = rng.permutation(n)
    return n, tri, order


@settings(max_examples=120, deadline=None)
@given(small_meshes())
def test_colouring_separates_closed_stars(mesh):
    n, tri, order = mesh
    classes = star_colouring(tri, n, order)
    assert sorted(np.concatenate(classes).tolist()) == list(range(n))  # every vertex once
    rank = np.argsort(order)
    assert all(np.all(np.diff(rank[c]) > 0) for c in classes)  # each class in the given order
    closed = [{v} for v in range(n)]
    for t in tri.tolist():  # a closed star's vertices: the vertex and those sharing a face
        for v in t:
            closed[v].update(t)
    for c in classes:
        members = c.tolist()
        for i, u in enumerate(members):
            for v in members[i + 1:]:
                assert not closed[u] & closed[v], (u, v)


# ------------------------------------------------------- passes, determinism
@pytest.mark.parametrize("order", ["colouring", "sequential"])
def test_cost_never_rises_over_a_pass(order):
    sample = rounded_box(400, noise=0.005, seed=5, resolution=3)
    given_ = validate_input(sample.points, sample.mesh.vertices, sample.mesh.triangles)
    with jax.enable_x64(True):
        plan, _ = initial_plan(given_.vertices, given_.triangles, given_.points, given_.masses, "exact", 0)
        for k in range(2):
            s = relocation_pass(plan, "exact", order, np.random.default_rng(k))
            assert s.cost_after <= s.cost_before * (1 + 1e-12)
            assert s.cost_after == pytest.approx(plan.total_cost(), rel=1e-12)
            assert s.accepted > 0
    n = plan.n_vertices
    assert s.calls == n if order == "sequential" else s.calls < n


def test_seeded_runs_are_identical_and_seeds_differ():
    sample = rounded_box(300, noise=0.005, seed=6, resolution=3)
    args = (sample.points, sample.mesh)
    a = recover_features(*args, passes=1, solver="exact", seed=1)
    b = recover_features(*args, passes=1, solver="exact", seed=1)
    c = recover_features(*args, passes=1, solver="exact", seed=2)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    assert not np.array_equal(a.vertices, c.vertices)


# ----------------------------------------------------------------- bad input
def square():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    t = np.array([[0, 1, 2], [0, 2, 3]])
    p = np.random.default_rng(0).random((50, 3)) * [1, 1, 0.01]
    return p, v, t


@pytest.mark.parametrize("change, message", [
    (lambda p, v, t: (p[:, :2], v, t), r"points must have shape \(N, 3\)"),
    (lambda p, v, t: (p, v[:, :2], t), r"vertices must have shape \(V, 3\)"),
    (lambda p, v, t: (np.where(np.arange(len(p))[:, None] == 3, np.nan, p), v, t), "finite|NaN"),
    (lambda p, v, t: (p, np.where(np.arange(4)[:, None] == 1, np.inf, v), t), "vertices must be finite"),
    (lambda p, v, t: (p, v, np.zeros((0, 3), int)), "no faces"),
    (lambda p, v, t: (p, v, t[:, :2]), r"triangles must have shape \(T, 3\)"),
    (lambda p, v, t: (p, v, np.array([[0, 1, 4], [0, 2, 3]])), "indexes outside"),
    (lambda p, v, t: (p, v, np.array([[0, 1, 1], [0, 2, 3]])), "repeats a vertex"),
    (lambda p, v, t: (p, np.vstack([v, [2, 0, 0]]), np.array([[0, 1, 4], [0, 2, 3]])), "zero area"),
    (lambda p, v, t: (p, v, np.array([[0, 1, 2], [2, 1, 0]])), "more than once"),
    (lambda p, v, t: (p, v, t + 0.5), "integer"),
    (lambda p, v, t: (p * 100, v, t), "different scales"),
    (lambda p, v, t: (p + [5, 0, 0], v, t), "far from the mesh"),
])
def test_bad_input_is_named(change, message):
    with pytest.raises(ValueError, match=message):
        p, v, t = change(*square())
        recover_features(p, (v, t), passes=0, solver="exact")


@pytest.mark.parametrize("option, message", [
    ({"order": "random"}, "order must be"), ({"passes": -1}, "passes must be"),
    ({"solver": "simplex"}, "solver must be"), ({"density_threshold": -1.0}, "threshold"),
])
def test_bad_options_are_named(option, message):
    with pytest.raises(ValueError, match=message):
        p, v, t = square()
        recover_features(p, (v, t), **option)


# ------------------------------------------------------ the plan as arrays
@pytest.fixture(scope="module")
def relaxed_box():
    sample = rounded_box(600, noise=0.005, seed=7, resolution=4)
    given_ = validate_input(sample.points, sample.mesh.vertices, sample.mesh.triangles)
    with jax.enable_x64(True):
        plan, _ = initial_plan(given_.vertices, given_.triangles, given_.points, given_.masses, "exact", 0)
    return plan


def test_cut_matches_the_reference_stencils(relaxed_box):
    plan = relaxed_box
    reference = surface_plan(plan)
    centres = star_colouring(plan.bins.keys, plan.n_vertices, np.arange(plan.n_vertices))[0]
    batch = plan.cut(plan.stars, centres)
    for b, v in enumerate(centres.tolist()):
        c = reference.complex
        s = reference.stencil(c.vertex_closure(v).vertices, c.star(v).triangles)
        p, k = len(s.points), len(s.lp.capacity)
        assert (batch.n_points[b], batch.n_bins[b]) == (p, k)
        np.testing.assert_array_equal(batch.point[b, :p], s.points)
        np.testing.assert_allclose(batch.mass[b, :p], s.lp.mass, rtol=1e-12)
        np.testing.assert_allclose(batch.cost[b, :p, :k], s.lp.cost, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(batch.simplex[b, :k], s.lp.simplex)
        np.testing.assert_array_equal(batch.is_vertex[b, :k], s.lp.is_vertex)
        assert batch.current[b] == pytest.approx(s.cost, rel=1e-12)
        assert batch.lower[b] <= batch.current[b] * (1 + 1e-12)
    assert plan.total_cost() == pytest.approx(reference.total_cost(), rel=1e-12)
    np.testing.assert_allclose(reference.point_mass(), plan.masses, rtol=1e-12)


def test_targets_match_the_reference(relaxed_box):
    from otjax.surfaces.relocation import relocation_targets
    plan = relaxed_box
    centres = star_colouring(plan.bins.keys, plan.n_vertices, np.arange(plan.n_vertices))[1]
    with jax.enable_x64(True):
        want = relocation_targets(surface_plan(plan), centres.tolist())
    np.testing.assert_allclose(plan.targets(centres), want, rtol=1e-10, atol=1e-12)


def test_batched_and_exact_solves_agree(relaxed_box):
    from otjax.surfaces.star_passes import solve_stars
    plan = relaxed_box
    rng = np.random.default_rng(0)
    plan.positions = plan.positions + rng.normal(scale=0.01, size=plan.positions.shape)  # stars to improve
    centres = star_colouring(plan.bins.keys, plan.n_vertices, rng.permutation(plan.n_vertices))[0]
    batch = plan.cut(plan.stars, centres, 64, 32)
    with jax.enable_x64(True):
        exact, batched = solve_stars(batch, "exact"), solve_stars(batch, "batched")
    assert exact.better.sum() > 0 and exact.solved > exact.closed_form
    for got in (exact, batched):
        assert np.all(got.cost <= batch.current)
        sent = got.plan.sum(axis=2)
        np.testing.assert_allclose(sent[got.better], batch.mass[got.better], rtol=1e-9)  # every point's mass
    # the batched solver is certified within 1e-3 of the optimum (NewtonOptions.rtol)
    both = exact.better & batched.better
    assert both.sum() >= 0.9 * exact.better.sum()
    np.testing.assert_array_less(batched.cost[both], exact.cost[both] * (1 + 2e-3))


# ----------------------------------------------------------- top-level call
def test_top_level_call_gives_a_surface_result(capsys):
    import otjax
    from otjax.surfaces import SurfaceResult
    box = rounded_box(300, noise=0.005, seed=8, resolution=3)
    result = otjax.recover_features(box.points, box.mesh, passes=1, solver="exact", progress=True)
    assert isinstance(result, SurfaceResult)
    run = result.stats
    np.testing.assert_array_equal(result.triangles, box.mesh.triangles[run.keep])
    np.testing.assert_array_equal(result.vertices, run.vertices)
    assert result.total_cost == run.cost_after and result.params["passes"] == 1
    assert "feature recovery" in capsys.readouterr().err  # the progress bar
    pair = otjax.recover_features(box.points, (box.mesh.vertices, box.mesh.triangles), passes=1,
                                  solver="exact")
    np.testing.assert_array_equal(pair.vertices, result.vertices)
    assert capsys.readouterr().err == ""
    with pytest.raises(ValueError, match="mesh must have vertices and triangles"):
        otjax.recover_features(box.points, box.mesh.vertices)
    # one public entry, the same object at both levels
    assert otjax.recover_features is otjax.surfaces.recover_features
    assert not any(hasattr(m, "recover_mesh_features") for m in (otjax, otjax.surfaces))
