"""Point files, images and atomic writes."""

import os
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

from otjax.io import (atomic_write, check_output_paths, image_to_points, read_image, read_points, write_files,
                      write_points)


@pytest.mark.parametrize("ext", [".xy", ".xyz", ".xym", ".csv", ".txt"])
@pytest.mark.parametrize("with_masses", [False, True])
def test_write_read_round_trip_is_exact(tmp_path, rng, ext, with_masses):
    pts = rng.standard_normal((50, 2)) * 10.0 ** rng.integers(-20, 20, size=(50, 1))
    masses = rng.random(50) if with_masses else None
    path = tmp_path / f"p{ext}"
    write_points(path, pts, masses)
    got, got_masses = read_points(path)
    np.testing.assert_array_equal(got, pts)  # 17 digits: bit-exact
    if with_masses:
        np.testing.assert_array_equal(got_masses, masses)
    else:
        assert got_masses is None
    assert got.dtype == np.float64


def test_cgal_weighted_points_read_as_they_are(tmp_path):
    """CGAL's curve reconstruction demo writes ``x y mass`` per line, space separated."""
    path = tmp_path / "demo.xym"
    path.write_text("0.5 -1.25 2\n3e-1 4 0.125\n-7 8.5 1\n")
    pts, masses = read_points(path)
    np.testing.assert_array_equal(pts, [[0.5, -1.25], [0.3, 4.0], [-7.0, 8.5]])
    np.testing.assert_array_equal(masses, [2.0, 0.125, 1.0])


def test_csv_with_header_comments_and_blank_lines(tmp_path):
    path = tmp_path / "p.csv"
    path.write_text(
        "# exported by hand\n\nx,y,mass\n1, 2, 3\n# a comment\n4,5,6  # trailing\n\n-1e-3,2E2,0\n"
    )
    pts, masses = read_points(path)
    np.testing.assert_array_equal(pts, [[1, 2], [4, 5], [-1e-3, 200]])
    np.testing.assert_array_equal(masses, [3, 6, 0])


def test_byte_order_mark_and_trailing_commas_are_read(tmp_path):
    path = tmp_path / "p.csv"
    path.write_bytes("\ufeffx,y\r\n1,2,\r\n3,4,\r\n5,6\r\n".encode())
    pts, masses = read_points(path)
    np.testing.assert_array_equal(pts, [[1, 2], [3, 4], [5, 6]])
    assert masses is None


def test_whitespace_separated_with_tabs(tmp_path):
    path = tmp_path / "p.xy"
    path.write_text("0\t0\n  1   0 \n0 1\n")
    pts, masses = read_points(path)
    np.testing.assert_array_equal(pts, [[0, 0], [1, 0], [0, 1]])
    assert masses is None


@pytest.mark.parametrize(
    ("name", "text", "words"),
    [
        ("p.xy", "0 0\n1 0\n0 x\n", ["p.xy:3", "not a row of numbers"]),
        ("p.xy", "x y\n0 0\n", ["p.xy:1", "not a row of numbers"]),  # headers only in .csv
        ("p.csv", "x,y\nu,v\n0,0\n", ["p.csv:2"]),  # only one header line
        ("p.csv", "x,y\n0,0\n1,1\nx,y\n", ["p.csv:4"]),  # a header after data is an error
        ("p.xy", "# c\n0 0\n\n1 0 1\n", ["p.xy:4", "expected 2 columns like line 2", "got 3"]),
        ("p.xy", "0 0 0 0\n", ["p.xy:1", "got 4"]),
        ("p.xy", "0\n", ["p.xy:1", "got 1"]),
        ("p.xy", "0 0\n1 nan\n", ["p.xy:2", "NaN or inf"]),
        ("p.xy", "# only a comment\n\n", ["no points"]),
        ("p.xy", "", ["no points"]),
        ("p.dat", "0 0\n", ["unknown input extension", ".dat"]),
        ("p.csv", "0,0,1\n1,,2\n", ["p.csv:2", "empty field"]),  # not read as the two numbers 1 2
        ("p.csv", "0,0\n, 1, 2\n", ["p.csv:2", "empty field"]),
        ("p.xy", "0 0\n1 , , 2\n", ["p.xy:2", "empty field"]),
    ],
)
def test_malformed_text_reports_file_and_line(tmp_path, name, text, words):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        read_points(path)
    for word in words:
        assert word in str(info.value)


