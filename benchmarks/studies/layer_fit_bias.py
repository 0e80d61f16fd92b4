"""How wrong is a half-space fit of the paper's experiment, whose sample was a 5 mm layer?

    python -m benchmarks.layer_fit_bias [--seeds 1] [--only 126,140,154] [--skip-reverse]

The paper (Liu et al., Soft Matter 2022 §3.2) pressed a glass bead R = 2 mm into a 5 mm thick
PDMS layer on a rigid base (d_c = 126, 140, 154 μm) and fitted the half-space model. The
bundled traces data/paper_dc*.csv are synthetic *half-space* traces, so they cannot show the
bias. Here:

1. clean traces of the same tests on a **bonded incompressible 5 mm layer** (H̄ = H/√(R d_c) =
   10.0, 9.4, 9.0), made by ``data/make_synthetic.py``'s generator (``clean_force(...,
   layer_m=5e-3)``: rtol 1e-7, Δr̄ = 0.01,
   544 nodes, L̄ = 1000, the input sampled at 40,001 points; the fits use
   ``fitting.FIT_SETTINGS``, rtol 3e-4, 132 nodes), cached as
   ``data/clean/layer5mm_dc*_clean.csv`` (generated when missing);
2. Gaussian noise of 1 % of the peak force on the force channel (seeds 5126, 5140, 5154, + k
   for the k-th further draw), written as ``data/layer5mm_dc*.csv`` for the first draw;
3. each noisy trace fitted (a) with the default half-space model and (b) with the known layer
   (``--substrate layer --thickness 5e-3``, bonded, ν = 0.5), compared by
   ``fitting.compare_models`` (both have the same parameters E*, η, z0, offset, so ΔBIC = ΔAIC =
   the likelihood ratio; the layer model is chosen when ΔBIC > 10);
4. ``reverse``: the bundled half-space trace data/paper_dc140.csv fitted with both models (the
   comparison should keep the half-space).

Writes benchmarks/out/layer_fit_bias.{md,json}, with the command, the machine and its load.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

from benchmarks._harness import ROOT

OUT = os.path.join(ROOT, "benchmarks", "out")

LAYER_M = 5e-3
INDENTS_UM = (126, 140, 154)
NOISE = 0.01
NAMES = ("E_star", "viscosity", "z0")
TRUE_KEYS = dict(E_star="true_E_star_Pa", viscosity="true_viscosity_Pa_s", z0="true_z0_m")


def _clean_path(um):
    return os.path.join(ROOT, "data", "clean", f"layer5mm_dc{um}_clean.csv")


def clean_trace(um, log):
    """The noiseless layer trace for d_c = ``um`` μm (cached in data/clean/)."""
    import fitting
    import lubjax
    from data import make_synthetic as ms

    path = _clean_path(um)
    if os.path.exists(path):
        return fitting.read_trace(path), 0.0
    start = time.perf_counter()
    indent = um * 1e-6
    times = np.arange(0.0, ms.QUIET_S + 154e-6 / ms.SPEED + ms.HOLD_S, 1.0 / ms.RATE_HZ)
    test, force = ms.clean_force(indent, 100.0, times, layer_m=LAYER_M)
    hbar = lubjax.layer_thickness_bar(LAYER_M, ms.RADIUS, indent)
    meta = ms._meta(f"layer5mm_dc{um}", test.E_star, 100.0, {
        "true_indent_m": f"{indent:.6g}", "true_speed_m_s": f"{ms.SPEED:.6g}",
        "true_beta": f"{test.beta:.6g}", "substrate": "bonded incompressible layer on a rigid base",
        "true_layer_thickness_m": f"{LAYER_M:g}", "true_layer_thickness_bar": f"{hbar:.6g}"})
    trace = fitting.make_trace(times, ms.travel(times, indent), force, ms.RADIUS,
                               dict(meta, noise_N="0"))
    fitting.write_trace(path, trace)
    wall = time.perf_counter() - start
    log(f"generated {os.path.relpath(path, ROOT)} (H̄ = {hbar:.3f}, β = {test.beta:.4g}, peak "
        f"{force.max():.4g} N) in {wall:.0f} s")
    return fitting.read_trace(path), wall


def noisy(trace, seed, name):
    import fitting

    sigma = NOISE * float(np.max(trace.force))
    rng = np.random.default_rng(seed)
    meta = dict(trace.metadata, noise_N=f"{sigma:.6g}", noise_seed=str(seed),
                noise_fraction_of_peak=f"{NOISE:g}")
    meta.pop("radius_m", None)
    return fitting.make_trace(trace.time, trace.displacement,
                              trace.force + rng.normal(0.0, sigma, trace.time.shape),
                              trace.radius, meta, name=name)


def _row(result, truth):
    out = dict(converged=bool(result.converged), chi2=float(result.stats["chi2"]),
               reduced_chi2=float(result.stats["reduced_chi2"]), wall_s=float(result.wall_s))
    for n in NAMES:
        v, e = float(result.values[n]), float(result.stderr[n])
        t = float(truth[n])
        out[n] = dict(value=v, stderr=e, bias=(v - t) / t, z=(v - t) / e if e > 0 else float("nan"))
    return out


def fit_pair(trace):
    """Half-space and layer fits of one trace, compared."""
    from fitting import ModelSpec, compare_models

    half = ModelSpec(drive="travel")
    layer = ModelSpec(drive="travel", layer=(LAYER_M, 0.5, "bonded"))
    a, b, cmp = compare_models([trace], simple=half, rich=layer)
    truth = {n: float(trace.metadata[TRUE_KEYS[n]]) for n in NAMES}
    return dict(halfspace=_row(a[0], truth), layer=_row(b[0], truth),
                delta_bic=float(cmp["delta_bic"]), likelihood_ratio=float(cmp["likelihood_ratio"]),
                choice=cmp["choice"], report=cmp["report"])


def _fmt(fit, n, scale):
    f = fit[n]
    return (f"{f['value'] * scale:.4g} ± {f['stderr'] * scale:.2g} "
            f"({100 * f['bias']:+.1f} %, z {f['z']:+.1f})")


def write_md(res):
    lines = [
        "# Half-space fit of a 5 mm layer (the paper's sample)", "",
        f"`{res['command']}`", "",
        f"Machine: {res['machine']}; total wall {res['wall_s']:.0f} s "
        f"(generation {res['generation_s']:.0f} s).", "",
        "Synthetic traces of the paper's tests on a bonded incompressible 5 mm layer on a rigid "
        "base (R = 2 mm, v0 = 0.1 mm/s, z0 = 140 μm, η = 100 Pa s, E* = 3.92 MPa), made on the "
        "fine generator grid (rtol 1e-7, 544 nodes, L̄ = 1000), 1 % Gaussian noise; fitted at "
        "`fitting.FIT_SETTINGS` (rtol 3e-4, 132 nodes) with the half-space (default) and with "
        "`--substrate layer --thickness 5e-3`. Values ± reported 1σ (relative bias, z-score).", "",
        "| trace | seed | H̄ | model | E* [MPa] | η [Pa s] | z0 [μm] | χ²/ν "
        "| ΔBIC (layer better if > 10) | choice |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res["rows"]:
        for model in ("halfspace", "layer"):
            f = r[model]
            lines.append(
                f"| {r['trace']} | {r['seed']} | {r['hbar']:.2f} | {model} | "
                f"{_fmt(f, 'E_star', 1e-6)} | "
                f"{_fmt(f, 'viscosity', 1)} | {_fmt(f, 'z0', 1e6)} | {f['reduced_chi2']:.3f} | "
                + (f"{r['delta_bic']:.1f} | {r['choice']} |" if model == "layer" else " | |"))
    lines += ["", "Summary over the noise draws (mean, min to max of the relative bias; ΔBIC):", "",
              "| trace | draws | half-space E* | half-space η | half-space z0 | layer E* | "
              "layer η | layer z0 | ΔBIC | layer chosen |", "|---" * 10 + "|"]
    for name in dict.fromkeys(r["trace"] for r in res["rows"]):
        rows = [r for r in res["rows"] if r["trace"] == name]

        def span(model, n, rows=rows):
            b = 100 * np.array([r[model][n]["bias"] for r in rows])
            return f"{b.mean():+.1f} % ({b.min():+.1f} to {b.max():+.1f})"

        dbic = np.array([r["delta_bic"] for r in rows])
        chosen = sum(r["choice"] != "elastic half-space" for r in rows)
        lines.append(f"| {name} | {len(rows)} | " + " | ".join(
            span(m, n) for m in ("halfspace", "layer") for n in NAMES)
            + f" | {dbic.mean():.1f} ({dbic.min():.1f} to {dbic.max():.1f}) | "
            f"{chosen}/{len(rows)} |")
    lines += ["", "The comparison's report per trace:", ""]
    for r in res["rows"]:
        lines += [f"- {r['trace']} (seed {r['seed']}): " + "; ".join(r["report"])]
    open(os.path.join(OUT, "layer_fit_bias.md"), "w").write("\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=1, help="noise draws per trace (default 1)")
    ap.add_argument("--only", default=",".join(map(str, INDENTS_UM)),
                    help="d_c values in μm (default 126,140,154)")
    ap.add_argument("--md-from-json", action="store_true",
                    help="only rewrite the .md from benchmarks/out/layer_fit_bias.json")
    ap.add_argument("--skip-reverse", action="store_true",
                    help="do not fit data/paper_dc140.csv (a half-space trace) with both models")
    args = ap.parse_args(argv)
    if args.md_from_json:
        with open(os.path.join(OUT, "layer_fit_bias.json")) as f:
            write_md(json.load(f))
        return
    import fitting
    import lubjax
    from benchmarks.machine import label
    from lubjax._threads import single_threaded_blas

    def log(msg):
        print(msg, flush=True)

    start = time.perf_counter()
    machine = label()
    rows, gen = [], 0.0
    with single_threaded_blas():
        for um in (int(u) for u in args.only.split(",")):
            clean, wall = clean_trace(um, log)
            gen += wall
            hbar = lubjax.layer_thickness_bar(LAYER_M, clean.radius, um * 1e-6)
            for k in range(args.seeds):
                seed = 5000 + um + 1000 * k
                trace = noisy(clean, seed, f"layer5mm_dc{um}")
                if k == 0:
                    fitting.write_trace(os.path.join(ROOT, "data", f"layer5mm_dc{um}.csv"), trace)
                t0 = time.perf_counter()
                row = dict(trace=f"layer5mm_dc{um}", seed=seed, hbar=hbar, **fit_pair(trace))
                log(f"{row['trace']} seed {seed}: half-space E* "
                    f"{100 * row['halfspace']['E_star']['bias']:+.2f} %, "
                    f"η {100 * row['halfspace']['viscosity']['bias']:+.2f} %, z0 "
                    f"{100 * row['halfspace']['z0']['bias']:+.2f} %; layer E* "
                    f"{100 * row['layer']['E_star']['bias']:+.2f} %; ΔBIC {row['delta_bic']:.1f} "
                    f"({time.perf_counter() - t0:.0f} s)")
                rows.append(row)
        if not args.skip_reverse:
            trace = fitting.read_trace(os.path.join(ROOT, "data", "paper_dc140.csv"))
            t0 = time.perf_counter()
            row = dict(trace="paper_dc140 (half-space data)", seed=140,
                       hbar=lubjax.layer_thickness_bar(LAYER_M, trace.radius, 140e-6),
                       **fit_pair(trace))
            log(f"reverse: ΔBIC {row['delta_bic']:.1f}, choice {row['choice']} "
                f"({time.perf_counter() - t0:.0f} s)")
            rows.append(row)
    res = dict(command="python -m benchmarks.layer_fit_bias " + " ".join(argv or sys.argv[1:]),
               machine=machine, machine_end=label(), wall_s=time.perf_counter() - start,
               generation_s=gen, rows=rows)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "layer_fit_bias.json"), "w") as f:
        json.dump(res, f, indent=1)
    write_md(res)
    log(f"wrote benchmarks/out/layer_fit_bias.md ({res['wall_s']:.0f} s)")


if __name__ == "__main__":
    main()
