"""JAX's persistent compilation cache for the command line: a repeated ``lubjax-fit`` call loads
the compiled solver from disk instead of compiling it again.

Never switched on by importing the library: only the CLI calls :func:`enable_compilation_cache`
(or a user, explicitly). Where: ``$LUBJAX_CACHE_DIR``, else ``$XDG_CACHE_HOME/lubjax/jax``, else
``~/.cache/lubjax/jax``. Off: ``LUBJAX_CACHE=0`` (or ``--no-cache``). The cache holds XLA
executables keyed by the program, the jax version and the device; deleting the folder is always
safe.

The XLA cache alone leaves most of a warm call's start-up in place: tracing and lowering the
solver's jvp-of-a-while-loop under vmap costs ~1.5 s per program before XLA is even asked. So
while the cache is on, :func:`exported` also keeps the *lowered* program (``jax.export``,
serialised with flatbuffers) under ``exported/`` in the same folder, keyed by the program's name,
its argument structure, shapes and dtypes, the jax version, the backend and a hash of the lubjax
and fitting sources (a changed solver never reuses a stale program). A warm call deserialises it
(milliseconds) and XLA's cache supplies the executable.
"""

from __future__ import annotations

import functools
import hashlib
import os
import tempfile

import jax
import numpy as np

#: Where enable_compilation_cache pointed the cache (None: off, the library's default).
_ENABLED: str | None = None
_LOADED: dict = {}


def cache_dir() -> str:
    """The cache folder (see module docstring)."""
    path = os.environ.get("LUBJAX_CACHE_DIR")
    if path:
        return path
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "lubjax", "jax")


def enable_compilation_cache(path: str | None = None) -> str | None:
    """Point JAX's persistent compilation cache at ``path`` (default :func:`cache_dir`); every
    compilation is cached (the solver's take seconds). Returns the folder, or None when
    ``LUBJAX_CACHE=0`` or the folder cannot be made (then nothing changes: a cache is an
    optimisation, never a reason to fail)."""
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
    global _ENABLED
    _ENABLED = path
    return path


@functools.lru_cache(maxsize=1)
def _source_hash() -> str:
    digest = hashlib.sha256()
    for package in ("lubjax", "fitting"):
        folder = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), package)
        for name in sorted(os.listdir(folder)):
            if name.endswith(".py"):
                with open(os.path.join(folder, name), "rb") as fh:
                    digest.update(name.encode() + fh.read())
    return digest.hexdigest()


def exported(name: str, fn):
    """``fn`` (a jitted function of pytrees of arrays), called through a stored ``jax.export``
    of it while the cache is on (see module docstring); plain ``fn`` otherwise, on several
    devices (an exported program is bound to its device count and shardings) or when anything
    about the stored program fails: it is an optimisation, never a reason to fail."""

    def call(*args):
        if _ENABLED is None or jax.device_count() != 1:
            return fn(*args)
        leaves, treedef = jax.tree_util.tree_flatten(args)
        try:
            program = _program(name, fn, leaves, treedef)
        except Exception:  # noqa: BLE001 - flatbuffers missing, an op that cannot be exported...
            return fn(*args)
        return program(*leaves)

    return call


def _program(name, fn, leaves, treedef):
    specs = [jax.ShapeDtypeStruct(np.shape(x), jax.numpy.result_type(x)) for x in leaves]
    key_text = repr((name, str(treedef), [(s.shape, str(s.dtype)) for s in specs],
                     jax.__version__, jax.default_backend(), _source_hash()))
    key = hashlib.sha256(key_text.encode()).hexdigest()[:32]
    if key in _LOADED:
        return _LOADED[key]
    folder = os.path.join(_ENABLED, "exported")
    path = os.path.join(folder, key + ".bin")
    program = None
    if os.path.exists(path):
        try:
            with open(path, "rb") as fh:
                program = jax.export.deserialize(bytearray(fh.read()))
        except Exception:  # noqa: BLE001 - a truncated or foreign file: export afresh
            program = None
    if program is None:
        def flat(*xs):
            return fn(*jax.tree_util.tree_unflatten(treedef, xs))

        program = jax.export.export(jax.jit(flat))(*specs)
        os.makedirs(folder, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:  # written whole, then renamed: readers never see half
            fh.write(program.serialize())
        os.replace(tmp, path)
    _LOADED[key] = jax.jit(program.call)
    return _LOADED[key]
