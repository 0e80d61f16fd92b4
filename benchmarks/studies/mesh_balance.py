"""Space against time at one tolerance: is the mesh that ``rtol`` gets balanced with the time
steps it gets? Each run keeps the time tolerance ``rtol`` and takes the base mesh (Δr̄, growth,
L̄; ``lubjax.Settings(rtol=...).mesh_parameters()``) of another tolerance, ``rtol ×
coarsening`` (below 1: a finer mesh), so the steps stay (nearly) the same and only the mesh changes.

    python -m benchmarks.mesh_balance [--coarsening 0.1 0.3 1 3 10] [--rtols 1e-3 1e-4 1e-5]
                                      [--order 3]

If the error hardly moves with the mesh, the time error dominates and the mesh rule
over-resolves that scene (cost per attempt ∝ N^2.4, one dense LU); if it follows the mesh, the
spatial error dominates. Error as in benchmarks/work_precision.py (max |F̄ - F̄_ref| / peak at
its output times, against its cached rtol-1e-8 reference; pointwise where F̄_ref > 1e-3 of its
peak). Run time: the faster of two calls, compilation excluded, single thread. The contact
refinements (rim, dimple) stay those of ``rtol``. About 6 minutes on 2 cores. Writes
benchmarks/out/mesh_balance.md (mesh_balance_order3.md with ``--order 3``: BDF3's steps).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import benchmarks.methods  # noqa: F401  (pins threads before numpy/jax load)

# isort: split
import lubjax
from benchmarks import machine
from benchmarks import work_precision as wp
from benchmarks._harness import OUT

CASES = [(100.0, 0.5), (1e4, 0.5), (100.0, 2.0)]
HORIZONS = (1.0, 5.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--coarsening", type=float, nargs="+", default=[0.1, 0.3, 1.0, 3.0, 10.0])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-3, 1e-4, 1e-5])
    ap.add_argument("--order", type=int, choices=(1, 2, 3), default=2,
                    help="time integrator (Settings.order; default 2, BDF2)")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    times = wp.all_output_times()
    refs = {case: wp.reference(*case)[0] for case in CASES}
    rows = []
    for t_end in HORIZONS:
        keep = times <= t_end + 1e-12
        for beta, z0 in CASES:
            for rtol in args.rtols:
                for coarsening in args.coarsening:
                    dr, growth, length = lubjax.Settings(rtol=rtol * coarsening).mesh_parameters()
                    settings = lubjax.Settings(rtol=rtol, dr=dr, mesh_growth=growth,
                                               length=length, error_estimate=False,
                                               order=args.order)
                    res = lubjax.relax(beta, z0, t_end, settings=settings)
                    run_s = min(res.run_s, lubjax.relax(beta, z0, t_end, settings=settings).run_s)
                    err, point = wp.errors(res.at(times[keep]), refs[(beta, z0)][keep])
                    rows.append((t_end, beta, z0, rtol, coarsening, err, point,
                                 res.accepted + res.rejected, res.r.size, run_s))
                    print(f"t̄ ≤ {t_end:g} β={beta:g} z̄0={z0:g} rtol={rtol:g} mesh of "
                          f"{rtol * coarsening:g}: error {err:.2e}, {res.r.size} nodes, "
                          f"{run_s:.3f} s", file=sys.stderr, flush=True)
    mach = machine.describe()
    command = ("python -m benchmarks.mesh_balance --coarsening "
               + " ".join(f"{c:g}" for c in args.coarsening)
               + " --rtols " + " ".join(f"{r:g}" for r in args.rtols)
               + (f" --order {args.order}" if args.order != 2 else ""))
    lines = [
        f"# Mesh against time steps at one tolerance ({machine.label(mach)})",
        "",
        f"`{command}` ({time.perf_counter() - start:.0f} s in all). Time tolerance rtol, base "
        "mesh of rtol × coarsening; error against benchmarks/work_precision.py's reference.",
        "",
        "| t̄ ≤ | β | z̄0 | rtol | mesh of | error / peak | pointwise | attempts | nodes | "
        "run s |",
        "|---" * 10 + "|",
    ]
    for t_end, beta, z0, rtol, c, err, point, attempts, nodes, run_s in rows:
        lines.append(f"| {t_end:g} | {beta:g} | {z0:g} | {rtol:g} | {rtol * c:g} | {err:.2e} | "
                     f"{point:.2e} | {attempts} | {nodes} | {run_s:.3f} |")
    name = "mesh_balance.md" if args.order == 2 else f"mesh_balance_order{args.order}.md"
    machine.write_report(os.path.join(OUT, name), lines)


if __name__ == "__main__":
    main()
