"""Reading point sets (text files, grayscale images) and writing files atomically.

Text formats (``.xy``, ``.xyz``, ``.xym``, ``.csv``, ``.txt``): one point per
line, the numbers separated by whitespace or commas (a comma may end a row,
but one that starts a row or follows another marks a missing value, an
error); ``#`` starts a comment; blank lines and a byte order mark are
skipped; a ``.csv`` may start with one non-numeric header line. Two columns
are ``x y``; three are ``x y mass`` (in this 2D library
``.xyz`` means ``x y mass``, not 3D coordinates; ``.xym`` is the weighted
point format of CGAL's curve reconstruction demo, ``x y mass`` per line).
Every data row has the same number of columns.

Images (``.png``, ``.jpg``, ``.jpeg``, ``.pgm``, ``.bmp``, ``.tif``,
``.tiff``): every pixel becomes a point at its centre, weighted by its
intensity, as in de Goes et al. 2011 (Fig. 11).

Every failure to read (missing file, bad line, unknown extension) is a
:class:`ValueError` naming the file, so that callers (the CLI) catch one type.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
from pathlib import Path

import numpy as np

TEXT_EXTENSIONS = (".xy", ".xyz", ".xym", ".csv", ".txt")
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff")

# Rec. 601 luma weights, the ones Pillow uses for its "L" conversion.
_LUMA = np.array([0.299, 0.587, 0.114])
_SEPARATOR = re.compile(r"[,\s]+")
# A comma that starts a line or follows another: a missing value, not a separator to merge
# (merged, "x,,mass" would silently read as "x mass"). A trailing comma is tolerated.
_EMPTY_FIELD = re.compile(r"^,|,\s*,")


def parse_row(fields: list[str]) -> list[float] | None:
    """The numbers of a split line, or ``None`` if some field is not a number."""
    try:
        return [float(f) for f in fields]
    except ValueError:
        return None


def read_text(path: Path) -> str:
    """The text of ``path``; a file that is not UTF-8 is a ``ValueError``."""
    try:
        return path.read_text(encoding="utf-8-sig")  # a byte order mark (Windows tools) is not data
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a UTF-8 text file") from None


def read_table(path: Path, text: str, layouts: dict[int, str], header_allowed: bool) -> np.ndarray:
    """The rows of a text point file as ``(n, c)`` float64, ``c`` a key of ``layouts``.

    Fields are separated by commas and/or white space; ``#`` starts a comment;
    with ``header_allowed`` one non-numeric line before the data is skipped.
    Every row has the first row's column count, every value is finite.

    Raises:
      ValueError: naming the file and line of the first malformed row.
    """
    rows: list[list[float]] = []
    first_line = 0  # line number of the first data row, for the column-count message
    for number, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        if _EMPTY_FIELD.search(line):
            raise ValueError(f"{path}:{number}: empty field (a comma with no number before it): {line[:80]!r}")
        values = parse_row(_SEPARATOR.split(line.strip(", \t")))
        if values is None:
            if header_allowed and not rows:
                header_allowed = False  # only one header line, and only before the data
                continue
            raise ValueError(f"{path}:{number}: not a row of numbers: {line[:80]!r}")
        header_allowed = False
        if not rows:
            if len(values) not in layouts:
                expected = " or ".join(f"{k} ({v})" for k, v in layouts.items())
                raise ValueError(f"{path}:{number}: expected {expected} columns, got {len(values)}")
            first_line = number
        elif len(values) != len(rows[0]):
            raise ValueError(
                f"{path}:{number}: expected {len(rows[0])} columns like line {first_line}, got {len(values)}"
            )
        if not all(np.isfinite(values)):
            raise ValueError(f"{path}:{number}: NaN or inf value: {line[:80]!r}")
        rows.append(values)
    if not rows:
        raise ValueError(f"{path}: no points (the file holds no data rows)")
    return np.array(rows, dtype=np.float64)


def _read_text(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    data = read_table(path, read_text(path), {2: "x y", 3: "x y mass"}, header_allowed=path.suffix.lower() == ".csv")
    return data[:, :2].copy(), (data[:, 2].copy() if data.shape[1] == 3 else None)


def read_points(
    path, *, invert: bool = False, threshold: float = 0.0
) -> tuple[np.ndarray, np.ndarray | None]:
    """Reads a point set from a text file or a grayscale image.

    Args:
      path: a file with one of :data:`TEXT_EXTENSIONS` or :data:`IMAGE_EXTENSIONS`.
      invert: images only: weight pixels by ``1 - intensity`` (dark drawing on white).
      threshold: images only: drop pixels whose mass is ``<= threshold``.

    Returns:
      ``(points, masses)``: ``(n, 2)`` float64 and ``(n,)`` float64, or ``None``
      for a two-column text file (unit masses). The values are not validated
      beyond being finite numbers; see :func:`otjax.validation.check_points`.

    Raises:
      ValueError: unknown extension, missing or unreadable file, malformed line
        (the message gives the file name and line number).

    Example:
      >>> points, masses = read_points("drawing.png", invert=True)  # doctest: +SKIP
    """
    path = Path(path)
    ext = path.suffix.lower()
    try:
        if ext in TEXT_EXTENSIONS:
            if invert or threshold != 0.0:
                raise ValueError(f"{path}: invert and threshold apply to images only, not to {ext} files")
            return _read_text(path)
        if ext in IMAGE_EXTENSIONS:
            try:
                return image_to_points(read_image(path), invert=invert, threshold=threshold)
            except ValueError as err:
                if str(path) in str(err):
                    raise
                raise ValueError(f"{path}: {err}") from None
    except OSError as err:
        raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
    raise ValueError(
        f"{path}: unknown input extension {ext!r}; expected one of {', '.join(TEXT_EXTENSIONS + IMAGE_EXTENSIONS)}"
    )


def _to_unit_float(image: np.ndarray) -> np.ndarray:
    """Integer pixel values scaled by their type's maximum; floats kept as they are."""
    if image.dtype.kind == "b":
        return image.astype(np.float64)
    if image.dtype.kind in "iu":
        return image.astype(np.float64) / np.iinfo(image.dtype).max
    if image.dtype.kind == "f":
        return image.astype(np.float64)
    raise ValueError(f"image must hold numbers, got dtype {image.dtype}")


