"""Where the default run's compile time goes: tracing and lowering against XLA's compile, for
``relax(100, 0.5, 5)``'s run program and its error estimate's coarse-mesh program, one after
the other and side by side in threads (as ``relax`` does), and with extra XLA options.

    python -m benchmarks.compile_breakdown [--repeat 4] [--options '{"xla_...": ...}']

(default ``--options``: ``{"xla_backend_optimization_level": 1}``)

Every measurement is a fresh process (nothing cached), the variants alternating round-robin;
each process also times five runs of the default call (``relax(...).run_s``, median), so an
option that compiles faster but runs slower shows both. Writes
benchmarks/out/compile_breakdown.md. For issue "Error control", item 8 (compile time).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

from benchmarks._harness import OUT, ROOT

CHILD = r"""
import json, sys, time
import lubjax
from lubjax import _compiler, _solve
from lubjax._discretisation import discretise
from lubjax._substrate import as_substrate

mode, options = sys.argv[1], json.loads(sys.argv[2])
_compiler.CPU_OPTIONS.update(options)
_compiler.compiler_options.cache_clear()
beta, z0, t_end = 100.0, 0.5, 5.0
settings = lubjax.Settings()
history = _solve._drive_of(None, None)
substrate = as_substrate(None)
mesh = lubjax.mesh_for(settings, drive=history, beta=beta, z0=z0, t_end=t_end)
programs = {"run": discretise(mesh, substrate), "coarse": discretise(mesh.coarsened(), substrate)}
tol = settings.tolerance()


def lower(disc):
    return _solve._lower_rollout(disc, history, substrate, tol, 0)


out = {}
if mode == "sequential":
    for name, disc in programs.items():
        start = time.perf_counter()
        lowered = lower(disc)
        traced = time.perf_counter()
        _compiler.compile_one(lowered)
        out[name + "_trace_s"] = traced - start
        out[name + "_compile_s"] = time.perf_counter() - traced
    out["total_s"] = sum(out.values())
else:
    start = time.perf_counter()
    _compiler.compile_all([lambda d=d: lower(d) for d in programs.values()])
    out["total_s"] = time.perf_counter() - start
lubjax.relax(beta, z0, t_end)
out["run_s"] = sorted(lubjax.relax(beta, z0, t_end).run_s for _ in range(5))[2]
print(json.dumps(out))
"""

COLUMNS = ("run_trace_s", "run_compile_s", "coarse_trace_s", "coarse_compile_s", "total_s",
           "run_s")


def main(argv=None):
    from benchmarks.machine import label, median_range, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=4)
    ap.add_argument("--options", default='{"xla_backend_optimization_level": 1}',
                    help="extra XLA options (JSON) for the last two variants")
    ap.add_argument("--out", default=os.path.join(OUT, "compile_breakdown.md"))
    args = ap.parse_args(argv)
    variants = [("sequential", "{}"), ("threads", "{}"),
                ("sequential", args.options), ("threads", args.options)]
    results = {v: [] for v in variants}
    for i in range(args.repeat):
        for v in variants:
            proc = subprocess.run([sys.executable, "-c", CHILD, *v], capture_output=True,
                                  text=True, cwd=ROOT, check=True)
            results[v].append(json.loads(proc.stdout.strip().splitlines()[-1]))
            print(f"  {i + 1}/{args.repeat} {v[0]} {v[1]}: {results[v][-1]}", flush=True)

    def cell(rows, key):
        return median_range(r[key] for r in rows) if key in rows[0] else "—"

    lines = [
        "# Compile time of the default run, by program and phase",
        "",
        f"`python -m benchmarks.compile_breakdown --repeat {args.repeat} --options "
        f"'{args.options}'`; {label()}. Fresh processes, variants alternating; median (min–max)"
        " in seconds. The default compiler options are lubjax/_compiler.py's CPU_OPTIONS.",
        "",
        "| compiled | extra XLA options | " + " | ".join(COLUMNS) + " |",
        "|---|---|" + "---|" * len(COLUMNS),
    ]
    for (mode, options), rows in results.items():
        lines.append(f"| {mode} | `{options}` | "
                     + " | ".join(cell(rows, k) for k in COLUMNS) + " |")
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