def test_binary_file_is_a_value_error(tmp_path):
    path = tmp_path / "p.xy"
    path.write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(ValueError, match="UTF-8"):
        read_points(path)


@pytest.mark.parametrize("name", ["missing.xy", "missing.png"])
def test_missing_file_is_a_value_error(tmp_path, name):
    with pytest.raises(ValueError, match="cannot read .*missing"):
        read_points(tmp_path / name)


def test_directory_is_a_value_error(tmp_path):
    (tmp_path / "d.xy").mkdir()
    with pytest.raises(ValueError, match="cannot read"):
        read_points(tmp_path / "d.xy")


def test_corrupt_image_is_a_value_error(tmp_path):
    path = tmp_path / "p.png"
    path.write_bytes(b"this is not a png")
    with pytest.raises(ValueError, match="p.png"):
        read_points(path)


def test_image_options_on_text_files_are_refused(tmp_path):
    path = tmp_path / "p.xy"
    write_points(path, np.eye(2))
    with pytest.raises(ValueError, match="images only"):
        read_points(path, invert=True)


def test_image_to_points_positions_and_orientation():
    h, w = 3, 4
    image = np.zeros((h, w))
    image[0, 0] = 1.0  # top-left
    image[2, 3] = 0.5  # bottom-right
    image[1, 2] = 0.25
    pts, masses = image_to_points(image)
    # Pixel centres, y up: the top-left pixel is at the top of the point cloud.
    np.testing.assert_array_equal(pts, [[0.5, h - 0.5], [2.5, 1.5], [3.5, 0.5]])
    np.testing.assert_array_equal(masses, [1.0, 0.25, 0.5])


def test_image_to_points_every_pixel_centre():
    h, w = 5, 7
    pts, masses = image_to_points(np.full((h, w), 0.3))
    assert len(pts) == h * w
    np.testing.assert_allclose(masses, 0.3)
    assert pts[:, 0].min() == 0.5 and pts[:, 0].max() == w - 0.5
    assert pts[:, 1].min() == 0.5 and pts[:, 1].max() == h - 0.5
    assert len(np.unique(pts, axis=0)) == h * w


def test_image_to_points_invert_and_threshold():
    image = np.array([[1.0, 0.9], [0.2, 0.0]])
    pts, masses = image_to_points(image, invert=True)
    np.testing.assert_allclose(masses, [0.1, 0.8, 1.0])
    np.testing.assert_array_equal(pts, [[1.5, 1.5], [0.5, 0.5], [1.5, 0.5]])
    pts, masses = image_to_points(image, threshold=0.5)
    np.testing.assert_array_equal(masses, [1.0, 0.9])
    pts, masses = image_to_points(image, invert=True, threshold=0.5)
    np.testing.assert_allclose(masses, [0.8, 1.0])


def test_image_to_points_scales_integers_and_converts_colour():
    _, masses = image_to_points(np.array([[255, 0], [51, 0]], np.uint8))
    np.testing.assert_allclose(masses, [1.0, 0.2])
    rgb = np.zeros((1, 2, 3))
    rgb[0, 0] = [1.0, 0.0, 0.0]  # pure red: Rec. 601 luma 0.299
    rgb[0, 1] = [1.0, 1.0, 1.0]
    _, masses = image_to_points(rgb)
    np.testing.assert_allclose(masses, [0.299, 1.0])
    rgba = np.zeros((1, 1, 4))  # fully transparent black reads as white paper
    _, masses = image_to_points(rgba)
    np.testing.assert_allclose(masses, [1.0])


