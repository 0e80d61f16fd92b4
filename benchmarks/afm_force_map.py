"""A force map fitted in one batched call: the 2x2 JPK map, and its curves tiled into a bigger one.

    XLA_FLAGS=--xla_force_host_platform_device_count=2 PJRT_NPROC=3 \\
        python -m benchmarks.afm_force_map [--tiles 16] [--devices 1,2]

Needs ``pip install lubjax[afm]`` and the instrument files of the pinned afmformats sdist,
fetched as tests/test_afm_files.py does (into ``LUBJAX_TESTDATA``, default
~/.cache/lubjax/testdata).

The map (afmformats' ``fmt-jpk-fd_map2x2_extracted.jpk-force-map``: the four corners of a
10x10 JPK map, R = 10 µm nominal, ν = 0.5) is read curve by curve (a curve that cannot be
read is rejected with its reason) and every curve's approach (300 samples, rtol 1e-3) is
fitted in ONE ``fitting.fit_traces`` call: one compiled model run per iteration for all
curves, the curves split over the devices with ``jax.sharding`` (lubjax/_sharding.py), each
device mapping over its share (``batching="map"``, the CPU default). Twice: with the film
(η fitted) and without it (η = 10⁻⁵ Pa s held: β > 10⁴, a Hertz contact through the
cantilever). A curve whose fit does not converge is rejected (marked in the figure).

Timing batches: the map itself, and ``--tiles`` curves made of the map's curves in turn, each
copy with independent white noise of the curve's own σ added to its force (so no two copies
are the same problem). Each batch is fitted twice in one process: the first call traces and
compiles the batched model for that batch shape and device count, the second (warm) call
only runs; compile ≈ first - warm. Curves/s = curves / warm wall time. The JAX compilation
cache is off (the library's default), so the first call really compiles.

Several CPU devices: XLA_FLAGS=--xla_force_host_platform_device_count=N before JAX starts,
and PJRT_NPROC=N+1 (XLA:CPU's thread pool needs one thread more than device programs:
lubjax/_sharding.py). On a machine with fewer cores than devices the devices share the cores.

Outputs: benchmarks/out/afm_force_map.md (the table), afm_force_map.png (the figure: E with
and without the film and the relative uncertainty, per map position; rejected curves
hatched, with the reason).
"""

from __future__ import annotations

import dataclasses
import os
import textwrap
import time

import jax
import numpy as np

import fitting
from benchmarks import _harness
from fitting import _afm
from fitting._scales import noise_level
from fitting._trace import TraceError

MAP = "afmformats-0.18.7/tests/data/fmt-jpk-fd_map2x2_extracted.jpk-force-map"
RADIUS = 10e-6
NU = 0.5
SAMPLES = 300
#: "Without the film": η held here (β > 10⁴ on every curve of the map).
ETA_FREE = 1e-5


def read_map(path):
    """(traces, positions, rejected): the curves that convert, (curve index, (grid index x,
    grid index y, position x [m], position y [m])) of each, and {curve index: (that tuple,
    reason)} for those that do not."""
    import afmformats

    curves = afmformats.load_data(path)
    traces, pos, rejected = [], [], {}
    for i, c in enumerate(curves):
        md = c.metadata
        xy = (int(md.get("grid index x", i)), int(md.get("grid index y", 0)),
              md.get("position x", np.nan), md.get("position y", np.nan))
        try:
            (tr,) = _afm.read_afm(path, radius=RADIUS, poisson=NU, max_samples=SAMPLES,
                                  curves=[i])
        except TraceError as exc:
            rejected[i] = (xy, str(exc))
            continue
        traces.append(tr)
        pos.append((i, xy))
    return traces, pos, rejected


