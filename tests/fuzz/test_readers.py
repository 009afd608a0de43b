"""Fuzzing the readers: any bytes under any input extension give either
points that pass the reader's contract or one ValueError naming the file;
never another exception, never a warning."""

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.io import read_points
from tests.fuzz.strategies import (check_points_pair, image_files, text_extensions, text_files,
                                   warnings_are_errors)
from tests.profiles import examples


def read_or_refuse(data: bytes, ext: str, **options):
    """``read_points`` on a file holding ``data``: its result, or ``None`` after a ValueError naming the file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / f"in put{ext}"
        path.write_bytes(data)
        try:
            with warnings_are_errors():
                points, masses = read_points(path, **options)
        except ValueError as err:
            assert str(path) in str(err), f"the message does not name the file: {err}"
            return None
    check_points_pair(points, masses)
    return points, masses


@settings(max_examples=examples(400, 4000))
@given(data=text_files, ext=text_extensions)
def test_text_files(data, ext):
    read_or_refuse(data, ext)


@settings(max_examples=examples(200, 2000))
@given(data=text_files, ext=st.sampled_from([".xy", ".csv"]), invert=st.booleans(),
       threshold=st.floats(allow_nan=True))
def test_image_options_on_text_files(data, ext, invert, threshold):
    if invert or threshold != 0.0:  # NaN included: it is not 0
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / f"p{ext}"
            path.write_bytes(data)
            with pytest.raises(ValueError, match="images only"):
                read_points(path, invert=invert, threshold=threshold)
    else:
        read_or_refuse(data, ext, invert=invert, threshold=threshold)


# Tables of finite floats, written with any of the separators the format allows: read back exactly.
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@settings(max_examples=examples(300, 3000))
@given(rows=st.integers(1, 20).flatmap(lambda n: st.lists(st.lists(finite, min_size=n, max_size=n), min_size=2,
                                                            max_size=3)),
       sep=st.sampled_from([" ", "\t", ",", ", ", " , ", "  "]), ext=st.sampled_from([".xy", ".xym", ".csv", ".txt"]),
       comments=st.booleans(), crlf=st.booleans())
def test_valid_tables_read_back_exactly(rows, sep, ext, comments, crlf):
    table = np.array(rows, np.float64).T  # (n, 2 or 3)
    lines = [sep.join(repr(float(v)) for v in row) + ("  # a comment" if comments else "") for row in table]
    if comments:
        lines = ["# header comment", ""] + lines
    got = read_or_refuse(("\r\n" if crlf else "\n").join(lines).encode(), ext)
    assert got is not None
    points, masses = got
    np.testing.assert_array_equal(points, table[:, :2])
    if table.shape[1] == 3:
        np.testing.assert_array_equal(masses, table[:, 2])
    else:
        assert masses is None


@settings(max_examples=examples(200, 2000))
@given(image=image_files(), invert=st.booleans(), threshold=st.sampled_from([0.0, -1.0, 0.5, 1.0, float("nan")]))
def test_image_files(image, invert, threshold):
    data, ext = image
    got = read_or_refuse(data, ext, invert=invert, threshold=threshold)
    if got is not None:
        points, masses = got
        assert masses is not None and np.all(masses > threshold) and np.all(masses <= 1)
        assert np.all(points % 1 == 0.5)  # pixel centres


@settings(max_examples=examples(100, 1000))
@given(data=st.binary(max_size=200), ext=st.sampled_from([".png", ".jpg", ".bmp", ".tif", ".pgm"]))
def test_random_bytes_as_images(data, ext):
    read_or_refuse(data, ext)
