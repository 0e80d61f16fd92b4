"""The fit's compiled programs across calls: a repeated ``lubjax-fit`` loads them from disk.

A warm call loads the compiled solver instead of compiling it again.

JAX's persistent compilation cache is lubjax's (lubjax/_compile_cache.py: where it lives, how it
is switched off; never on by importing the library): :func:`enable_compilation_cache` turns it
on and, while it is on, the stored programs below.

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

from lubjax._fitting_api import compile_cache as _compile_cache
from lubjax._fitting_api import compiler as _compiler

#: The cache folder (lubjax/_compile_cache.py; re-exported: tests, users).
cache_dir = _compile_cache.cache_dir

#: Where enable_compilation_cache pointed the cache (None: off, the library's default).
_ENABLED: str | None = None
_LOADED: dict = {}


def enable_compilation_cache(path: str | None = None) -> str | None:
    """:func:`lubjax.enable_compilation_cache` (JAX's persistent cache; see there), and the
    stored lowered programs of :func:`exported` in the same folder while it is on."""
    global _ENABLED
    _ENABLED = _compile_cache.enable_compilation_cache(path)
    return _ENABLED


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
    return _compiler.cached(_LOADED, key, lambda: _load_or_export(key, fn, specs, treedef))[0]


def _load_or_export(key, fn, specs, treedef):
    """The stored program of ``key`` (exported afresh if missing or unreadable), jitted."""
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
        # The function under fn's jit: a jit with compiler options (lubjax/_compiler.py) may
        # not be nested in another; the options apply where the program is loaded, below.
        inner = getattr(fn, "__wrapped__", fn)

        def flat(*xs):
            return inner(*jax.tree_util.tree_unflatten(treedef, xs))

        program = jax.export.export(jax.jit(flat))(*specs)
        os.makedirs(folder, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".tmp")
        with os.fdopen(fd, "wb") as fh:  # written whole, then renamed: readers never see half
            fh.write(program.serialize())
        os.replace(tmp, path)
    return _compiler.jit(program.call)
