"""Near-dry contacts: the steps a stiff or slow scene costs, by what the film's error is measured
against (``Settings.film_error``), and the force's accuracy there against converged runs.

    python -m benchmarks.near_dry [--quick] [--accuracy]
    python -m benchmarks.near_dry --map [--quick] [--drives travel,load,spring,free]

Steps: relax(β, z̄0, 5) at the default tolerance, β ∈ {10², 10⁴, ..., 10⁹} × z̄0 ∈ {0.1, 0.5, 1}
(no error estimate: its coarse runs do not change the steps counted), accepted steps and run
time, with ``film_error="auto"`` (the default), ``"relative"`` and ``"force"``,
and the ratio to the β = 100 run of the same z̄0 and norm (the target: at most 3). A run that
did not reach t̄ = 5 is marked "budget" with the time it reached.

``--accuracy``: for β ∈ {10⁴, 10⁵, 10⁶, 10⁷} at z̄0 = 0.5 and β = 10⁹ at z̄0 ∈ {0.1, 0.5}
(``ACCURACY_CASES``), the force of "auto" and "relative" against a reference (rtol 1e-6, its
finer mesh; the relative norm, but the force norm at β = 10⁹) checked by a second one (rtol
3e-6, dr = 0.0035): the largest |F̄ - F̄_ref| over the peak, and pointwise where F̄_ref > 10⁻³
of its peak; and how far min h̄ is from a relative reference's. Writes
benchmarks/out/near_dry.md.

``--map``: a near-dry stability map of every drive, each cell run with the default settings
and with ``film_error="relative"`` (no error estimate: it does not change the run's steps), to
t̄ = 2 (the ramp and as long a hold; ``--t-end``): travel, load and spring (``Travel()``,
``Load()``, ``Spring()`` with their default numbers) over β ∈ {10⁴, ..., 10⁹} × z̄0 ∈ {0.1,
0.5, 1}, and the free sphere (``FreeSphere(2β/(π St), -1, 0)``, the collision's scales: z̄0 = 1
the starting gap, t̄ ≤ 4) over β × St ∈ {10, 100, 1000}. Each cell is (first match): refused
(SolverError / ValueError raised), diverged (NaN/inf or |F̄| > 10⁶), stalled (the step budget
spent or the step collapsed before t_end; the t̄ reached is in the cell), negative film,
inaccurate (the response, F̄ or for a load and a free sphere z̄, more than 10⁻² of its range
from a tighter run: rtol 10⁻⁵, the force norm, on the default spacing, where the cell's own run took
at most ``--ref-budget`` seconds), ok (checked so), ok, unchecked (no tighter run). Writes
benchmarks/out/near_dry_map{,_quick}.{csv,md,png} after each drive (partial maps survive).
``--quick``: β ∈ {10⁴, 10⁶, 10⁸, 10⁹}, z̄0 = 0.5 (St = 100).
"""

from __future__ import annotations

import csv
import dataclasses
import os
import time

import jax
import numpy as np

import lubjax
from benchmarks import _harness
from lubjax.stepper import Status, discretise, evaluate_host, rollout

BETAS = (1e2, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9)
Z0S = (0.1, 0.5, 1.0)
#: "auto" is the default (relative below β = 10⁵, force from there on).
MODES = ("auto", "relative", "force")
#: The map runs the default and the relative norm ("force" is "auto" at every β ≥ 10⁵ it maps).
MAP_MODES = ("auto", "relative")
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


#: (β, z̄0, the references' film norm): "relative" references also converge the film (their
#: min h̄ is compared); at β = 10⁹ the relative reference is out of reach (its rtol-1e-6 run
#: did not finish), so the force norm's references check the force only.
ACCURACY_CASES = ((1e4, 0.5, "relative"), (1e5, 0.5, "relative"), (1e6, 0.5, "relative"),
                  (1e7, 0.5, "relative"), (1e9, 0.5, "force"), (1e9, 0.1, "force"))
QUICK_ACCURACY_CASES = ((1e6, 0.5, "relative"), (1e9, 0.5, "force"))


