"""BLAS threads under load: the default run with the library's single-threaded BLAS, and without.

    python -m benchmarks.threads [--repeat 5] [--busy N]

Issue "Error control", item 8: on a loaded machine the CPU LAPACK's threads oversubscribe the
cores and the same run swung from 0.15 s to 33 s. ``lubjax/_threads.py`` limits BLAS to one
thread around the solves (threadpoolctl). This measures what that buys: the default run
(``relax(100, 0.5, t_end=5)``, estimate off so one program is timed) in a fresh process per
variant,

- ``limited``: the library as shipped;
- ``free``: the limit switched off (``LUBJAX_BLAS_LIMIT=0``), OpenBLAS's own thread count,

each on the machine as it is ("quiet") and with ``--busy`` spinning processes (default 2 per
core) started beside it ("loaded"). Reported: best and median run time of ``--repeat`` runs
(compilation excluded: ``Result.run_s``) and the loaded/quiet ratio, with the load averages, so
a machine that was not quiet shows. Writes benchmarks/out/threads.md.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from benchmarks._harness import OUT, ROOT

CHILD = r"""
import json, sys
import lubjax
settings = lubjax.Settings(error_estimate=False)
lubjax.relax(100, 0.5, 5.0, settings=settings)          # compile
runs = [lubjax.relax(100, 0.5, 5.0, settings=settings).run_s for _ in range(int(sys.argv[1]))]
from threadpoolctl import threadpool_info
threads = [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]
print(json.dumps({"runs": runs, "blas_threads": threads}))
"""

SPIN = "import time\nend = time.time() + 600\nwhile time.time() < end: pass\n"


def measure(variant, repeat):
    env = dict(os.environ, PYTHONPATH=ROOT, LUBJAX_BLAS_LIMIT="0" if variant == "free" else "1")
    proc = subprocess.run([sys.executable, "-c", CHILD, str(repeat)], env=env,
                          capture_output=True, text=True, check=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None):
    from benchmarks.machine import describe, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--busy", type=int, default=2 * (os.cpu_count() or 1),
                    help="spinning processes beside the loaded runs (default 2 per core)")
    args = ap.parse_args(argv)
    rows = {}
    for load in ("quiet", "loaded"):
        spinners = []
        if load == "loaded":
            spinners = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(args.busy)]
            time.sleep(2.0)
        try:
            for variant in ("limited", "free"):
                print(f"{load:6s} {variant:7s} ...", file=sys.stderr, flush=True)
                out = measure(variant, args.repeat)
                rows[load, variant] = dict(out, load1=os.getloadavg()[0])
        finally:
            for p in spinners:
                p.kill()
            for p in spinners:
                p.wait()
    machine = describe()
    lines = [
        f"# BLAS threads under load ({machine})",
        "",
        f"`python -m benchmarks.threads --repeat {args.repeat} --busy {args.busy}`: "
        "`relax(100, 0.5, t_end=5)` (estimate off), run time without compilation, "
        f"{args.repeat} runs per cell in a fresh process; loaded = {args.busy} spinning "
        "processes beside it. `limited`: the library (BLAS held to one thread around the "
        "solves); `free`: that limit removed.",
        "",
        "| variant | BLAS pool threads | quiet best / median [s] | loaded best / median [s] | "
        "loaded/quiet (median) | load1 quiet / loaded |",
        "|---|---|---|---|---|---|",
    ]
    for variant in ("limited", "free"):
        q, lo = rows["quiet", variant], rows["loaded", variant]
        qm, lm = statistics.median(q["runs"]), statistics.median(lo["runs"])
        lines.append(
            f"| {variant} | {q['blas_threads']} | {min(q['runs']):.3f} / {qm:.3f} | "
            f"{min(lo['runs']):.3f} / {lm:.3f} | {lm / qm:.2f} | "
            f"{q['load1']:.1f} / {lo['load1']:.1f} |"
        )
    lines += ["", "Run times of every run (s):", ""]
    for (load, variant), r in rows.items():
        lines.append(f"- {load} {variant}: " + ", ".join(f"{x:.3f}" for x in r["runs"]))
    write_report(os.path.join(OUT, "threads.md"), lines)


if __name__ == "__main__":
    main()
