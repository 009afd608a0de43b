"""``otjax surface`` and ``otjax recover``, in process: bad input is one error line,
exit 1 and no file; small built-in examples write files that read back."""

import json

import jsonschema
import numpy as np
import pytest

from otjax.cli import main
from otjax.io3d import read_mesh
from otjax.surfaces.result import SurfaceResult, json_schema


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("otjax: error: "), err
    return lines[0]


def listing(root):
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*"))


@pytest.fixture
def files(tmp_path):
    rng = np.random.default_rng(3)
    good = tmp_path / "pts.xyz"
    np.savetxt(good, np.c_[rng.random((200, 2)), np.zeros(200)])
    nan = tmp_path / "nan.xyz"
    nan.write_text("0 0 0\n1 0 0\nnan 1 0\n0 1 1\n")
    empty_mesh = tmp_path / "empty.off"
    empty_mesh.write_text("OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n")
    far_mesh = tmp_path / "far.off"
    far_mesh.write_text("OFF\n3 1 0\n1000 0 0\n1001 0 0\n1000 1 0\n3 0 1 2\n")
    big_mesh = tmp_path / "big.off"
    big_mesh.write_text("OFF\n3 1 0\n0 0 0\n1000 0 0\n0 1000 0\n3 0 1 2\n")
    return tmp_path


@pytest.mark.parametrize("argv, says", [
    (["surface", "{d}/missing.xyz", "-n", "8"], "missing.xyz"),
    (["surface", "{d}/nan.xyz", "-n", "4"], "nan"),
    (["surface", "{d}/pts.xyz", "-n", "8", "-o", "{d}/out.stl"], "extension"),
    (["surface", "{d}/pts.xyz", "-n", "8", "-o", "{d}/no/out.ply"], "does not exist"),
    (["surface", "{d}/pts.xyz", "-n", "8", "-o", "{d}/a.ply", "-o", "{d}/a.ply"], "twice"),
    (["surface", "{d}/pts.xyz", "-n", "100000"], "n_vertices"),
    (["surface", "--example", "cube", "--points", "10"], "--points"),
    (["surface", "{d}/pts.xyz", "-n", "8", "-o", "{d}/a.ply", "--bin-density", "0"], "bin_density"),
    (["surface", "{d}/pts.xyz", "-n", "8", "-o", "{d}/a.ply", "--final-density-factor", "0.5"],
     "final_density_factor"),
    (["recover", "{d}/pts.xyz", "{d}/empty.off"], "face"),
    (["recover", "{d}/pts.xyz", "{d}/far.off", "-o", "{d}/r.ply"], "far from the mesh"),
    (["recover", "{d}/pts.xyz", "{d}/big.off", "-o", "{d}/r.ply"], "different scales"),
    (["recover", "{d}/pts.xyz", "{d}/pts.xyz"], "extension"),
])
def test_bad_input_is_one_line_exit_1_and_no_file(files, capsys, argv, says):
    before = listing(files)
    assert main([a.format(d=files) for a in argv]) == 1
    assert says.lower() in one_error_line(capsys).lower()
    assert listing(files) == before


def test_surface_example_writes_files_that_read_back(tmp_path, capsys):
    # The smallest example the command accepts: writing and reading back do not depend on its size.
    argv = ["surface", "--example", "crossing", "--points", "100", "-n", "10", "--solver", "exact", "--quiet"]
    assert main(argv + ["-o", str(tmp_path / "a.json"), "-o", str(tmp_path / "a.ply")]) == 0
    data = json.loads((tmp_path / "a.json").read_text())
    jsonschema.validate(data, json_schema())
    assert data["params"]["bin_density"] == 150 and data["params"]["final_density_factor"] == 4
    result = SurfaceResult.from_dict(data)
    assert len(result.vertices) >= 10 and 0 < result.triangle_mass.sum() <= 100 * (1 + 1e-9)
    mesh = read_mesh(tmp_path / "a.ply")
    np.testing.assert_array_equal(mesh.vertices, result.vertices)
    np.testing.assert_array_equal(mesh.triangles, result.triangles)
    assert capsys.readouterr().out == ""


def test_recover_example_drops_the_facets_over_the_hole(tmp_path, capsys):
    out = tmp_path / "r.obj"
    assert main(["recover", "--example", "holed_square", "--points", "400", "--passes", "1", "--solver", "exact",
                 "-o", str(out)]) == 0
    mesh = read_mesh(out)
    centroids = mesh.vertices[mesh.triangles].mean(1)
    inside = np.all((centroids[:, :2] > 0.4) & (centroids[:, :2] < 0.6), axis=1)  # well inside the hole
    assert len(mesh.triangles) < 16 * 16 * 2 and not inside.any()
    assert "wrote" in capsys.readouterr().out
