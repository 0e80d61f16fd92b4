"""Work-precision chart for the relaxation test: run time against error in F̄(t̄), t̄ ∈ [0, 1]
and t̄ ∈ [0, 5], every method timed in the same run on the same machine.

    python -m benchmarks.work_precision --quick   # β=100, z̄0 ∈ {0.5, 2}, fewer levels
    python -m benchmarks.work_precision           # + β=1e4, z̄0=0.5, all levels

Methods: (a) the paper's scheme ported to numpy (dense 2N×2N solve per step, uniform Δr̄, L̄ = 4,
uniform Δt̄) — the baseline, its own settings Δr̄ = 0.01, Δt̄ = 1e-3 marked; (b) ``lubjax.relax``
traced by its one accuracy knob ``Settings(rtol=...)`` (mesh from rtol, contact refinement on,
``error_estimate=False``; one extra point with all defaults, estimate included); (b3) the same
sweep with ``Settings(order=3)`` (BDF3, an option); (c) lubjax's
stepper with one idea switched off (uniform mesh L̄ = 4; BDF1) — fixed steps no longer exist in
lubjax, so that variant is not run; (d) Newton / Picard implicit Euler on the same FV mesh
arrays; (e) explicit Euler (one short run, its stable step at t̄ = 0 and the projected cost);
(f) method of lines, scipy ``solve_ivp`` BDF / Radau with the exact Jacobian.

Error = max over output times of |F̄ - F̄_ref| / max F̄_ref (output times every 0.01 on [0, 1],
every 0.05 on [0, 5]); "pointwise" = max |F̄/F̄_ref - 1| where F̄_ref > 1e-3 of its peak.
Reference: lubjax at rtol 1e-8 (REFERENCE below), cached in benchmarks/out/cache/wp_*.npz, with
its change against a second tight level (REFERENCE_CHECK) in the tables. Run time excludes
compilation / one-off setup (influence matrices), reported apart as compile_s. Single thread
(BLAS/XLA pinned by benchmarks.methods); the load average is recorded per row.

Writes benchmarks/out/work_precision{,_quick}.{csv,md,png}.
"""

from __future__ import annotations

import csv
import hashlib
import json
import time
from pathlib import Path

import benchmarks.methods  # noqa: F401  (pins threads before numpy/jax load)
from benchmarks import _harness

# isort: split
import numpy as np

import lubjax
from benchmarks import accuracy
from benchmarks.methods import (
    common,
    explicit_euler,
    lubjax_default,
    lubjax_variant,
    mol,
    newton,
    paper_scheme,
    picard,
)

OUT = Path(_harness.OUT)
CASES_FULL = [(100.0, 0.5), (100.0, 2.0), (1e4, 0.5)]
CASES_QUICK = [(100.0, 0.5), (100.0, 2.0)]
HORIZONS = {1.0: 0.01, 5.0: 0.05}  # t̄_end: output spacing
RTOLS_FULL = [1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6]
RTOLS_QUICK = [1e-2, 1e-3, 1e-4, 1e-5]
PAPER_SETTINGS = (0.01, 1e-3)
REFERENCE = lubjax.Settings(rtol=1e-8, atol=1e-16, dr=0.004, mesh_growth=1.02, length=2000.0,
                            max_steps=400_000, error_estimate=False, contact_radius="auto",
                            rim_refinement=7.0, contact_refinement=2.0)
# The check level is benchmarks/accuracy.py's reference (rtol 1e-7, dr 0.005, growth 1.04,
# L̄ 1000): its cached runs (out/cache/ref_*, to t̄ = 10³, read here, never written) are reused
# where they exist, and it is run to t̄ = 5 (cached as wp_check_*) where they do not.
REFERENCE_CHECK = accuracy.REFERENCE
PEAK_FRACTION = 1e-3  # pointwise errors where F̄_ref > this fraction of its peak


def output_times(t_end):
    return common.default_t_out(t_end, HORIZONS[t_end])


def all_output_times():
    return np.unique(np.round(np.concatenate([output_times(t) for t in HORIZONS]), 12))


