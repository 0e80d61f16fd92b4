"""Refinement study of the default settings: what accuracy do they buy, and which knob limits it?

    python benchmarks/refinement.py [--quick] [--out benchmarks/out/refinement.md]

For each (β, z̄0) the error of a run is max_t |F̄(t̄) - F̄_ref(t̄)| / max_t |F̄_ref| over the output
times t̄ = 0.05, 0.10, ..., 5 (made grid nodes of every run). The reference is a much finer run
(dr/4, dt/5, mesh and time-step growth 1.02, L̄ = 400); the table also shows the defaults with one
knob refined at a time, and the reference against a half-as-fine run, so the reference's own
error is visible.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import platform
import sys

import numpy as np

import lubjax

T_OUT = np.round(np.arange(0.05, 5.0 + 1e-9, 0.05), 10)


def force_at_outputs(beta, z0, settings):
    plan = lubjax.make_plan(5.0, settings=settings, include=tuple(T_OUT))
    out = lubjax.rollout(plan.disc, beta, z0, plan.travel, plan.coeffs)
    force = np.asarray(out.force)
    idx = np.searchsorted(plan.t, T_OUT)
    assert np.allclose(plan.t[idx], T_OUT)
    return force[idx], float(np.min(out.film_min)), plan.t.size - 1, plan.disc.r.shape[0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer cases, cheaper reference")
    ap.add_argument("--out", default="benchmarks/out/refinement.md")
    args = ap.parse_args(argv)
    default = lubjax.Settings()
    fine = 2 if args.quick else 4
    reference = dataclasses.replace(
        default, dr=default.dr / fine, dt=default.dt / (fine + 1), mesh_growth=1.02,
        time_growth=1.02, length=400.0,
    )
    half_ref = dataclasses.replace(
        default, dr=default.dr / (fine / 2), dt=default.dt / ((fine + 1) / 2), mesh_growth=1.03,
        time_growth=1.04, length=200.0,
    )
    variants = {
        "default": default,
        "dr/2": dataclasses.replace(default, dr=default.dr / 2),
        "dt/2": dataclasses.replace(default, dt=default.dt / 2, time_growth=1.05),
        "L̄×4": dataclasses.replace(default, length=400.0),
        "mesh growth 1.02": dataclasses.replace(default, mesh_growth=1.02),
        "BDF1 (order 1)": dataclasses.replace(default, order=1),
        "half-fine reference": half_ref,
    }
    cases = [(b, z) for b in (1.0, 10.0, 100.0, 1000.0) for z in (0.5, 1.0, 2.0)]
    if args.quick:
        cases = [(100.0, 0.5), (1000.0, 2.0)]
    rows = []
    for beta, z0 in cases:
        print(f"β = {beta:g}, z̄0 = {z0:g}: reference ...", file=sys.stderr, flush=True)
        ref = force_at_outputs(beta, z0, reference)[0]
        scale = np.max(np.abs(ref))
        for name, s in variants.items():
            f, hmin, steps, nodes = force_at_outputs(beta, z0, s)
            err = float(np.max(np.abs(f - ref)) / scale)
            rows.append(dict(beta=beta, z0=z0, variant=name, error=err, steps=steps, nodes=nodes,
                             h_min=hmin))
            print(f"   {name:20s} error {err:.2e}  ({steps} steps, {nodes} nodes)",
                  file=sys.stderr, flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out.replace(".md", ".csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    names = list(variants)
    lines = [
        f"Max error of F̄ over t̄ ∈ [0.05, 5] relative to its peak; reference = {reference}.",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores.",
        "",
        "| β | z̄0 | " + " | ".join(names) + " |",
        "|---|---|" + "---|" * len(names),
    ]
    for beta, z0 in cases:
        errs = [r["error"] for r in rows if r["beta"] == beta and r["z0"] == z0]
        lines.append(f"| {beta:g} | {z0:g} | " + " | ".join(f"{e:.1e}" for e in errs) + " |")
    steps = {r["variant"]: (r["steps"], r["nodes"]) for r in rows}
    lines.append("| steps, nodes | | " + " | ".join(f"{steps[n][0]}, {steps[n][1]}" for n in names)
                 + " |")
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
