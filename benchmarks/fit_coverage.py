"""Are the reported standard errors honest? z-scores over seeded noise draws, scene by scene.

    python -m benchmarks.fit_coverage [--scenes relaxation creep ...] [--draws 50]
                                      [--rho 0 0.8] [--t-bar 3] [--seed 2024] [--out FILE]

Each draw is a clean trace of the fine generator (data/clean/: rtol 1e-7 on a 544-node mesh,
the stage's lag, the input sampled finely; not the fit's discretisation) plus Gaussian noise of
marginal σ = 1 % of the response's peak on the response channel (the force; the displacement
under a prescribed load), white (ρ = 0) or AR(1) (n_k = ρ n_{k-1} + √(1-ρ²) σ ε_k). The draws
of a scene are fitted in one batched call, as ``lubjax-fit`` would fit that trace, at the
default ``fitting.FIT_SETTINGS``, on the trace cut to t̄ ≤ ``--t-bar``. Scenes (``SCENES``):

* relaxation: paper_dc154 (glass bead, PDMS, silicone oil; β = 54), travel;
* creep: creep_30mN, a prescribed load (the displacement is the response);
* spring: spring_dc140, the sphere on a load cell of known stiffness;
* viscoelastic: visco_dc140, a standard linear solid (E0/E∞ = 1.5, τ = 0.5 s) fitted as one;
* near-dry: water_dc140 (PDMS under water, β = 5.4e6): η is bounded only from above.

For each parameter, z = (estimate - truth)/reported error: honest errors put 68 % of the draws
within 1σ and 95 % within 2σ (where the fit gives a parameter a profile-χ² interval, near
dry η's and, through it, E*'s and z0's, a draw counts as within kσ when the truth lies inside
its interval at k σ; η's one-sided intervals are left out of its rms z, E*'s and z0's z is
over their 1σ interval's half on the truth's side; "profile intervals" says how many)
(N = 50 draws scatter those fractions by ±7 % and ±3 %) and give rms z ≈ 1 (±0.1). The
white-noise errors alone (no AR(1) sandwich, no solver error) are shown beside them. Writes
``--out`` (default benchmarks/out/fit_coverage.md) after every row.
"""

from __future__ import annotations

import os
import time
from typing import NamedTuple

import fitting
from benchmarks import _harness
from benchmarks._harness import ROOT
from fitting._scales import cut_trace

TRUE = {"E_star": "true_E_star_Pa", "viscosity": "true_viscosity_Pa_s", "z0": "true_z0_m",
        "stiffening": "true_stiffening", "relaxation_time": "true_relaxation_time_s"}
SYMBOL = {"E_star": "E*", "viscosity": "η", "z0": "z0", "stiffening": "E0/E∞",
          "relaxation_time": "τ"}


class Scene(NamedTuple):
    stem: str  # data/clean/<stem>_clean.csv
    fit_kwargs: dict
    parameters: tuple = ("E_star", "viscosity", "z0")


SCENES = {
    "relaxation": Scene("paper_dc154", {}),
    "creep": Scene("creep_30mN", {}),
    "spring": Scene("spring_dc140", {}),
    "viscoelastic": Scene("visco_dc140", {"viscoelastic": True},
                          ("E_star", "viscosity", "z0", "stiffening", "relaxation_time")),
    "near-dry": Scene("water_dc140", {}),
}


def clean_trace(stem="paper_dc154", t_bar=3.0):
    """The noiseless trace of ``stem`` cut to t̄ ≤ ``t_bar`` after its start."""
    return cut_trace(fitting.read_trace(os.path.join(ROOT, "data", "clean", f"{stem}_clean.csv")),
                     t_bar)


def _markdown(rows):
    lines = ["| scene | noise | converged | parameter | within 1σ | within 2σ | rms z | "
             "rms z (white only) | mean bias / SE | scatter / SE | solver part / SE | "
             "noise model used | residuals' lag-1 | noise ρ (AR(1) errors) | "
             "profile intervals |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for scene, rho, out in rows:
        for name, t in out["table"].items():
            lines.append(
                f"| {scene} | {'white' if rho == 0 else f'AR(1) ρ = {rho:g}'} | "
                f"{out['converged']}/{out['n']} | {SYMBOL[name]} | "
                f"{t['within_1sigma']:.0%} | {t['within_2sigma']:.0%} | {t['rms_z']:.2f} | "
                f"{t['rms_z_white']:.2f} | {t['mean_bias_over_se']:+.2f} | "
                f"{t['scatter_over_se']:.2f} | {t['solver_over_se']:.2f} | "
                f"{', '.join(out['noise_models'])} | {out['lag1']:.2f} | "
                f"{out['noise_correlation']:.2f} | {t['profiled']}/{out['n']} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = _harness.parser(__doc__, "fit_coverage.md")
    p.add_argument("--scenes", nargs="+", choices=sorted(SCENES), default=["relaxation"])
    p.add_argument("--draws", type=int, default=50)
    p.add_argument("--rho", type=float, nargs="+", default=[0.0, 0.8])
    p.add_argument("--t-bar", type=float, default=3.0)
    p.add_argument("--seed", type=int, default=2024, help="the noise draws' seed")
    args = _harness.parse(p, argv)

    cleans = {name: clean_trace(SCENES[name].stem, args.t_bar) for name in args.scenes}
    rows = []
    for rho in args.rho:  # every scene's white-noise row first
        for name, clean in cleans.items():
            scene = SCENES[name]
            truth = {n: float(clean.metadata[TRUE[n]]) for n in scene.parameters}
            start = time.perf_counter()
            draws = fitting.noise_draws(clean, args.draws, rho, seed=args.seed)
            out = fitting.coverage(draws, truth, **scene.fit_kwargs)
            rows.append((name, rho, out))
            print(f"{name}, rho = {rho:g}: {args.draws} draws fitted in "
                  f"{time.perf_counter() - start:.0f} s", flush=True)
            text = (f"# Coverage of the reported errors\n\n`{_harness.command(argv)}` "
                    f"({_harness.label()})\n\n" + _markdown(rows))
            with open(args.out, "w") as fh:
                fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
