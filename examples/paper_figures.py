"""Regenerate the analogues of the paper's Figs 3-6 as PNGs.

    python examples/paper_figures.py [--out examples/out] [--rtol 1e-4] [--dpi 110] [--no-fig3]

Fig 3: pressure at t̄ = 5 and force for β = 100, z̄0 = 0.5 under refinement of the tolerance
(which sets the steps and the mesh), of the fine zone's spacing and of the domain, and on the
paper's uniform L̄ = 4 mesh. Figs 4-6: pressure, film thickness and substrate
displacement at several times for β = 100 and z̄0 = 0.5, 1, 2 (solid: loading, dashed: hold;
for z̄0 = 2, where the sphere stops short of the surface, the hold times resolve the pressure's
decay on t_R = t_c/β), with the short-time rigid-squeeze (eq 12b) and long-time Hertz (eq 14)
asymptotes in Fig 4a; axes and legends say in words what each dimensionless quantity is.
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

TIMES = (0.2, 0.4, 0.6, 0.8, 1.0, 1.5, 2.0, 3.0, 5.0)
#: Hold times of a sphere that stops short of the surface (z̄0 > 1), after the stop at t̄ = 1 in
#: units of t_R = t_c/β: with no contact the film's pressure is gone within a few t_R (at β = 100
#: it is 1e-8 of its peak by t̄ = 1.05), so the hold times of ``TIMES`` would all draw p̄ = 0.
SHORT_HOLD = (0.1, 0.25, 0.5, 1.0)
BETA = 100.0


def profile_times(beta, z0):
    """``TIMES``, or for z̄0 > 1 the loading times and hold times that resolve the decay."""
    if z0 <= 1.0:
        return TIMES
    return tuple(t for t in TIMES if t <= 1.0) + tuple(1.0 + k / beta for k in SHORT_HOLD)


def _profiles(beta, z0, settings=None):
    return lubjax.relax(beta, z0, t_end=5.0, profile_times=profile_times(beta, z0),
                        settings=settings)


#: Each profile figure: file, Result field, and its quantity in words (the paper's
#: dimensionless variables, eqs 7-8: lengths in d_c, radii in √(R d_c), pressure in
#: (2E*/π)√(d_c/R), time in t_c = d_c/v0).
PROFILES = (
    ("fig4_pressure.png", "pressure", "film pressure  p̄ = p / ((2E*/π)·√(d_c/R))"),
    ("fig5_film.png", "film", "film thickness  h̄ = h / d_c"),
    ("fig6_displacement.png", "displacement", "surface displacement  w̄ = w / d_c"),
)
RADIUS_LABEL = "radius  r̄ = r / √(R d_c)"
HERTZ_LABEL = "Hertz contact (long-time limit)"
SQUEEZE_LABEL = "rigid sphere squeezing the film (short-time limit)"
SUPTITLE = ("{what} at β = {beta:g} as the sphere is pushed in to depth d_c (solid, "
            "t̄ = t v0/d_c ≤ 1) and held (dashed); z̄0 = initial gap / d_c")


def profile_figure(results: dict, field: str, label: str):
    """One profile figure (a panel per z̄0 of ``results``, {z̄0: Result}), its axes and legends
    in words; the pressure's z̄0 = 0.5 panel with the Hertz and rigid-squeeze limits."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
    for ax, (z0, res) in zip(axes, results.items()):
        sel = res.r <= 2.0
        colors = plt.cm.viridis(np.linspace(0, 0.9, len(res.profile_times)))
        for c, t, prof in zip(colors, res.profile_times, getattr(res, field)):
            ls = "-" if t <= 1.0 else "--"
            hold = (t - 1.0) * BETA
            curve = (f"t̄ = {t:g}" if z0 <= 1.0 or t <= 1.0
                     else f"t̄ = 1 + {hold:.2g} t_R")
            ax.plot(res.r[sel], prof[sel], ls=ls, color=c, label=curve)
        if field == "pressure" and z0 == 0.5:
            ax.plot(res.r[sel], lubjax.hertz_pressure(res.r[sel], z0), "ko", ms=3,
                    markevery=4, label=HERTZ_LABEL)
            for t in (0.2, 0.4):
                ax.plot(res.r[sel], lubjax.rigid_squeeze_pressure(res.r[sel], z0 - t, -1, 100),
                        "rx", ms=3, markevery=4, label=SQUEEZE_LABEL if t == 0.2 else None)
        if field == "film":
            ax.set_ylim(0, 2.2 if z0 < 2 else 3.2)
        title = f"initial gap z̄0 = {z0:g}"
        if z0 > 1.0:
            title += " (no contact: the hold decays on t_R = t_c/β)"
        ax.set_title(title, fontsize=10 if z0 > 1.0 else 12)
        ax.set_xlabel(RADIUS_LABEL)
        ax.set_ylabel(label)
    # the pressure falls to zero outside the contact: its legends go there, clear of the curves
    loc = "upper right" if field == "pressure" else "best"
    axes[0].legend(fontsize=7, ncol=2, loc=loc)
    axes[2].legend(fontsize=7, ncol=2, loc=loc)
    fig.suptitle(SUPTITLE.format(what=label.split("  ")[0].capitalize(), beta=BETA),
                 fontsize=11)
    fig.tight_layout()
    return fig


