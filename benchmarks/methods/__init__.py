"""Benchmark methods for the relaxation test: each module has ``run(beta, z0, t_out, **opts)``.

Importing this package pins BLAS and XLA to ``LUBJAX_BENCH_THREADS`` threads (default 1:
``benchmarks._harness.pin_threads``). All timings are single-threaded unless stated.
"""

from .._harness import pin_threads

pin_threads()

METHODS = (
    "paper_scheme",
    "lubjax_default",
    "lubjax_variant",
    "newton",
    "picard",
    "explicit_euler",
    "mol",
)
