"""Work-precision chart for the relaxation test: error in F̄(t̄) on t̄ ∈ [0, 5] against run time.

    python benchmarks/work_precision.py            # full: 4 cases, all methods (~10-20 min)
    python benchmarks/work_precision.py --quick    # β=100, z̄0=0.5 only, coarse levels (~2 min)

Error = max |F̄ - F̄_ref| / max |F̄_ref| at t̄ = 0, 0.05, ..., 5. Reference: lubjax (graded mesh,
BDF2) at dr=0.01, dt=1e-3, time_growth=1.025, dt_min=1e-7, mesh_growth=1.03, L̄=300; its
convergence is reported as the difference to the next coarser level (dr=0.02, dt=2e-3,
growth 1.05) — row method="reference" in the CSV. Wall time is measured after compilation and
one-off setup (influence matrices), which are reported apart (compile_s). Everything runs
single-threaded (BLAS and XLA pinned). Explicit Euler is not run to t̄ = 5: its stable step at
t̄ = 0 (from the Jacobian's eigenvalues) is reported with the projected cost; one short run at a
"large" step shows the blow-up.

Writes benchmarks/out/work_precision.csv and .png (machine in both).
"""

from __future__ import annotations

import argparse
import csv
import json
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
    lubjax_default,
    lubjax_variant,
    mol,
    newton,
    paper_scheme,
    picard,
)

OUT = Path(__file__).resolve().parent / "out"
CASES_FULL = [(100.0, 0.5), (100.0, 1.0), (100.0, 2.0), (1e4, 0.5)]
CASES_QUICK = [(100.0, 0.5)]
REF_LEVELS = {
    "coarse": dict(dr=0.02, dt=2e-3, dt_min=1e-7, time_growth=1.05, mesh_growth=1.04,
                   length=300.0),
    "fine": dict(dr=0.01, dt=1e-3, dt_min=1e-7, time_growth=1.025, mesh_growth=1.03,
                 length=300.0),
}
LJ_LEVELS = [  # (dr, dt, time_growth): coarse, default, fine
    (0.04, 1e-2, 1.2),
    (0.02, 5e-3, 1.1),
    (0.01, 2.5e-3, 1.05),
]


def reference(beta, z0, t_out):
    """Fine lubjax solution (cached on disk) and the difference to the next coarser level."""
    key = f"ref_b{beta:g}_z{z0:g}_n{t_out.size}_t{t_out[-1]:g}.npz"
    path = OUT / "cache" / key
    if path.exists():
        d = np.load(path)
        return d["fine"], float(d["diff"]), float(d["wall_fine"])
    res = {}
    walls = {}
    for name, s in REF_LEVELS.items():
        f, info = lubjax_default.run(beta, z0, t_out, settings=lubjax.Settings(**s),
                                     warmup=False)
        if not info["ok"]:
            raise RuntimeError(f"reference level {name} failed for beta={beta}, z0={z0}")
        res[name], walls[name] = f, info["wall_s"]
    diff = float(np.max(np.abs(res["fine"] - res["coarse"])) / np.max(np.abs(res["fine"])))
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, fine=res["fine"], coarse=res["coarse"], diff=diff, wall_fine=walls["fine"])
    return res["fine"], diff, walls["fine"]


