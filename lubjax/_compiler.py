"""How lubjax's programs are compiled: XLA options that halve the CPU compile time, and the
several programs of one call compiled side by side.

A solver program is one ``while_loop`` whose body (an attempted step) XLA splits into ~90 small
loop fusions; on the CPU each becomes a kernel of its own, and generating them is most of the
compile time. XLA's classic elemental emitters compile these kernels about twice as fast as its
newer MLIR fusion emitters, with code as fast and the same steps (``benchmarks/default_run.py``
compares both; tests/test_compiler.py). So lubjax asks for the classic ones, per program
(``compiler_options``, never the process-wide ``XLA_FLAGS``), on the CPU only, and only where
this jaxlib still knows the option (:func:`compiler_options` probes it once).
``LUBJAX_XLA_OPTIONS=0`` switches it off.

:func:`compile_all` compiles several programs (``relax``'s run and its error estimate's coarse-mesh
run) in threads: XLA releases the GIL while it compiles, so the second program is traced while
the first compiles, and on two cores both compile at once.

:func:`cached` and :func:`cached_all` keep compiled programs across calls: ``relax``'s
(lubjax/_solve.py), ``sweep``'s (lubjax/_sweep.py) and the fits' stored programs
(fitting/_cache.py). Each caller owns its dict of programs and its key (what shapes the program:
mesh size, tree structure, leaf shapes, ...); the helpers build what is missing and say how long
that took, so a call can report its compile time apart (0 when everything was cached).
"""

from __future__ import annotations

import functools
import os
import time
from concurrent.futures import ThreadPoolExecutor

import jax

#: XLA debug options for lubjax's programs on the CPU (see the module docstring).
CPU_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


@functools.cache
def compiler_options() -> dict:
    """:data:`CPU_OPTIONS` on a CPU backend whose XLA knows them; else ``{}``. Off:
    ``LUBJAX_XLA_OPTIONS=0``."""
    if os.environ.get("LUBJAX_XLA_OPTIONS", "1").strip().lower() in ("0", "off", "no", "false"):
        return {}
    if jax.default_backend() != "cpu":
        return {}
    try:
        # An option this XLA does not know raises at compile time ("No such compile option"):
        # a newer jaxlib may drop it, and a missing speed-up is no reason to fail.
        jax.jit(lambda x: x + 1.0).lower(1.0).compile(compiler_options=dict(CPU_OPTIONS))
    except Exception:  # noqa: BLE001 - any refusal means: compile with XLA's defaults
        return {}
    return dict(CPU_OPTIONS)


def jit(fn, **kwargs):
    """``jax.jit`` with :func:`compiler_options`."""
    return jax.jit(fn, compiler_options=compiler_options() or None, **kwargs)


def compile_one(lowered):
    """``lowered.compile()`` with :func:`compiler_options`."""
    return lowered.compile(compiler_options=compiler_options() or None)


def compile_all(lowerers) -> list:
    """Compile several programs side by side: ``lowerers`` are zero-argument callables that
    trace and lower one program each (``jax.jit(f).lower(...)``). Tracing holds the GIL, so it
    runs here, one program after another, while XLA compiles the ones already lowered in
    worker threads (it releases the GIL): on two cores the coarse-mesh program of ``relax``'s
    error estimate is traced while its main program compiles."""
    lowerers = list(lowerers)
    if len(lowerers) <= 1:
        return [compile_one(lower()) for lower in lowerers]
    with ThreadPoolExecutor(max_workers=min(len(lowerers), os.cpu_count() or 1)) as pool:
        futures = [pool.submit(compile_one, lower()) for lower in lowerers]
        return [f.result() for f in futures]


def cached(programs: dict, key, build):
    """``programs[key]``, built by ``build()`` (and stored) if it is not there yet. Returns
    (program, seconds spent building: 0.0 when cached)."""
    if key in programs:
        return programs[key], 0.0
    start = time.perf_counter()
    programs[key] = build()
    return programs[key], time.perf_counter() - start


def cached_all(programs: dict, keys, lowerers) -> tuple[list, float]:
    """The programs of ``keys`` (one per entry of ``lowerers``, zero-argument callables that
    trace and lower one program each): the missing ones are compiled side by side
    (:func:`compile_all`) and stored in ``programs``. Returns (programs, seconds spent: 0.0
    when all were cached)."""
    keys = list(keys)
    missing = {k: lower for k, lower in zip(keys, lowerers) if k not in programs}
    seconds = 0.0
    if missing:
        start = time.perf_counter()
        programs.update(zip(missing, compile_all(missing.values())))
        seconds = time.perf_counter() - start
    return [programs[k] for k in keys], seconds
