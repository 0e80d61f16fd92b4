"""What a substrate costs per step: half-space, layer, viscoelastic, viscoelastic layer.

    python -m benchmarks.substrate_cost [--repeat 3]

Issue "Substrates": the layer's matrix is built once per (mesh, H̄, ν) and a layered run should
cost the same per step as a half-space run; a viscoelastic step within 1.5×. One scene (β = 100,
z̄0 = 0.5, t̄ ≤ 5, default Settings with the estimate off, the plain mesh so that every
substrate runs on the same nodes) per substrate, in this process: the influence matrix's build
time (0 where an earlier row built it: matrices are cached per mesh and elastic geometry), the
first call's compile time, the best of ``--repeat`` run times, the attempts (accepted +
rejected) and the run time per attempt against the half-space's, measured in the same run.
Writes benchmarks/out/substrate_cost.md with the machine and its load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from benchmarks._harness import OUT


def main(argv=None):
    import lubjax
    from benchmarks.machine import describe, write_report

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    settings = lubjax.Settings(error_estimate=False, contact_radius=None)
    mesh = settings.mesh()
    sls = dict(stiffening=2.0, tau_bar=1.0)
    cases = [
        ("half-space", lubjax.HalfSpace()),
        ("layer H̄ = 10, bonded, ν = ½", lubjax.Layer(10.0)),
        ("viscoelastic half-space (SLS, E₀/E∞ = 2, τ = t_c)",
         lubjax.Viscoelastic.standard_linear_solid(sls["stiffening"], sls["tau_bar"])),
        ("viscoelastic layer (the same SLS on H̄ = 10)",
         lubjax.Viscoelastic.standard_linear_solid(
             sls["stiffening"], sls["tau_bar"], elastic=lubjax.Layer(10.0))),
    ]
    rows = []
    for label, substrate in cases:
        print(label, "...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        lubjax.stepper.discretise(mesh, substrate)
        build = time.perf_counter() - start
        first = lubjax.relax(100, 0.5, 5.0, substrate=substrate, settings=settings)
        runs = [lubjax.relax(100, 0.5, 5.0, substrate=substrate, settings=settings)
                for _ in range(args.repeat)]
        best = min(runs, key=lambda r: r.run_s)
        attempts = best.accepted + best.rejected
        rows.append((label, build, first.compile_s, best.run_s, best.accepted, best.rejected,
                     best.run_s / attempts, float(best.force.max())))
    base = rows[0][6]
    lines = [
        f"# Cost per step by substrate ({describe()})",
        "",
        f"`python -m benchmarks.substrate_cost --repeat {args.repeat}`: "
        "`relax(100, 0.5, t_end=5)`, "
        f"Settings(error_estimate=False, contact_radius=None): {mesh.r.size} nodes for all; "
        "build = the influence matrix (0: cached from an earlier row), run = best of "
        f"{args.repeat}; load1 {os.getloadavg()[0]:.1f}.",
        "",
        "| substrate | build [s] | compile [s] | run [s] | accepted (rejected) | run per attempt "
        "[ms] | per attempt / half-space | peak F̄ |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for label, build, comp, run, acc, rej, per, peak in rows:
        lines.append(f"| {label} | {build:.2f} | {comp:.2f} | {run:.3f} | {acc} ({rej}) | "
                     f"{per * 1e3:.2f} | {per / base:.2f} | {peak:.4f} |")
    write_report(os.path.join(OUT, "substrate_cost.md"), lines)


if __name__ == "__main__":
    main()
