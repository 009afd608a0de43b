"""The ``otjax`` command line, in process (plumbing with a fake reconstruction) and end to end."""

import json
import os
import subprocess
import sys
import types
from fractions import Fraction

import jsonschema
import numpy as np
import pytest

import otjax.cli
from otjax.cli import main
from otjax.curves.result import CurveResult, json_schema
from otjax.io import write_points

SQUARE = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.2]], float)


class FakeReconstruct:
    """Records its calls and returns a small valid result over the first three points."""

    def __init__(self, error=None):
        self.calls = []
        self.error = error

    def __call__(self, points, masses=None, **kwargs):
        self.calls.append((np.asarray(points), masses, kwargs))
        if self.error is not None:
            raise self.error
        return CurveResult(
            vertices=np.asarray(points, float)[:3],
            edges=[[0, 1], [1, 2]],
            isolated=[],
            edge_mass=[1.0, 2.0],
            edge_relevance=[3.0, 4.0],
            total_cost=0.25,
            params={k: v for k, v in kwargs.items() if k != "progress"},
            seconds=0.01,
            points=points,
        )


def fake_datasets(calls):
    def load_example(name, seed=0, n=None):
        calls.append({"name": name, "seed": seed, "n": n})
        count = 7 if n is None else n
        t = np.linspace(0, 2 * np.pi, count, endpoint=False)
        return np.stack([np.cos(t), np.sin(t)], 1), np.ones(count), {}, {"n_vertices": 5, "relevance": 0.25}

    return types.SimpleNamespace(
        EXAMPLES={"ring": "seven points on a ring", "other": "another"}, load_example=load_example
    )


@pytest.fixture
def fake(monkeypatch):
    f = FakeReconstruct()
    monkeypatch.setattr(otjax.cli, "reconstruct_curve", f)
    f.example_calls = []
    monkeypatch.setattr(otjax.cli, "datasets", fake_datasets(f.example_calls))
    return f


@pytest.fixture
def square_file(tmp_path):
    path = tmp_path / "in" / "square.xy"
    write_points(path, SQUARE)
    return path


def one_error_line(capsys):
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("otjax: error: ")
    assert "Traceback" not in err
    return lines[0]


def test_file_input_passes_only_given_options(fake, square_file, capsys):
    assert main(["curve", str(square_file), "-n", "3"]) == 0
    ((points, masses, kwargs),) = fake.calls
    np.testing.assert_array_equal(points, SQUARE)
    assert masses is None
    # Options the user did not give keep the library defaults (not passed at all).
    assert kwargs == {"n_vertices": 3, "progress": True}
    out = capsys.readouterr().out
    assert "3 vertices, 2 edges, 0 isolated" in out and "0.25" in out


def test_every_option_reaches_the_api(fake, square_file, capsys):
    argv = [
        "curve",
        str(square_file),
        "-n",
        "4",
        "--tolerance",
        "0.1",
        "--relevance",
        "2.5",
        "--relocation",
        "7",
        "--final-relocations",
        "3",
        "--refine",
        "--queue",
        "parallel",
        "--choices",
        "9",
        "--initial-vertices",
        "3",
        "--round-fraction",
        "0.2",
        "--seed",
        "11",
        "--merge-duplicates",
        "--keep-chords",
        "--keep-ends",
        "--no-progress",
    ]
    assert main(argv) == 0
    ((_, _, kwargs),) = fake.calls
    assert kwargs == {
        "n_vertices": 4,
        "tolerance": 0.1,
        "relevance": 2.5,
        "relocation": 7,
        "final_relocations": 3,
        "refine": True,
        "queue": "parallel",
        "choices": 9,
        "initial_vertices": 3,
        "round_fraction": 0.2,
        "seed": 11,
        "merge_duplicates": True,
        "chords": False,
        "fit_ends": False,
        "progress": False,
    }


