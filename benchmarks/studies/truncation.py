"""Domain truncation against the tolerance: the force error of cutting the domain at the L̄ that
each rtol gets, against the same mesh continued to a domain 20x longer.

    python -m benchmarks.truncation [--out benchmarks/out/truncation.md]

The truncation drops the r̄⁻⁴ pressure tail, ≈ 4z̄/L̄² of the force (docs/model.md); the mesh rule
(lubjax._mesh.mesh_from_tolerance) keeps that below rtol/8 for z̄ ≤ 1. Cases: β = 100 at
z̄0 ∈ {0.5, 2} (z̄0 = 2 keeps the film widest, z̄ = 1 in the hold), ramp and hold to t̄ = 5, the
error max |F̄_L - F̄_20L| over 501 times relative to the peak, and pointwise where F̄ > 10⁻⁶ peak.
Both runs take their time steps at rtol = 1e-7 (TIME_RTOL), so that what differs is the domain
alone and not which steps two controllers chose (those differ by ~rtol themselves).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import lubjax
from benchmarks.machine import label, write_report

RTOLS = (1e-2, 1e-3, 1e-4, 1e-5)
TIME_RTOL = 1e-7
Z0S = (0.5, 2.0)
TIMES = np.linspace(0.0, 5.0, 501)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="benchmarks/out/truncation.md")
    args = ap.parse_args(argv)
    lines = [
        f"Domain truncation at the L̄ of each tolerance, against 20 L̄ (β = 100, t̄ ≤ 5); "
        f"{time.strftime('%Y-%m-%d')}, {label()}.",
        "",
        "| rtol | L̄ | z̄0 | max ΔF̄/peak | pointwise ΔF̄/F̄ | below rtol |",
        "|---|---|---|---|---|---|",
    ]
    for rtol in RTOLS:
        dr, growth, length = lubjax.Settings(rtol=rtol).mesh_parameters()
        for z0 in Z0S:
            forces = []
            for factor in (1.0, 20.0):
                settings = lubjax.Settings(rtol=TIME_RTOL, dr=dr, mesh_growth=growth,
                                           length=factor * length, error_estimate=False,
                                           contact_radius=None, max_steps=100_000)  # fmt: skip
                forces.append(lubjax.relax(100.0, z0, 5.0, settings=settings).at(TIMES))
            cut, long = forces
            peak = np.max(np.abs(long))
            big = np.abs(long) > 1e-6 * peak
            err = np.max(np.abs(cut - long)) / peak
            rel = np.max(np.abs(cut[big] / long[big] - 1))
            lines.append(f"| {rtol:g} | {length:.0f} | {z0:g} | {err:.1e} | {rel:.1e} | "
                         f"{'yes' if err < rtol else 'no'} |")
            print(lines[-1], flush=True)
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