def method_runs(quick: bool):
    """(group, label, module, opts, is_special) for every run of one case."""
    runs = []
    paper = [(0.04, 4e-3), (0.02, 2e-3)] + ([] if quick else [(0.01, 1e-3)])
    for dr, dt in paper:
        tag = " [paper's settings]" if (dr, dt) == (0.01, 1e-3) else ""
        runs.append(("(a) paper scheme, numpy 2N×2N", f"dr={dr} dt={dt}{tag}", paper_scheme,
                     dict(dr=dr, dt=dt, length=4.0)))
    for dr, dt, g in LJ_LEVELS:
        tag = " [default]" if (dr, dt, g) == (0.02, 5e-3, 1.1) else ""
        runs.append(("(b) lubjax.relax (graded, BDF2, growing dt)", f"dr={dr} dt={dt} "
                     f"growth={g}{tag}", lubjax_default,
                     dict(settings=lubjax.Settings(dr=dr, dt=dt, time_growth=g))))
    levels = LJ_LEVELS[:2] if quick else LJ_LEVELS
    for dr, dt, g in levels:
        runs.append(("(c) lubjax, uniform mesh L=4", f"dr={dr} dt={dt} growth={g}",
                     lubjax_variant, dict(mesh="uniform", dr=dr, length=4.0, dt=dt, growth=g)))
        runs.append(("(c) lubjax, BDF1 (order=1)", f"dr={dr} dt={dt} growth={g}",
                     lubjax_variant, dict(order=1, dr=dr, dt=dt, growth=g)))
        runs.append(("(c) lubjax, fixed dt (no growth)", f"dr={dr} dt={dt}", lubjax_variant,
                     dict(steps="fixed", dr=dr, dt=dt)))
    for dr, dt, g in LJ_LEVELS[:2] + ([] if quick else [(0.02, 2.5e-3, 1.05)]):
        runs.append(("(d) Newton, implicit BE (graded, growing dt)", f"dr={dr} dt={dt} "
                     f"growth={g}", newton, dict(steps="grow", dr=dr, dt=dt, growth=g)))
        runs.append(("(d) Picard on mobility, implicit BE", f"dr={dr} dt={dt} growth={g}",
                     picard, dict(split="mobility", omega=1.0, steps="grow", dr=dr, dt=dt,
                                  growth=g)))
    runs.append(("(d) Picard p/w split, ω=0.5 (Davis-style)", "dr=0.04 dt=0.01 fixed", picard,
                 dict(split="elastic", omega=0.5, steps="fixed", dr=0.04, dt=1e-2)))
    runs.append(("(d) Picard p/w split, ω=0.5 (Davis-style)", "dr=0.04 dt=1e-3 fixed", picard,
                 dict(split="elastic", omega=0.5, steps="fixed", dr=0.04, dt=1e-3)))
    for rtol in ([1e-3, 1e-5] if quick else [1e-3, 1e-5, 1e-7]):
        runs.append(("(f) MOL, solve_ivp BDF + exact Jacobian", f"dr=0.02 rtol={rtol}", mol,
                     dict(rtol=rtol, dr=0.02)))
    if not quick:
        runs.append(("(f) MOL, solve_ivp BDF + exact Jacobian", "dr=0.01 rtol=1e-7", mol,
                     dict(rtol=1e-7, dr=0.01)))
        runs.append(("(f) MOL, solve_ivp Radau + exact Jacobian", "dr=0.02 rtol=1e-5", mol,
                     dict(rtol=1e-5, dr=0.02, method="Radau")))
    return runs


def explicit_rows(beta, z0, t_out, mach):
    """Explicit Euler: one short run at Δt̄ = 1e-6 (blows up), the stability limit at t̄ = 0 and
    the projected cost of [0, 5] at that limit from the measured cost per step."""
    rows = []
    short = t_out[t_out <= 0.05 + 1e-12]
    for mesh, dr, length in (("uniform", 0.05, 4.0), ("graded", 0.02, 100.0)):
        f, info = explicit_euler.run(beta, z0, short, mesh=mesh, dr=dr, length=length, dt=1e-6)
        per_step = info["wall_s"] / max(info["n_steps"], 1)
        lim = explicit_euler.stability_limit(beta, z0, mesh=mesh, dr=dr, length=length)
        projected = per_step * t_out[-1] / lim
        rows.append(dict(
            method="(e) explicit Euler", label=f"{mesh} dr={dr} L={length:g}: dt=1e-6 to t=0.05",
            error=float("nan"), wall_s=info["wall_s"], compile_s=info["compile_s"],
            ok=info["ok"], finite=info["finite"], film_positive=info["film_positive"],
            converged=True, h_min=info["h_min"], n_steps=info["n_steps"],
            n_nodes=info["n_nodes"],
            extra=json.dumps(dict(stable_dt_at_t0=lim, projected_wall_s_to_t5=projected,
                                  per_step_s=per_step))))
    return rows