def test_tolerance_alone_is_enough_for_files(fake, square_file):
    assert main(["curve", str(square_file), "--tolerance", "0.5", "--quiet"]) == 0
    assert fake.calls[0][2] == {"tolerance": 0.5, "progress": False}


def test_masses_column_is_passed(fake, tmp_path):
    path = tmp_path / "w.csv"
    write_points(path, SQUARE, np.arange(1.0, 6.0))
    assert main(["curve", str(path), "-n", "3", "--quiet"]) == 0
    np.testing.assert_array_equal(fake.calls[0][1], np.arange(1.0, 6.0))


def test_outputs_are_written(fake, square_file, tmp_path, capsys):
    outs = [tmp_path / "o" / "r.json", tmp_path / "o" / "r.svg", tmp_path / "o" / "r.png"]
    argv = ["curve", str(square_file), "-n", "3", "--mkdir"]
    for o in outs:
        argv += ["-o", str(o)]
    assert main(argv) == 0
    assert sorted(os.listdir(tmp_path / "o")) == ["r.json", "r.png", "r.svg"]
    d = json.loads(outs[0].read_text())
    jsonschema.validate(d, json_schema())
    assert d["params"] == {"n_vertices": 3}
    out = capsys.readouterr().out
    assert all(f"wrote {o}" in out for o in outs)