@pytest.mark.parametrize(
    ("image", "words"),
    [
        (np.zeros((2, 2)), ["no pixel"]),
        (np.ones((2, 2)), ["no pixel", "invert"]),  # with invert=True below
        (np.zeros(4), ["shape"]),
        (np.zeros((2, 2, 2, 2)), ["shape"]),
        (np.zeros((2, 2, 5)), ["shape"]),
        (np.array([[np.nan, 1.0]]), ["NaN"]),
    ],
)
def test_image_to_points_rejects(image, words):
    invert = bool(np.all(image == 1.0)) and image.ndim == 2
    with pytest.raises(ValueError) as info:
        image_to_points(image, invert=invert)
    for word in words:
        assert word in str(info.value)


def test_png_round_trip_to_one_level(tmp_path, rng):
    image = rng.random((6, 9))
    path = tmp_path / "g.png"
    matplotlib.image.imsave(path, image, cmap="gray", vmin=0.0, vmax=1.0)
    got = read_image(path)
    assert got.shape == image.shape and got.dtype == np.float64
    np.testing.assert_allclose(got, image, atol=1 / 255)
    pts, masses = read_points(path, threshold=-1.0)  # keep every pixel
    assert len(pts) == image.size
    np.testing.assert_allclose(masses, image.ravel(), atol=1 / 255)


def test_bmp_through_pillow(tmp_path):
    from PIL import Image

    pixels = np.array([[0, 128, 255]], np.uint8)
    Image.fromarray(pixels).save(tmp_path / "g.bmp")
    np.testing.assert_allclose(read_image(tmp_path / "g.bmp"), pixels / 255.0)


def _leftovers(directory):
    return sorted(os.listdir(directory))


def test_atomic_write_success_replaces_and_leaves_no_temp(tmp_path):
    path = tmp_path / "sub" / "dir" / "out.txt"  # parents are created
    path.parent.mkdir(parents=True)
    path.write_text("old")
    with atomic_write(path) as f:
        f.write("new")
        assert path.read_text() == "old"  # not visible until the block ends
    assert path.read_text() == "new"
    assert _leftovers(path.parent) == ["out.txt"]


def test_atomic_write_creates_parents_and_binary(tmp_path):
    path = tmp_path / "a" / "b" / "out.bin"
    with atomic_write(path, "wb") as f:
        f.write(b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"


def test_atomic_write_failure_leaves_nothing(tmp_path):
    path = tmp_path / "out.txt"
    with pytest.raises(RuntimeError, match="boom"), atomic_write(path) as f:
        f.write("half")
        raise RuntimeError("boom")
    assert _leftovers(tmp_path) == []


def test_atomic_write_failure_keeps_existing_file(tmp_path):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with pytest.raises(KeyboardInterrupt), atomic_write(path) as f:
        f.write("half")
        raise KeyboardInterrupt
    assert path.read_text() == "old"
    assert _leftovers(tmp_path) == ["out.txt"]


def test_atomic_write_respects_umask(tmp_path):
    path = tmp_path / "out.txt"
    with atomic_write(path) as f:
        f.write("x")
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    assert os.stat(path).st_mode == os.stat(plain).st_mode


def test_write_points_rejects_bad_shapes(tmp_path):
    with pytest.raises(ValueError, match=r"\(n, 2\)"):
        write_points(tmp_path / "p.xy", np.zeros((3, 3)))
    with pytest.raises(ValueError, match="masses"):
        write_points(tmp_path / "p.xy", np.zeros((3, 2)), np.ones(2))
    assert _leftovers(tmp_path) == []


EXTS = (".json", ".svg")


def test_check_output_paths_accepts_good_paths(tmp_path):
    (tmp_path / "old.json").write_text("x")  # an existing file is replaced, not refused
    paths = [tmp_path / "a.json", str(tmp_path / "old.json"), tmp_path / "new" / "deeper" / "b.svg"]
    assert check_output_paths(paths, EXTS, mkdir=True) == [tmp_path / "a.json", tmp_path / "old.json",
                                                          tmp_path / "new" / "deeper" / "b.svg"]
    assert not (tmp_path / "new").exists()  # checking creates nothing


@pytest.mark.parametrize(
    ("outputs", "mkdir", "words"),
    [
        (["r.json", "r.pdf"], False, ["r.pdf", "unknown output extension"]),
        (["missing/r.json"], False, ["missing", "does not exist", "--mkdir"]),
        (["file.txt/r.json"], True, ["file.txt", "not a directory"]),
        (["file.txt/sub/r.json"], True, ["file.txt", "not a directory"]),
        (["dir.json"], False, ["existing directory"]),
        (["r.json", "dir.json/../r.json"], False, ["given twice"]),
        (["in.json"], False, ["overwrite the input"]),
        (["hardlink.json"], False, ["overwrite the input"]),
    ],
)
def test_check_output_paths_rejects(tmp_path, outputs, mkdir, words):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "dir.json").mkdir()
    (tmp_path / "in.json").write_text("{}")
    os.link(tmp_path / "in.json", tmp_path / "hardlink.json")
    before = _leftovers(tmp_path)
    with pytest.raises(ValueError) as info:
        check_output_paths([tmp_path / o for o in outputs], EXTS, inputs=[tmp_path / "in.json"], mkdir=mkdir)
    for word in words:
        assert word in str(info.value)
    assert _leftovers(tmp_path) == before