def tiled(traces, n, seed=0):
    """``n`` curves: the map's in turn, each with fresh white noise of its own σ added."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        tr = traces[k % len(traces)]
        f = tr.force + rng.normal(0.0, noise_level(tr.force), tr.force.size)
        out.append(tr._replace(force=f, name=f"{tr.name}~{k}"))
    return out


def timed(traces, settings, devices, **kw):
    t0 = time.perf_counter()
    res = fitting.fit_traces(traces, settings=settings, devices=devices, **kw)
    return res, time.perf_counter() - t0


def batch_row(label, traces, settings, devices, repeats, compiles=True, **kw):
    """Fit ``traces`` once cold and ``repeats`` times warm. ``compiles``: the first call is
    the first of this program (batch shape, device count); otherwise an earlier row compiled
    it and its first call is only another run."""
    _, first = timed(traces, settings, devices, **kw)
    warm = []
    for _ in range(repeats):
        res, wall = timed(traces, settings, devices, **kw)
        warm.append(wall)
    w = float(np.median(warm))
    conv = sum(r.converged for r in res)
    row = dict(batch=label, curves=len(traces), devices=devices, first_s=first,
               warm=_harness.median_range(warm), compile_s=first - w if compiles else None,
               curves_per_s=len(traces) / w, iterations=max(r.n_iterations for r in res),
               model_runs=res[0].n_model_runs, converged=conv)
    print(f"{label}, {devices} device(s): first {first:.1f} s, warm {row['warm']} s, "
          f"{row['curves_per_s']:.2f} curves/s, {conv}/{len(traces)} converged", flush=True)
    return row, res


def rejection(r):
    """Why a fit is not a result ('' if it is one)."""
    if not r.converged:
        return "not converged: " + (r.flags[0] if r.flags else "")
    if not r.identifiable:
        return "not identifiable"
    return ""


def figure(path, pos, rejected, film, free):
    """E with and without the film and σ_E/E per map position; rejected curves hatched."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    cells = {i: xy for i, xy in pos} | {i: v[0] for i, v in rejected.items()}
    xs = sorted({c[0] for c in cells.values()})
    ys = sorted({c[1] for c in cells.values()})
    at = {i: (xs.index(c[0]), ys.index(c[1])) for i, c in cells.items()}  # (column, row)

    def grid(values):
        g = np.full((len(ys), len(xs)), np.nan)
        for i, v in values.items():
            g[at[i][1], at[i][0]] = v
        return g

    def ticks(k, values):  # grid index and position [µm] of each column (k=0) or row (k=1)
        return [f"{v}\n({np.nanmean([c[2 + k] for c in cells.values() if c[k] == v]) * 1e6:.0f})"
                for v in values]

    e = lambda r: r.E_star * (1 - NU**2)  # noqa: E731
    idx = [i for i, _ in pos]
    bad = {i: rejection(r) for i, r in zip(idx, film)} | {i: v[1] for i, v in rejected.items()}
    bad_free = {i: rejection(r) for i, r in zip(idx, free)} | {
        i: v[1] for i, v in rejected.items()}
    panels = [
        ("E with the film [Pa]", {i: e(r) for i, r in zip(idx, film)}, film, bad, "log"),
        ("E without the film [Pa]", {i: e(r) for i, r in zip(idx, free)}, free, bad_free, "log"),
        ("σ_E/E with the film", {i: r.stderr["E_star"] / r.E_star for i, r in zip(idx, film)},
         film, bad, "lin"),
    ]
    allE = [v for p in panels[:2] for v in p[1].values() if np.isfinite(v)]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.4), constrained_layout=True)
    for ax, (title, vals, res, rej, scale) in zip(axes, panels):
        ok = {i: v for i, v in vals.items() if not rej.get(i)}
        norm = LogNorm(min(allE), max(allE)) if scale == "log" else None
        im = ax.imshow(grid(ok), origin="lower", cmap="viridis", norm=norm,
                       vmin=0 if scale == "lin" else None, aspect="equal")
        fig.colorbar(im, ax=ax, shrink=0.8)
        for i, (col, row) in at.items():
            if rej.get(i):
                ax.add_patch(plt.Rectangle((col - 0.5, row - 0.5), 1, 1, fill=False,
                                           hatch="//", edgecolor="red", alpha=0.5))
                why = "\n".join(textwrap.wrap(rej[i], 26, max_lines=4, placeholder=" ..."))
                ax.text(col, row, f"#{i} rejected\n{why}", ha="center", va="center",
                        fontsize=7, color="darkred",
                        bbox=dict(facecolor="white", alpha=0.85, edgecolor="none"))
                continue
            r = res[idx.index(i)]
            if scale == "log":
                txt = f"#{i}\n{e(r):.0f} ± {r.stderr['E_star'] * (1 - NU**2):.0f}"
            else:
                txt = f"#{i}\n{vals[i]:.3f}"
            ax.text(col, row, txt, ha="center", va="center", fontsize=9, color="white",
                    bbox=dict(facecolor="black", alpha=0.35, edgecolor="none"))
        ax.set_xticks(range(len(xs)), ticks(0, xs))
        ax.set_yticks(range(len(ys)), ticks(1, ys))
        ax.set_xlabel("grid index x (position [µm])")
        ax.set_ylabel("grid index y (position [µm])")
        n_rej = sum(1 for v in rej.values() if v)
        ax.set_title(f"{title}\n{n_rej} of {len(cells)} rejected (hatched)", fontsize=10)
    fig.suptitle("JPK force map (corners of a 10x10 grid), R = 10 µm nominal, ν = 0.5: "
                 "lubjax-fit, one batched call per panel", fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = _harness.parser(__doc__, "afm_force_map.md")
    ap.add_argument("--tiles", type=int, default=16,
                    help="curves in the tiled batch (default 16; 0: the map only)")
    ap.add_argument("--repeats", type=int, default=2, help="warm calls per batch (default 2)")
    ap.add_argument("--devices", default=None,
                    help="device counts to time, comma-separated (default: 1 and all)")
    args = _harness.parse(ap, argv)
    root = os.environ.get("LUBJAX_TESTDATA", os.path.expanduser("~/.cache/lubjax/testdata"))
    n_all = len(jax.devices())
    counts = sorted({1, n_all}) if args.devices is None else [
        int(x) for x in args.devices.split(",")]
    settings = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3)
    traces, pos, rejected = read_map(os.path.join(root, MAP))
    rows = []
    film = free = None
    for dev in counts:
        row, res = batch_row("the map, with the film", traces, settings, dev, args.repeats)
        rows.append(row)
        row, res_free = batch_row("the map, without the film", traces, settings, dev,
                                  args.repeats, compiles=False, fixed={"viscosity": ETA_FREE})
        rows.append(row)
        if dev == counts[0]:
            film, free = res, res_free
        if args.tiles:
            rows.append(batch_row(f"{args.tiles} tiled curves, with the film",
                                  tiled(traces, args.tiles), settings, dev, args.repeats)[0])
    base = os.path.splitext(args.out)[0]
    figure(base + ".png", pos, rejected, film, free)
    info = _harness.describe()
    lines = [f"Machine: {_harness.label(info)}; {n_all} JAX device(s) "
             f"({jax.devices()[0].platform}), XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}, "
             f"PJRT_NPROC={os.environ.get('PJRT_NPROC', '')!r}.", "",
             f"Command: `{_harness.command(argv)}`", "",
             "| batch | curves | devices | first call [s] | warm call [s], median (range) | "
             "compile ≈ first - warm [s] | curves/s (warm) | iterations (max) | model runs | "
             "converged |", "|" + "---|" * 10]
    for r in rows:
        comp = ("— (the program above)" if r["compile_s"] is None
                else f"{r['compile_s']:.1f}")
        lines.append(f"| {r['batch']} | {r['curves']} | {r['devices']} | {r['first_s']:.1f} | "
                     f"{r['warm']} | {comp} | {r['curves_per_s']:.2f} | "
                     f"{r['iterations']} | {r['model_runs']} | {r['converged']}/{r['curves']} |")
    lines += ["", "Per curve of the map (E = 0.75 E*, Pa; one device):", "",
              "| curve | position [µm] | E with the film | β | reduced χ² | E without the film "
              "| reduced χ² | rejected |", "|---|---|---|---|---|---|---|---|"]
    for (i, xy), f, g in zip(pos, film, free):
        why = "; ".join(x for x in (rejection(f), rejection(g)) if x) or "no"
        c = 1 - NU**2  # E = E*(1 - ν²)
        lines.append(
            f"| {i} | ({xy[2] * 1e6:.0f}, {xy[3] * 1e6:.0f}) | {f.E_star * c:.4g} ± "
            f"{f.stderr['E_star'] * c:.2g} | {f.beta:.3g} | {f.stats['reduced_chi2']:.3g} | "
            f"{g.E_star * c:.4g} ± {g.stderr['E_star'] * c:.2g} | "
            f"{g.stats['reduced_chi2']:.3g} | {why} |")
    for i, (xy, why) in rejected.items():
        lines.append(f"| {i} | ({xy[2] * 1e6:.0f}, {xy[3] * 1e6:.0f}) | — | — | — | — | — | "
                     f"{why} |")
    _harness.write_report(args.out, lines)
    print(f"wrote {args.out} and {base}.png")


if __name__ == "__main__":
    main()
