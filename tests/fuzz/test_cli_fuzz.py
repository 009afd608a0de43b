"""Fuzzing ``otjax curve`` in process: any input file, any options, any
outputs end in exit 0 with every output written, exit 1 with one error line
and nothing new on disk, or a usage error (exit 2) with nothing new on disk;
never a traceback, never a warning.

The reconstruction itself is the real one up to the end of validation; a
spy then returns a small result, so that every example stays cheap. A few
tiny inputs run the real reconstruction to the end."""

import contextlib
import io
import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import event, given, settings
from hypothesis import strategies as st

import otjax.cli
import otjax.curves.reconstruct as reconstruct_module
from otjax.cli import main
from otjax.curves.result import CurveResult
from tests.fuzz.strategies import image_files, listing, text_extensions, text_files, warnings_are_errors
from tests.profiles import examples


class Validated(Exception):
    pass


def _stop(points, masses, params, progress):
    raise Validated


def spy_reconstruct(points, masses=None, **kwargs):
    """The real reconstruct_curve up to its run, then a three-vertex result over its first points."""
    real_run = reconstruct_module._run
    reconstruct_module._run = _stop
    try:
        reconstruct_module.reconstruct_curve(points, masses, **kwargs)
    except Validated:
        pass
    finally:
        reconstruct_module._run = real_run
    pts = np.asarray(points, np.float64)
    return CurveResult(vertices=pts[:3], edges=[[0, 1], [1, 2]], isolated=[], edge_mass=[1.0, 1.0],
                       edge_relevance=[1.0, 1.0], total_cost=0.5,
                       params={k: v for k, v in kwargs.items() if k != "progress"}, seconds=0.0, points=pts)


def mostly(valid, odd=("nan", "inf", "-1", "1e309", "abc", "", "10000000000000000000000")):
    """An option's value: usually one of its type, sometimes an odd string."""
    return st.one_of(valid, valid, valid, valid, valid, st.sampled_from(list(odd)))


integer_value = mostly(st.integers(-2, 30).map(str))
real_value = mostly(st.sampled_from(["0", "0.1", "0.5", "1", "1e-9", "2.5", "1e300", "-0.0"]))
OPTIONS = {
    "-n": integer_value, "--relocation": integer_value, "--final-relocations": integer_value,
    "--choices": integer_value, "--initial-vertices": integer_value, "--seed": integer_value,
    "--points": integer_value, "--tolerance": real_value, "--relevance": real_value, "--density": real_value,
    "--round-fraction": real_value, "--threshold": real_value,
    "--background": mostly(st.sampled_from(["auto", "none"])),
    "--queue": mostly(st.sampled_from(["exhaustive", "multiple-choice", "parallel"])),
}
FLAGS = ["--keep-chords", "--refine", "--invert", "--merge-duplicates", "--quiet", "--no-progress",
         "--no-compile-cache", "--mkdir"]


@st.composite
def valid_tables(draw) -> bytes:
    """A well-formed point file: 3-30 rows of ``x y`` or ``x y mass``."""
    n, columns = draw(st.integers(3, 30)), draw(st.sampled_from([2, 3]))
    seed = draw(st.integers(0, 2**32 - 1))
    table = np.random.default_rng(seed).random((n, columns)) * draw(st.sampled_from([1.0, 1e-300, 1e300, 1e6]))
    sep = draw(st.sampled_from([" ", ",", "\t"]))
    return "\n".join(sep.join(repr(float(v)) for v in row) for row in table).encode()


output_name = st.one_of(
    st.sampled_from(["r.json", "r.svg", "r.png", "out/r.json", "out/deeper/r.svg"]),
    st.sampled_from(["r.json", "r.svg", "r.png", "out/r.json", "out/deeper/r.svg"]),
    st.sampled_from(["r.pdf", "r", "in.xy/r.json", "dir", "same.json", "./same.json", "link/same.json"]),
)


