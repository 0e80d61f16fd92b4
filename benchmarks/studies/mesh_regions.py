"""Where on the mesh the spatial error lives: the mesh ``relax`` uses for a tolerance, with the
cells of one radial band split in two (every other band unchanged), run at a time tolerance far
below the mesh's error, against benchmarks/work_precision.py's cached reference.

    python -m benchmarks.mesh_regions [--rtols 1e-4 1e-5] [--time-rtol 1e-8] [--order 2]

A band whose refinement lowers the error a lot carries much of it; one whose refinement changes
nothing is over-resolved for that scene (its nodes cost LU work, ∝ N³, for nothing). Bands:
inside the contact, around its edge (r̄ = √(1 - z̄0) ≈ 0.71 for z̄0 = 0.5 at the end of the
ramp), the rest of the uniform fine zone (r̄ ≤ 1.6), the start of the growing cells, and the
far field. "base" is the mesh as it is; "coarsen" rows drop every other node of a band instead.
``--trade`` runs, instead of the bands, base and meshes that move nodes from the fine zone to the
first growing cells: Δr̄ of the fine zone × 1.15 or × 1.4, with the cells of [1.6, 10] split.
Error as in work_precision.py: max |F̄ - F̄_ref| / peak at its output times, pointwise where
F̄_ref > 1e-3 of its peak. Run time: the second call of a jitted ``force_curve`` (forward
mode), single thread, so it compares the bands, not the speed. About 25 minutes on 2 cores
(the default time tolerance 1e-8 takes thousands of BDF2 steps; ``--trade`` ~8 minutes). Writes
benchmarks/out/mesh_regions.md (mesh_regions_trade.md with ``--trade``).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

import benchmarks.methods  # noqa: F401  (pins threads before numpy/jax load)

# isort: split
import jax

import lubjax
from benchmarks import machine
from benchmarks import work_precision as wp
from benchmarks._harness import OUT

SCENES = [(100.0, 0.5, 1.0), (100.0, 0.5, 5.0), (100.0, 2.0, 5.0)]
BANDS = [(0.0, 0.6), (0.6, 0.85), (0.85, 1.2), (1.2, 1.6), (1.6, 4.0), (4.0, 10.0),
         (10.0, np.inf)]
TRADE_FACTORS = (1.15, 1.4)
#: The scenes' drive: the ramp and hold as a prescribed travel (what relax makes of a history).
RAMP = lubjax.Travel(lubjax.RampHold())


def refined(mesh: lubjax.Mesh, lo: float, hi: float) -> lubjax.Mesh:
    """``mesh`` with every cell whose midpoint lies in [lo, hi] split at its midpoint."""
    r = np.asarray(mesh.r)
    mid = 0.5 * (r[:-1] + r[1:])
    extra = mid[(mid >= lo) & (mid <= hi)]
    return lubjax.Mesh(tuple(float(x) for x in np.sort(np.concatenate([r, extra]))))


def coarsened(mesh: lubjax.Mesh, lo: float, hi: float) -> lubjax.Mesh:
    """``mesh`` without every other interior node in (lo, hi)."""
    r = np.asarray(mesh.r)
    inside = 1 + np.flatnonzero((r[1:-1] > lo) & (r[1:-1] < hi))
    drop = set(inside[1::2].tolist())
    return lubjax.Mesh(tuple(float(x) for i, x in enumerate(r) if i not in drop))


def run(mesh, settings, beta, z0, t_end, t_out):
    plan = lubjax.Plan(lubjax.stepper.discretise(mesh), settings.tolerance(), lubjax.RampHold(),
                       t_end, t_out, mesh)
    curve = jax.jit(lambda b, z: lubjax.force_curve(plan, b, z))
    curve(beta, z0).block_until_ready()
    start = time.perf_counter()
    force = np.asarray(curve(beta, z0).block_until_ready())
    return force, time.perf_counter() - start


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-4, 1e-5],
                    help="tolerances whose relax mesh is examined")
    ap.add_argument("--time-rtol", type=float, default=1e-8,
                    help="time tolerance of every run (far below the meshes' errors)")
    ap.add_argument("--order", type=int, choices=(1, 2, 3), default=2)
    ap.add_argument("--trade", action="store_true",
                    help="a coarser fine zone with the first growing cells split, not the bands")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    times = wp.all_output_times()
    rows = []
    for beta, z0, t_end in SCENES:
        ref_all = wp.reference(beta, z0)[0]
        t_out = wp.output_times(t_end)
        ref = ref_all[np.isin(np.round(times, 12), np.round(t_out, 12))]
        for rtol in args.rtols:
            mesh_settings = lubjax.Settings(rtol=rtol, error_estimate=False)
            base = lubjax.mesh_for(mesh_settings, drive=RAMP, beta=beta, z0=z0, t_end=t_end)
            settings = dataclasses.replace(mesh_settings, rtol=args.time_rtol, order=args.order)
            variants = [("base", base)]
            if args.trade:
                dr = mesh_settings.mesh_parameters()[0]
                for factor in TRADE_FACTORS:
                    coarser = dataclasses.replace(mesh_settings, dr=dr * factor)
                    mesh = lubjax.mesh_for(coarser, drive=RAMP, beta=beta, z0=z0, t_end=t_end)
                    variants.append((f"Δr̄ × {factor:g}, split [1.6, 10]",
                                     refined(mesh, 1.6, 10.0)))
            else:
                variants += [(f"refine [{lo:g}, {hi:g}]", refined(base, lo, hi))
                             for lo, hi in BANDS]
                variants += [(f"coarsen [{lo:g}, {hi:g}]", coarsened(base, lo, hi))
                             for lo, hi in BANDS[:1]]
            for label, mesh in variants:
                force, run_s = run(mesh, settings, beta, z0, t_end, t_out)
                err, point = wp.errors(force, ref)
                rows.append((beta, z0, t_end, rtol, label, mesh.size, err, point, run_s))
                print(f"β={beta:g} z̄0={z0:g} t̄ ≤ {t_end:g} mesh of rtol {rtol:g} {label:22s} "
                      f"N={mesh.size:4d} error {err:.2e} pointwise {point:.2e} {run_s:.2f} s",
                      file=sys.stderr, flush=True)
    mach = machine.describe()
    command = ("python -m benchmarks.mesh_regions --rtols "
               + " ".join(f"{r:g}" for r in args.rtols) + f" --time-rtol {args.time_rtol:g}"
               + (f" --order {args.order}" if args.order != 2 else "")
               + (" --trade" if args.trade else ""))
    lines = [
        f"# Where the spatial error lives ({machine.label(mach)})",
        "",
        f"`{command}` ({time.perf_counter() - start:.0f} s in all). The mesh `relax` uses at "
        "rtol (with its contact refinements), "
        + ("and that of a fine zone 1.15 or 1.4 times coarser with the cells of [1.6, 10] split"
           if args.trade else "one band's cells split (or every other node dropped)")
        + f", time tolerance {args.time_rtol:g}; error against "
        "benchmarks/work_precision.py's reference.",
        "",
        "| β | z̄0 | t̄ ≤ | mesh of rtol | variant | nodes | error / peak | pointwise | run s |",
        "|---" * 9 + "|",
    ]
    for beta, z0, t_end, rtol, label, nodes, err, point, run_s in rows:
        lines.append(f"| {beta:g} | {z0:g} | {t_end:g} | {rtol:g} | {label} | {nodes} | "
                     f"{err:.2e} | {point:.2e} | {run_s:.2f} |")
    name = "mesh_regions_trade.md" if args.trade else "mesh_regions.md"
    machine.write_report(os.path.join(OUT, name), lines)


if __name__ == "__main__":
    main()
