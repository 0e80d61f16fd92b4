"""Benchmark methods for the relaxation test: each module has ``run(beta, z0, t_out, **opts)``.

Importing this package pins BLAS and XLA to ``LUBJAX_BENCH_THREADS`` threads (default 1) when
numpy/jax are not imported yet: on the shared 2-core machines OpenBLAS' default pool made a
214×214 solve ~20x slower than one thread (measured). All timings are single-threaded unless
stated.
"""

import os

_THREADS = os.environ.get("LUBJAX_BENCH_THREADS", "1")
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, _THREADS)
if _THREADS == "1" and "multi_thread_eigen" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "")
        + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    ).strip()

METHODS = (
    "paper_scheme",
    "lubjax_default",
    "lubjax_variant",
    "newton",
    "picard",
    "explicit_euler",
    "mol",
)