def _reference_run(beta, z0, settings, tag):
    times = all_output_times()
    key = repr(settings).encode()
    path = OUT / "cache" / f"wp_{tag}_b{beta:g}_z{z0:g}_{hashlib.sha1(key).hexdigest()[:10]}.npz"
    if tag == "check" and Path(accuracy.cache_path(beta, z0, "ref")).exists():
        path = Path(accuracy.cache_path(beta, z0, "ref"))  # accuracy.py's, same settings
    if path.exists():
        d = np.load(path)
        if "steps" not in d:  # accuracy.py's cache: t and the fields only
            return np.interp(times, np.r_[0.0, d["t"]], np.r_[0.0, d["force"]]), dict(
                run_s=float("nan"), steps=-1, nodes=-1, file=path.name)
        if np.all(np.min(np.abs(d["t"][None, :] - times[:, None]), axis=1) < 1e-9):
            return np.interp(times, d["t"], d["force"]), dict(
                run_s=float(d["run_s"]), steps=int(d["steps"]), nodes=int(d["nodes"]))
    start = time.perf_counter()
    res = lubjax.relax(beta, z0, float(times[-1]), settings=settings)
    if not res.finished:
        raise RuntimeError(f"reference {tag} did not finish for beta={beta}, z0={z0}")
    force = res.at(times)
    meta = dict(run_s=time.perf_counter() - start, steps=int(res.accepted), nodes=int(res.r.size))
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, t=times, force=force, **meta)
    print(f"  reference {tag} β={beta:g} z̄0={z0:g}: {meta['steps']} steps, {meta['nodes']} "
          f"nodes, {meta['run_s']:.0f} s", flush=True)
    return force, meta


def reference(beta, z0):
    """F̄_ref at all output times, the check level's, and their run statistics."""
    ref, meta = _reference_run(beta, z0, REFERENCE, "ref")
    check, meta_c = _reference_run(beta, z0, REFERENCE_CHECK, "check")
    return ref, check, meta, meta_c


def errors(f, ref):
    peak = np.max(np.abs(ref))
    with np.errstate(invalid="ignore", divide="ignore"):
        err = float(np.max(np.abs(f - ref)) / peak)
        big = np.abs(ref) > PEAK_FRACTION * peak
        point = float(np.max(np.abs(f[big] / ref[big] - 1)))
    return (err if np.isfinite(err) else float("nan"),
            point if np.isfinite(point) else float("nan"))


