"""CurveResult: JSON (against the shipped schema), SVG, PNG, validation."""

import json
import os
import xml.etree.ElementTree as ET

import jsonschema
import matplotlib
import numpy as np
import pytest

from otjax.curves.result import JSON_KEYS, CurveResult, json_schema

SVG = "{http://www.w3.org/2000/svg}"


def make_result(rng, k=6, with_points=True):
    """A square-ish loop over ``k - 1`` vertices plus one isolated vertex."""
    angle = np.linspace(0, 2 * np.pi, k - 1, endpoint=False)
    vertices = np.vstack([np.stack([np.cos(angle), np.sin(angle)], 1), [[3.0, 3.0]]])
    edges = np.stack([np.arange(k - 1), (np.arange(k - 1) + 1) % (k - 1)], 1)
    return CurveResult(
        vertices=vertices,
        edges=edges,
        isolated=np.array([k - 1]),
        edge_mass=rng.random(k - 1),
        edge_relevance=rng.random(k - 1) * 100,
        total_cost=np.float64(0.125),
        params={"n_vertices": np.int64(k), "tolerance": None, "relevance": np.float32(0.5), "seed": 3},
        seconds=1.5,
        points=rng.standard_normal((40, 2)) if with_points else None,
    )


def test_json_has_exactly_the_design_keys_and_plain_types(rng):
    d = make_result(rng).to_dict()
    assert (
        set(d)
        == set(JSON_KEYS)
        == {"vertices", "edges", "isolated", "edge_mass", "edge_relevance", "total_cost", "params", "seconds"}
    )
    text = json.dumps(d, allow_nan=False)  # would fail on NumPy types
    assert json.loads(text)["params"] == {"n_vertices": 6, "tolerance": None, "relevance": 0.5, "seed": 3}


def test_save_json_validates_against_schema_and_round_trips(tmp_path, rng):
    r = make_result(rng)
    path = tmp_path / "out" / "r.json"
    r.save(path)
    d = json.loads(path.read_text())
    jsonschema.validate(d, json_schema())
    back = CurveResult.load(path)
    for name in ("vertices", "edges", "isolated", "edge_mass", "edge_relevance"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
        assert getattr(back, name).dtype == getattr(r, name).dtype
    assert back.total_cost == r.total_cost and back.seconds == r.seconds
    assert back.points is None  # inputs are not saved
    assert os.listdir(path.parent) == ["r.json"]


def test_empty_result_round_trips(tmp_path):
    r = CurveResult(
        vertices=[[0.0, 1.0]],
        edges=[],
        isolated=[0],
        edge_mass=[],
        edge_relevance=[],
        total_cost=0.0,
        params={},
        seconds=0.0,
    )
    assert r.edges.shape == (0, 2) and r.edges.dtype == np.int64
    r.save(tmp_path / "r.json")
    jsonschema.validate(json.loads((tmp_path / "r.json").read_text()), json_schema())
    back = CurveResult.load(tmp_path / "r.json")
    assert back.edges.shape == (0, 2) and back.isolated.tolist() == [0]


def test_schema_rejects_what_it_should(rng):
    schema = json_schema()
    good = make_result(rng).to_dict()
    jsonschema.validate(good, schema)
    for bad in (
        {k: v for k, v in good.items() if k != "edges"},
        dict(good, extra=1),
        dict(good, edges=[[0, 1.5]]),
        dict(good, vertices=[[0.0, 1.0, 2.0]]),
        dict(good, total_cost=-1.0),
        dict(good, isolated=[-1]),
    ):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)


def test_svg_is_xml_with_one_line_per_edge(tmp_path, rng):
    r = make_result(rng)
    path = tmp_path / "r.svg"
    r.save(path)
    root = ET.parse(path).getroot()
    assert root.tag == f"{SVG}svg"
    lines = root.findall(f".//{SVG}line")
    assert len(lines) == len(r.edges)
    vertices = root.find(f".//{SVG}g[@id='vertices']")
    assert len(vertices) == len(r.vertices) - len(r.isolated)
    assert len(root.find(f".//{SVG}g[@id='isolated']")) == len(r.isolated)
    assert len(root.find(f".//{SVG}g[@id='points']")) == len(r.points)
    # Everything drawn lies inside the view box, and y is flipped: the
    # isolated vertex (3, 3), the top-right of the data, is near the top-right.
    _, _, box_w, box_h = map(float, root.get("viewBox").split())
    xs = [float(c.get("cx")) for c in root.iter(f"{SVG}circle")]
    ys = [float(c.get("cy")) for c in root.iter(f"{SVG}circle")]
    assert 0 <= min(xs) and max(xs) <= box_w and 0 <= min(ys) and max(ys) <= box_h
    square = root.find(f".//{SVG}g[@id='isolated']")[0]
    assert float(square.get("y")) < 0.1 * box_h and float(square.get("x")) > 0.8 * box_w


