"""Stability map: which methods give finite, positive-film, sensible F̄(t̄) over β × z̄0.

    python -m benchmarks.stability_map --quick   # 4 β × 4 z̄0, Δt̄ ∈ {1e-2, 1e-1}
    python -m benchmarks.stability_map           # 8 β × 7 z̄0, Δt̄ ∈ {1e-3, 1e-2, 1e-1}

β log-spaced in [1e-1, 1e6], z̄0 log-spaced in [0.05, 5]. Two kinds of rows:

* ``lubjax_default``: ``lubjax.relax(β, z̄0, 1e6)`` with every default (rtol 1e-4, error
  estimate, contact refinement, ``check="raise"``) on t̄ ∈ [0, 10⁶]. Held to: finite, positive
  film, non-negative force, or a clear refusal (``SolverError`` / ``ValueError``, message in the
  CSV). Its accuracy is checked twice: on t̄ ≤ 5 against ``relax`` at rtol 1e-6 (no estimate)
  on the default mesh (same contact refinement), and at t̄ = 10⁶ against the long-time limit:
  Hertz's F̄∞ = (2π/3)(1 - z̄0)^{3/2} for z̄0 < 1, F̄ → 0 (below 10 % of the peak) for z̄0 ≥ 1.
* comparison methods on t̄ ∈ [0, 5] at fixed uniform Δt̄ on cheap meshes (stated in the figure):
  the paper scheme as published (uniform Δr̄ = 0.02, L̄ = 4; the w̄-eliminated N×N form of the
  same equations, identical up to rounding, to keep the map affordable); Newton (fully implicit
  BE), Picard (p/w split, ω = 0.5, ≤ 50 iterations), explicit Euler: a coarse graded FV mesh
  (dr = 0.05, r_fine = 1.6, L̄ = 10, growth 1.1). Their reference is lubjax's stepper at
  rtol 1e-6 on the *same mesh* (``lubjax_variant``), so "inaccurate" measures the time stepping,
  not the domain truncation. Output times t̄ = 0, 0.1, ..., 5.

Each cell is classified (first match): refused (SolverError / ValueError raised), diverged
(NaN/inf or |F̄| > 1e6), stalled (an implicit step's iteration did not converge, or the run did
not reach t̄_end), negative film (min h̄ ≤ 0 at some step), negative force (min F̄ < -1e-3 max |F̄|;
the raw min is in the CSV), inaccurate (max |F̄ - F̄_ref| > 10 % of max F̄_ref, or the long-time
check above off by > 10 %), ok.

Writes benchmarks/out/stability_map{,_quick}.{csv,png}.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path

import benchmarks.methods  # noqa: F401  (pins threads before numpy/jax load)
from benchmarks import _harness

# isort: split
import numpy as np

import lubjax
from benchmarks.methods import (
    common,
    explicit_euler,
    lubjax_variant,
    newton,
    paper_scheme,
    picard,
)

OUT = Path(_harness.OUT)
CATEGORIES = ["ok", "inaccurate", "negative force", "negative film", "stalled", "diverged",
              "refused", "no reference"]
COLORS = ["#4caf50", "#ffeb3b", "#ff9800", "#e91e63", "#3f51b5", "#212121", "#9e9e9e",
          "#e0e0e0"]
COARSE = dict(mesh="graded", dr=0.05, r_fine=1.6, length=10.0, mesh_growth=1.1)
PAPER_MESH = dict(mesh="uniform", dr=0.02, length=4.0)
LONG_T = 1e6
SHORT_T = 5.0
REF_RTOL = 1e-6


def _failed(exc, t_out):
    return np.full(t_out.size, np.nan), dict(
        refused=True, message=f"{type(exc).__name__}: {exc}"[:400], finite=False,
        film_positive=False, converged=False, h_min=float("nan"), wall_s=float("nan"),
        compile_s=float("nan"), n_steps=0)


def lubjax_long(beta, z0, t_out):
    """All defaults to t̄ = 10⁶; F̄ at t_out (≤ 5) and the long-time value at 10⁶."""
    start = time.perf_counter()
    try:
        res = lubjax.relax(beta, z0, LONG_T)
    except (lubjax.SolverError, ValueError) as exc:
        return _failed(exc, t_out)
    wall = time.perf_counter() - start - res.compile_s
    info = common.make_info(wall_s=wall, compile_s=res.compile_s, force=res.force,
                            film_min=res.film_min, converged=res.finished,
                            n_steps=res.accepted)
    info.update(refused=False, message="", f_long=float(res.force[-1]),
                f_peak=float(np.max(res.force)), f_min_all=float(np.min(res.force)))
    return res.at(t_out), info


METHODS = {
    "lubjax_default": dict(
        title=f"lubjax.relax, all defaults, t̄ ≤ {LONG_T:g} (graded, BDF2, rtol 1e-4)",
        run=lambda b, z, t, dt: lubjax_long(b, z, t), dts=[None], ref="relax"),
    "paper_scheme": dict(
        title="paper scheme as published (uniform Δr̄=0.02, L̄=4, BE, lagged m, n)",
        run=lambda b, z, t, dt: paper_scheme.run(b, z, t, dr=0.02, length=4.0, dt=dt,
                                                 reduced=True),
        ref=PAPER_MESH),
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
        run=lambda b, z, t, dt: explicit_euler.run(b, z, t, dt=dt, **COARSE),
        ref=COARSE),
}

_REF_CACHE: dict = {}


def reference(beta, z0, t_out, kind):
    key = (beta, z0, repr(kind))
    if key not in _REF_CACHE:
        try:
            if kind == "relax":
                # the default mesh (same contact refinement), tight time tolerance
                dr, growth, length = lubjax.Settings().mesh_parameters()
                res = lubjax.relax(beta, z0, float(t_out[-1]), check="flag",
                                   settings=lubjax.Settings(rtol=REF_RTOL, dr=dr, length=length,
                                                            mesh_growth=growth,
                                                            error_estimate=False))
                f = res.at(t_out) if res.ok else None
            else:
                f, info = lubjax_variant.run(beta, z0, t_out, rtol=REF_RTOL, **kind)
                f = f if info["ok"] else None
        except Exception:  # noqa: BLE001  (no reference: the cell says so)
            f = None
        _REF_CACHE[key] = f
    return _REF_CACHE[key]


def classify(f, info, ref, z0):
    if info.get("refused"):
        return "refused", float("nan")
    with np.errstate(invalid="ignore"):
        if not info["finite"] or not np.all(np.isfinite(f)) or np.max(np.abs(f)) > 1e6:
            return "diverged", float("nan")
        err = float(np.max(np.abs(f - ref)) / np.max(np.abs(ref))) if ref is not None \
            else float("nan")
    if not info["converged"]:
        return "stalled", err
    if not info["film_positive"]:
        return "negative film", err
    f_min = min(np.min(f), info.get("f_min_all", 0.0))
    if f_min < -1e-3 * max(np.max(np.abs(f)), info.get("f_peak", 0.0)):
        return "negative force", err
    if ref is None:
        return "no reference", err
    if err > 0.1:
        return "inaccurate", err
    if "f_long" in info:
        hertz = float(lubjax.hertz_force(z0))
        long_err = (abs(info["f_long"] / hertz - 1) if hertz > 0
                    else abs(info["f_long"]) / info["f_peak"])
        info["long_error"] = long_err
        if long_err > 0.1:
            return "inaccurate", err
    return "ok", err


def _ticks(ax, betas, z0s):
    ax.set_xticks(range(len(betas)), [f"{b:.0e}".replace("e+0", "e").replace("e-0", "e-")
                                      for b in betas], fontsize=7, rotation=45)
    ax.set_yticks(range(len(z0s)), [f"{z:.2g}" for z in z0s], fontsize=7)
    ax.set_xlabel("β")
    ax.set_ylabel("z̄0")


def plot_all(rows, names, betas, z0s, dts, path):
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    cmap = ListedColormap(COLORS)
    # as many columns as the method with the most time steps has (lubjax's own row has one)
    ncol = max(len(METHODS[name].get("dts", dts)) for name in names)
    size = (max(3.9 * ncol, 7.8), 3.2 * len(names) + 0.8)
    fig, axes = plt.subplots(len(names), ncol, figsize=size, squeeze=False)
    for row_axes, name in zip(axes, names, strict=True):
        cols = METHODS[name].get("dts", dts)
        for k, ax in enumerate(row_axes):
            if k >= len(cols):
                ax.axis("off")
                continue
            dt = cols[k]
            grid = np.full((len(z0s), len(betas)), np.nan)
            cells = [r for r in rows if r["method"] == name and r["dt"] == dt]
            for r in cells:
                grid[z0s.index(r["z0"]), betas.index(r["beta"])] = CATEGORIES.index(
                    r["category"])
            ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(CATEGORIES) - 0.5, origin="lower",
                      aspect="auto")
            _ticks(ax, betas, z0s)
            for r in cells:
                i, j = z0s.index(r["z0"]), betas.index(r["beta"])
                text = (f"{100 * r['error']:.0f}%" if r["category"] == "inaccurate"
                        and np.isfinite(r["error"]) and r["error"] > 0.1 else
                        f"L{100 * r['long_error']:.0f}%" if r["category"] == "inaccurate"
                        else "")
                if text:
                    ax.text(j, i, text, ha="center", va="center", fontsize=6)
            when = (f"t̄ ≤ {LONG_T:g}" if dt is None else f"Δt̄ = {dt:g}, t̄ ≤ {SHORT_T:g}")
            ax.set_title(f"{name}: {when}", fontsize=8)
        row_axes[0].annotate(METHODS[name]["title"], xy=(0, 0.5), xycoords="axes fraction",
                             xytext=(-42, 0), textcoords="offset points", rotation=90,
                             va="center", ha="center", fontsize=6)
    handles = [Patch(color=c, label=k) for k, c in zip(CATEGORIES, COLORS, strict=True)]
    fig.legend(handles=handles, loc="lower center", ncol=4, fontsize=8, frameon=False)
    # The machine is named once, in the page's caption and the CSV, not in the picture.
    fig.suptitle("Stability map, relaxation test (inaccurate: % = max error vs reference on "
                 "t̄ ≤ 5, L% = long-time check)", fontsize=8)
    fig.tight_layout(rect=(0.02, 0.05, 1, 0.96))
    fig.savefig(path, dpi=100)
    plt.close(fig)


FIELDS = ["method", "beta", "z0", "dt", "t_end", "category", "error", "long_error", "f_long",
          "h_min", "F_min", "F_max", "finite", "film_positive", "converged", "wall_s",
          "compile_s", "n_steps", "message", "cpu", "cores", "threads", "load1"]


def write(rows, names, betas, z0s, dts, out, suffix):
    with open(out / f"stability_map{suffix}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k) for k in FIELDS})
    plot_all(rows, names, betas, z0s, dts, out / f"stability_map{suffix}.png")


def replot(out, suffix, betas, z0s, dts):
    """Redraw ``stability_map{suffix}.png`` from its CSV (the runs take hours, the plot not)."""
    with open(out / f"stability_map{suffix}.csv") as f:
        rows = [dict(r, beta=float(r["beta"]), z0=float(r["z0"]),
                     dt=float(r["dt"]) if r["dt"] else None, error=float(r["error"]),
                     long_error=float(r["long_error"])) for r in csv.DictReader(f)]
    names = list(dict.fromkeys(r["method"] for r in rows))
    plot_all(rows, names, betas, z0s, dts, out / f"stability_map{suffix}.png")


def main(argv=None):
    import matplotlib

    matplotlib.use("Agg")
    ap = _harness.parser(__doc__)
    ap.add_argument("--quick", action="store_true", help="4 β × 4 z̄0 × Δt̄ ∈ {1e-2, 1e-1}")
    ap.add_argument("--methods", default="paper_scheme,newton,picard,explicit_euler,lubjax_default",
                    help="comma-separated subset (order of the runs and of the figure's rows)")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--replot", action="store_true", help="redraw the PNG from the CSV")
    args = _harness.parse(ap, argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.quick:
        betas = [float(f"{b:.3g}") for b in np.logspace(-1, 6, 4)]
        z0s = [float(f"{z:.3g}") for z in np.geomspace(0.05, 5.0, 4)]
        dts = [1e-2, 1e-1]
    else:
        betas = [float(f"{b:.3g}") for b in np.logspace(-1, 6, 8)]
        z0s = [float(f"{z:.3g}") for z in np.geomspace(0.05, 5.0, 7)]
        dts = [1e-3, 1e-2, 1e-1]
    if args.replot:
        replot(out, "_quick" if args.quick else "", betas, z0s, dts)
        return
    names = [n for n in args.methods.split(",") if n]
    t_out = common.default_t_out(SHORT_T, 0.1)
    rows = []
    start = time.perf_counter()
    for name in names:
        m = METHODS[name]
        t_m = time.perf_counter()
        for dt in m.get("dts", dts):
            for beta in betas:
                for z0 in z0s:
                    ref = reference(beta, z0, t_out, m["ref"])
                    mach = _harness.describe()
                    try:
                        f, info = m["run"](beta, z0, t_out, dt)
                    except (lubjax.SolverError, ValueError) as exc:
                        f, info = _failed(exc, t_out)
                    cat, err = classify(f, info, ref, z0)
                    with np.errstate(invalid="ignore"):
                        fin = np.isfinite(f)
                        fmin = float(np.min(f[fin])) if fin.any() else float("nan")
                        fmax = float(np.max(f[fin])) if fin.any() else float("nan")
                    rows.append(dict(
                        method=name, beta=beta, z0=z0, dt=dt,
                        t_end=LONG_T if dt is None else SHORT_T, category=cat, error=err,
                        long_error=info.get("long_error", float("nan")),
                        f_long=info.get("f_long", float("nan")), h_min=info["h_min"],
                        F_min=fmin, F_max=fmax, finite=info["finite"],
                        film_positive=info["film_positive"], converged=info["converged"],
                        wall_s=info["wall_s"], compile_s=info["compile_s"],
                        n_steps=info["n_steps"], message=info.get("message", ""), **mach))
                    if dt is None:
                        print(f"    {name} β={beta:g} z0={z0:g}: {cat} err={err:.2e} "
                              f"long={rows[-1]['long_error']:.2e} {rows[-1]['message'][:80]} "
                              f"({rows[-1]['wall_s']:.1f}s)", flush=True)
            counts = {c: sum(1 for r in rows if r["method"] == name and r["dt"] == dt
                             and r["category"] == c) for c in CATEGORIES}
            print(f"{name:15s} dt={dt}: " + ", ".join(f"{k} {v}" for k, v in counts.items()
                                                      if v), flush=True)
        print(f"  {name} took {time.perf_counter() - t_m:.0f} s", flush=True)
        write(rows, [n for n in names if any(r["method"] == n for r in rows)], betas, z0s, dts,
              out, "_quick" if args.quick else "")  # after each method: partial maps survive
    suffix = "_quick" if args.quick else ""
    print(f"wrote {out}/stability_map{suffix}.{{csv,png}} in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