def accuracy_table(cases):
    """Each case against a reference (rtol 1e-6 on its finer mesh) checked by a second one
    (rtol 3e-6 on a mesh of another spacing, dr = 0.0035)."""
    lines = ["| β | z̄0 | reference check: F/peak | film_error | steps | F/peak | F pointwise | "
             "min h̄ (relative to the reference's) |", "|---|---|---|---|---|---|---|---|"]
    for beta, z0, ref_mode in cases:
        ref_settings = lubjax.Settings(rtol=1e-6, error_estimate=False, max_steps=300_000,
                                       film_error=ref_mode)
        check_settings = dataclasses.replace(ref_settings, rtol=3e-6, dr=0.0035)
        ref, _ = run(beta, z0, ref_settings)
        check, _ = run(beta, z0, check_settings)
        f_ref = evaluate_host(ref.steps, TIMES, "force")
        h_ref = evaluate_host(ref.steps, TIMES, "film_min")
        peak = np.max(np.abs(f_ref))
        ref_change = np.max(np.abs(evaluate_host(check.steps, TIMES, "force") - f_ref)) / peak
        for mode in ("auto", "relative"):
            traj, _ = run(beta, z0, lubjax.Settings(error_estimate=False, film_error=mode))
            if int(traj.status) != Status.DONE:
                row = (f"| {beta:.0e} | {z0:g} | {ref_change:.1e} | {mode} | budget at t̄ = "
                       f"{float(traj.t_final):.3g} | | | |")
            else:
                f = evaluate_host(traj.steps, TIMES, "force")
                h = evaluate_host(traj.steps, TIMES, "film_min")
                big = np.abs(f_ref) > 1e-3 * peak
                film = (f"{np.max(np.abs(h / h_ref - 1)):.1e}" if ref_mode == "relative"
                        else "(no film reference)")
                row = (f"| {beta:.0e} | {z0:g} | {ref_change:.1e} | {mode} | "
                       f"{int(traj.accepted)} | {np.max(np.abs(f - f_ref)) / peak:.1e} | "
                       f"{np.max(np.abs(f[big] / f_ref[big] - 1)):.1e} | {film} |")
            print(row, flush=True)
            lines.append(row)
    return lines


MAP_BETAS = (1e4, 1e5, 1e6, 1e7, 1e8, 1e9)
MAP_DRIVES = ("travel", "load", "spring", "free")
STOKES = (10.0, 100.0, 1000.0)
FREE_T_END = 4.0
MAP_REF_RTOL = 1e-5
#: 100 × the default rtol: the global error is a few rtol (docs/accuracy.md), so a cell this far
#: off its tighter run has failed, not merely drifted.
INACCURATE = 1e-2
MAP_CATEGORIES = ("ok", "ok, unchecked", "inaccurate", "negative film", "stalled", "diverged",
                  "refused")
MAP_COLORS = ("#4caf50", "#a5d6a7", "#ffeb3b", "#e91e63", "#3f51b5", "#212121", "#9e9e9e")
MAP_FIELDS = ("drive", "beta", "param", "value", "film_error", "category", "accepted",
              "rejected", "t_reached", "t_end", "run_s", "compile_s", "error", "h_min",
              "message", "cpu", "cores", "threads", "load1")


def scene(name, beta, value, t_end):
    """(drive, z̄0, t_end, the response compared) of a map cell; ``value`` is z̄0, or St for the
    free sphere."""
    if name == "free":
        return lubjax.FreeSphere(2.0 * beta / (np.pi * value), -1.0, 0.0), 1.0, FREE_T_END, "gap"
    drive = {"travel": lubjax.Travel, "load": lubjax.Load, "spring": lubjax.Spring}[name]()
    return drive, value, t_end, "gap" if name == "load" else "force"


def _response_error(res, ref, field):
    """max |y - y_ref| over the tighter run's range of y (F̄: its peak; z̄: its travel)."""
    times = np.linspace(float(ref.t[0]), res.t_end, 400)
    y, y_ref = res.at(times, field), ref.at(times, field)
    scale = (np.max(np.abs(y_ref)) if field == "force"
             else np.max(np.abs(y_ref - y_ref[0])))
    return float(np.max(np.abs(y - y_ref)) / scale)


_MAP_REFS: dict = {}


def map_reference(name, beta, value, t_end):
    """The tighter run of a cell (rtol 10⁻⁵ on the default settings' mesh, the force norm: the
    force it checks converges either way, and the relative norm's run spends 2·10⁵ attempts
    where the default stalls), or None if it did not finish cleanly; one per cell, shared by
    both norms."""
    key = (name, beta, value, t_end)
    if key not in _MAP_REFS:
        drive, z0, t_end, _ = scene(name, beta, value, t_end)
        dr, growth, length = lubjax.Settings().mesh_parameters()
        settings = lubjax.Settings(rtol=MAP_REF_RTOL, dr=dr, mesh_growth=growth, length=length,
                                   error_estimate=False, max_steps=200_000, film_error="force")
        ref = lubjax.relax(beta, z0, t_end, drive=drive, settings=settings, check="flag")
        _MAP_REFS[key] = ref if ref.ok else None
    return _MAP_REFS[key]


