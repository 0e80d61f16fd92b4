"""The default run's cost: compile and run time against the tolerance, estimate on and off.

    python -m benchmarks.default_run [--repeat 5]

Issue "Error control", item 8 asks the default run (β = 100, z̄0 = 0.5, t̄ ≤ 5) for no more than
0.16 s run and 0.9 s compile on a quiet 2-core machine (the figures of the old hand-tuned
grid, whose error there was up to 4.8e-3 of the peak). Each row is a fresh process (so the
first call compiles): ``lubjax.relax(100, 0.5, 5)`` at ``Settings(rtol=…, error_estimate=…)``,
the first call's compile time (``Result.compile_s``), the best and median run time of
``--repeat`` further calls (``Result.run_s``), the first call's wall time (what a fresh process
waits for), steps, nodes, and the error against a reference at rtol 1e-7
(benchmarks/accuracy.py's settings, cached in benchmarks/out/cache). Each row also runs a
process with ``LUBJAX_XLA_OPTIONS=0`` (XLA's default CPU fusion emitters, the compile before
lubjax/_compiler.py), so the ratio comes from the same run.
Writes benchmarks/out/default_run.md with the machine and its load averages.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile

from benchmarks import _harness
from benchmarks._harness import OUT, ROOT

CHILD = r"""
import json, sys, os, time
import numpy as np, lubjax
rtol, estimate, repeat = float(sys.argv[1]), sys.argv[2] == "on", int(sys.argv[3])
if len(sys.argv) > 4:  # the CLIs' persistent compilation cache, in this folder
    lubjax.enable_compilation_cache(sys.argv[4])
settings = lubjax.Settings(rtol=rtol, error_estimate=estimate)
start = time.perf_counter()
first = lubjax.relax(100, 0.5, 5.0, settings=settings)
first_call_s = time.perf_counter() - start
runs = [lubjax.relax(100, 0.5, 5.0, settings=settings).run_s for _ in range(repeat)]
t = np.linspace(0.01, 5.0, 500)
print(json.dumps({"compile_s": first.compile_s, "first_run_s": first.run_s, "runs": runs,
                  "first_call_s": first_call_s,
                  "steps": first.accepted, "rejected": first.rejected, "nodes": int(first.r.size),
                  "force": first.at(t).tolist(), "load1": os.getloadavg()[0]}))
"""


def main(argv=None):
    import numpy as np

    from benchmarks import accuracy
    from benchmarks._harness import describe, write_report

    ap = _harness.parser(__doc__)
    ap.add_argument("--repeat", type=int, default=5)
    args = _harness.parse(ap, argv)
    t = np.linspace(0.01, 5.0, 500)
    ref = accuracy.reference(100.0, 0.5, accuracy.REFERENCE, "ref")
    ref_force = np.interp(t, accuracy.T_OUT, ref["force"])
    peak = np.max(np.abs(ref_force))
    def child(rtol, estimate, *cache, **env):
        proc = subprocess.run(
            [sys.executable, "-c", CHILD, str(rtol), estimate, str(args.repeat), *cache],
            env=dict(os.environ, PYTHONPATH=ROOT, **env), capture_output=True, text=True,
            check=True,
        )
        return json.loads(proc.stdout.strip().splitlines()[-1])

    rows = []
    for rtol in (1e-2, 1e-3, 3e-4, 1e-4):
        for estimate in ("off", "on"):
            print(f"rtol {rtol:g}, estimate {estimate} ...", file=sys.stderr, flush=True)
            out = child(rtol, estimate)
            # As a repeated `lubjax relax` runs it: the persistent cache filled by one process,
            # read by the next (only its compile time is reported).
            with tempfile.TemporaryDirectory() as cache:
                child(rtol, estimate, cache)
                out["cached_compile_s"] = child(rtol, estimate, cache)["compile_s"]
            # XLA's default CPU fusion emitters (lubjax/_compiler.py switched off), same run.
            out["xla_default"] = child(rtol, estimate, LUBJAX_XLA_OPTIONS="0")
            err = np.max(np.abs(np.asarray(out["force"]) - ref_force)) / peak
            rows.append((rtol, estimate, out, err))
    lines = [
        f"# The default run's cost ({describe()})",
        "",
        f"`python -m benchmarks.default_run --repeat {args.repeat}`: `relax(100, 0.5, t_end=5)`, "
        "a fresh process per row; compile = the first call's `compile_s`; run = best / median of "
        f"{args.repeat} further calls' `run_s`; error = max |F̄ - F̄_ref| / peak on t̄ ∈ [0.01, 5] "
        "against benchmarks/accuracy.py's reference (rtol 1e-7). Defaults: rtol 1e-4, estimate on. "
        "compile, cache = the same in a process whose persistent compilation cache (what the "
        "`lubjax` CLI turns on) an earlier process filled. first call = the first call's wall "
        "time (compile, run and everything else a fresh process pays). XLA defaults = the same "
        "in a fresh process with `LUBJAX_XLA_OPTIONS=0` (XLA's default CPU fusion emitters: "
        "lubjax/_compiler.py).",
        "",
        "| rtol | estimate | compile [s] | first call [s] | compile / first call / run median, "
        "XLA defaults [s] | compile, cache [s] | run best / median [s] | "
        "steps (rejected) | nodes | error / peak | load1 |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for rtol, estimate, out, err in rows:
        xd = out["xla_default"]
        lines.append(
            f"| {rtol:g} | {estimate} | {out['compile_s']:.2f} | {out['first_call_s']:.2f} | "
            f"{xd['compile_s']:.2f} / {xd['first_call_s']:.2f} / "
            f"{statistics.median(xd['runs']):.3f} | {out['cached_compile_s']:.2f} | "
            f"{min(out['runs']):.3f} / "
            f"{statistics.median(out['runs']):.3f} | {out['steps']} ({out['rejected']}) | "
            f"{out['nodes']} | {err:.1e} | {out['load1']:.1f} |"
        )
    write_report(os.path.join(OUT, "default_run.md"), lines)


if __name__ == "__main__":
    main()