def method_runs(quick: bool, t_end: float):
    """(group, label, module, opts) for every run of one case and horizon."""
    runs = []
    paper = [(0.04, 4e-3), (0.02, 2e-3), PAPER_SETTINGS]
    for dr, dt in paper:
        tag = " [paper's settings]" if (dr, dt) == PAPER_SETTINGS else ""
        runs.append(("(a) paper scheme, numpy 2N×2N, L=4", f"dr={dr} dt={dt}{tag}",
                     paper_scheme, dict(dr=dr, dt=dt, length=4.0)))
    for rtol in (RTOLS_QUICK if quick else RTOLS_FULL):
        tag = " [default rtol]" if rtol == 1e-4 else ""
        runs.append(("(b) lubjax.relax, rtol sweep", f"rtol={rtol:g}{tag}", lubjax_default,
                     dict(settings=lubjax.Settings(rtol=rtol, error_estimate=False))))
    for rtol in (RTOLS_QUICK if quick else RTOLS_FULL):
        runs.append(("(b3) lubjax.relax, Settings(order=3) (BDF3), rtol sweep", f"rtol={rtol:g}",
                     lubjax_default,
                     dict(settings=lubjax.Settings(rtol=rtol, order=3, error_estimate=False))))
    runs.append(("(b') lubjax.relax, all defaults (+error estimate)", "rtol=1e-4 estimate on",
                 lubjax_default, dict(settings=lubjax.Settings())))
    for rtol, dr in ([(1e-3, 0.02), (1e-4, 0.01)] if quick else
                     [(1e-3, 0.02), (1e-4, 0.01), (1e-5, 0.005)]):
        runs.append(("(c) lubjax stepper, uniform mesh L=4", f"rtol={rtol:g} dr={dr}",
                     lubjax_variant, dict(mesh="uniform", dr=dr, length=4.0, rtol=rtol)))
    for rtol in ([1e-3, 1e-4] if quick else [1e-3, 1e-4, 1e-5]):
        runs.append(("(c) lubjax stepper, BDF1 (order=1)", f"rtol={rtol:g}", lubjax_variant,
                     dict(order=1, rtol=rtol)))
    levels = [(0.04, 1e-2, 1.2), (0.02, 5e-3, 1.1)] + ([] if quick else [(0.02, 2.5e-3, 1.05)])
    for dr, dt, g in levels:
        runs.append(("(d) Newton, implicit BE (graded, growing dt)",
                     f"dr={dr} dt={dt} growth={g}", newton,
                     dict(steps="grow", dr=dr, dt=dt, growth=g)))
        runs.append(("(d) Picard on mobility, implicit BE", f"dr={dr} dt={dt} growth={g}",
                     picard, dict(split="mobility", omega=1.0, steps="grow", dr=dr, dt=dt,
                                  growth=g)))
    for dt in (1e-2, 1e-3):
        runs.append(("(d) Picard p/w split, ω=0.5 (Davis-style)", f"dr=0.04 dt={dt:g} fixed",
                     picard, dict(split="elastic", omega=0.5, steps="fixed", dr=0.04, dt=dt)))
    for rtol in ([1e-3, 1e-5] if quick else [1e-3, 1e-5, 1e-7]):
        runs.append(("(f) MOL, solve_ivp BDF + exact Jacobian", f"dr=0.02 rtol={rtol:g}", mol,
                     dict(rtol=rtol, dr=0.02)))
    runs.append(("(f) MOL, solve_ivp Radau + exact Jacobian", "dr=0.02 rtol=1e-5", mol,
                 dict(rtol=1e-5, dr=0.02, method="Radau")))
    if not quick:
        runs.append(("(f) MOL, solve_ivp BDF + exact Jacobian", "dr=0.01 rtol=1e-7", mol,
                     dict(rtol=1e-7, dr=0.01)))
    return runs


def explicit_rows(beta, z0, t_end):
    """Explicit Euler: one short run at Δt̄ = 1e-6 to t̄ = 0.01, its stability limit at t̄ = 0 and
    the projected cost of [0, t_end] at that limit from the measured cost per step."""
    rows = []
    short = np.array([0.0, 0.01])
    for mesh, dr, length in (("uniform", 0.05, 4.0), ("graded", 0.02, 100.0)):
        _, info = explicit_euler.run(beta, z0, short, mesh=mesh, dr=dr, length=length, dt=1e-6)
        per_step = info["wall_s"] / max(info["n_steps"], 1)
        lim = explicit_euler.stability_limit(beta, z0, mesh=mesh, dr=dr, length=length)
        rows.append(dict(
            method="(e) explicit Euler", label=f"{mesh} dr={dr} L={length:g}: dt=1e-6 to t=0.01",
            error=float("nan"), pointwise=float("nan"), wall_s=info["wall_s"],
            compile_s=info["compile_s"], ok=info["ok"], n_steps=info["n_steps"],
            n_nodes=info["n_nodes"],
            extra=json.dumps(dict(stable_dt_at_t0=lim, per_step_s=per_step,
                                  projected_wall_s=per_step * t_end / lim))))
    return rows