def map_cell(name, beta, value, mode, t_end, ref_budget):
    """One cell of the map: its row for the CSV."""
    drive, z0, t_end, field = scene(name, beta, value, t_end)
    row = dict(drive=name, beta=beta, param="St" if name == "free" else "z0", value=value,
               film_error=mode, t_end=t_end, message="", error=float("nan"),
               **_harness.describe())
    try:
        res = lubjax.relax(beta, z0, t_end, drive=drive, check="flag",
                           settings=lubjax.Settings(film_error=mode, error_estimate=False))
    except (lubjax.SolverError, ValueError) as exc:
        return dict(row, category="refused", message=f"{type(exc).__name__}: {exc}"[:300])
    row.update(accepted=res.accepted, rejected=res.rejected, t_reached=float(res.t[-1]),
               run_s=res.run_s, compile_s=res.compile_s, h_min=float(np.min(res.film_min)),
               message="; ".join(res.problems())[:300])
    if not np.all(np.isfinite(res.force)) or np.max(np.abs(res.force)) > 1e6:
        return dict(row, category="diverged")
    if not res.finished:
        return dict(row, category="stalled")
    if not res.film_positive:
        return dict(row, category="negative film")
    if res.run_s > ref_budget:
        return dict(row, category="ok, unchecked")
    ref = map_reference(name, beta, value, t_end)
    if ref is None:
        return dict(row, category="ok, unchecked", message="the tighter run did not finish")
    row["error"] = _response_error(res, ref, field)
    return dict(row, category="inaccurate" if row["error"] > INACCURATE else "ok")


def _cell_text(r):
    if r["category"] == "refused":
        return "refused"
    steps = r["accepted"]
    text = f"{steps / 1000:.1f}k" if steps >= 1000 else f"{steps}"
    if r["category"] == "stalled":
        return f"t̄ {r['t_reached']:.2g}"
    if r["category"] == "inaccurate":
        return f"{text}\n{100 * r['error']:.0f}%"
    return text