def run_case(beta, z0, quick, t_out, mach):
    ref, diff, wall_ref = reference(beta, z0, t_out)
    scale = np.max(np.abs(ref))
    rows = [dict(method="reference", label="lubjax fine vs next coarser level", error=diff,
                 wall_s=wall_ref, compile_s=float("nan"), ok=True, finite=True,
                 film_positive=True, converged=True, h_min=float("nan"), n_steps=0, n_nodes=0,
                 extra=json.dumps(dict(levels=REF_LEVELS)))]
    for group, label, module, opts in method_runs(quick):
        t0 = time.perf_counter()
        f, info = module.run(beta, z0, t_out, **opts)
        with np.errstate(invalid="ignore"):
            err = float(np.max(np.abs(f - ref)) / scale)
        if not np.isfinite(err):
            err = float("nan")
        extra = {k: v for k, v in info.items() if k not in (
            "wall_s", "compile_s", "ok", "finite", "film_positive", "converged", "h_min",
            "n_steps", "n_nodes")}
        rows.append(dict(method=group, label=label, error=err, wall_s=info["wall_s"],
                         compile_s=info["compile_s"], ok=info["ok"], finite=info["finite"],
                         film_positive=info["film_positive"], converged=info["converged"],
                         h_min=info["h_min"], n_steps=info["n_steps"],
                         n_nodes=info.get("n_nodes", 0), extra=json.dumps(extra, default=str)))
        print(f"  β={beta:g} z0={z0:g} {group:48s} {label:40s} err={err:9.2e} "
              f"wall={info['wall_s']:8.3f}s compile={info['compile_s']:6.2f}s ok={info['ok']} "
              f"({time.perf_counter() - t0:.1f}s)", flush=True)
    rows += explicit_rows(beta, z0, t_out, mach)
    for r in rows:
        r.update(beta=beta, z0=z0)
    return rows


STYLE = {
    "(a)": dict(color="k", marker="s"),
    "(b)": dict(color="tab:red", marker="o", lw=2.5),
    "(c) lubjax, uniform": dict(color="tab:orange", marker="v"),
    "(c) lubjax, BDF1": dict(color="tab:purple", marker="^"),
    "(c) lubjax, fixed": dict(color="tab:pink", marker="<"),
    "(d) Newton": dict(color="tab:blue", marker="D"),
    "(d) Picard on": dict(color="tab:cyan", marker="P"),
    "(d) Picard p/w": dict(color="tab:gray", marker="X"),
    "(f) MOL, solve_ivp BDF": dict(color="tab:green", marker="*"),
    "(f) MOL, solve_ivp Radau": dict(color="olive", marker="h"),
    "(e)": dict(color="tab:brown", marker=">"),
}


def style(method):
    for k, v in STYLE.items():
        if method.startswith(k):
            return v
    return dict(color="k", marker=".")


