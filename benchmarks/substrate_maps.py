"""Where the richer substrates matter: maps of the error of the default elastic half-space.

    python -m benchmarks.substrate_maps [--quick] [--only viscoelastic|layer] [--z0 0.5,1]

1. Viscoelastic: a relaxation test (ramp to t̄ = 1, hold to t̄ = 5) on a standard linear solid,
   E(t) = E∞ + (E₀ - E∞) e^{-t/τ}, against the elastic half-space at E*∞ (the relaxed modulus,
   the one a long-time measurement gives) and at E*₀ (the instantaneous one): the maximum
   |F̄ - F̄_elastic| over the run relative to the peak, over τ/t_c × E₀/E∞, for β = 54,
   z̄0 = 1 (the paper's d_c = 140 μm test). The 1 % contour marks where the elastic model is no
   longer good enough at either modulus. All members of the map run in one vmap (the solid's
   parameters are traced leaves of the substrate).
2. Layer (needs lubjax/_layer.py): the bonded incompressible layer against the half-space over
   H̄ = H/√(R d_c) × β for z̄0 ∈ {0.5, 1} (``--z0``; --quick: 1 only), one panel each: the
   maximum |F̄_layer - F̄_halfspace| relative to the peak, over t̄ ∈ [0, 5], with the 1 % contour;
   the paper's samples (H = 5 mm, R = 2 mm, d_c = 126-154 μm, β ≈ 41-68; z̄0 = 1.11-0.91) are
   marked on every panel.

Outputs: benchmarks/out/substrate_maps.md and benchmarks/out/substrate_maps.png
(substrate_maps_<only>.md/.png with --only).
"""

from __future__ import annotations

import math
import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from benchmarks import _harness
from benchmarks._harness import OUT, label

SETTINGS = lubjax.Settings(error_estimate=False)
TIMES = np.linspace(0.0, 5.0, 501)
PAPER = dict(radius=2e-3, thickness=5e-3, indents=(126e-6, 140e-6, 154e-6), betas=(41, 54, 68))


def viscoelastic_map(quick):
    beta, z0 = 54.0, 1.0
    taus = np.geomspace(0.01, 100.0, 7 if quick else 13)
    ratios = np.array([1.02, 1.1, 1.5, 3.0] if quick else [1.01, 1.03, 1.1, 1.3, 2.0, 3.0, 5.0])
    plan = lubjax.make_plan(5.0, settings=SETTINGS, times=TIMES)
    elastic = np.asarray(lubjax.force_curve(plan, beta, z0))

    def one(m, tau):
        solid = lubjax.Viscoelastic.standard_linear_solid(m, tau)
        traj = lubjax.stepper.rollout(plan.disc, beta, z0, plan.drive, plan.t_end, plan.tol,
                              substrate=solid)  # fmt: skip
        return lubjax.stepper.evaluate(traj.steps, plan.t, "force"), traj.finished

    M, T = np.meshgrid(ratios, taus, indexing="ij")
    start = time.perf_counter()
    force, finished = jax.jit(jax.vmap(one))(jnp.asarray(M.ravel()), jnp.asarray(T.ravel()))
    force = np.asarray(force).reshape(*M.shape, -1)
    seconds = time.perf_counter() - start
    assert np.all(np.asarray(finished))
    instant = {}
    for m in ratios:  # the elastic solver at E*₀: F̄ = m F̄(mβ)
        instant[m] = m * np.asarray(lubjax.force_curve(plan, m * beta, z0))
    peak = np.max(force, axis=-1)
    err_relaxed = np.max(np.abs(force - elastic), axis=-1) / peak
    err_instant = np.stack([
        np.max(np.abs(force[i] - instant[m]), axis=-1) / peak[i] for i, m in enumerate(ratios)
    ])  # fmt: skip
    return dict(taus=taus, ratios=ratios, relaxed=err_relaxed, instant=err_instant,
                seconds=seconds, beta=beta, z0=z0)  # fmt: skip


def layer_map(quick, z0s=None):
    thick = np.geomspace(1.0, 100.0, 5 if quick else 9)
    betas = np.geomspace(1.0, 1e4, 5 if quick else 9)
    z0s = z0s or ((1.0,) if quick else (0.5, 1.0))
    half = {z0: lubjax.sweep(betas, z0, 5.0, settings=SETTINGS, times=TIMES) for z0 in z0s}
    err = {}
    start = time.perf_counter()
    for z0 in z0s:
        rows = []
        for h in thick:
            layer = lubjax.Layer(float(h), 0.5, "bonded")
            res = lubjax.sweep(betas, z0, 5.0, substrate=layer, settings=SETTINGS, times=TIMES)
            ref = half[z0].force
            rows.append(np.max(np.abs(res.force - ref), axis=1) / np.max(ref, axis=1))
            print(f"  layer H̄={h:.3g} z̄0={z0:g} done", flush=True)
        err[z0] = np.array(rows)
    return dict(thick=thick, betas=betas, err=err, seconds=time.perf_counter() - start)


def paper_points():
    r = PAPER["radius"]
    return [(PAPER["thickness"] / math.sqrt(r * d), b, d) for d, b in
            zip(PAPER["indents"], PAPER["betas"])]  # fmt: skip


