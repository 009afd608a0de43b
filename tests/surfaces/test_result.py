"""SurfaceResult: construction checks, JSON round trip against the shipped
schema, mesh files read back, all-or-nothing saving, filtering, plots."""

import json
import os

import jsonschema
import matplotlib
import numpy as np
import pytest

from otjax.datasets3d import cube_truth
from otjax.io3d import read_mesh
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.plan import BinSettings, SurfacePlan
from otjax.surfaces.plot import plan_segments, plot_complex
from otjax.surfaces.result import SurfaceResult, json_schema
from tests.fuzz.strategies import listing

matplotlib.use("Agg")


def cube_result(**fields):
    """The unit cube's 12 facets, two of them light, a dangling edge, an isolated vertex."""
    m = cube_truth().mesh
    vertices = np.concatenate([m.vertices, [[2.0, 2.0, 2.0], [3.0, 2.0, 2.0], [0.1, 0.2, 0.3]]])
    mass = np.linspace(1.0, 2.0, 12)
    mass[[0, 5]] = 0.01
    base = {"vertices": vertices, "triangles": m.triangles, "triangle_mass": mass, "edges": [[8, 9]],
            "isolated": [10], "vertex_mass": np.r_[np.zeros(8), 0.0, 0.0, 0.5], "total_cost": 0.125,
            "params": {"n_vertices": np.int64(11), "name": "cube", "tol": np.float32(0.5)}, "seconds": 1.5}
    return SurfaceResult.from_arrays(**{**base, **fields})


def test_json_round_trip_is_exact_and_follows_the_schema(tmp_path):
    r = cube_result()
    r.save(tmp_path / "r.json")
    data = json.loads((tmp_path / "r.json").read_text())
    jsonschema.validate(data, json_schema())
    back = SurfaceResult.load(tmp_path / "r.json")
    for name in ("vertices", "triangles", "edges", "isolated", "triangle_mass", "vertex_mass", "triangle_density"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
        assert getattr(back, name).dtype == getattr(r, name).dtype
    assert (back.total_cost, back.seconds) == (0.125, 1.5)
    assert back.params == {"n_vertices": 11, "name": "cube", "tol": 0.5}
    assert back.to_dict() == data
    np.testing.assert_allclose(r.triangle_density, r.triangle_mass / 0.5)  # every cube facet has area 1/2


def test_schema_accepts_unknown_vertex_masses_and_is_shipped():
    r = cube_result(vertex_mass=None)
    jsonschema.validate(r.to_dict(), json_schema())
    assert SurfaceResult.from_dict(r.to_dict()).vertex_mass is None
    schema = json_schema()
    assert schema["required"] == list(r.to_dict())
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**r.to_dict(), "triangle_mass": [-1.0] * 12}, schema)


@pytest.mark.parametrize("change, message", [
    (lambda d: d.pop("triangles"), "missing key"),
    (lambda d: d.update(extra=1), "unknown key"),
    (lambda d: d.update(triangles=[[0, 1, 99]] * 12), "out of range"),
    (lambda d: d.update(triangles=[[0, 1, 1]] * 12), "three different"),
    (lambda d: d.update(triangle_mass=[1.0] * 11), "triangle_mass must have shape"),
    (lambda d: d.update(triangle_density=[5.0] * 12), "does not match"),
    (lambda d: d.update(vertex_mass=[-1.0] * 11), "vertex_mass must be >= 0"),
    (lambda d: d.update(total_cost=float("nan")), "total_cost"),
    (lambda d: d.update(vertices=[[0, 0]] * 11), "vertices must have shape"),
])
def test_malformed_dicts_are_value_errors(change, message):
    d = cube_result().to_dict()
    change(d)
    with pytest.raises(ValueError, match=message):
        SurfaceResult.from_dict(d)


