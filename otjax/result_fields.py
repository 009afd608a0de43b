"""Checked array fields and plain JSON values, shared by the result classes of
every dimension (:class:`otjax.CurveResult`, :class:`otjax.surfaces.SurfaceResult`)."""

from __future__ import annotations

import json
import math
import numbers
from pathlib import Path

import numpy as np


def float_array(value, name: str, shape: tuple) -> np.ndarray:
    """A finite float64 array of ``shape`` (``-1``: any length); ``None`` is empty.

    Raises:
      ValueError: not numbers, another shape, NaN or inf (naming ``name``).
    """
    try:
        arr = np.asarray([] if value is None else value)
        if arr.dtype.kind not in "iuf" and arr.size:
            raise TypeError
        arr = arr.astype(np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be an array of numbers") from None
    if arr.size == 0:
        arr = arr.reshape([0 if s == -1 else s for s in shape])
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("n" if s == -1 else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{name} must have shape {want}, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def index_array(value, name: str, shape: tuple, n: int) -> np.ndarray:
    """An int64 array of ``shape`` of indices into ``n`` rows; ``None`` is empty.

    Raises:
      ValueError: not integers, another shape, or an index outside ``[0, n)``.
    """
    arr = np.asarray([] if value is None else value)
    if arr.size and arr.dtype.kind not in "iu":
        raise ValueError(f"{name} must hold integer indices, got dtype {arr.dtype}")
    arr = float_array(arr if arr.size else np.zeros(0), name, shape).astype(np.int64)
    if arr.size and (arr.min() < 0 or arr.max() >= n):
        raise ValueError(f"{name} index out of range: indices must be in [0, {n}), got {arr.min()}..{arr.max()}")
    return arr


def plain_json(value, where: str):
    """``value`` as plain JSON types (NumPy scalars and arrays, tuples and paths converted).

    Raises:
      ValueError: NaN or inf, or a type JSON cannot hold (``where`` names the place).
    """
    if isinstance(value, np.ndarray):
        return plain_json(value.tolist(), where)
    if isinstance(value, np.generic):
        return plain_json(value.item(), where)
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        value = float(value)
        if not math.isfinite(value):  # NaN and inf are not JSON
            raise ValueError(f"{where} is {value}, which JSON cannot hold")
        return value
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, dict):
        return {str(k): plain_json(v, f"{where}[{k!r}]") for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain_json(v, f"{where}[{i}]") for i, v in enumerate(value)]
    raise ValueError(f"{where} of type {type(value).__name__} is not JSON-serialisable")


def check_json_keys(d, keys, what: str) -> None:
    """Raises ValueError unless ``d`` is a dict with exactly ``keys`` (``what``: e.g. ``"curve result"``)."""
    if not isinstance(d, dict):
        raise ValueError(f"a {what} must be a JSON object, got {type(d).__name__}")  # noqa: TRY004
    missing = [k for k in keys if k not in d]
    if missing:
        raise ValueError(f"{what} is missing key(s): {', '.join(missing)}")
    unknown = sorted(set(d) - set(keys))
    if unknown:
        raise ValueError(f"{what} has unknown key(s): {', '.join(map(str, unknown))}")


def load_json(path, from_dict):
    """``from_dict`` of the JSON file at ``path``; every failure is a ValueError naming the file."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        raise ValueError(f"cannot read {path}: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a UTF-8 text file") from None
    try:
        d = json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err})") from None
    try:
        return from_dict(d)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None
