"""What every standing benchmark shares: its command line, thread pinning, the machine stamp and
where its outputs go.

Run the benchmarks as modules from the repository root, ``python -m benchmarks.NAME``; each
writes under ``benchmarks/out/`` unless told ``--out``. ::

    from benchmarks import _harness

    def main(argv=None):
        ap = _harness.parser(__doc__, "accuracy.md", quick="β ∈ {10, 1000} only")
        ap.add_argument(...)                       # the benchmark's own options
        args = _harness.parse(ap, argv)            # pins the threads, prints the machine
        ...
        _harness.write_report(args.out, lines)     # lines may quote _harness.command(argv)

Threads: BLAS and XLA:CPU get ``--threads`` threads (default ``LUBJAX_BENCH_THREADS``, else 1):
on shared 2-core machines a default OpenBLAS pool made a 214×214 solve ~20x slower than one
thread. The machine stamp (``machine.label``) records the CPU, cores, threads and load.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time

from .machine import describe, label, median_range, write_report

__all__ = ["DATA", "OUT", "ROOT", "command", "describe", "label", "median_range", "parse",
           "parser", "pin_threads", "timed", "write_report"]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "benchmarks", "out")
DATA = os.path.join(ROOT, "data")


def pin_threads(threads: int | str | None = None) -> int:
    """Give BLAS and XLA:CPU ``threads`` threads (default: ``LUBJAX_BENCH_THREADS``, else 1).

    Environment variables reach libraries not loaded yet and the subprocesses a benchmark
    starts; threadpoolctl resets the BLAS already loaded; XLA reads its flags when JAX starts
    its CPU backend (the first computation), so call this before any."""
    n = int(threads if threads is not None else os.environ.get("LUBJAX_BENCH_THREADS", "1"))
    if n < 1:
        raise ValueError(f"threads must be at least 1, got {n}")
    os.environ["LUBJAX_BENCH_THREADS"] = str(n)
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(n)
    flags = os.environ.get("XLA_FLAGS", "")
    if n == 1 and "multi_thread_eigen" not in flags:
        os.environ["XLA_FLAGS"] = (flags + " --xla_cpu_multi_thread_eigen=false "
                                   "intra_op_parallelism_threads=1").strip()
    if "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=n, user_api="blas")
    return n


def parser(doc: str, out: str | None = None, quick: str | None = None) -> argparse.ArgumentParser:
    """The benchmark's parser: its docstring as the help text, ``--threads``, and ``--out``
    (default ``benchmarks/out/<out>``) and ``--quick`` (help text ``quick``) where given."""
    first, _, rest = doc.strip().partition("\n\n")
    ap = argparse.ArgumentParser(prog=_prog(), description=first, epilog=rest or None,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=None,
                    help="BLAS and XLA:CPU threads (default: LUBJAX_BENCH_THREADS, else 1)")
    if out is not None:
        ap.add_argument("--out", default=os.path.join(OUT, out),
                        help=f"output file (default: benchmarks/out/{out})")
    if quick is not None:
        ap.add_argument("--quick", action="store_true", help=f"a short run: {quick}")
    return ap


def parse(ap: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse, pin the threads, make the output folder and print the machine stamp."""
    args = ap.parse_args(argv)
    args.threads = pin_threads(args.threads)
    if getattr(args, "out", None):
        os.makedirs(os.path.dirname(os.path.abspath(args.out)) or ".", exist_ok=True)
    print(f"{ap.prog}: {label()}", file=sys.stderr, flush=True)
    return args


def _prog() -> str:
    """``python -m benchmarks.X`` for the module running as the program."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    name = spec.name if spec is not None else os.path.splitext(os.path.basename(sys.argv[0]))[0]
    return f"python -m {name}"


def command(argv=None) -> str:
    """The command that reproduces this run, as a report quotes it: ``python -m benchmarks.X
    ARGS`` (``argv`` default: this process's arguments)."""
    args = sys.argv[1:] if argv is None else list(argv)
    return " ".join([_prog(), *map(shlex.quote, args)])


def timed(fn, *args, repeat: int = 3):
    """``fn(*args)`` once cold, then ``repeat`` times warm (each to ``jax.block_until_ready``):
    (its output, the first call's seconds, the best warm call's seconds)."""
    import jax  # not at import: pin_threads must run before JAX starts its CPU backend

    start = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    first = time.perf_counter() - start
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - start)
    return out, first, min(times)
