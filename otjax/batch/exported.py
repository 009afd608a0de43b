"""Kernel shapes kept on disk as exported modules, so a new process skips tracing them.

JAX's persistent compilation cache (:mod:`otjax.compile_cache`) keeps
compiled executables, but it finds them by the lowered module: every new
process still traces and lowers each kernel shape before the cache can
answer, about 0.2 s a shape of the curve scoring kernel on a 2-core CPU, the
largest part of a small run's start-up after the imports
(docs/decisions.md#exported_kernels). :func:`exported_kernel` keeps each
shape's lowered module (:mod:`jax.export`) in a folder of the compilation
cache; a later process reads it back in milliseconds and the compilation
cache supplies the executable.

An entry is named by the kernel, its static arguments, the JAX and jaxlib
versions, the backend and a digest of otjax's own sources, so an edited
kernel never runs from an old export. An entry that cannot be read is
exported again; one that cannot be written is not kept.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile
from pathlib import Path
from typing import Callable

import jax
import numpy as np

SUFFIX = ".jaxexport"


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """A digest of every Python source of the otjax package (names and bytes)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def export_dir() -> Path | None:
    """The folder of exported kernels: ``exported`` inside JAX's compilation
    cache directory, or ``None`` while that cache is off."""
    cache = jax.config.jax_compilation_cache_dir
    return Path(cache) / "exported" if cache else None


def entry_name(kernel: Callable, static: dict) -> str:
    """The file name of ``kernel`` at the static arguments ``static``."""
    parts = [f"{k}={np.dtype(v).name if isinstance(v, type) else v}" for k, v in sorted(static.items())]
    versions = f"{jax.__version__}-{jax.lib.__version__}-{jax.default_backend()}-{source_digest()}"
    text = f"{kernel.__module__}.{kernel.__qualname__}({','.join(parts)})@{versions}"
    return hashlib.sha256(text.encode()).hexdigest()[:32] + SUFFIX


def exported_kernel(kernel: Callable, static: dict, args) -> Callable:
    """``kernel`` at the static arguments ``static``, as a callable of ``args``' shapes.

    With JAX's compilation cache on, the lowered module is read from
    :func:`export_dir` (or exported there first); the call then compiles
    from the compilation cache without tracing ``kernel``. With the cache
    off it is ``kernel`` itself with ``static`` bound.

    Args:
      kernel: a jitted function whose outputs are arrays, tuples or
        NamedTuples registered with
        :func:`jax.export.register_namedtuple_serialization`.
      static: its static keyword arguments.
      args: example positional arguments (only shapes and dtypes are read).

    Returns:
      ``f(*args) -> outputs``, the same outputs as ``kernel(*args, **static)``.
    """
    plain = functools.partial(kernel, **static)
    directory = export_dir()
    if directory is None:
        return plain
    path = directory / entry_name(kernel, static)
    exported = _read(path)
    if exported is None:
        shapes = [jax.ShapeDtypeStruct(np.shape(a), a.dtype) for a in args]
        exported = jax.export.export(jax.jit(plain))(*shapes)
        _write(path, exported)
    return jax.jit(exported.call)


def _read(path: Path):
    try:
        blob = path.read_bytes()
    except OSError:
        return None
    try:
        return jax.export.deserialize(bytearray(blob))
    except Exception:  # noqa: BLE001 -- a truncated or foreign file: export again
        return None


def _write(path: Path, exported) -> None:
    tmp = None
    try:
        blob = exported.serialize()
        path.parent.mkdir(parents=True, exist_ok=True)
        # Written beside and renamed: a process reading concurrently sees
        # the whole entry or none.
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            f.write(blob)
        os.replace(tmp, path)
        tmp = None
    except (OSError, ImportError, ValueError):
        pass
    finally:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
