"""Regime map over (β, z̄0) with one vmapped sweep: the peak force at t̄ = 1 and the late-hold
force, against the Hertz limit F̄∞ = (2π/3)(1 - z̄0)^{3/2} (eq 16).

    python examples/regime_map.py [--n 12] [--t-hold 100] [--rtol 1e-4] [--dpi 110]
        [--out examples/out/regime_map.png]
"""

from __future__ import annotations

import argparse
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import lubjax  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=12, help="points per axis")
    ap.add_argument("--t-hold", type=float, default=100.0, help="late-hold time t̄")
    ap.add_argument("--rtol", type=float, default=None,
                    help="Settings.rtol of the sweep (default: lubjax's)")
    ap.add_argument("--dpi", type=float, default=110, help="resolution of the PNG")
    ap.add_argument("--out", default="examples/out/regime_map.png")
    args = ap.parse_args(argv)
    betas = np.logspace(-1, 4, args.n)
    z0s = np.linspace(0.2, 2.0, args.n)
    B, Z = np.meshgrid(betas, z0s)
    print(f"sweeping {B.size} cases to t̄ = {args.t_hold:g} ...", file=sys.stderr, flush=True)
    settings = None if args.rtol is None else lubjax.Settings(rtol=args.rtol)
    res = lubjax.sweep(B, Z, args.t_hold, settings=settings)
    print(f"  compile {res.compile_s:.1f} s, run {res.run_s:.1f} s, "
          f"{int((~res.ok).sum())} flagged", file=sys.stderr)
    i1 = np.searchsorted(res.t, 1.0)
    f1 = res.force[:, i1].reshape(B.shape)
    late = res.force[:, -1].reshape(B.shape)
    hertz = lubjax.hertz_force(Z)
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.5))
    im = ax[0].pcolormesh(B, Z, np.log10(np.maximum(f1, 1e-12)), shading="nearest")
    fig.colorbar(im, ax=ax[0], label="log10 F̄(t̄ = 1)")
    ax[0].set_title("peak force (end of loading)")
    ratio = np.where(hertz > 0, late / np.where(hertz > 0, hertz, 1), np.nan)
    im = ax[1].pcolormesh(B, Z, ratio, shading="nearest", vmin=0.9, vmax=1.5, cmap="coolwarm")
    fig.colorbar(im, ax=ax[1], label=f"F̄(t̄ = {args.t_hold:g}) / F̄∞ (Hertz, eq 16)")
    ax[1].set_title("late hold relative to Hertz (z̄0 < 1)")
    # Relative to the peak and floored at 1e-6: below that the decayed force is at the level of
    # BDF2's ~1e-6 oscillation about zero, which a log scale would show as noise.
    peak = res.force.max(axis=1).reshape(B.shape)
    rel = np.log10(np.maximum(late / peak, 1e-6))
    im = ax[2].pcolormesh(B, Z, rel, shading="nearest", vmin=-6, vmax=0)
    fig.colorbar(im, ax=ax[2], label=f"log10 F̄(t̄ = {args.t_hold:g}) / peak F̄ (floor 1e-6)")
    ax[2].set_title("late-hold force relative to peak")
    for a in ax:
        a.set_xscale("log")
        a.axhline(1.0, color="k", ls="--", lw=1)
        # x in axes fractions: the first cell reaches left of betas[0], which would clip it
        a.text(0.02, 1.03, "z̄0 = 1: Hertz limit F̄∞ > 0 below, 0 above", fontsize=7,
               transform=a.get_yaxis_transform())
        a.set_xlabel("β")
        a.set_ylabel("z̄0")
        bad = ~res.ok.reshape(B.shape)
        if bad.any():
            a.plot(B[bad], Z[bad], "kx", label="flagged run")
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    fig.savefig(args.out, dpi=args.dpi)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
