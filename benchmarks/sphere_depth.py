"""Where the sphere's true profile matters: the force against the depth δ/R, paraboloid against
sphere, with and without a film.

    python -m benchmarks.sphere_depth [--png docs/figures/sphere_depth.png]

One ramp to d_c = R (ε = d_c/R = 1) from z̄0 = 0.02, so the depth δ/R = ε (t̄ - z̄0) runs to 0.98,
at β = 10⁸ (near dry: the film left is ~10⁻⁵ d_c) and β = 10³ (a film the ramp squeezes, still
thin against d_c; an AFM tip in water, E ~ 1 kPa, R = 10 μm, d_c = 2 μm, v = 1 μm/s, has β ~ 10⁴;
at β ~ 10 the film would be as thick as d_c = R itself, no longer a thin film),
with ``lubjax.Paraboloid()`` and ``lubjax.Sphere(1.0)``, the default settings (no error
estimate). Forces in units of E* R² (F = (2/π) ε^{3/2} F̄ E* R², eq 11b), against Hertz's
(4/3)(δ/R)^{3/2} and Sneddon's rigid sphere (``lubjax.sneddon_sphere``). The table gives, at
depths from 0.01 R to 0.9 R, how far the paraboloid is from the sphere (dry: Hertz over Sneddon)
and how far each near-dry run is from its closed form. Writes benchmarks/out/sphere_depth.md
and the chart (``--png``, default benchmarks/out/sphere_depth.png).
"""

from __future__ import annotations

import os
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

import lubjax  # noqa: E402
from benchmarks import _harness  # noqa: E402
from lubjax._checks import MAX_TRAVEL_OVER_RADIUS  # noqa: E402

EPS, Z0 = 1.0, 0.02
BETAS = {"dry (β = 10⁸)": 1e8, "film (β = 10³)": 1e3}
SHAPES = {"paraboloid": lubjax.Paraboloid(), "sphere": lubjax.Sphere(EPS)}
DEPTHS = (0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 0.9)


def sneddon_force(depth):
    """Sneddon's F/(E* R²) at δ/R = ``depth`` (the contact radius solved from δ)."""
    if depth <= 0:
        return 0.0
    a = brentq(lambda x: lubjax.sneddon_sphere(x)[0] - depth, 1e-12, 1 - 1e-15, xtol=1e-15)
    return float(lubjax.sneddon_sphere(a)[1])


def hertz_force(depth):
    """Hertz's F/(E* R²) = (4/3)(δ/R)^{3/2}."""
    return 4.0 / 3.0 * np.clip(depth, 0.0, None) ** 1.5


def runs(times):
    """{(film label, shape): (F/(E* R²) at ``times``, seconds)}."""
    settings = lubjax.Settings(error_estimate=False)
    out = {}
    for film, beta in BETAS.items():
        for name, shape in SHAPES.items():
            start = time.perf_counter()
            res = lubjax.relax(beta, Z0, 1.0, settings=settings, indenter=shape)
            force = np.asarray(res.at(times)) * 2.0 / np.pi * EPS**1.5
            out[film, name] = force, time.perf_counter() - start
            print(f"{film}, {name}: {res.accepted} steps, {out[film, name][1]:.1f} s",
                  flush=True)
    return out


def chart(path, depth, forces):
    fig, (ax, rel) = plt.subplots(1, 2, figsize=(11, 4.4))
    fine = np.linspace(0, depth[-1], 400)
    ax.plot(fine, hertz_force(fine), "k--", lw=1, label="Hertz (paraboloid, dry)")
    ax.plot(fine, [sneddon_force(d) for d in fine], "k:", lw=1.5, label="Sneddon (sphere, dry)")
    styles = {"paraboloid": "C0", "sphere": "C3"}
    for (film, name), (force, _) in forces.items():
        ls = "-" if film.startswith("dry") else "-."
        ax.plot(depth, force, ls, color=styles[name], lw=1.4, label=f"lubjax {name}, {film}")
    ax.axvline(MAX_TRAVEL_OVER_RADIUS, color="grey", lw=0.8)
    ax.text(0.205, 0.02, "paraboloid's limit 0.2 R", rotation=90, color="grey", fontsize=8,
            transform=ax.get_xaxis_transform())
    ax.set(xlabel="depth δ/R", ylabel="force F/(E* R²)", xlim=(0, depth[-1]), ylim=(0, None),
           title=f"ramp to d_c = R from z̄0 = {Z0:g}")
    ax.legend(fontsize=8)
    mask = depth > 0.005
    for film in BETAS:
        ratio = forces[film, "paraboloid"][0][mask] / forces[film, "sphere"][0][mask] - 1
        ls = "-" if film.startswith("dry") else "-."
        rel.loglog(depth[mask], ratio, ls, color="C2", label=f"lubjax, {film}")
    ref = np.geomspace(0.005, depth[-1], 200)
    rel.loglog(ref, hertz_force(ref) / np.array([sneddon_force(d) for d in ref]) - 1, "k:",
               lw=1.5, label="Hertz / Sneddon - 1")
    for y, text in ((1e-2, "1 %"), (1e-4, "default rtol")):
        rel.axhline(y, color="grey", lw=0.6, ls="--")
        rel.text(0.006, y * 1.15, text, fontsize=8, color="grey")
    rel.axvline(MAX_TRAVEL_OVER_RADIUS, color="grey", lw=0.8)
    rel.set(xlabel="depth δ/R", ylabel="paraboloid / sphere - 1 (force)",
            title="how much the paraboloid overestimates")
    rel.legend(fontsize=8)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)


def main(argv=None):
    ap = _harness.parser(__doc__, "sphere_depth.md")
    ap.add_argument("--png", default=os.path.join(_harness.OUT, "sphere_depth.png"),
                    help="the chart (default benchmarks/out/sphere_depth.png)")
    args = _harness.parse(ap, argv)
    times = np.linspace(Z0, 1.0, 491)
    depth = EPS * (times - Z0)
    forces = runs(times)
    chart(args.png, depth, forces)
    lines = [
        "# Where the sphere's true profile matters", "",
        f"`{_harness.command(argv)}`; {_harness.label()}", "",
        f"Ramp to d_c = R (ε = {EPS:g}) from z̄0 = {Z0:g}; forces F/(E* R²). Errors: near-dry "
        "runs (β = 10⁸) against Hertz (paraboloid) and Sneddon (sphere); the paraboloid's "
        "excess over the sphere, dry and with the film of β = 10³.", "",
        "| δ/R | Sneddon | Hertz/Sneddon - 1 | sphere β=10⁸ vs Sneddon | paraboloid β=10⁸ vs "
        "Hertz | paraboloid/sphere - 1, β = 10³ |",
        "|---|---|---|---|---|---|",
    ]
    dry, film = list(BETAS)
    for d in DEPTHS:
        i = int(np.argmin(np.abs(depth - d)))
        s, h = sneddon_force(depth[i]), hertz_force(depth[i])
        lines.append(
            f"| {depth[i]:.3g} | {s:.5g} | {h / s - 1:.2e} | "
            f"{forces[dry, 'sphere'][0][i] / s - 1:.1e} | "
            f"{forces[dry, 'paraboloid'][0][i] / h - 1:.1e} | "
            f"{forces[film, 'paraboloid'][0][i] / forces[film, 'sphere'][0][i] - 1:.2e} |")
    cost = ", ".join(f"{k[1]} {k[0]} {v[1]:.1f} s" for k, v in forces.items())
    lines += ["", f"Run times (compile included): {cost}.", "", f"Chart: `{args.png}`."]
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()