def test_svg_without_points(tmp_path, rng):
    r = make_result(rng, with_points=False)
    root = ET.fromstring(r.to_svg())
    assert root.find(f".//{SVG}g[@id='points']") is None
    assert len(root.findall(f".//{SVG}line")) == len(r.edges)


def test_png_is_a_png(tmp_path, rng):
    path = tmp_path / "r.png"
    make_result(rng).save(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert os.listdir(tmp_path) == ["r.png"]


def test_png_uses_no_pyplot_figure(rng):
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    make_result(rng).to_png()
    assert plt.get_fignums() == before


def test_plot_on_given_axes(rng):
    from matplotlib.figure import Figure

    ax = Figure().add_subplot()
    r = make_result(rng)
    assert r.plot(ax) is ax
    assert len(ax.collections) == 4  # points, edges, vertices, isolated
    assert ax.get_aspect() == 1.0
    ax2 = Figure().add_subplot()
    r.plot(ax2, show_points=False)
    assert len(ax2.collections) == 3


@pytest.mark.parametrize("name", ["r.pdf", "r", "r.json.bak", "r.JSON.txt"])
def test_unknown_extension_raises_before_writing(tmp_path, rng, name):
    with pytest.raises(ValueError, match="unknown output extension"):
        make_result(rng).save(tmp_path / "sub" / name)
    assert not (tmp_path / "sub").exists()


def test_uppercase_extension_is_accepted(tmp_path, rng):
    make_result(rng).save(tmp_path / "R.JSON")
    assert CurveResult.load(tmp_path / "R.JSON").edges.shape == (5, 2)


def test_unserialisable_params_write_nothing(tmp_path, rng):
    r = make_result(rng)
    r.params["bad"] = object()
    with pytest.raises(ValueError, match="bad"):
        r.save(tmp_path / "r.json")
    r.params["bad"] = float("nan")
    with pytest.raises(ValueError, match="JSON"):
        r.save(tmp_path / "r.json")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    ("change", "words"),
    [
        ({"edges": [[0, 1], [1, 9]]}, ["edges", "out of range", "[0, 3)"]),
        ({"edges": [[0, -1], [1, 2]]}, ["edges", "out of range"]),
        ({"edges": [[0, 0], [1, 2]]}, ["different vertices"]),
        ({"edges": [[0, 1.5], [1, 2]]}, ["edges", "integer"]),
        ({"isolated": [3]}, ["isolated", "out of range"]),
        ({"vertices": [[0, 0, 0]]}, ["vertices", "shape"]),
        ({"vertices": [[0, "a"]]}, ["vertices", "numbers"]),
        ({"edge_mass": [1.0]}, ["edge_mass", "(2,)"]),
        ({"edge_relevance": [1.0, 2.0, 3.0]}, ["edge_relevance", "(2,)"]),
        ({"total_cost": "x"}, ["total_cost"]),
        ({"total_cost": -1.0}, ["total_cost", ">= 0"]),
        ({"seconds": None}, ["seconds"]),
        ({"params": []}, ["params", "dict"]),
    ],
)
def test_from_dict_rejects_malformed(change, words):
    d = {
        "vertices": [[0, 0], [1, 0], [0, 1]],
        "edges": [[0, 1], [1, 2]],
        "isolated": [],
        "edge_mass": [1.0, 1.0],
        "edge_relevance": [1.0, 1.0],
        "total_cost": 0.5,
        "params": {},
        "seconds": 1.0,
    }
    CurveResult.from_dict(d)  # the unchanged dict is fine
    with pytest.raises(ValueError) as info:
        CurveResult.from_dict(dict(d, **change))
    for word in words:
        assert word in str(info.value)


def test_from_dict_rejects_missing_and_unknown_keys(rng):
    d = make_result(rng).to_dict()
    with pytest.raises(ValueError, match="missing key.*edge_mass"):
        CurveResult.from_dict({k: v for k, v in d.items() if k != "edge_mass"})
    with pytest.raises(ValueError, match="unknown key.*colour"):
        CurveResult.from_dict(dict(d, colour="red"))
    with pytest.raises(ValueError, match="JSON object"):
        CurveResult.from_dict([1, 2])


def test_load_reports_bad_files(tmp_path):
    with pytest.raises(ValueError, match="cannot read"):
        CurveResult.load(tmp_path / "missing.json")
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: not valid JSON"):
        CurveResult.load(tmp_path / "bad.json")
    (tmp_path / "short.json").write_text('{"vertices": []}')
    with pytest.raises(ValueError, match="short.json: .*missing"):
        CurveResult.load(tmp_path / "short.json")


def test_matplotlib_backend_untouched(rng):
    backend = matplotlib.get_backend()
    make_result(rng).to_png()
    assert matplotlib.get_backend() == backend