def main(argv=None):
    ap = _harness.parser(__doc__)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", choices=("viscoelastic", "layer"))
    ap.add_argument("--z0", help="layer map: comma-separated z̄0 values (default 0.5,1; "
                    "--quick: 1)")
    args = _harness.parse(ap, argv)
    z0s = tuple(float(v) for v in args.z0.split(",")) if args.z0 else None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = [f"Where the richer substrates matter; {time.strftime('%Y-%m-%d')}, {label()}.", ""]
    panels = []
    if args.only in (None, "viscoelastic"):
        print("viscoelastic map ...", flush=True)
        v = viscoelastic_map(args.quick)
        panels.append(("visco", v))
        best = np.minimum(v["relaxed"], v["instant"])
        lines += [
            f"Viscoelastic (standard linear solid), β = {v['beta']:g}, z̄0 = {v['z0']:g}, "
            f"t̄ ∈ [0, 5]: max |F̄ - F̄_elastic| / peak, the elastic model at the better of "
            f"E*∞ and E*₀ ({v['ratios'].size * v['taus'].size} runs in one vmap, "
            f"{v['seconds']:.1f} s with compilation):", "",
            "| E₀/E∞ \\ τ/t_c | " + " | ".join(f"{t:.3g}" for t in v["taus"]) + " |",
            "|---" * (v["taus"].size + 1) + "|",
        ]  # fmt: skip
        for i, m in enumerate(v["ratios"]):
            lines.append(f"| {m:g} | " + " | ".join(f"{e:.1e}" for e in best[i]) + " |")
        lines.append("")
    if args.only in (None, "layer"):
        if not hasattr(lubjax, "Layer"):
            print("this lubjax has no Layer substrate: layer map skipped", flush=True)
        else:
            print("layer map ...", flush=True)
            lay = layer_map(args.quick, z0s)
            panels += [("layer", dict(lay, z0=z0)) for z0 in lay["err"]]
            for z0, err in lay["err"].items():
                lines += [
                    f"Bonded incompressible layer vs half-space, z̄0 = {z0:g}: max |ΔF̄| / peak "
                    f"over t̄ ∈ [0, 5]:", "",
                    "| H̄ \\ β | " + " | ".join(f"{b:.3g}" for b in lay["betas"]) + " |",
                    "|---" * (lay["betas"].size + 1) + "|",
                ]  # fmt: skip
                for i, h in enumerate(lay["thick"]):
                    lines.append(f"| {h:.3g} | " + " | ".join(f"{e:.1e}" for e in err[i]) + " |")
                lines.append("")
            pts = ", ".join(f"H̄ = {h:.1f}, β ≈ {b}" for h, b, _ in paper_points())
            lines += [f"The paper's samples (H = 5 mm): {pts}.", ""]

    fig, axes = plt.subplots(1, len(panels), figsize=(6.5 * len(panels), 4.8), squeeze=False)
    for ax, (kind, d) in zip(axes[0], panels):
        if kind == "visco":
            best = np.minimum(d["relaxed"], d["instant"])
            X, Y = np.meshgrid(d["taus"], d["ratios"])
            cs = ax.contourf(X, Y, np.log10(best), levels=np.arange(-5, 0.01, 0.5), cmap="viridis")
            ax.contour(X, Y, best, levels=[0.01], colors="r", linewidths=2)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_yticks(d["ratios"], [f"{m:g}" for m in d["ratios"]])
            ax.minorticks_off()
            ax.set_xlabel("relaxation time τ / t_c")
            ax.set_ylabel("E₀ / E∞")
            ax.set_title(f"viscoelastic vs elastic (best of E∞, E₀), β = {d['beta']:g}, "
                         f"z̄0 = {d['z0']:g}\nred: 1 % of the peak force", fontsize=9)
            fig.colorbar(cs, ax=ax, label="log10 max|ΔF̄|/peak")
        else:
            z0 = d["z0"]
            X, Y = np.meshgrid(d["betas"], d["thick"])
            err = d["err"][z0]
            cs = ax.contourf(X, Y, np.log10(np.maximum(err, 1e-6)), extend="both",
                             levels=np.arange(-5, 0.01, 0.5), cmap="viridis")  # fmt: skip
            ax.contour(X, Y, err, levels=[0.01], colors="r", linewidths=2)
            for h, b, _dc in paper_points():
                ax.plot(b, h, "w*", ms=12, mec="k")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel("β")
            ax.set_ylabel("H̄ = H/√(R d_c)")
            ax.set_title(f"bonded incompressible layer vs half-space, z̄0 = {z0:g}\n"
                         "red: 1 % of the peak force; stars: the paper's samples", fontsize=9)
            fig.colorbar(cs, ax=ax, label="log10 max|ΔF̄|/peak")
    fig.tight_layout()
    os.makedirs(OUT, exist_ok=True)
    # --only writes beside the full run's files rather than over them.
    stem = "substrate_maps" + (f"_{args.only}" if args.only else "")
    png = os.path.join(OUT, f"{stem}.png")
    fig.savefig(png, dpi=110)
    md = os.path.join(OUT, f"{stem}.md")
    with open(md, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {md} and {png}")


if __name__ == "__main__":
    main()