def test_load_errors_name_the_file(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text("{")
    with pytest.raises(ValueError, match="not valid JSON") as err:
        SurfaceResult.load(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("ext", [".ply", ".obj", ".off"])
def test_mesh_files_read_back_the_same_arrays(tmp_path, ext):
    r = cube_result()
    r.vertices[0] = [0.1, 1 / 3, 2.0**-40]  # digits a short decimal would lose
    r.save(tmp_path / f"r{ext}")
    mesh = read_mesh(tmp_path / f"r{ext}")
    np.testing.assert_array_equal(mesh.vertices, r.vertices)
    np.testing.assert_array_equal(mesh.triangles, r.triangles)
    np.testing.assert_array_equal(mesh.edges, r.edges if ext != ".off" else np.zeros((0, 2)))


def test_ply_carries_the_masses_and_densities(tmp_path):
    from plyfile import PlyData

    r = cube_result()
    r.save(tmp_path / "r.ply")
    ply = PlyData.read(str(tmp_path / "r.ply"))
    np.testing.assert_array_equal(ply["face"]["mass"], r.triangle_mass)
    np.testing.assert_array_equal(ply["face"]["density"], r.triangle_density)
    np.testing.assert_array_equal(ply["vertex"]["mass"], r.vertex_mass)


def test_same_result_gives_the_same_bytes(tmp_path):
    names = ["r.json", "r.ply", "r.obj", "r.off"]
    for d in ("a", "b"):
        cube_result().save(*(tmp_path / d / n for n in names), mkdir=True)
    for n in names:
        assert (tmp_path / "a" / n).read_bytes() == (tmp_path / "b" / n).read_bytes()


@pytest.mark.parametrize("paths, message", [
    (["ok.json", "bad.xyz"], "unknown output extension"),
    (["ok.json", "missing/r.ply"], "does not exist"),
    (["ok.json", "ok.json"], "given twice"),
    (["ok.json", "dir"], "existing directory|unknown output extension"),
])
def test_bad_paths_fail_before_anything_is_written(tmp_path, paths, message):
    (tmp_path / "dir").mkdir()
    before = listing(tmp_path)
    with pytest.raises(ValueError, match=message):
        cube_result().save(*(tmp_path / p for p in paths))
    assert listing(tmp_path) == before


def test_unserialisable_params_leave_nothing(tmp_path):
    r = cube_result(params={"f": object()})
    with pytest.raises(ValueError, match="not JSON-serialisable"):
        r.save(tmp_path / "a.ply", tmp_path / "b.json")
    assert os.listdir(tmp_path) == []


def test_filtered_drops_light_facets_and_keeps_the_rest():
    r = cube_result()
    f = r.filtered(0.5)
    assert len(f.triangles) == 10 and f.params["threshold"] == 0.5
    np.testing.assert_array_equal(f.triangle_mass, np.delete(r.triangle_mass, [0, 5]))
    assert len(f.edges) == 1 and len(f.isolated) == 1
    np.testing.assert_array_equal(f.vertices[f.isolated], r.vertices[r.isolated])
    mean = r.triangle_mass.sum() / 6.0  # the cube's area
    assert np.all(np.diff(r.sorted_density) <= 0) and r.sorted_density[-1] == pytest.approx(0.01 / 0.5 / mean)
    assert len(r.filtered(0.0).triangles) == 12
    with pytest.raises(ValueError, match="threshold"):
        r.filtered(-1)


def test_plot_draws_facets_points_plan_and_highlights():
    r = cube_result(points=np.random.default_rng(0).random((50, 3)), masses=np.ones(50))
    ax = r.plot(highlight=[[0, 1]])
    assert ax.name == "3d"
    labels = [c.get_label() for c in ax.collections]
    assert {"facets", "edges", "highlighted edges", "input points", "isolated"} <= set(labels)
    facets = ax.collections[labels.index("facets")]
    colours = facets.get_facecolor()
    assert len(colours) == 12 and not np.allclose(colours[0], colours[11])  # coloured by density
    matplotlib.pyplot.close("all")


def test_plan_segments_join_points_to_their_bins():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], float)
    c = SimplicialComplex(v, np.array([[0, 1, 2], [1, 2, 3]]))
    rng = np.random.default_rng(1)
    points = np.c_[rng.random((30, 2)), np.zeros(30)]
    plan = SurfacePlan(c, points, np.ones(30), BinSettings(diagonal=2.0))
    # Move some mass onto a facet bin: a stencil's plan sending each point to its nearest bin.
    st = plan.stencil([0, 1, 2], [(0, 1, 2)])
    lp = st.lp
    send = np.zeros_like(lp.cost)
    send[np.arange(len(lp.mass)), np.argmin(lp.cost, axis=1)] = lp.mass
    plan.assign(st, send)
    segs, to_vertex = plan_segments(plan)
    n_entries = sum(len(e.point) for e in plan.vertex_entries.values()) + \
        sum(len(e.point) for e in plan.facet_entries.values())
    assert len(segs) == n_entries and to_vertex.sum() == sum(len(e.point) for e in plan.vertex_entries.values())
    assert (~to_vertex).any()
    np.testing.assert_array_equal(np.sort(segs[:, 0], axis=0), np.sort(points[np.concatenate(
        [e.point for e in plan.vertex_entries.values()] + [e.point for e in plan.facet_entries.values()])], axis=0))
    ends = segs[to_vertex, 1]
    assert np.all(np.any(np.all(ends[:, None] == v[None], axis=2), axis=1))  # vertex segments end on vertices
    ax = plot_complex(v, [[0, 1, 2], [1, 2, 3]], points=points, plan=plan)
    assert "transport plan" in [c.get_label() for c in ax.collections]
    matplotlib.pyplot.close("all")