def test_check_output_paths_rejects_a_read_only_directory(tmp_path, monkeypatch):
    # access(2) itself, not file modes: root may write to a mode-0500 directory.
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: Path(p) != tmp_path / "ro" and real(p, mode))
    (tmp_path / "ro").mkdir()
    with pytest.raises(ValueError, match="no permission to write in .*ro"):
        check_output_paths([tmp_path / "ro" / "r.json"], EXTS)
    with pytest.raises(ValueError, match="no permission to write in .*ro"):
        check_output_paths([tmp_path / "ro" / "new" / "r.json"], EXTS, mkdir=True)


def test_write_files_writes_all_and_creates_directories_when_asked(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "x" / "y" / "b.bin"
    a.write_text("old")
    write_files([(a, "new ü"), (b, b"\x00\x01")], mkdir=True)
    assert a.read_text(encoding="utf-8") == "new ü" and b.read_bytes() == b"\x00\x01"
    assert _leftovers(tmp_path) == ["a.txt", "x"] and _leftovers(b.parent) == ["b.bin"]


def test_write_files_without_mkdir_does_not_create_directories(tmp_path):
    with pytest.raises(FileNotFoundError):
        write_files([(tmp_path / "a.txt", "a"), (tmp_path / "missing" / "b.txt", "b")])
    assert _leftovers(tmp_path) == []


@pytest.mark.parametrize("fail_at", [0, 1, 2])
def test_write_files_rolls_back_every_rename(tmp_path, monkeypatch, fail_at):
    """A failure at the k-th rename: the first k files are undone (an old one restored), temporaries removed."""
    old = tmp_path / "old.txt"
    old.write_text("old")
    files = [(old, "replaced"), (tmp_path / "d" / "new.txt", "new"), (tmp_path / "e" / "f" / "last.txt", "last")]
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if len(calls) == fail_at + 1:
            raise OSError("rename failed")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OSError, match="rename failed"):
        write_files(files, mkdir=True)
    monkeypatch.setattr(os, "replace", real)
    assert _leftovers(tmp_path) == ["old.txt"] and old.read_text() == "old"


def test_write_files_interrupted_while_writing_leaves_nothing(tmp_path, monkeypatch):
    def explode(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", explode)
    with pytest.raises(KeyboardInterrupt):
        write_files([(tmp_path / "a.txt", "a"), (tmp_path / "sub" / "b.txt", "b")], mkdir=True)
    assert _leftovers(tmp_path) == []