def _grayscale(image) -> np.ndarray:
    """``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)`` pixels to ``(H, W)`` float64 in [0, 1].

    Colour becomes Rec. 601 luminance; transparency is composited over white,
    so a dark drawing on a transparent background reads like one on paper.
    """
    image = _to_unit_float(np.asarray(image))
    if image.ndim == 3 and image.shape[2] in (1, 2, 3, 4):
        channels = image.shape[2]
        alpha = image[..., -1] if channels in (2, 4) else None
        colour = image[..., : 3 if channels >= 3 else 1]
        gray = colour @ _LUMA if colour.shape[2] == 3 else colour[..., 0]
        if alpha is not None:
            gray = gray * alpha + (1.0 - alpha)
        image = gray
    if image.ndim != 2:
        raise ValueError(f"image must have shape (H, W) or (H, W, 1|2|3|4), got shape {image.shape}")
    if not np.isfinite(image).all():
        raise ValueError("image contains NaN or inf pixels")
    return np.clip(image, 0.0, 1.0)  # the luma weights sum to 1 only up to rounding


def read_image(path) -> np.ndarray:
    """Reads an image as grayscale intensities.

    Args:
      path: a PNG, JPEG, PGM, BMP or TIFF file.

    Returns:
      ``(H, W)`` float64 in [0, 1]; row 0 is the top of the picture.

    Example:
      >>> read_image("drawing.png").shape  # doctest: +SKIP
      (480, 640)
    """
    import matplotlib.image
    from PIL import Image, UnidentifiedImageError

    try:
        pixels = matplotlib.image.imread(os.fspath(path))
    except UnidentifiedImageError:
        raise ValueError(f"{path}: not a readable image") from None
    except Image.DecompressionBombError as err:  # Pillow's guard against huge images
        raise ValueError(f"{path}: {err}") from None
    except OSError as err:
        if err.errno is not None:  # the file system's error (missing file, a directory, ...)
            raise
        raise ValueError(f"{path}: not a readable image ({err})") from None
    except Exception as err:  # noqa: BLE001  any other decoder failure on a corrupt file
        # Pillow's decoders report corrupt data as SyntaxError, ValueError, EOFError,
        # struct.error, zlib.error, IndexError, ...: to the caller it is one problem.
        raise ValueError(f"{path}: not a readable image ({type(err).__name__}: {err})") from None
    try:
        return _grayscale(pixels)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


