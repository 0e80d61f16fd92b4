"""Near-dry contacts: the steps a stiff or slow scene costs, by what the film's error is measured
against (``Settings.film_error``), and the force's accuracy there against converged runs.

    python -m benchmarks.near_dry [--quick] [--accuracy]

Steps: relax(β, z̄0, 5) at the default tolerance, β ∈ {10², 10⁴, ..., 10⁹} × z̄0 ∈ {0.1, 0.5, 1}
(no error estimate: its coarse runs do not change the steps counted), accepted steps and run
time, with ``film_error="relative"`` (the default) and ``"force"`` (the fits'), and the ratio
to the β = 100 run of the same z̄0 (the target: at most 3). A run that did not reach t̄ = 5 is
marked "budget" with the time it reached.

``--accuracy``: for β ∈ {10⁴, 10⁶, 10⁷}, z̄0 = 0.5, the force of both against a reference
(film_error="relative", rtol 1e-6, its finer mesh) checked by a second one (rtol 3e-6): the
largest |F̄ - F̄_ref| over the peak, and pointwise where F̄_ref > 10⁻³ of its peak; and how far
min h̄ is from the reference's. Writes benchmarks/out/near_dry.md.
"""

from __future__ import annotations

import dataclasses
import time

import jax
import numpy as np

import lubjax
from benchmarks import _harness
from lubjax.stepper import Status, discretise, evaluate_host, rollout

BETAS = (1e2, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9)
Z0S = (0.1, 0.5, 1.0)
MODES = ("relative", "force")
T_END = 5.0
TIMES = np.linspace(0.02, T_END, 500)


def run(beta, z0, settings):
    """(trajectory, seconds run) of relax's run on relax's mesh, without the error estimate."""
    drive = lubjax.Travel()
    disc = discretise(lubjax.mesh_for(settings, drive=drive, beta=beta, z0=z0, t_end=T_END))
    fn = jax.jit(lambda b, z, tol: rollout(disc, b, z, drive, T_END, tol))
    tol = settings.tolerance()
    jax.block_until_ready(fn(beta, z0, tol))  # compile
    start = time.perf_counter()
    traj = jax.block_until_ready(fn(beta, z0, tol))
    return traj, time.perf_counter() - start


def steps_table(betas, z0s):
    lines = ["| z̄0 | film_error | " + " | ".join(f"β = {b:.0e}" for b in betas) + " |",
             "|---|---|" + "---|" * len(betas)]
    for z0 in z0s:
        for mode in MODES:
            settings = lubjax.Settings(error_estimate=False, film_error=mode)
            cells, base = [], None
            for beta in betas:
                traj, seconds = run(beta, z0, settings)
                n = int(traj.accepted)
                base = n if base is None else base
                done = int(traj.status) == Status.DONE
                cell = (f"{n} ({n / base:.1f}×, {seconds:.1f} s)" if done else
                        f"budget at t̄ = {float(traj.t_final):.3g}")
                cells.append(cell)
                print(f"z0={z0} {mode} beta={beta:g}: {cell}", flush=True)
            lines.append(f"| {z0:g} | {mode} | " + " | ".join(cells) + " |")
    return lines


def accuracy_table(betas, z0=0.5):
    ref_settings = lubjax.Settings(rtol=1e-6, error_estimate=False, max_steps=200_000,
                                   film_error="relative")
    check_settings = dataclasses.replace(ref_settings, rtol=3e-6)
    lines = ["| β | reference check: F/peak | film_error | steps | F/peak | F pointwise | "
             "min h̄ (relative to the reference's) |", "|---|---|---|---|---|---|---|"]
    for beta in betas:
        ref, _ = run(beta, z0, ref_settings)
        check, _ = run(beta, z0, check_settings)
        f_ref = evaluate_host(ref.steps, TIMES, "force")
        h_ref = evaluate_host(ref.steps, TIMES, "film_min")
        peak = np.max(np.abs(f_ref))
        ref_change = np.max(np.abs(evaluate_host(check.steps, TIMES, "force") - f_ref)) / peak
        for mode in MODES:
            traj, _ = run(beta, z0, lubjax.Settings(error_estimate=False, film_error=mode))
            f = evaluate_host(traj.steps, TIMES, "force")
            h = evaluate_host(traj.steps, TIMES, "film_min")
            big = np.abs(f_ref) > 1e-3 * peak
            row = (f"| {beta:.0e} | {ref_change:.1e} | {mode} | {int(traj.accepted)} | "
                   f"{np.max(np.abs(f - f_ref)) / peak:.1e} | "
                   f"{np.max(np.abs(f[big] / f_ref[big] - 1)):.1e} | "
                   f"{np.max(np.abs(h / h_ref - 1)):.1e} |")
            print(row, flush=True)
            lines.append(row)
    return lines


def main(argv=None):
    ap = _harness.parser(__doc__, "near_dry.md", quick="β ∈ {10², 10⁶, 10⁹}, z̄0 = 0.5")
    ap.add_argument("--accuracy", action="store_true", help="also the force against references")
    args = _harness.parse(ap, argv)
    betas, z0s = ((1e2, 1e6, 1e9), (0.5,)) if args.quick else (BETAS, Z0S)
    lines = [f"# Near-dry contacts ({_harness.label()})", "",
             f"`{_harness.command(argv)}`", "",
             "Accepted steps of relax(β, z̄0, 5) at the default tolerance (ratio to β = 100, run "
             "time after compiling):", "", *steps_table(betas, z0s)]
    if args.accuracy:
        lines += ["", "The force against a converged reference, z̄0 = 0.5:", "",
                  *accuracy_table((1e4, 1e6, 1e7))]
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()
