"""Generators of malformed and extreme input for the fuzz tests, and the
structural checks a successful result must pass.

A helper module, not a test file.
"""

from __future__ import annotations

import contextlib
import io
import os
import warnings

import numpy as np
from hypothesis import strategies as st

from otjax.io import IMAGE_EXTENSIONS, TEXT_EXTENSIONS

# Numbers as text: ordinary, extreme (overflow, underflow, subnormal), special, and near misses.
ODD_NUMBERS = ["1e400", "-1e400", "1e-400", "5e-324", "-4.9e-324", "2.2250738585072014e-308", "1.7976931348623157e308",
               "nan", "NaN", "-inf", "Infinity", "0x10", "1_0", "\u0661\u0662", "1e", "--1", "+.5", "0.", ".",
               "1,5", "", "abc", "None", "0" * 400 + "1", "9" * 400, "1e-5", "-0", "-0.0"]
finite_text = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.floats(-1e3, 1e3).map(lambda x: f"{x:.3f}"),
)
number_text = st.one_of(finite_text, st.floats(width=64).map(repr), st.integers(-(10**20), 10**20).map(str),
                        st.sampled_from(ODD_NUMBERS))
separator = st.sampled_from([" ", "  ", "\t", ",", ", ", " ,", ";", ",,", " \t ", "|"])
newline = st.sampled_from(["\n", "\r\n", "\r", "\x0b", "\u2028"])


@st.composite
def text_rows(draw) -> str:
    """A text point file: rows of fields with mixed separators, comments, blank lines, a header.

    Each file draws how dirty it is: how often a field is an odd token
    (``nan``, ``1e400``, ``abc``, ...), a row has another column count, or a
    separator is an odd one; from clean to mostly garbage.
    """
    odd_field, ragged, odd_sep = (draw(st.sampled_from([0.0, 0.0, 0.05, 0.3])) for _ in range(3))

    def chance(p):
        return p > 0 and draw(st.floats(0, 1)) < p

    lines = []
    columns = draw(st.integers(1, 4))
    for _ in range(draw(st.integers(0, 25))):
        kind = draw(st.sampled_from(["row"] * 12 + ["comment", "blank", "header"]))
        if kind == "row":
            k = draw(st.integers(0, 5)) if chance(ragged) else columns
            fields = [draw(number_text if chance(odd_field) else finite_text) for _ in range(k)]
            line = draw(separator if chance(odd_sep) else st.sampled_from([" ", ",", "\t", ", "])).join(fields)
            if chance(odd_sep):
                line = draw(st.sampled_from(["", " ", ",", "\t"])) + line + draw(st.sampled_from(["", " ", ",", "# x"]))
        elif kind == "comment":
            line = "# " + draw(st.text(max_size=20))
        elif kind == "blank":
            line = draw(st.sampled_from(["", "   ", "\t"]))
        else:
            line = draw(st.sampled_from(["x,y", "x y mass", "x,y,m", "a;b"]))
        lines.append(line)
    text = draw(newline).join(lines) + draw(st.sampled_from(["", "\n"]))
    if draw(st.booleans()):
        text = "\ufeff" + text
    return text


@st.composite
def mangled(draw, data: bytes) -> bytes:
    """``data`` truncated, with bytes flipped, or with random bytes spliced in."""
    how = draw(st.sampled_from(["keep", "truncate", "flip", "splice"]))
    if how == "truncate" and data:
        return data[: draw(st.integers(0, len(data) - 1))]
    if how == "flip" and data:
        out = bytearray(data)
        for _ in range(draw(st.integers(1, 4))):
            i = draw(st.integers(0, len(out) - 1))
            out[i] ^= 1 << draw(st.integers(0, 7))
        return bytes(out)
    if how == "splice":
        i = draw(st.integers(0, len(data)))
        return data[:i] + draw(st.binary(max_size=16)) + data[i:]
    return data