@st.composite
def command_lines(draw):
    """``(input bytes and name or None, argv tail, output names)``."""
    kind = draw(st.sampled_from(["example", "image", "text", "table", "table", "table"]))
    if kind == "example":
        source = None
        head = ["--example", draw(st.sampled_from(["noisy-star", "star", "nope", ""]))]
    elif kind == "image":
        data, ext = draw(image_files())
        source = (data, "in" + ext)
        head = ["in" + ext]
    else:
        data = draw(text_files) if kind == "text" else draw(valid_tables())
        source = (data, "in" + draw(text_extensions))
        head = [source[1]]
    tail = []
    for option in draw(st.lists(st.sampled_from(sorted(OPTIONS)), unique=True, max_size=4)):
        tail += [option, draw(OPTIONS[option])]
    tail += draw(st.lists(st.sampled_from(FLAGS), unique=True, max_size=3))
    if "-n" not in tail and draw(st.integers(0, 5)) > 0:
        tail += ["-n", draw(st.integers(1, 5).map(str))]
    outputs = draw(st.lists(output_name, max_size=3))
    for name in outputs:
        tail += ["-o", name]
    return source, head + tail, outputs


def run_cli(argv):
    """``(exit status, stdout, stderr)`` of ``main(argv)``, a usage error's status included."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings_are_errors():
        try:
            status = main(argv)
        except SystemExit as exc:
            status = exc.code
    return status, out.getvalue(), err.getvalue()


def check_outcome(status, out, err, before, after, outputs, root):
    event(f"exit status {status}")
    if status in (1, 2):
        event(err.strip().splitlines()[-1][:45])
    if status == 0:
        assert "Traceback" not in err and "error" not in err.lower(), err
        for name in outputs:
            assert (root / name).is_file(), name
        new = set(after) - set(before)
        real_root = os.path.realpath(root)
        written = {os.path.relpath(os.path.realpath(root / name), real_root) for name in outputs}
        assert all(any(w == n or w.startswith(n + os.sep) for w in written) for n in new), (new, written)
    elif status == 1:
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("otjax: error: "), err
        assert after == before, "a failed run left something behind"
    else:
        assert status == 2 and "usage:" in err, (status, err)
        assert after == before


def in_directory(root: Path):
    (root / "dir").mkdir()
    (root / "link").symlink_to(root)
    return contextlib.chdir(root)


@settings(max_examples=examples(150, 1500))
@given(command=command_lines())
def test_any_command_line(command):
    source, argv, outputs = command
    real = otjax.cli.reconstruct_curve
    otjax.cli.reconstruct_curve = spy_reconstruct
    try:
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(tmp)
            if source is not None:
                (root / source[1]).write_bytes(source[0])
            with in_directory(root):
                before = listing(root)
                status, out, err = run_cli(["curve", *argv])
                after = listing(root)
            check_outcome(status, out, err, before, after, outputs, root)
    finally:
        otjax.cli.reconstruct_curve = real


@settings(max_examples=examples(6, 60))
@given(points=st.lists(st.tuples(st.integers(0, 3), st.integers(0, 3)), min_size=3, max_size=8, unique=True),
       scale=st.sampled_from(["1", "1e-300", "1e300"]), n=st.integers(1, 3),
       outputs=st.one_of(st.just(["r.json", "r.svg"]), st.just(["r.json"]),
                         st.lists(st.sampled_from(["r.json", "r.svg", "bad.pdf", "missing/r.json"]), max_size=2)))
def test_tiny_files_end_to_end(points, scale, n, outputs):
    text = "\n".join(f"{x}{'e0' if scale == '1' else ''} {y}" for x, y in points)
    if scale != "1":
        text = "\n".join(f"{x}{scale[1:]} {y}{scale[1:]}" for x, y in points)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "in.xy").write_text(text)
        with in_directory(root):
            before = listing(root)
            argv = ["curve", "in.xy", "-n", str(n), "--merge-duplicates", "--no-progress"]
            for name in outputs:
                argv += ["-o", name]
            status, out, err = run_cli(argv)
            after = listing(root)
        check_outcome(status, out, err, before, after, outputs, root)
        if status == 0:
            assert "vertices" in out
