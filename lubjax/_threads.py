"""Keep the CPU's BLAS/LAPACK single-threaded around the solver's small dense solves.

For (N-1)×(N-1) systems, N ≈ 200-300, threads gain nothing and under load oversubscribe the
cores (docs/design.md, "Numerical hygiene"); ``threadpoolctl`` limits them for a call.
``LUBJAX_BLAS_LIMIT=0`` leaves BLAS's own thread count alone.
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
