"""JAX's persistent compilation cache for the command lines: a repeated ``lubjax`` or
``lubjax-fit`` call loads the compiled solver from disk instead of compiling it again.

Never switched on by importing the library. Off: ``LUBJAX_CACHE=0`` (or ``--no-cache``);
deleting the folder is always safe (``fitting`` keeps its lowered programs there too).
"""

from __future__ import annotations

import os

import jax


def cache_dir() -> str:
    """The cache folder: ``$LUBJAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/lubjax/jax``, else
    ``~/.cache/lubjax/jax``."""
    path = os.environ.get("LUBJAX_CACHE_DIR")
    if path:
        return path
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "lubjax", "jax")


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Point JAX's persistent compilation cache at a folder; every compilation is cached (the
    solver's take seconds).

    Args:
        path: the folder; None (default): ``$LUBJAX_CACHE_DIR``, else
            ``$XDG_CACHE_HOME/lubjax/jax`` or ``~/.cache/lubjax/jax``.

    Returns:
        The folder, or None when ``LUBJAX_CACHE=0`` or the folder cannot be made or written
        (then nothing changes: a cache is an optimisation, never a reason to fail).
    """
    if os.environ.get("LUBJAX_CACHE", "1").strip().lower() in ("0", "off", "no", "false"):
        return None
    path = cache_dir() if path is None else path
    try:
        os.makedirs(path, exist_ok=True)
    except OSError:
        return None
    if not os.access(path, os.W_OK):
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path