def figs_4_to_6(out, settings=None, dpi=110):
    results = {}
    for z0 in (0.5, 1.0, 2.0):
        print(f"  β = {BETA:g}, z̄0 = {z0}", file=sys.stderr)
        results[z0] = _profiles(BETA, z0, settings)
    for name, field, label in PROFILES:
        fig = profile_figure(results, field, label)
        fig.savefig(os.path.join(out, name), dpi=dpi)
        plt.close(fig)


def fig3_refinement(out):
    """The default run under refinement of its one knob (rtol, which also sets the mesh), of the
    fine zone's spacing alone, of the domain, and on the paper's uniform L̄ = 4 mesh."""
    base = lubjax.Settings()
    dr, growth, length = base.mesh_parameters()
    variants = [
        (f"default (rtol 1e-4: dr={dr:g}, growth {growth:g}, L={length:.0f})", base),
        ("rtol = 1e-5 (mesh from it)", lubjax.Settings(rtol=1e-5)),
        ("rtol = 1e-3 (mesh from it)", lubjax.Settings(rtol=1e-3)),
        ("dr = 0.007", lubjax.Settings(dr=0.007)),
        ("dr = 0.028", lubjax.Settings(dr=0.028)),
        ("L = 25", lubjax.Settings(length=25.0)),
        ("paper domain L = 4, uniform dr=0.01", None),
    ]
    fig, ax = plt.subplots(1, 3, figsize=(17, 4.4))
    t_common = np.linspace(0.01, 5.0, 500)
    curves = {}
    for label, settings in variants:
        print(f"  refinement: {label}", file=sys.stderr)
        if settings is None:
            mesh = lubjax.uniform_mesh(0.01, 4.0)
            traj = lubjax.stepper.rollout(lubjax.stepper.discretise(mesh), 100.0, 0.5,
                                          lubjax.RampHold(), 5.0, base.tolerance(),
                                          profile_times=np.array([5.0]))
            r, p = mesh.r, np.asarray(traj.profiles[0])
            curves[label] = np.asarray(lubjax.stepper.evaluate(traj.steps, t_common))
        else:
            res = lubjax.relax(100.0, 0.5, t_end=5.0, settings=settings, profile_times=[5.0])
            r, p = res.r, res.pressure[0]
            curves[label] = res.at(t_common)
        sel = r <= 1.5
        ax[0].plot(r[sel], p[sel], label=label)
        ax[1].plot(t_common, curves[label], label=label)
    finest = curves["rtol = 1e-5 (mesh from it)"]
    peak = np.max(finest)
    for label, force in curves.items():
        if label.startswith("rtol = 1e-5"):
            continue
        ax[2].semilogy(t_common, np.maximum(np.abs(force - finest) / peak, 1e-9), label=label)
    ax[0].plot(r[sel], lubjax.hertz_pressure(r[sel], 0.5), "k:", label="Hertz (eq 14)")
    ax[0].set_xlabel("r̄")
    ax[0].set_ylabel("p̄ at t̄ = 5")
    ax[0].set_title("Fig 3 analogue: β = 100, z̄0 = 0.5")
    ax[0].legend(fontsize=7)
    ax[1].set_xlabel("t̄")
    ax[1].set_ylabel("F̄")
    ax[1].axhline(lubjax.hertz_force(0.5), color="k", ls=":")
    ax[1].set_title("force under the same refinements")
    ax[2].set_xlabel("t̄")
    ax[2].set_ylabel("|F̄ − F̄(rtol 1e-5)| / peak")
    ax[2].set_ylim(1e-7, 1)
    ax[2].set_title("difference from the rtol = 1e-5 run")
    ax[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, "fig3_refinement.png"), dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="examples/out")
    ap.add_argument("--rtol", type=float, default=None,
                    help="Settings.rtol of the Figs 4-6 runs (default: lubjax's)")
    ap.add_argument("--dpi", type=float, default=110, help="resolution of the Figs 4-6 PNGs")
    ap.add_argument("--no-fig3", action="store_true",
                    help="skip Fig 3 (its reference run at rtol 1e-5 takes the longest)")
    args = ap.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    settings = None if args.rtol is None else lubjax.Settings(rtol=args.rtol)
    print("Figs 4-6", file=sys.stderr)
    figs_4_to_6(args.out, settings, args.dpi)
    names = [name for name, _, _ in PROFILES]
    if not args.no_fig3:
        print("Fig 3", file=sys.stderr)
        fig3_refinement(args.out)
        names.insert(0, "fig3_refinement.png")
    print(f"wrote {args.out}/" + ", ".join(names))


if __name__ == "__main__":
    main()
