"""Stability map: which methods give finite, positive-film, sensible F̄(t̄) over β × z̄0 × Δt̄.

    python benchmarks/stability_map.py           # 8 β × 6 z̄0 × Δt̄ ∈ {1e-3, 1e-2, 1e-1} (~15 min)
    python benchmarks/stability_map.py --quick   # 3 × 3 × {1e-2, 1e-1} (~1-2 min)

Relaxation test on t̄ ∈ [0, 5]; β log-spaced in [1e-1, 1e6], z̄0 log-spaced in [0.1, 5].
Methods and resolutions (cheap ones, stated in the figures):

* paper scheme as published (uniform Δr̄ = 0.02, L̄ = 4, uniform Δt̄; the w̄-eliminated N×N form
  of the same equations, identical up to rounding, to keep the map affordable);
* lubjax default (``lubjax.relax``, Settings(dt=Δt̄): Δt̄ is the loading-phase cap, steps still
  start at 1e-6 after each jump and grow without cap in the hold);
* Newton (fully implicit BE), Picard (p/w split, ω = 0.5, ≤ 50 iterations), explicit Euler:
  uniform Δt̄ on a coarse graded FV mesh (dr = 0.05, r_fine = 1.6, L̄ = 10, growth 1.1).

Each cell is classified (first match): diverged (NaN/inf or |F̄| > 1e6), stall (an implicit
step's iteration did not converge), negative film (min h̄ < 0 at some step), negative force
(min F̄ < -1e-3 max |F̄| at the outputs; the raw min is in the CSV), inaccurate
(max |F̄ - F̄_ref| > 10 % of max F̄_ref), ok. F̄_ref is
lubjax (BDF2, growing steps from 1e-6, cap 2e-3, growth 1.08) on the *same mesh* as the method
(L̄ = 4 uniform for the paper scheme, the coarse mesh for Newton/Picard/explicit, the default
mesh for lubjax), so "inaccurate" measures the time stepping, not the domain truncation. Output
times t̄ = 0, 0.1, ..., 5 (nodes of every uniform grid; lubjax is interpolated linearly on its
own grid).

Writes benchmarks/out/stability_map.csv, stability_map_<method>.png, stability_map.png; --quick
writes benchmarks/out/quick/stability_map_quick.{csv,png} and its per-method PNGs there, never
over the full map's.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import benchmarks.methods  # noqa: E402,F401  (pins threads before numpy/jax load)

# isort: split
import numpy as np  # noqa: E402

import lubjax  # noqa: E402
from benchmarks import machine  # noqa: E402
from benchmarks.methods import (  # noqa: E402
    common,
    explicit_euler,
    lubjax_variant,
    newton,
    paper_scheme,
    picard,
)

OUT = Path(__file__).resolve().parent / "out"
CATEGORIES = ["ok", "inaccurate", "negative force", "negative film", "stall", "diverged",
              "no reference"]
COLORS = ["#4caf50", "#ffeb3b", "#ff9800", "#e91e63", "#3f51b5", "#212121", "#bdbdbd"]
COARSE = dict(mesh="graded", dr=0.05, r_fine=1.6, length=10.0, mesh_growth=1.1)
REF_GRID = dict(steps="grow", dt=2e-3, dt_min=1e-6, growth=1.08, order=2)


def lubjax_relax(beta, z0, t_out, dt):
    start = time.perf_counter()
    res = lubjax.relax(beta, z0, float(t_out[-1]), settings=lubjax.Settings(dt=dt),
                       check="flag")
    wall = time.perf_counter() - start - res.compile_s
    f = np.interp(t_out, res.t, res.force)
    info = common.make_info(wall_s=wall, compile_s=res.compile_s, force=res.force,
                            film_min=res.film_min, n_steps=res.t.size - 1)
    return f, info


METHODS = {
    "paper_scheme": dict(
        title="paper scheme as published (uniform Δr̄=0.02, L̄=4, BE, lagged m, n)",
        run=lambda b, z, t, dt: paper_scheme.run(b, z, t, dr=0.02, length=4.0, dt=dt,
                                                 reduced=True),
        ref=dict(mesh="uniform", dr=0.02, length=4.0)),
    "lubjax_default": dict(
        title="lubjax.relax default (graded, BDF2; Δt̄ = loading cap, growing steps)",
        run=lubjax_relax, ref=dict(mesh="graded")),
    "newton": dict(
        title="Newton, fully implicit BE (coarse graded FV mesh, uniform Δt̄)",
        run=lambda b, z, t, dt: newton.run(b, z, t, steps="fixed", dt=dt, **COARSE),
        ref=COARSE),
    "picard": dict(
        title="Picard p/w split, ω=0.5, ≤50 it. (coarse graded FV mesh, uniform Δt̄)",
        run=lambda b, z, t, dt: picard.run(b, z, t, steps="fixed", dt=dt, omega=0.5,
                                           max_iter=50, split="elastic", **COARSE),
        ref=COARSE),
    "explicit_euler": dict(
        title="explicit Euler (coarse graded FV mesh, uniform Δt̄)",
        run=lambda b, z, t, dt: explicit_euler.run(
            b, z, t, dt=dt, **{k: v for k, v in COARSE.items()}),
        ref=COARSE),
}

_REF_CACHE: dict = {}


def reference(beta, z0, t_out, mesh_opts):
    key = (beta, z0, tuple(sorted(mesh_opts.items())))
    if key not in _REF_CACHE:
        f, info = lubjax_variant.run(beta, z0, t_out, **mesh_opts, **REF_GRID)
        _REF_CACHE[key] = f if info["ok"] else None
    return _REF_CACHE[key]


def classify(f, info, ref):
    with np.errstate(invalid="ignore"):
        if not info["finite"] or not np.all(np.isfinite(f)) or np.max(np.abs(f)) > 1e6:
            return "diverged", float("nan")
        err = float(np.max(np.abs(f - ref)) / np.max(np.abs(ref))) if ref is not None \
            else float("nan")
    if not info["converged"]:
        return "stall", err
    if not info["film_positive"]:
        return "negative film", err
    if np.min(f) < -1e-3 * np.max(np.abs(f)):
        return "negative force", err
    if ref is None:
        return "no reference", err
    if err > 0.1:
        return "inaccurate", err
    return "ok", err


def plot_method(rows, name, betas, z0s, dts, mach, path, ax_row=None):
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    cmap = ListedColormap(COLORS)
    own = ax_row is None
    if own:
        fig, axes = plt.subplots(1, len(dts), figsize=(4.6 * len(dts), 4.4), squeeze=False)
        axes = axes[0]
    else:
        axes = ax_row
    for ax, dt in zip(axes, dts, strict=True):
        grid = np.full((len(z0s), len(betas)), np.nan)
        for r in rows:
            if r["method"] == name and r["dt"] == dt:
                i, j = z0s.index(r["z0"]), betas.index(r["beta"])
                grid[i, j] = CATEGORIES.index(r["category"])
        ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(CATEGORIES) - 0.5, origin="lower",
                  aspect="auto")
        ax.set_xticks(range(len(betas)), [f"{b:.0e}".replace("e+0", "e").replace("e-0", "e-")
                                          for b in betas], fontsize=7, rotation=45)
        ax.set_yticks(range(len(z0s)), [f"{z:.2g}" for z in z0s], fontsize=7)
        ax.set_xlabel("β")
        ax.set_ylabel("z̄0")
        ax.set_title(f"{METHODS[name]['title'] if own else name}\nΔt̄ = {dt:g}",
                     fontsize=8 if own else 9)
        for r in rows:
            if r["method"] == name and r["dt"] == dt and r["category"] == "inaccurate":
                i, j = z0s.index(r["z0"]), betas.index(r["beta"])
                ax.text(j, i, f"{100 * r['error']:.0f}%", ha="center", va="center", fontsize=6)
    if own:
        handles = [Patch(color=c, label=k) for k, c in zip(CATEGORIES, COLORS, strict=True)]
        fig.legend(handles=handles, loc="lower center", ncol=len(CATEGORIES), fontsize=8,
                   frameon=False)
        fig.suptitle(machine.label(mach), fontsize=7, y=0.995)
        fig.tight_layout(rect=(0, 0.06, 1, 0.97))
        fig.savefig(path, dpi=110)
        plt.close(fig)


def plot_all(rows, names, betas, z0s, dts, mach, path):
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    fig, axes = plt.subplots(len(names), len(dts), figsize=(3.6 * len(dts), 2.9 * len(names)),
                             squeeze=False)
    for row, name in zip(axes, names, strict=True):
        plot_method(rows, name, betas, z0s, dts, mach, None, ax_row=row)
    handles = [Patch(color=c, label=k) for k, c in zip(CATEGORIES, COLORS, strict=True)]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.suptitle("Stability map, relaxation test t̄ ∈ [0, 5] (per-method details in "
                 "stability_map_<method>.png)\n" + machine.label(mach), fontsize=8)
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    fig.savefig(path, dpi=100)
    plt.close(fig)


FIELDS = ["method", "beta", "z0", "dt", "category", "error", "h_min", "F_min", "F_max",
          "finite", "film_positive", "converged", "wall_s", "compile_s", "n_steps", "cpu",
          "cores", "threads", "load1"]


def main(argv=None):
    import matplotlib

    matplotlib.use("Agg")
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="3 β × 3 z̄0 × Δt̄ ∈ {1e-2, 1e-1}")
    ap.add_argument("--methods", default=",".join(METHODS), help="comma-separated subset")
    ap.add_argument("--out", default=None, help="output folder (default benchmarks/out, "
                    "benchmarks/out/quick with --quick)")
    args = ap.parse_args(argv)
    out = Path(args.out) if args.out else (OUT / "quick" if args.quick else OUT)
    out.mkdir(parents=True, exist_ok=True)
    if args.quick:
        betas, z0s, dts = [1e-1, 1e2, 1e5], [0.1, 0.7, 5.0], [1e-2, 1e-1]
    else:
        betas = [float(f"{b:.3g}") for b in np.logspace(-1, 6, 8)]
        z0s = [float(f"{z:.3g}") for z in np.logspace(np.log10(0.1), np.log10(5.0), 6)]
        dts = [1e-3, 1e-2, 1e-1]
    names = [n for n in args.methods.split(",") if n]
    t_out = common.default_t_out(5.0, 0.1)
    mach = machine.describe()
    rows = []
    start = time.perf_counter()
    for name in names:
        m = METHODS[name]
        t_m = time.perf_counter()
        for dt in dts:
            for beta in betas:
                for z0 in z0s:
                    ref = reference(beta, z0, t_out, m["ref"])
                    f, info = m["run"](beta, z0, t_out, dt)
                    cat, err = classify(f, info, ref)
                    with np.errstate(invalid="ignore"):
                        fmin = float(np.nanmin(f)) if np.any(np.isfinite(f)) else float("nan")
                        fmax = float(np.nanmax(f)) if np.any(np.isfinite(f)) else float("nan")
                    rows.append(dict(method=name, beta=beta, z0=z0, dt=dt, category=cat,
                                     error=err, h_min=info["h_min"], F_min=fmin, F_max=fmax,
                                     finite=info["finite"], film_positive=info["film_positive"],
                                     converged=info["converged"], wall_s=info["wall_s"],
                                     compile_s=info["compile_s"], n_steps=info["n_steps"],
                                     **mach))
            counts = {c: sum(1 for r in rows if r["method"] == name and r["dt"] == dt
                             and r["category"] == c) for c in CATEGORIES}
            print(f"{name:15s} dt={dt:g}: " + ", ".join(f"{k} {v}" for k, v in counts.items()
                                                        if v), flush=True)
        print(f"  {name} took {time.perf_counter() - t_m:.0f} s", flush=True)
        plot_method(rows, name, betas, z0s, dts, mach, out / f"stability_map_{name}.png")
    suffix = "_quick" if args.quick else ""
    with open(out / f"stability_map{suffix}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k) for k in FIELDS})
    plot_all(rows, names, betas, z0s, dts, mach, out / f"stability_map{suffix}.png")
    print(f"wrote {out}/stability_map{suffix}.csv and PNGs in "
          f"{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
