"""Keep the CPU's BLAS/LAPACK single-threaded around the solver's small dense solves.

On CPU, JAX's ``linalg.solve`` calls the LAPACK that scipy ships (OpenBLAS). For the solver's
(N-1)×(N-1) systems (N ≈ 200-300) threading gains nothing, and when other processes load the
machine OpenBLAS's spinning threads oversubscribe the cores: the default run then swings from
0.15 s to tens of seconds (issue "Error control", item 8).
``threadpoolctl`` (maintained by the scikit-learn developers) limits the threads of the BLAS
libraries already loaded in this process, for the duration of a call, and restores them after.
``LUBJAX_BLAS_LIMIT=0`` leaves BLAS's own thread count alone (to measure what the limit buys).
"""

from __future__ import annotations

import contextlib
import functools
import os


@functools.lru_cache(maxsize=1)
def _controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


@contextlib.contextmanager
def single_threaded_blas():
    """Limit BLAS to one thread inside the block (no-op if no BLAS pool is found, or with
    ``LUBJAX_BLAS_LIMIT=0``)."""
    if os.environ.get("LUBJAX_BLAS_LIMIT", "1").strip().lower() in ("0", "off", "no", "false"):
        yield
        return
    with _controller().limit(limits=1, user_api="blas"):
        yield