def run_case(beta, z0, t_end, quick, ref_all, check_all):
    times = all_output_times()
    t_out = output_times(t_end)
    sel = np.isin(np.round(times, 12), np.round(t_out, 12))
    ref, check = ref_all[sel], check_all[sel]
    err_c, point_c = errors(check, ref)
    rows = [dict(method="reference", label="rtol 1e-8 vs check level rtol 1e-7", error=err_c,
                 pointwise=point_c, wall_s=float("nan"), compile_s=float("nan"), ok=True,
                 n_steps=0, n_nodes=0,
                 extra=json.dumps(dict(ref=repr(REFERENCE), check=repr(REFERENCE_CHECK))))]
    for r in rows:
        r.update(_harness.describe())
    for group, label, module, opts in method_runs(quick, t_end):
        t0 = time.perf_counter()
        mach = _harness.describe()
        try:
            f, info = module.run(beta, z0, t_out, **opts)
        except Exception as exc:  # a method that refuses or crashes is a data point too
            f, info = np.full(t_out.size, np.nan), dict(
                wall_s=float("nan"), compile_s=float("nan"), ok=False, n_steps=0,
                message=f"{type(exc).__name__}: {exc}"[:300])
        err, point = errors(np.asarray(f, dtype=np.float64), ref)
        extra = {k: v for k, v in info.items() if k not in (
            "wall_s", "compile_s", "ok", "n_steps", "n_nodes", "force")}
        rows.append(dict(method=group, label=label, error=err, pointwise=point,
                         wall_s=info["wall_s"], compile_s=info["compile_s"], ok=info["ok"],
                         n_steps=info["n_steps"], n_nodes=info.get("n_nodes", 0),
                         extra=json.dumps(extra, default=str), **mach))
        print(f"  β={beta:g} z0={z0:g} t≤{t_end:g} {group[:44]:44s} {label:30s} err={err:9.2e} "
              f"run={info['wall_s']:8.3f}s compile={info['compile_s']:6.2f}s ok={info['ok']} "
              f"load={mach['load1']} ({time.perf_counter() - t0:.1f}s)", flush=True)
    mach = _harness.describe()
    rows += [dict(r, **mach) for r in explicit_rows(beta, z0, t_end)]
    for r in rows:
        r.update(beta=beta, z0=z0, t_end=t_end)
    return rows


STYLE = {
    "(a)": dict(color="k", marker="s", lw=1.8),
    "(b')": dict(color="tab:red", marker="*", ms=14, ls="none"),
    "(b)": dict(color="tab:red", marker="o", lw=2.5),
    "(b3)": dict(color="darkred", marker="d", lw=2.0, ls="--"),
    "(c) lubjax stepper, uniform": dict(color="tab:orange", marker="v"),
    "(c) lubjax stepper, BDF1": dict(color="tab:purple", marker="^"),
    "(d) Newton": dict(color="tab:blue", marker="D"),
    "(d) Picard on": dict(color="tab:cyan", marker="P"),
    "(d) Picard p/w": dict(color="tab:gray", marker="X"),
    "(f) MOL, solve_ivp BDF": dict(color="tab:green", marker="h"),
    "(f) MOL, solve_ivp Radau": dict(color="olive", marker="p"),
    "(e)": dict(color="tab:brown", marker=">"),
}


def style(method):
    for k, v in STYLE.items():
        if method.startswith(k):
            return v
    return dict(color="k", marker=".")


Y_TOP = 3e3