def image_to_points(image, *, invert: bool = False, threshold: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Turns pixels into weighted points at the pixel centres.

    Pixel ``(row, col)`` of an ``H``-row image becomes the point
    ``(col + 0.5, H - row - 0.5)``: x to the right, y up, so the picture is
    neither mirrored nor upside down.

    Args:
      image: ``(H, W)`` intensities (or ``(H, W, 3|4)`` colour, turned to
        luminance); integers are scaled to [0, 1] by their type's maximum.
      invert: use ``1 - intensity`` as the mass, for a dark drawing on white.
      threshold: drop pixels whose mass is ``<= threshold`` (so the default
        drops the black ones, which carry no mass anyway).

    Returns:
      ``(points, masses)``: ``(n, 2)`` float64 and ``(n,)`` float64, in
      row-major pixel order.

    Example:
      >>> p, m = image_to_points(np.array([[1.0, 0.0], [0.0, 0.5]]))
      >>> p.tolist(), m.tolist()
      ([[0.5, 1.5], [1.5, 0.5]], [1.0, 0.5])
    """
    gray = _grayscale(image)
    mass = 1.0 - gray if invert else gray
    rows, cols = np.nonzero(mass > threshold)
    if len(rows) == 0:
        raise ValueError(
            f"no pixel has mass above the threshold {threshold} (all {gray.size} pixels dropped); "
            "is the image blank, or does it need invert?"
        )
    height = gray.shape[0]
    points = np.stack([cols + 0.5, height - rows - 0.5], axis=1).astype(np.float64)
    return points, mass[rows, cols]


@contextlib.contextmanager
def atomic_write(path, mode: str = "w"):
    """Opens a file that appears at ``path`` only if the ``with`` block succeeds.

    The data goes to a temporary file in the same directory (so the final
    rename stays on one file system and is atomic), which replaces ``path`` on
    success and is removed on any exception: readers never see a half-written
    file, and a failed write leaves an existing ``path`` untouched. Missing
    parent directories are created.

    Args:
      path: destination file.
      mode: ``"w"`` (text, UTF-8) or ``"wb"`` (binary).

    Example:
      >>> import tempfile
      >>> with tempfile.TemporaryDirectory() as tmp:
      ...     with atomic_write(Path(tmp) / "sub" / "out.txt") as f:
      ...         _ = f.write("done")
      ...     (Path(tmp) / "sub" / "out.txt").read_text()
      'done'
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"mode must be 'w' or 'wb', got {mode!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    while True:
        tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            # os.open with 0o666 lets the umask decide the permissions, as for a plain open();
            # tempfile.mkstemp would leave the output readable by its owner only.
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            break
        except FileExistsError:
            continue
    try:
        with os.fdopen(fd, mode, **({"encoding": "utf-8"} if mode == "w" else {})) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def check_output_paths(paths, extensions, *, inputs=(), mkdir: bool = False) -> list[Path]:
    """Checks output paths before any work, so that a run never fails at its end.

    Each path must have one of ``extensions``, must not be an existing
    directory, must not be given twice (after resolving ``..`` and symbolic
    links) and must not be one of ``inputs``; its parent must be an existing
    writable directory, or, with ``mkdir``, its nearest existing ancestor must
    be one (the missing directories are created by :func:`write_files`).

    Args:
      paths: the output paths, in the order given.
      extensions: accepted lower-case suffixes (``".json"``, ...).
      inputs: input files the outputs must not overwrite.
      mkdir: allow missing parent directories.

    Returns:
      The paths as :class:`Path` objects, in order.

    Raises:
      ValueError: naming the first offending path and what is wrong with it.
    """
    out = [Path(p) for p in paths]
    for path in out:  # every extension first: a typo is the likeliest mistake
        if path.suffix.lower() not in extensions:
            raise ValueError(
                f"{path}: unknown output extension {path.suffix!r}; expected one of {', '.join(extensions)}"
            )
    seen: dict[Path, Path] = {}
    sources = [Path(p).resolve() for p in inputs]
    for path in out:
        if path.is_dir():
            raise ValueError(f"{path}: output is an existing directory")
        _check_output_directory(path, mkdir)
        resolved = path.resolve()
        if resolved in seen:
            raise ValueError(f"{path}: the same output file is given twice (also as {seen[resolved]})")
        seen[resolved] = path
        for source in sources:
            if resolved == source or (path.exists() and source.exists() and os.path.samefile(path, source)):
                raise ValueError(f"{path}: output would overwrite the input file")
    return out


def _check_output_directory(path: Path, mkdir: bool) -> None:
    parent = path.parent
    missing = []
    while not parent.exists():
        if parent.is_symlink():
            raise ValueError(f"{path}: {parent} is a broken symbolic link")
        missing.append(parent)
        if parent.parent == parent:
            break
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"{path}: {parent} is not a directory")
    if missing and not mkdir:
        raise ValueError(f"{path}: directory {path.parent} does not exist; create it or pass mkdir=True (CLI: --mkdir)")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{path}: no permission to write in {parent}")