def plot(rows, cases, mach, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncol = 2 if len(cases) > 1 else 1
    nrow = (len(cases) + ncol - 1) // ncol
    fig, axes = plt.subplots(nrow, ncol, figsize=(7.5 * ncol, 5.6 * nrow), squeeze=False)
    fail_y = 3.0
    for ax, (beta, z0) in zip(axes.flat, cases, strict=False):
        sel = [r for r in rows if r["beta"] == beta and r["z0"] == z0]
        ref = [r for r in sel if r["method"] == "reference"][0]
        methods = []
        for r in sel:
            if r["method"] not in methods and r["method"] != "reference":
                methods.append(r["method"])
        for m in methods:
            rr = [r for r in sel if r["method"] == m]
            st = style(m)
            if m.startswith("(e)"):
                for r in rr:
                    ex = json.loads(r["extra"])
                    ax.plot(ex["projected_wall_s_to_t5"], fail_y, ls="none", mfc="none",
                            ms=9, color=st["color"], marker=st["marker"])
                ax.plot([], [], ls="none", mfc="none", color=st["color"], marker=st["marker"],
                        label="(e) explicit Euler: projected wall at its stable dt (off scale)")
                continue
            good = [r for r in rr if r["ok"] and np.isfinite(r["error"])]
            bad = [r for r in rr if not (r["ok"] and np.isfinite(r["error"]))]
            good.sort(key=lambda r: r["wall_s"])
            if good:
                ax.plot([r["wall_s"] for r in good], [max(r["error"], 1e-8) for r in good],
                        color=st["color"], marker=st["marker"], lw=st.get("lw", 1.2), ms=6,
                        label=m)
            else:
                ax.plot([], [], color=st["color"], marker=st["marker"], label=m + " (failed)")
            for r in bad:
                ax.plot(r["wall_s"], fail_y, color=st["color"], marker="x", ms=9, mew=2)
            for r in good:
                if "[paper's settings]" in r["label"] or "[default]" in r["label"]:
                    ax.plot(r["wall_s"], r["error"], marker="o", ms=16, mfc="none",
                            color=st["color"], mew=2)
        ax.axhline(ref["error"] / 3, color="0.6", ls=":", lw=1)
        ax.axhline(1e-3, color="tab:red", ls="--", lw=0.8)
        ax.axhline(fail_y, color="0.8", lw=0.8)
        ax.text(1.2e-3, fail_y * 1.15, "failed (x) / not run",
                fontsize=7, color="0.4")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(1e-3, None)
        ax.set_ylim(1e-7, 10)
        ax.set_xlabel("wall time after compilation [s] (single thread)")
        ax.set_ylabel("max |F̄ - F̄_ref| / max F̄_ref on t̄ ∈ [0, 5]")
        ax.set_title(f"β = {beta:g}, z̄0 = {z0:g}   (ref. level diff {ref['error']:.1e}; "
                     f"dotted: its /3)", fontsize=10)
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(cases):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.suptitle("Relaxation test work-precision (circled: paper's settings / lubjax default; "
                 "red dashed: 1e-3)\n" + machine.label(mach), fontsize=10)
    fig.tight_layout(rect=(0, 0.03 + 0.035 * ((len(labels) + 1) // 2) / nrow, 1, 0.95))
    fig.savefig(path, dpi=110)
    plt.close(fig)


FIELDS = ["beta", "z0", "method", "label", "error", "wall_s", "compile_s", "ok", "finite",
          "film_positive", "converged", "h_min", "n_steps", "n_nodes", "extra", "cpu", "cores",
          "threads", "load1"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="one case, coarse levels only")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cases = CASES_QUICK if args.quick else CASES_FULL
    t_out = common.default_t_out(5.0, 0.05)
    rows = []
    start = time.perf_counter()
    for beta, z0 in cases:
        mach = machine.describe()
        case_rows = run_case(beta, z0, args.quick, t_out, mach)
        for r in case_rows:
            r.update(mach)
        rows += case_rows
    name = "work_precision_quick" if args.quick else "work_precision"
    with open(out / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k) for k in FIELDS})
    mach = machine.describe()
    plot(rows, cases, mach, out / f"{name}.png")
    summary(rows, cases)
    print(f"wrote {out / (name + '.csv')} and .png in {time.perf_counter() - start:.0f} s")


def summary(rows, cases):
    for beta, z0 in cases:
        sel = [r for r in rows if r["beta"] == beta and r["z0"] == z0]
        base = [r for r in sel if r["method"].startswith("(a)")]
        base = max(base, key=lambda r: r["n_steps"])  # the finest = paper's own settings
        dflt = [r for r in sel if "[default]" in r["label"]][0]
        ref = [r for r in sel if r["method"] == "reference"][0]
        print(f"β={beta:g} z0={z0:g}: reference level diff {ref['error']:.2e}; paper scheme "
              f"({base['label']}) err {base['error']:.2e} wall {base['wall_s']:.2f}s; lubjax "
              f"default err {dflt['error']:.2e} wall {dflt['wall_s']:.3f}s "
              f"(compile {dflt['compile_s']:.2f}s); speed ratio "
              f"{base['wall_s'] / dflt['wall_s']:.0f}x")


if __name__ == "__main__":
    main()
