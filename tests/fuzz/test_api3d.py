"""Fuzzing the surface entry points, reconstruct_surface and recover_features:
malformed and extreme points, masses, meshes and parameters give one
ValueError naming the problem, or pass validation with canonical input that
is finite and inside the canonical frame; never another exception, never a
warning. A spy stands in for the first step after validation; a few tiny
inputs run reconstruct_surface to the end."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import otjax.surfaces.features as features_module
import otjax.surfaces.reconstruct as reconstruct_module
from otjax.surfaces.features import recover_features
from otjax.surfaces.reconstruct import reconstruct_surface
from tests.fuzz.strategies import warnings_are_errors
from tests.profiles import examples

EXTREMES = [0.0, -0.0, 1.0, 1e-300, 5e-324, 1e300, 1.7976931348623157e308, 2.0**-1000, 1e12 + 0.5, float("nan"),
            float("inf"), float("-inf")]
coordinate = st.one_of(st.floats(width=64), st.sampled_from(EXTREMES), st.integers(-3, 3).map(float))
finite = st.one_of(st.floats(-10, 10), st.sampled_from([x for x in EXTREMES if np.isfinite(x)]),
                   st.integers(-3, 3).map(float))


class Validated(Exception):
    """Raised by the spy in place of the run: validation passed."""


@st.composite
def point_arrays(draw, dim=3):
    """Mostly ``(n, 3)`` floats; also flat, collinear, wrong-shaped, non-numeric arrays."""
    kind = draw(st.sampled_from(["finite"] * 5 + ["floats", "plane", "line", "shape", "dtype"]))
    n = draw(st.integers(0, 30))
    if kind in ("finite", "floats"):
        c = finite if kind == "finite" else coordinate
        return np.array(draw(st.lists(st.tuples(c, c, c), min_size=n, max_size=n)), np.float64).reshape(-1, 3)
    if kind in ("plane", "line"):
        t = np.array(draw(st.lists(st.integers(-20, 20), min_size=2 * n, max_size=2 * n)), np.float64).reshape(-1, 2)
        scale = draw(st.sampled_from([1.0, 2.0**-900, 2.0**900, 1e-7]))
        z = np.zeros(n) if kind == "plane" else t[:, 0]
        return scale * np.stack([t[:, 0], t[:, 1] if kind == "plane" else -t[:, 0], z], 1)
    if kind == "shape":
        shape = draw(st.sampled_from([(n,), (n, 2), (n, 4), (n, 3, 1), (0, 3), ()]))
        return np.ones(shape) * draw(finite)
    return np.array(draw(st.sampled_from([[["a", "b", "c"]], [[1, 2, None]], [[True, False, True]]])), dtype=object)


masses_of = st.one_of(st.none(), st.sampled_from(["ones", "negative", "nan", "zero", "short", "tiny", "huge"]))


def make_masses(kind, points):
    n = np.shape(points)[0] if np.ndim(points) else 1
    if kind is None:
        return None
    values = {"ones": np.ones(n), "negative": -np.ones(n), "nan": np.full(n, np.nan), "zero": np.zeros(n),
              "short": np.ones(max(n - 1, 0)), "tiny": np.full(n, 5e-324), "huge": np.full(n, 1e308)}
    return values[kind]


def spy(name):
    def run(*args, **kwargs):
        points = args[2] if name == "initial_plan" else args[0]
        assert np.isfinite(points).all() and np.abs(points).max() <= 1.0  # canonical frame
        raise Validated
    return run


@settings(max_examples=examples(300, 3000), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(points=point_arrays(), masses=masses_of,
       n_vertices=st.one_of(st.integers(-2, 40), st.sampled_from([True, 4.5, 10**30, "10", None])),
       queue=st.sampled_from(["multiple-choice", "exhaustive", "parallel", "fifo", None]),
       choices=st.one_of(st.integers(-1, 50), st.just(2.5)), fraction=st.sampled_from([0.15, 0.0, 1.0, 2.0, -0.1, np.nan]),
       solver=st.sampled_from(["batched", "exact", "auto", ""]),
       seed=st.one_of(st.integers(-5, 2**70), st.sampled_from([1.5, None, "0"])),
       final_density_factor=st.sampled_from([4.0, 1, 0.5, np.nan, np.inf, "2", None]))
def test_reconstruct_surface_validates_or_names_the_problem(monkeypatch, points, masses, n_vertices, queue, choices,
                                                             fraction, solver, seed, final_density_factor):
    monkeypatch.setattr(reconstruct_module, "initial_complex", spy("initial_complex"))
    try:
        with warnings_are_errors():
            reconstruct_surface(points, make_masses(masses, points), n_vertices, queue=queue, choices=choices,
                                fraction=fraction, solver=solver, seed=seed,
                                final_density_factor=final_density_factor)
    except ValueError as err:
        assert str(err).strip()
    except Validated:
        pass


@st.composite
def meshes(draw):
    """A triangulated square grid (sometimes broken: bad indices, repeated or degenerate faces, no faces)."""
    k = draw(st.integers(2, 4))
    g = np.stack(np.meshgrid(np.arange(k), np.arange(k)), -1).reshape(-1, 2) / (k - 1)
    vertices = np.column_stack([g, np.zeros(len(g))])
    quads = [(i * k + j, i * k + j + 1, (i + 1) * k + j, (i + 1) * k + j + 1) for i in range(k - 1) for j in range(k - 1)]
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, d), (a, d, c))], np.int64)
    flaw = draw(st.sampled_from([None] * 4 + ["index", "repeat", "degenerate", "empty", "float", "nan", "scale"]))
    if flaw == "index":
        triangles[0, 0] = draw(st.sampled_from([-1, len(vertices), 10**12]))
    elif flaw == "repeat":
        triangles = np.concatenate([triangles, triangles[:1]])
    elif flaw == "degenerate":
        triangles[0] = [0, 0, 1]
    elif flaw == "empty":
        triangles = np.zeros((0, 3), np.int64)
    elif flaw == "float":
        triangles = triangles + 0.5
    elif flaw == "nan":
        vertices[0, 2] = np.nan
    elif flaw == "scale":
        vertices = vertices * 1e6
    return vertices, triangles


@settings(max_examples=examples(300, 3000), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(points=point_arrays(), mesh=meshes(), masses=masses_of,
       passes=st.one_of(st.integers(-1, 5), st.sampled_from([True, 1.5, None])),
       order=st.sampled_from(["colouring", "sequential", "random"]),
       threshold=st.sampled_from([0.1, 0.0, -1.0, np.nan, np.inf, "0.1"]),
       seed=st.one_of(st.integers(-5, 2**70), st.sampled_from([1.5, None, "0"])))
def test_recover_features_validates_or_names_the_problem(monkeypatch, points, mesh, masses, passes, order, threshold,
                                                         seed):
    monkeypatch.setattr(features_module, "initial_plan", spy("initial_plan"))
    vertices, triangles = mesh
    try:
        with warnings_are_errors():
            recover_features(points, (vertices, triangles), make_masses(masses, points), passes=passes,
                             order=order, density_threshold=threshold, seed=seed)
    except ValueError as err:
        assert str(err).strip()
    except Validated:
        pass


@settings(max_examples=examples(6, 60), deadline=None)
@given(seed=st.integers(0, 2**16), n=st.integers(8, 40), flat=st.booleans(), n_vertices=st.integers(4, 6))
def test_tiny_point_sets_run_to_a_sound_surface(seed, n, flat, n_vertices):
    rng = np.random.default_rng(seed)
    points = rng.random((n, 3)) * ([1, 1, 0] if flat else 1)
    try:
        with warnings_are_errors():
            r = reconstruct_surface(points, n_vertices=n_vertices, solver="exact", fraction=1.0, seed=seed)
    except ValueError as err:  # e.g. fewer initial vertices than asked
        assert "n_vertices" in str(err)
        return
    # Never below the target; above it only when every remaining collapse is inadmissible.
    assert np.isfinite(r.vertices).all() and len(r.vertices) >= n_vertices
    lo, hi = points.min(0), points.max(0)
    assert np.all(r.vertices >= lo - (hi - lo)) and np.all(r.vertices <= hi + (hi - lo))  # no box corner
    if len(r.triangles):
        assert np.all(r.triangle_area > 0)
    assert np.isfinite(r.total_cost) and r.total_cost >= 0
    assert r.triangle_mass.sum() <= n * (1 + 1e-9) and np.all(r.triangle_mass >= 0)
    for rows in (r.triangles, r.edges, r.isolated):
        assert rows.size == 0 or (rows.min() >= 0 and rows.max() < len(r.vertices))