def plot(rows, panels, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ncol = 2
    nrow = (len(panels) + 1) // 2
    fig, axes = plt.subplots(nrow, ncol, figsize=(7.2 * ncol, 5.2 * nrow), squeeze=False)
    fail_x = 3.0  # failed runs are drawn at this error, explicit Euler's projection at Y_TOP
    for ax, (beta, z0, t_end) in zip(axes.flat, panels, strict=False):
        sel = [r for r in rows if (r["beta"], r["z0"], r["t_end"]) == (beta, z0, t_end)]
        ref = [r for r in sel if r["method"] == "reference"][0]
        methods = list(dict.fromkeys(r["method"] for r in sel if r["method"] != "reference"))
        for m in methods:
            rr = [r for r in sel if r["method"] == m]
            st = dict(style(m))
            if m.startswith("(e)"):
                for k, r in enumerate(rr):
                    proj = json.loads(r["extra"])["projected_wall_s"]
                    ax.plot(fail_x, min(proj, Y_TOP), ls="none", mfc="none", ms=9,
                            color=st["color"], marker=st["marker"])
                    ax.annotate(f"{r['label'].split(':')[0]}: {proj:.0e} s",
                                (fail_x, min(proj, Y_TOP)), fontsize=6, ha="right",
                                xytext=(-8, -3 - 9 * k), textcoords="offset points")
                ax.plot([], [], ls="none", mfc="none", color=st["color"], marker=st["marker"],
                        label="(e) explicit Euler: projected run time at its stable dt")
                continue
            good = sorted((r for r in rr if r["ok"] and np.isfinite(r["error"])),
                          key=lambda r: r["error"])
            bad = [r for r in rr if not (r["ok"] and np.isfinite(r["error"]))]
            if good:
                ax.plot([max(r["error"], 1e-7) for r in good], [r["wall_s"] for r in good],
                        color=st["color"], marker=st["marker"], lw=st.get("lw", 1.2),
                        ms=st.get("ms", 6), ls=st.get("ls", "-"), label=m)
            else:
                ax.plot([], [], color=st["color"], marker=st["marker"], label=m)
            for r in bad:
                if np.isfinite(r["wall_s"]):
                    ax.plot(fail_x, r["wall_s"], color=st["color"], marker="x", ms=9, mew=2)
            for r in good:
                if "[paper's settings]" in r["label"] or "[default rtol]" in r["label"]:
                    ax.plot(r["error"], r["wall_s"], marker="o", ms=16, mfc="none",
                            color=st["color"], mew=2)
        ax.axvline(ref["error"], color="0.5", ls=":", lw=1)
        ax.axvline(fail_x, color="0.8", lw=0.8)
        ax.text(fail_x * 1.1, 2e-3, "failed / not run", fontsize=7, color="0.4", rotation=90)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(1e-7, 10)
        ax.set_ylim(1e-3, Y_TOP * 2)
        ax.set_xlabel(f"max |F̄ - F̄_ref| / max F̄_ref on t̄ ∈ [0, {t_end:g}]")
        ax.set_ylabel("run time after compilation [s] (single thread)")
        ax.set_title(f"β = {beta:g}, z̄0 = {z0:g}, t̄ ≤ {t_end:g}   (dotted: reference's change "
                     f"vs check level, {ref['error']:.1e})", fontsize=9)
        ax.grid(True, which="major", alpha=0.3)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    # The machine is named once, in the page's caption and the CSV, not in the picture.
    fig.suptitle("Relaxation test work-precision (circled: paper's settings Δr̄=0.01 Δt̄=1e-3 / "
                 "lubjax default rtol 1e-4; x at the right: failed)", fontsize=10)
    fig.tight_layout(rect=(0, 0.025 + 0.03 * ((len(labels) + 1) // 2) / nrow, 1, 0.95))
    fig.savefig(path, dpi=100)
    plt.close(fig)


FIELDS = ["beta", "z0", "t_end", "method", "label", "error", "pointwise", "wall_s", "compile_s",
          "ok", "n_steps", "n_nodes", "extra", "cpu", "cores", "threads", "load1"]


def fmt(x, spec=".2e"):
    return "—" if x is None or not np.isfinite(x) else format(x, spec)


def is_lubjax(r):
    return r["method"].startswith("(b)") and r["ok"] and np.isfinite(r["error"])


def speed_table(rows, panels):
    """Per paper-scheme point: the cheapest lubjax rtol point at equal or better error."""
    lines = ["| β | z̄0 | t̄ ≤ | paper scheme | its error | its run s | lubjax rtol at ≤ that "
             "error | its error | its run s | speed ratio |", "|---" * 10 + "|"]
    for beta, z0, t_end in panels:
        sel = [r for r in rows if (r["beta"], r["z0"], r["t_end"]) == (beta, z0, t_end)]
        lub = [r for r in sel if is_lubjax(r)]
        for p in (r for r in sel if r["method"].startswith("(a)")):
            better = [r for r in lub if r["error"] <= p["error"]]
            best = min(better, key=lambda r: r["wall_s"]) if better else None
            ratio = p["wall_s"] / best["wall_s"] if best and p["ok"] else float("nan")
            lines.append(f"| {beta:g} | {z0:g} | {t_end:g} | {p['label']} | {fmt(p['error'])} | "
                         f"{fmt(p['wall_s'], '.3g')} | {best['label'] if best else 'none'} | "
                         f"{fmt(best['error']) if best else '—'} | "
                         f"{fmt(best['wall_s'], '.3g') if best else '—'} | "
                         f"{fmt(ratio, '.0f')}× |")
    return lines


def front_table(rows, panels, metric="error"):
    """At each error level: the cheapest run reaching it, lubjax ((b), or (b3): the same call
    with Settings(order=3)) vs the best other method, and their run-time ratio. ``metric``:
    "error" (relative to the peak) or "pointwise" (relative to F̄ itself where F̄_ref >
    PEAK_FRACTION of its peak). A level below the reference's own change against its check
    level (in the same metric) is marked: errors that small are not resolved by the reference."""
    levels = [1e-2, 1e-3, 1e-4, 1e-5, 1e-6]

    def cell(b):
        return f"{fmt(b['wall_s'], '.3g')} ({b['label']})" if b else "—"

    lines = ["| β | z̄0 | t̄ ≤ | error ≤ | lubjax (b) run s | lubjax (b3) order=3 run s | "
             "best other method | its run s | "
             "lubjax ahead (lubjax's best run s / other's) |", "|---" * 9 + "|"]
    for beta, z0, t_end in panels:
        panel = [r for r in rows if (r["beta"], r["z0"], r["t_end"]) == (beta, z0, t_end)]
        sel = [r for r in panel if r["method"] != "reference" and not r["method"].startswith("(e)")]
        ref = [r for r in panel if r["method"] == "reference"]
        resolution = ref[0][metric] if ref and np.isfinite(ref[0][metric]) else 0.0
        for e in levels:
            reach = [r for r in sel if r["ok"] and np.isfinite(r[metric]) and r[metric] <= e]
            lub = [r for r in reach if r["method"].startswith("(b)")]
            lub3 = [r for r in reach if r["method"].startswith("(b3)")]
            oth = [r for r in reach if not r["method"].startswith("(b")]
            b2 = min(lub, key=lambda r: r["wall_s"]) if lub else None
            b3 = min(lub3, key=lambda r: r["wall_s"]) if lub3 else None
            bl = min((b for b in (b2, b3) if b), key=lambda r: r["wall_s"], default=None)
            bo = min(oth, key=lambda r: r["wall_s"]) if oth else None
            if bl is None:
                ahead = "not reached" if bo is None else "no (lubjax's sweep stops short)"
            elif bo is None:
                ahead = "yes (nobody else)"
            else:
                ratio = f"{bl['wall_s'] / bo['wall_s']:.2g}×"
                ahead = ("yes" if bl["wall_s"] < bo["wall_s"] else "no") + f" ({ratio})"
            if e < resolution:
                ahead += f"; unresolved: the reference changes by {resolution:.1e}"
            lines.append(f"| {beta:g} | {z0:g} | {t_end:g} | {e:.0e} | {cell(b2)} | {cell(b3)} "
                         f"| {bo['method'] + ' ' + bo['label'] if bo else 'none reaches it'} | "
                         f"{fmt(bo['wall_s'], '.3g') if bo else '—'} | {ahead} |")
    return lines


def write_md(rows, panels, refs, path, command, elapsed):
    mach = _harness.describe()
    out = [f"# Work-precision, relaxation test\n\n`{command}` ({elapsed:.0f} s in all); "
           f"{_harness.label(mach)} at the end (each row's load is in the CSV).\n",
           "Error: max |F̄ - F̄_ref| / max F̄_ref at the output times; pointwise: max |F̄/F̄_ref "
           f"- 1| where F̄_ref > {PEAK_FRACTION:g} of its peak. Run time excludes compilation "
           "and one-off setup (compile_s).\n",
           f"Reference: `{REFERENCE!r}`; check level: `{REFERENCE_CHECK!r}`.\n",
           "| β | z̄0 | reference steps / nodes | check level steps / nodes |", "|---|---|---|---|"]
    for (beta, z0), (meta, meta_c) in refs.items():
        check = (f"{meta_c['steps']} / {meta_c['nodes']}" if "file" not in meta_c
                 else f"accuracy.py's cached run {meta_c['file']}")
        out.append(f"| {beta:g} | {z0:g} | {meta['steps']} / {meta['nodes']} | {check} |")
    out += ["", "## Lubjax at equal or better error vs the paper's scheme", ""]
    out += speed_table(rows, panels)
    out += ["", "## The front: cheapest run reaching each error", ""]
    out += front_table(rows, panels)
    out += ["", "## The pointwise front: cheapest run reaching each pointwise error", "",
            f"The same with max |F̄/F̄_ref - 1| where F̄_ref > {PEAK_FRACTION:g} of its peak (the "
            "early rise and the decaying tail count, not only the peak).", ""]
    out += front_table(rows, panels, "pointwise")
    out += ["", "## All runs", "", "| β | z̄0 | t̄ ≤ | method | settings | error | pointwise | "
            "run s | compile s | steps | nodes | ok | load |", "|---" * 13 + "|"]
    for r in rows:
        out.append(f"| {r['beta']:g} | {r['z0']:g} | {r['t_end']:g} | {r['method']} | "
                   f"{r['label']} | {fmt(r['error'])} | {fmt(r['pointwise'])} | "
                   f"{fmt(r['wall_s'], '.3g')} | {fmt(r['compile_s'], '.2f')} | {r['n_steps']} | "
                   f"{r['n_nodes']} | {r['ok']} | {r.get('load1')} |")
    ex = [r for r in rows if r["method"].startswith("(e)")]
    if ex:
        out += ["", "Explicit Euler ((e), not run to the end): "
                + "; ".join(f"β={r['beta']:g} z̄0={r['z0']:g} t̄≤{r['t_end']:g} {r['label']}: "
                            f"stable Δt̄ at t̄=0 {json.loads(r['extra'])['stable_dt_at_t0']:.1e},"
                            f" projected {json.loads(r['extra'])['projected_wall_s']:.3g} s"
                            for r in ex)]
    path.write_text("\n".join(out) + "\n")


def main(argv=None):
    ap = _harness.parser(__doc__)
    ap.add_argument("--quick", action="store_true", help="β=100 only, fewer levels")
    ap.add_argument("--out", default=str(OUT))
    ap.add_argument("--replot", action="store_true", help="redraw the PNG from the CSV")
    args = _harness.parse(ap, argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cases = CASES_QUICK if args.quick else CASES_FULL
    if args.replot:
        name = "work_precision_quick" if args.quick else "work_precision"
        with open(out / f"{name}.csv") as f:
            rows = [dict(r, beta=float(r["beta"]), z0=float(r["z0"]), t_end=float(r["t_end"]),
                         error=float(r["error"]), wall_s=float(r["wall_s"]),
                         ok=r["ok"] == "True") for r in csv.DictReader(f)]
        plot(rows, [(b, z, t) for b, z in cases for t in HORIZONS], out / f"{name}.png")
        return
    rows, refs, panels = [], {}, []
    start = time.perf_counter()
    for beta, z0 in cases:
        ref, check, meta, meta_c = reference(beta, z0)
        refs[(beta, z0)] = (meta, meta_c)
        for t_end in HORIZONS:
            panels.append((beta, z0, t_end))
            rows += run_case(beta, z0, t_end, args.quick, ref, check)
    name = "work_precision_quick" if args.quick else "work_precision"
    with open(out / f"{name}.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        for r in rows:
            w.writerow({k: r.get(k) for k in FIELDS})
    plot(rows, panels, out / f"{name}.png")
    write_md(rows, panels, refs, out / f"{name}.md", _harness.command(argv),
             time.perf_counter() - start)
    print("\n".join(speed_table(rows, panels) + [""] + front_table(rows, panels) + [""]
                    + front_table(rows, panels, "pointwise")))
    print(f"wrote {out / name}.{{csv,md,png}} in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