def write_files(files, *, mkdir: bool = False) -> None:
    """Writes several files all or nothing.

    Every file goes to a temporary in its target directory first; only when
    all are written are they renamed into place. On any failure (or
    interrupt) the temporaries are removed, files already renamed are
    rolled back (an existing file they replaced is restored) and directories
    created here are removed, so nothing new remains.

    Args:
      files: ``(path, data)`` pairs; ``data`` is ``str`` (written as UTF-8)
        or ``bytes``.
      mkdir: create missing parent directories.
    """
    files = [(Path(p), d) for p, d in files]
    created: list[Path] = []
    temps: list[Path] = []
    done: list[tuple[Path, Path | None, bool]] = []  # renamed: (path, backup of what it replaced, existed)
    try:
        for path, _ in files:
            if mkdir:
                created += _make_parents(path.parent)
        for path, data in files:
            temps.append(_write_temp(path, data))
        for (path, _), tmp in zip(files, temps):
            existed = path.exists()
            backup = _backup(path) if existed else None
            done.append((path, backup, existed))  # before the rename: a failed one is undone the same way
            os.replace(tmp, path)
    except BaseException:
        for path, backup, existed in reversed(done):
            with contextlib.suppress(OSError):
                if backup is not None and os.path.samefile(backup, path):
                    os.unlink(backup)  # not replaced yet (and rename() between two links to one file is a no-op)
                elif backup is not None:
                    os.replace(backup, path)
                elif not existed:
                    os.unlink(path)
        for tmp in temps:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        for directory in reversed(created):
            with contextlib.suppress(OSError):
                directory.rmdir()
        raise
    for _, backup, _ in done:
        if backup is not None:
            with contextlib.suppress(OSError):
                os.unlink(backup)


def _make_parents(directory: Path) -> list[Path]:
    """Creates ``directory`` and its missing ancestors; returns those created, outermost first."""
    missing = []
    while not directory.exists():
        missing.append(directory)
        directory = directory.parent
    for d in reversed(missing):
        d.mkdir()
    return list(reversed(missing))


def _temp_name(path: Path, kind: str) -> Path:
    return path.with_name(f".{path.name}.{secrets.token_hex(4)}.{kind}")


def _write_temp(path: Path, data) -> Path:
    while True:
        tmp = _temp_name(path, "tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask decides, as for open()
            break
        except FileExistsError:
            continue
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode("utf-8") if isinstance(data, str) else data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return tmp


def _backup(path: Path) -> Path | None:
    """A hard link to the existing file at ``path``, to restore it on rollback."""
    backup = _temp_name(path, "bak")
    try:
        os.link(path, backup)
    except OSError:  # a file system without hard links: the old file cannot come back on rollback
        return None
    return backup


def write_points(path, points, masses=None) -> None:
    """Writes points (and masses) as text that :func:`read_points` reads back exactly.

    Numbers are written with 17 significant digits, which round-trips every
    float64. A ``.csv`` path gets commas, any other one spaces.

    Args:
      path: destination file (written atomically).
      points: ``(n, 2)`` coordinates.
      masses: ``(n,)`` masses, or ``None`` for a two-column file.

    Example:
      >>> import tempfile
      >>> with tempfile.TemporaryDirectory() as tmp:
      ...     write_points(Path(tmp) / "star.xy", np.array([[0.5, 1.0], [2.0, -3.0]]))
      ...     read_points(Path(tmp) / "star.xy")[0]
      array([[ 0.5,  1. ],
             [ 2. , -3. ]])
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 2:
        raise ValueError(f"points must have shape (n, 2), got shape {points.shape}")
    columns = [points[:, 0], points[:, 1]]
    header = "# x y"
    if masses is not None:
        masses = np.asarray(masses, dtype=np.float64)
        if masses.shape != (len(points),):
            raise ValueError(f"masses must have shape ({len(points)},), got shape {masses.shape}")
        columns.append(masses)
        header += " mass"
    sep = "," if Path(path).suffix.lower() == ".csv" else " "
    table = np.stack(columns, axis=1)
    lines = [header] + [sep.join(f"{v:.17g}" for v in row) for row in table]
    with atomic_write(path) as f:
        f.write("\n".join(lines) + "\n")