text_files = st.one_of(
    st.binary(max_size=300),
    text_rows().map(lambda t: t.encode("utf-8")),
    text_rows().map(lambda t: t.encode("utf-8")).flatmap(mangled),
)
text_extensions = st.sampled_from(list(TEXT_EXTENSIONS) + [".XY", ".Csv", ".dat", ""])


@st.composite
def image_files(draw) -> tuple[bytes, str]:
    """``(bytes, extension)``: a small image in a Pillow format, possibly mangled."""
    from PIL import Image

    h, w = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    mode = draw(st.sampled_from(["L", "RGB", "RGBA", "LA", "1", "I;16", "P"]))
    fmt, ext = draw(st.sampled_from([("PNG", ".png"), ("BMP", ".bmp"), ("TIFF", ".tif"), ("PPM", ".pgm"),
                                     ("JPEG", ".jpg")]))
    levels = draw(st.sampled_from([(0, 0), (255, 255), (0, 255)]))
    seed = draw(st.integers(0, 2**32 - 1))
    pixels = np.random.default_rng(seed).integers(levels[0], levels[1] + 1, (h, w, 4), dtype=np.uint8)
    image = Image.fromarray(pixels, "RGBA").convert(mode if mode != "I;16" else "I")
    if mode == "I;16":
        image = image.convert("I;16")
    buffer = io.BytesIO()
    try:
        image.save(buffer, fmt)
    except (OSError, ValueError, KeyError):  # a mode the format cannot hold: save it as PNG
        buffer = io.BytesIO()
        image.save(buffer, "PNG")
        ext = ".png"
    return draw(mangled(buffer.getvalue())), ext


def check_points_pair(points, masses) -> None:
    """What a reader promises on success: ``(n, 2)`` finite float64 and ``None`` or ``(n,)`` finite."""
    assert isinstance(points, np.ndarray) and points.dtype == np.float64
    assert points.ndim == 2 and points.shape[1] == 2 and len(points) >= 1
    assert np.isfinite(points).all()
    if masses is not None:
        assert masses.dtype == np.float64 and masses.shape == (len(points),)
        assert np.isfinite(masses).all()


def check_result(result, n_points: int, total_mass: float) -> None:
    """Structural checks of a :class:`CurveResult`: finite, valid indices, mass conserved."""
    k = len(result.vertices)
    assert result.vertices.shape == (k, 2) and np.isfinite(result.vertices).all()
    assert k <= n_points
    assert result.edges.dtype == np.int64 and result.edges.shape[1:] == (2,)
    if result.edges.size:
        assert result.edges.min() >= 0 and result.edges.max() < k
        assert np.all(result.edges[:, 0] != result.edges[:, 1])
        assert len({frozenset(e) for e in result.edges.tolist()}) == len(result.edges)  # no edge twice
    assert len(set(result.isolated.tolist())) == len(result.isolated)
    assert np.all((result.isolated >= 0) & (result.isolated < k))
    on_edges = set(result.edges.ravel().tolist())
    assert on_edges.isdisjoint(result.isolated.tolist())
    assert on_edges | set(result.isolated.tolist()) == set(range(k))  # every vertex is used
    assert np.isfinite(result.edge_mass).all() and np.all(result.edge_mass >= 0)
    assert np.isfinite(result.edge_relevance).all() and np.all(result.edge_relevance >= 0)
    # Edges hold part of the input's mass, never more than all of it.
    assert result.edge_mass.sum() <= total_mass * (1 + 1e-9)
    assert np.isfinite(result.total_cost) and result.total_cost >= 0
    assert np.isfinite(result.masses).all() and result.masses.sum() <= total_mass * (1 + 1e-9)


@contextlib.contextmanager
def warnings_are_errors():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def listing(root) -> list[str]:
    """Every file and directory under ``root``, relative, sorted."""
    out = []
    for base, dirs, files in os.walk(root):
        out += [os.path.relpath(os.path.join(base, name), root) for name in dirs + files]
    return sorted(out)


ALL_INPUT_EXTENSIONS = TEXT_EXTENSIONS + IMAGE_EXTENSIONS