def plot_map(rows, drives, betas, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    cmap = ListedColormap(MAP_COLORS)
    fig, axes = plt.subplots(len(drives), len(MAP_MODES),
                             figsize=(4.6 * len(MAP_MODES), 2.3 * len(drives)), squeeze=False)
    for row_axes, name in zip(axes, drives, strict=True):
        for ax, mode in zip(row_axes, MAP_MODES, strict=True):
            cells = [r for r in rows if r["drive"] == name and r["film_error"] == mode]
            values = sorted({r["value"] for r in cells})
            grid = np.full((max(len(values), 1), len(betas)), np.nan)
            for r in cells:
                i, j = values.index(r["value"]), betas.index(r["beta"])
                grid[i, j] = MAP_CATEGORIES.index(r["category"])
                ax.text(j, i, _cell_text(r), ha="center", va="center", fontsize=6)
            ax.imshow(grid, cmap=cmap, vmin=-0.5, vmax=len(MAP_CATEGORIES) - 0.5,
                      origin="lower", aspect="auto")
            ax.set_xticks(range(len(betas)), [f"{b:.0e}".replace("e+0", "e") for b in betas],
                          fontsize=7)
            ax.set_yticks(range(len(values)), [f"{v:g}" for v in values], fontsize=7)
            ax.set_ylabel("St" if name == "free" else "z̄0", fontsize=8)
            ax.set_xlabel("β", fontsize=8)
            ax.set_title(f"{name}, film_error={mode!r}", fontsize=8)
    handles = [Patch(color=c, label=k) for k, c in zip(MAP_CATEGORIES, MAP_COLORS, strict=True)]
    fig.legend(handles=handles, loc="lower center", ncol=len(MAP_CATEGORIES), fontsize=7,
               frameon=False)
    # (the machine and commit are in the report and the page's caption, once)
    fig.suptitle("Near-dry stability map, default settings and the relative norm (cells: accepted "
                 "steps; stalled: the t̄ reached; inaccurate: error / range)", fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def map_table(rows, drives, betas):
    lines = ["| drive | z̄0 / St | film_error | " + " | ".join(f"β = {b:.0e}" for b in betas)
             + " |", "|---|---|---|" + "---|" * len(betas)]
    for name in drives:
        for value in sorted({r["value"] for r in rows if r["drive"] == name}):
            for mode in MAP_MODES:
                by_beta = {r["beta"]: r for r in rows if r["drive"] == name
                           and r["value"] == value and r["film_error"] == mode}
                cells = []
                for b in betas:
                    r = by_beta.get(b)
                    if r is None:
                        cells.append("")
                    elif r["category"] in ("ok", "ok, unchecked"):
                        mark = "" if r["category"] == "ok" else "*"
                        cells.append(f"{r['accepted']}{mark} ({r['run_s']:.1f} s)")
                    elif r["category"] == "stalled":
                        cells.append(f"stalled at t̄ = {r['t_reached']:.3g}")
                    elif r["category"] == "inaccurate":
                        cells.append(f"inaccurate ({r['error']:.1e}), {r['accepted']}")
                    else:
                        cells.append(r["category"])
                label = f"St = {value:g}" if name == "free" else f"{value:g}"
                lines.append(f"| {name} | {label} | {mode} | " + " | ".join(cells) + " |")
    return lines


def stability_map(args, argv):
    betas = (1e4, 1e6, 1e8, 1e9) if args.quick else MAP_BETAS
    z0s = (0.5,) if args.quick else Z0S
    stokes = (100.0,) if args.quick else STOKES
    drives = [d for d in args.drives.split(",") if d]
    for d in drives:
        if d not in MAP_DRIVES:
            raise SystemExit(f"--drives: unknown drive {d!r}; choose from {', '.join(MAP_DRIVES)}")
    stem = os.path.join(os.path.dirname(os.path.abspath(args.out)),
                        "near_dry_map" + ("_quick" if args.quick else ""))
    rows, start = [], time.perf_counter()
    for name in drives:
        for value in stokes if name == "free" else z0s:
            for beta in betas:
                for mode in MAP_MODES:
                    r = map_cell(name, beta, value, mode, args.t_end, args.ref_budget)
                    rows.append(r)
                    print(f"{name} {r['param']}={value:g} β={beta:.0e} {mode}: {r['category']} "
                          f"steps {r.get('accepted')} t̄ {r.get('t_reached', float('nan')):.3g} "
                          f"run {r.get('run_s', float('nan')):.1f} s err {r['error']:.1e} "
                          f"[{time.perf_counter() - start:.0f} s]", flush=True)
        done = [d for d in drives if any(r["drive"] == d for r in rows)]
        with open(stem + ".csv", "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=MAP_FIELDS)
            w.writeheader()
            w.writerows({k: r.get(k) for k in MAP_FIELDS} for r in rows)
        plot_map(rows, done, list(betas), stem + ".png")
        lines = [f"# Near-dry stability map ({_harness.label()})", "",
                 f"`{_harness.command(argv)}` ({time.perf_counter() - start:.0f} s)", "",
                 f"Accepted steps (run time after compiling) of each drive to t̄ = {args.t_end:g} "
                 f"(free sphere: {FREE_T_END:g}), default settings (film_error \"auto\") and "
                 f"film_error=\"relative\" (no error estimate); * = no tighter run (rtol "
                 f"{MAP_REF_RTOL:g}) to check it against; inaccurate: > {INACCURATE:g} of the "
                 "response's range off it.", "",
                 *map_table(rows, done, list(betas))]
        _harness.write_report(stem + ".md", lines)
    print(f"wrote {stem}.{{csv,md,png}} in {time.perf_counter() - start:.0f} s")


def main(argv=None):
    ap = _harness.parser(__doc__, "near_dry.md", quick="β ∈ {10², 10⁶, 10⁹}, z̄0 = 0.5 (with "
                         "--map: β ∈ {10⁴, 10⁶, 10⁸, 10⁹}, z̄0 = 0.5, St = 100)")
    ap.add_argument("--accuracy", action="store_true", help="also the force against references")
    ap.add_argument("--map", action="store_true",
                    help="the near-dry stability map of every drive instead of the steps table")
    ap.add_argument("--drives", default=",".join(MAP_DRIVES),
                    help="with --map: comma-separated subset of travel,load,spring,free")
    ap.add_argument("--t-end", type=float, default=2.0,
                    help="with --map: t̄ of the travel, load and spring runs (default 2)")
    ap.add_argument("--ref-budget", type=float, default=10.0,
                    help="with --map: run the tighter check only where the cell's run took at "
                         "most this many seconds (default 10)")
    args = _harness.parse(ap, argv)
    if args.map:
        stability_map(args, argv)
        return
    betas, z0s = ((1e2, 1e6, 1e9), (0.5,)) if args.quick else (BETAS, Z0S)
    lines = [f"# Near-dry contacts ({_harness.label()})", "",
             f"`{_harness.command(argv)}`", "",
             "Accepted steps of relax(β, z̄0, 5) at the default tolerance (ratio to β = 100, run "
             "time after compiling):", "", *steps_table(betas, z0s)]
    if args.accuracy:
        lines += ["", "The force against a converged reference:", "",
                  *accuracy_table(QUICK_ACCURACY_CASES if args.quick else ACCURACY_CASES)]
    _harness.write_report(args.out, lines)


if __name__ == "__main__":
    main()
