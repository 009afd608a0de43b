"""A persistent cache of compiled kernels, so that only the first run compiles.

A reconstruction compiles its scoring kernel once per batch shape (about
0.9 s each on a 2-core CPU, four shapes for a 50k-point input): a sixth
of a 50k-point run's wall time. JAX can keep compiled executables on
disk and reuse them in later processes; this module turns that on. JAX's
setting is process-wide, so the library never turns it on by itself: the
command line does (``--no-compile-cache`` to opt out), and library users call
:func:`enable_compilation_cache`.
"""

from __future__ import annotations

import os
from pathlib import Path

ENV = "OTJAX_COMPILE_CACHE"
_OFF = ("", "0", "off", "no", "false")


def default_cache_dir() -> Path | None:
    """Where the command line keeps compiled kernels, or ``None`` if disabled.

    ``$OTJAX_COMPILE_CACHE`` if set (``off`` or ``0`` disables the cache),
    else ``$XDG_CACHE_HOME/otjax/jax``, else ``~/.cache/otjax/jax``.
    """
    env = os.environ.get(ENV)
    if env is not None:
        return None if env.strip().lower() in _OFF else Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "otjax" / "jax"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turns on JAX's persistent compilation cache in ``path``.

    Every compiled kernel is then written there and read back by later
    processes with the same JAX version and machine (JAX keys the entries by
    both). Call it before the first reconstruction of the process.

    Args:
      path: cache directory, created if missing; default
        :func:`default_cache_dir` (or ``~/.cache/otjax/jax`` if that is
        disabled).

    Returns:
      The directory in use.

    Raises:
      OSError: the directory cannot be created.
    """
    import jax

    path = Path(path).expanduser() if path is not None else (
        default_cache_dir() or Path.home() / ".cache" / "otjax" / "jax")
    path.mkdir(parents=True, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", str(path))
    # JAX only caches compiles above 1 s by default; every kernel here is below.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path