def test_quiet_prints_nothing(fake, square_file, tmp_path, capsys):
    assert main(["curve", str(square_file), "-n", "3", "--quiet", "-o", str(tmp_path / "r.json")]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert (tmp_path / "r.json").exists()


def test_example_uses_its_defaults_and_options_override(fake):
    assert main(["curve", "--example", "ring", "--quiet"]) == 0
    assert fake.example_calls == [{"name": "ring", "seed": 0, "n": None}]
    assert fake.calls[0][2] == {"n_vertices": 5, "relevance": 0.25, "progress": False}
    assert (
        main(
            [
                "curve",
                "--example",
                "ring",
                "-n",
                "4",
                "--relevance",
                "0",
                "--seed",
                "9",
                "--points",
                "12",
                "--quiet",
            ]
        )
        == 0
    )
    assert fake.example_calls[1] == {"name": "ring", "seed": 9, "n": 12}
    assert len(fake.calls[1][0]) == 12
    assert fake.calls[1][2] == {"n_vertices": 4, "relevance": 0.0, "seed": 9, "progress": False}


def test_example_with_tolerance_stops_by_tolerance(fake):
    assert main(["curve", "--example", "ring", "--tolerance", "0.2", "--quiet"]) == 0
    assert fake.calls[0][2] == {"relevance": 0.25, "tolerance": 0.2, "progress": False}


def test_list_examples(fake, capsys):
    assert main(["curve", "--list-examples"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 2
    assert out[0].split()[0] == "ring" and "seven points on a ring" in out[0]
    assert out[1].split()[0] == "other"
    assert fake.calls == []


def test_list_examples_real_names(capsys):
    from otjax import datasets

    assert main(["curve", "--list-examples"]) == 0
    listed = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert listed == list(datasets.EXAMPLES)


def _write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


# DESIGN.md "Bad input", each through the CLI: exit 1, one error line, no output, no reconstruction.
BAD_FILES = {
    "empty": ("e.xy", "", "no points"),
    "too few": ("f.xy", "0 0\n1 0\n", "at least 3"),
    "nan": ("n.xy", "0 0\n1 0\nnan 1\n", "NaN"),
    "inf": ("i.xy", "0 0\n1 0\n0 inf\n", "NaN or inf"),
    "wrong columns": ("c.xy", "0 0 0 0\n", "columns"),
    "ragged": ("r.xy", "0 0\n1 0 1\n", "columns"),
    "malformed": ("m.xy", "0 0\n1 0\n0 one\n", "m.xy:3"),
    "negative mass": ("neg.xyz", "0 0 1\n1 0 -1\n0 1 1\n", "negative"),
    "zero mass": ("z.xyz", "0 0 0\n1 0 0\n0 1 0\n", "all zero"),
    "duplicates": ("d.xy", "0 0\n1 0\n0 1\n1 0\n", "--merge-duplicates"),
    "coincident": ("o.xy", "2 2\n2 2\n2 2\n", "coincide"),
    "binary": ("b.xy", None, "UTF-8"),
    "unknown extension": ("u.ply2", "0 0\n", "unknown input extension"),
    "blank image": ("blank.png", None, "no pixel"),
}


@pytest.mark.parametrize("case", sorted(BAD_FILES))
def test_bad_input_file(case, fake, tmp_path, capsys):
    name, text, words = BAD_FILES[case]
    path = tmp_path / "in" / name
    if case == "binary":
        path.parent.mkdir()
        path.write_bytes(b"\x00\xff\xfe\x81")
    elif case == "blank image":
        import matplotlib.image

        path.parent.mkdir()
        matplotlib.image.imsave(path, np.zeros((4, 4)), cmap="gray", vmin=0, vmax=1)
    else:
        _write(path, text)
    out = tmp_path / "out.json"
    assert main(["curve", str(path), "-n", "3", "-o", str(out)]) == 1
    assert words in one_error_line(capsys)
    assert not out.exists() and fake.calls == []


def test_collinear_points_are_accepted(fake, tmp_path):
    """The pinned box corners make a triangulation of points on one line well defined."""
    path = _write(tmp_path / "l.xy", "0 0\n1 1\n2 2\n3 3\n")
    assert main(["curve", str(path), "-n", "2", "--quiet"]) == 0
    np.testing.assert_array_equal(fake.calls[0][0], [[0, 0], [1, 1], [2, 2], [3, 3]])


def test_merge_duplicates_accepts_duplicates(fake, tmp_path):
    path = _write(tmp_path / "d.xy", "0 0\n1 0\n0 1\n1 0\n")
    assert main(["curve", str(path), "-n", "3", "--merge-duplicates", "--quiet"]) == 0
    assert fake.calls[0][2]["merge_duplicates"] is True


@pytest.mark.parametrize(("n", "words"), [("0", "at least 1"), ("6", "cannot exceed"), ("-2", "at least 1")])
def test_absurd_targets(n, words, fake, square_file, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["curve", str(square_file), "-n", n, "-o", str(out)]) == 1
    assert words in one_error_line(capsys)
    assert not out.exists() and fake.calls == []


def test_missing_file(fake, tmp_path, capsys):
    assert main(["curve", str(tmp_path / "nope.xy"), "-n", "3"]) == 1
    line = one_error_line(capsys)
    assert "nope.xy" in line and "No such file" in line


@pytest.mark.parametrize("bad", ["r.pdf", "r", "r.xy"])
def test_unknown_output_extension_writes_nothing(bad, fake, square_file, tmp_path, capsys):
    good = tmp_path / "o" / "r.json"
    assert main(["curve", str(square_file), "-n", "3", "-o", str(good), "-o", str(tmp_path / "o" / bad)]) == 1
    assert "unknown output extension" in one_error_line(capsys)
    assert not (tmp_path / "o").exists()
    assert fake.calls == []  # rejected before any work


def test_unknown_example(fake, capsys):
    assert main(["curve", "--example", "nope"]) == 1
    line = one_error_line(capsys)
    assert "nope" in line and "ring" in line


def test_api_value_error_is_one_line(monkeypatch, square_file, tmp_path, capsys):
    monkeypatch.setattr(
        otjax.cli, "reconstruct_curve", FakeReconstruct(ValueError("relevance\nmust be >= 0"))
    )
    out = tmp_path / "r.json"
    assert main(["curve", str(square_file), "-n", "3", "-o", str(out)]) == 1
    assert one_error_line(capsys) == "otjax: error: relevance must be >= 0"
    assert not out.exists()


def test_unwritable_output_is_an_error(fake, square_file, tmp_path, capsys):
    (tmp_path / "r.json").mkdir()  # a directory where the file should go
    assert main(["curve", str(square_file), "-n", "3", "-o", str(tmp_path / "r.json")]) == 1
    assert "existing directory" in one_error_line(capsys)
    assert os.listdir(tmp_path / "r.json") == []
    assert fake.calls == []  # found before any work


def tree(root):
    """Every file and directory under ``root``, relative, sorted."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize("out_exists", [True, False])
def test_a_bad_second_output_fails_before_the_reconstruction_and_writes_nothing(
        out_exists, fake, square_file, tmp_path, capsys):
    """``-o out/good.json -o INPUT/x.json``: the second parent is a file, which is found before any work."""
    if out_exists:
        (tmp_path / "out").mkdir()
    before = tree(tmp_path)
    argv = ["curve", str(square_file), "-n", "3", "-o", str(tmp_path / "out" / "good.json"),
            "-o", str(square_file / "x.json"), "--mkdir"]
    assert main(argv) == 1
    assert "not a directory" in one_error_line(capsys)
    assert fake.calls == []
    assert tree(tmp_path) == before


def test_a_missing_output_directory_needs_mkdir(fake, square_file, tmp_path, capsys):
    out = tmp_path / "a" / "b" / "r.json"
    assert main(["curve", str(square_file), "-n", "3", "-o", str(out)]) == 1
    line = one_error_line(capsys)
    assert "does not exist" in line and "--mkdir" in line
    assert fake.calls == [] and not (tmp_path / "a").exists()
    assert main(["curve", str(square_file), "-n", "3", "-o", str(out), "--mkdir", "--quiet"]) == 0
    assert json.loads(out.read_text())["params"] == {"n_vertices": 3}


@pytest.mark.parametrize("second", ["o/r.json", "o/../o/./r.json", "link/r.json"])
def test_the_same_output_twice_is_an_error(second, fake, square_file, tmp_path, capsys):
    (tmp_path / "o").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "o")
    argv = ["curve", str(square_file), "-n", "3", "-o", str(tmp_path / "o" / "r.json"), "-o", str(tmp_path / second)]
    assert main(argv) == 1
    assert "given twice" in one_error_line(capsys)
    assert fake.calls == [] and os.listdir(tmp_path / "o") == []


def test_an_output_may_not_overwrite_the_input(fake, tmp_path, capsys):
    import matplotlib.image

    image = np.ones((4, 4))
    image[1, 1] = image[2, 3] = image[3, 0] = 0.0
    path = tmp_path / "dots.png"
    matplotlib.image.imsave(path, image, cmap="gray", vmin=0, vmax=1)
    content = path.read_bytes()
    (tmp_path / "alias.png").symlink_to(path)
    for out in (path, tmp_path / "." / "dots.png", tmp_path / "alias.png"):
        assert main(["curve", str(path), "-n", "3", "--invert", "-o", str(out)]) == 1
        assert "overwrite the input" in one_error_line(capsys)
    assert fake.calls == [] and path.read_bytes() == content


def test_a_failed_write_leaves_nothing_new(fake, square_file, tmp_path, monkeypatch, capsys):
    """The reconstruction succeeds, the last output fails to render: no output appears, an old one is kept."""
    (tmp_path / "o").mkdir()
    old = tmp_path / "o" / "r.json"
    old.write_text("old")

    def broken(self, *args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(CurveResult, "to_png", broken)
    argv = ["curve", str(square_file), "-n", "3", "-o", str(old), "-o", str(tmp_path / "o" / "r.svg"),
            "-o", str(tmp_path / "new" / "r.png"), "--mkdir"]
    assert main(argv) == 1
    assert "disk full" in one_error_line(capsys)
    assert len(fake.calls) == 1
    assert tree(tmp_path / "o") == ["r.json"] and old.read_text() == "old"
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["curve"],  # no input
        ["curve", "x.xy", "--example", "ring"],  # both
        ["curve", "--example", "ring", "--invert"],  # image option on an example
        ["curve", "-n", "3"],
        ["curve", "-n", "three", "x.xy"],
        ["frobnicate"],
        [],
    ],
)
def test_usage_errors_exit_2(argv, fake, capsys):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    assert "usage:" in capsys.readouterr().err
    assert fake.calls == []


def test_file_needs_n_or_tolerance(fake, square_file, capsys):
    with pytest.raises(SystemExit) as info:
        main(["curve", str(square_file)])
    assert info.value.code == 2
    assert "-n" in capsys.readouterr().err


def test_image_input_with_invert_and_threshold(fake, tmp_path):
    import matplotlib.image

    image = np.ones((5, 6))
    image[1, 1] = image[3, 4] = image[2, 2] = 0.0  # three black dots on white
    image[4, 0] = 0.6
    path = tmp_path / "dots.png"
    matplotlib.image.imsave(path, image, cmap="gray", vmin=0, vmax=1)
    assert main(["curve", str(path), "-n", "3", "--invert", "--threshold", "0.5", "--quiet"]) == 0
    points, masses, _ = fake.calls[0]
    np.testing.assert_array_equal(points, [[1.5, 3.5], [2.5, 2.5], [4.5, 1.5]])
    np.testing.assert_allclose(masses, 1.0)


def test_python_m_otjax_help():
    proc = subprocess.run(
        [sys.executable, "-m", "otjax", "curve", "--help"],
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "--example" in proc.stdout and "--merge-duplicates" in proc.stdout


def test_a_curve_command_never_loads_the_3d_half():
    """The curve command, its help and the top-level help list the surface
    commands without importing the surface package; a surface command does."""
    probe = ("import sys, contextlib, io; import otjax.cli as c\n"
             "for argv in ({}):\n"
             "    with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):\n"
             "        c.main(argv)\n"
             "print(sorted(m for m in ('otjax.surfaces', 'otjax.lp', 'highspy') if m in sys.modules))\n"
             "print('surface' in out.getvalue() and 'recover' in out.getvalue())")

    def loaded(argvs):
        proc = subprocess.run([sys.executable, "-c", probe.format(argvs)], check=False, capture_output=True,
                              text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout.split("\n")[:2]

    assert loaded("['curve', '--list-examples'], ['--help']") == ["[]", "True"]
    assert loaded("['curve', '--help'],") == ["[]", "False"]
    assert loaded("['surface', '--help'],")[0] == "['highspy', 'otjax.lp', 'otjax.surfaces']"


def test_3d_names_of_the_package_load_on_first_use():
    import otjax
    import otjax.surfaces.features

    assert otjax.recover_features is otjax.surfaces.features.recover_features
    assert {"surfaces", "lp", "io3d", "datasets3d", "metrics3d", "recover_features"} <= set(dir(otjax))
    with pytest.raises(AttributeError, match="no attribute 'surface'"):
        otjax.surface  # noqa: B018


def test_python_m_otjax_exits_with_the_status_of_main(tmp_path):
    """The process entry (which freezes the collector before exit) passes the status on."""
    args = [sys.executable, "-m", "otjax", "curve", str(tmp_path / "missing.xy"), "-n", "3"]
    proc = subprocess.run(args, check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("otjax: error:")
    assert "missing.xy" in proc.stderr


def test_end_to_end_circle(tmp_path, capsys):
    """The real reconstruction: 200 slightly noisy points on a circle, 8 vertices."""
    rng = np.random.default_rng(5)
    angle = rng.random(200) * 2 * np.pi
    radius = 1 + 0.01 * rng.standard_normal(200)
    write_points(tmp_path / "circle.xy", np.stack([radius * np.cos(angle), radius * np.sin(angle)], 1))
    out = tmp_path / "circle.json"
    assert main(["curve", str(tmp_path / "circle.xy"), "-n", "8", "-o", str(out), "--no-progress"]) == 0
    assert "8 vertices" in capsys.readouterr().out
    d = json.loads(out.read_text())
    jsonschema.validate(d, json_schema())
    r = CurveResult.from_dict(d)
    assert len(r.vertices) == 8 and len(r.edges) == 8 and len(r.isolated) == 0
    # On the circle up to what an optimal octagon needs (its vertices sit outside the circle).
    np.testing.assert_allclose(np.linalg.norm(r.vertices, axis=1), 1.0, atol=0.2)
    # A closed curve: every vertex has exactly two edges.
    np.testing.assert_array_equal(np.bincount(r.edges.ravel(), minlength=8), 2)
    assert d["params"]["n_vertices"] == 8


def test_end_to_end_at_1e_minus_300(tmp_path, capsys):
    """Coordinates near the bottom of float64's range: the same octagon as at unit scale, the
    cost given with its power of two (it underflows in input units)."""
    angle = np.linspace(0, 2 * np.pi, 80, endpoint=False) + 0.1
    write_points(tmp_path / "tiny.xy", 1e-300 * np.stack([np.cos(angle), np.sin(angle)], 1))
    out = tmp_path / "tiny.json"
    assert main(["curve", str(tmp_path / "tiny.xy"), "-n", "8", "-o", str(out), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "8 vertices, 8 edges" in printed and "x 2^-" in printed
    r = CurveResult.load(out)
    np.testing.assert_allclose(np.linalg.norm(r.vertices / 1e-300, axis=1), 1.0, atol=0.2)
    np.testing.assert_array_equal(np.bincount(r.edges.ravel(), minlength=8), 2)
    # In unit-circle units: 80 points of mass 1, each within 0.2 of the octagon.
    cost = Fraction(r.total_cost) * Fraction(2) ** r.params["cost_exponent"] / Fraction(1e-300) ** 2
    assert r.params["cost_exponent"] < -1900 and 0 < cost < 80 * 0.2**2


def _cli(args, env):
    return subprocess.run([sys.executable, "-m", "otjax", "curve", *args], check=False, capture_output=True,
                          text=True, timeout=300, env=env)


def test_compile_cache_is_written_then_reused_with_the_same_result(tmp_path):
    """Default: kernels land in $XDG_CACHE_HOME/otjax/jax; a second run reads them back.

    100 points: every run compiles kernels and the second must compile none, at
    any size; more points would only add collapses to each of the three runs."""
    env = {k: v for k, v in os.environ.items() if k != "OTJAX_COMPILE_CACHE"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    args = ["--example", "noisy-star", "--points", "100", "--quiet"]
    first = _cli(args + ["-o", str(tmp_path / "a.json")], env)
    assert first.returncode == 0, first.stderr
    cache = tmp_path / "cache" / "otjax" / "jax"
    entries = sorted(p.name for p in cache.iterdir())
    assert entries, "no compiled kernel was cached"
    second = _cli(args + ["-o", str(tmp_path / "b.json")], env)
    assert second.returncode == 0, second.stderr
    assert sorted(p.name for p in cache.iterdir()) == entries  # nothing new to compile
    a, b = (json.loads((tmp_path / f"{k}.json").read_text()) for k in "ab")
    assert a["vertices"] == b["vertices"] and a["edges"] == b["edges"]
    # Opting out writes nothing.
    env["XDG_CACHE_HOME"] = str(tmp_path / "other")
    third = _cli(args + ["--no-compile-cache"], env)
    assert third.returncode == 0, third.stderr
    assert not (tmp_path / "other").exists()


@pytest.mark.parametrize("points", ["2", "2147483648", "10000000000000000000000"])
def test_example_sizes_out_of_range_are_one_line_errors(fake, capsys, points):
    assert main(["curve", "--example", "ring", "--points", points, "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--points must be between 3 and" in err[0] and points in err[0]
    assert fake.example_calls == [] and fake.calls == []
