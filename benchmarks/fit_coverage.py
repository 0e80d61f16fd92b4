"""Are the reported standard errors honest? z-scores over seeded noise draws.

    python benchmarks/fit_coverage.py [--draws 60] [--rho 0 0.8] [--t-bar 3]

Each draw is a clean trace of the fine generator (data/clean/, rtol 1e-7, 544 nodes: not the
fit's discretisation) plus Gaussian noise of marginal σ = 1 % of the peak force, white (ρ = 0)
or AR(1) (n_k = ρ n_{k-1} + √(1-ρ²) σ ε_k). All draws are fitted in one batched call. For each
parameter, z = (estimate - truth)/reported error; honest errors give rms z ≈ 1 (the rms of N
draws scatters by ≈ 1/√(2N) around it: ±0.14 at N = 24, ±0.09 at N = 60). The white-noise
errors alone (no AR(1) sandwich, no solver error) are shown beside them.

The fit runs at its default ``fitting.FIT_SETTINGS`` (rtol 3e-4, 132 nodes) on the trace cut to
t̄ ≤ ``--t-bar``. Writes benchmarks/out/fit_coverage.md.
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import fitting  # noqa: E402

COVERAGE_SETTINGS = fitting.FIT_SETTINGS
TRUE = {"E_star": "true_E_star_Pa", "viscosity": "true_viscosity_Pa_s", "z0": "true_z0_m"}


def clean_trace(stem="paper_dc154", t_bar=3.0):
    tr = fitting.read_trace(os.path.join(ROOT, "data", "clean", f"{stem}_clean.csv"))
    sc = fitting.scales_from_trace(tr)
    keep = tr.time < sc.t_on + t_bar * sc.time_scale
    return tr._replace(time=tr.time[keep], displacement=tr.displacement[keep],
                       force=tr.force[keep])


def noise_draws(clean, n, rho=0.0, fraction=0.01, seed=2024):
    """n noisy copies of ``clean``: stationary AR(1) noise, marginal σ = fraction × peak."""
    rng = np.random.default_rng(seed)
    sigma = fraction * float(np.max(clean.force))
    out = []
    for k in range(n):
        e = rng.normal(0.0, sigma, clean.force.size)
        noise = np.empty_like(e)
        noise[0] = e[0]
        for i in range(1, e.size):
            noise[i] = rho * noise[i - 1] + np.sqrt(1 - rho**2) * e[i]
        out.append(clean._replace(force=clean.force + noise, name=f"draw{k}"))
    return out


def coverage(draws, clean, settings=COVERAGE_SETTINGS, **fit_kwargs):
    """rms z per parameter: reported errors, and the white-noise part alone."""
    results = fitting.fit_traces(draws, settings=settings, **fit_kwargs)
    table = {}
    for name, key in TRUE.items():
        true = float(clean.metadata[key])
        est = np.array([r.values[name] for r in results])
        se = np.array([r.stderr[name] for r in results])
        white = np.array([r.stats["error_parts"]["white"][name] for r in results])
        solver = np.array([r.stats["error_parts"].get("solver", {}).get(name, 0.0)
                           for r in results])
        table[name] = dict(
            rms_z=float(np.sqrt(np.mean(((est - true) / se) ** 2))),
            rms_z_white=float(np.sqrt(np.mean(((est - true) / white) ** 2))),
            mean_bias_over_se=float(np.mean(est - true) / np.mean(se)),
            scatter_over_se=float(np.std(est, ddof=1) / np.mean(se)),
            solver_over_se=float(np.mean(solver) / np.mean(se)),
        )
    models = sorted({r.stats["noise_model"] for r in results})
    return dict(table=table, converged=int(sum(r.converged for r in results)), n=len(results),
                noise_models=models,
                lag1=float(np.mean([r.stats["autocorrelation_lag1"] for r in results])))


def _markdown(rows):
    lines = ["| noise | draws | parameter | rms z (reported) | rms z (white only) | "
             "mean bias / SE | scatter / SE | solver part / SE | noise model used |",
             "|---|---|---|---|---|---|---|---|---|"]
    for rho, out in rows:
        for name, t in out["table"].items():
            lines.append(
                f"| {'white' if rho == 0 else f'AR(1) ρ = {rho:g}'} | {out['n']} | {name} | "
                f"{t['rms_z']:.2f} | {t['rms_z_white']:.2f} | {t['mean_bias_over_se']:+.2f} | "
                f"{t['scatter_over_se']:.2f} | {t['solver_over_se']:.2f} | "
                f"{', '.join(out['noise_models'])} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=60)
    p.add_argument("--rho", type=float, nargs="+", default=[0.0, 0.8])
    p.add_argument("--t-bar", type=float, default=3.0)
    args = p.parse_args(argv)
    from benchmarks.machine import describe

    clean = clean_trace(t_bar=args.t_bar)
    rows = []
    for rho in args.rho:
        out = coverage(noise_draws(clean, args.draws, rho), clean)
        rows.append((rho, out))
        print(rho, out, flush=True)
    text = (f"# Coverage of the reported errors ({describe()})\n\n"
            f"`python benchmarks/fit_coverage.py --draws {args.draws} --rho "
            f"{' '.join(f'{r:g}' for r in args.rho)} --t-bar {args.t_bar:g}`\n\n"
            + _markdown(rows))
    os.makedirs(os.path.join(ROOT, "benchmarks", "out"), exist_ok=True)
    with open(os.path.join(ROOT, "benchmarks", "out", "fit_coverage.md"), "w") as fh:
        fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
