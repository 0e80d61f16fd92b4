"""Accuracy of the drives (force control, free sphere) against converged runs, and the
restitution chart.

    python -m benchmarks.drives [--quick] [--out benchmarks/out/drives.md]

1. Creep of the paper's tribometer: R = 2 mm, E* = 3.92 MPa, η = 100 Pa s, z0 = 140 μm, a load
   of 30 mN ramped in 1 s and held to 60 s (``lubjax creep`` with those numbers). The approach
   δ(t) = z0 - z(t) and h(0, t) at 600 times, default settings against a tight reference
   (rtol 1e-6, dr 0.005, L̄ 2000); a second tight run (rtol 3e-6, dr 0.0075, L̄ 1000) shows how far
   the reference is converged. Errors: max |δ - δ_ref| / δ_ref(60 s), and pointwise
   |h(0)/h_ref(0) - 1|.
2. Collisions (Davis, Serayssol & Hinch 1986): the restitution coefficient e (speed when the
   sphere passes back through its starting gap, over the approach speed) against St for two
   elasticity parameters ε = 2/(3π²β), default settings against the same tight reference.
   Chart: benchmarks/out/restitution.png.
3. Work against precision for both drives: the creep approach error and the restitution error
   (ε = 1e-3, St = 50) at rtol ∈ {1e-2, ..., 1e-5} against the same references, with the run
   time (compilation excluded; reported apart) — the third panel of the chart.

4. ``--collision`` (alone): the free sphere's thinnest film over the collision, min over t̄ of
   min h̄, at default settings against runs converged in the mesh: the rebound contact refined
   6× and 8× at rtol 1e-5, Richardson-extrapolated at the observed order 2 (the uniform
   Δr̄ = 0.005 reference above is itself up to 2 % off this film). Writes
   benchmarks/out/collision_film.md.

References are cached in benchmarks/out/cache/drives_* (delete to recompute).
"""

from __future__ import annotations

import json
import os
import time
from functools import partial

import numpy as np

import lubjax
from benchmarks import _harness
from benchmarks._harness import OUT, label

CACHE = os.path.join(OUT, "cache")
REFERENCE = lubjax.Settings(rtol=1e-6, atol=1e-14, dr=0.005, mesh_growth=1.02, length=2000.0,
                            max_steps=400_000, error_estimate=False)  # fmt: skip
CHECK = lubjax.Settings(rtol=3e-6, atol=1e-14, dr=0.0075, mesh_growth=1.03, length=1000.0,
                        max_steps=400_000, error_estimate=False)  # fmt: skip
CREEP = lubjax.CreepTest(3.92e6, 2e-3, 100.0, load=0.03, ramp_time=1.0, gap=140e-6)
CREEP_T = np.linspace(0.05, 60.0, 600)  # s


def _cached(name, compute):
    path = os.path.join(CACHE, f"drives_{name}.json")
    if os.path.exists(path):
        with open(path) as f:
            return json.load(f)
    value = compute()
    os.makedirs(CACHE, exist_ok=True)
    with open(path, "w") as f:
        json.dump(value, f)
    return value


def creep(settings):
    tc, d = CREEP.time_scale, CREEP.indent
    res = lubjax.relax(CREEP.beta, CREEP.z0_bar, 60.0 / tc, drive=CREEP.drive(), settings=settings)
    times = CREEP_T / tc
    return {
        "approach": (CREEP.gap - res.at(times, "gap") * d).tolist(),
        "h0": (res.at(times, "film_center") * d).tolist(),
        "steps": res.accepted,
        "run_s": res.run_s,
        "gap_error": (res.gap_error * d).tolist() if settings.error_estimate else None,
        "t": (res.t * tc).tolist(),
    }


def bounce(beta, stokes, settings, t_end=12.0):
    drive = lubjax.FreeSphere(2 * beta / (np.pi * stokes), -1.0, 0.0)
    res = lubjax.relax(beta, 1.0, t_end, drive=drive, settings=settings, check="flag")
    return {"e": lubjax.restitution(res), "steps": res.accepted, "run_s": res.run_s,
            "ok": res.ok, "min_gap": float(res.gap.min())}  # fmt: skip


COLLISIONS = ((1e-3, 20.0), (1e-3, 50.0), (1e-3, 100.0), (1e-3, 1000.0), (1e-5, 20.0),
              (1e-5, 50.0))
#: the converged runs' rebound-contact refinements and tolerance
COLLISION_REFINEMENTS = (6.0, 8.0)
COLLISION_RTOL = 1e-5


def collision_film(beta, stokes, settings, refinement=None):
    """min over t̄ of min h̄ of a collision, its estimated error there, the restitution and the
    cost; on the rule's mesh, or with the rebound contact refined ``refinement`` times."""
    drive = lubjax.FreeSphere(2 * beta / (np.pi * stokes), -1.0, 0.0)
    mesh = None
    if refinement is not None:
        rim = np.sqrt(drive.final_depth(1.0))
        # (a contact beyond the default fine zone gets a wider one)
        mesh = lubjax.Settings(r_fine=max(1.6, 1.25 * rim)).mesh(rim, refinement, refinement)
    res = lubjax.relax(beta, 1.0, 12.0, drive=drive, settings=settings, check="flag", mesh=mesh)
    i = int(np.argmin(res.film_min))
    estimate = res.film_min_error[i] if res.film_min_error is not None else np.nan
    return {"film": float(res.film_min[i]), "t": float(res.t[i]), "estimate": float(estimate),
            "e": lubjax.restitution(res), "steps": res.accepted, "nodes": int(res.r.size),
            "run_s": res.run_s}  # fmt: skip


def collisions(out):
    """The collision film table (``--collision``)."""
    tight = lubjax.Settings(rtol=COLLISION_RTOL, max_steps=200_000, error_estimate=False)
    c1, c2 = COLLISION_REFINEMENTS
    lines = [f"Collision film against converged runs; {label()}.", "",
             f"Converged: the rebound contact refined {c1:g}x and {c2:g}x at rtol "
             f"{COLLISION_RTOL:g}, extrapolated at order 2; 'ref. unc.' is the extrapolation's "
             "step.", "",
             "| ε | β | St | min h̄ default | converged | error | estimate | ref. unc. | "
             "nodes | steps | run_s |", "|" + "---|" * 11]  # fmt: skip
    for eps, st in COLLISIONS:
        beta = 2 / (3 * np.pi**2 * eps)
        print(f"collision ε={eps:g} St={st:g} ...", flush=True)
        fine = [_cached(f"collision_{eps:g}_{st:g}_x{c:g}",
                        partial(collision_film, beta, st, tight, c)) for c in (c1, c2)]
        step = (fine[0]["film"] - fine[1]["film"]) / ((c2 / c1) ** 2 - 1)  # f = f∞ + K/c²
        converged = fine[1]["film"] - step
        d = collision_film(beta, st, lubjax.Settings())
        err = d["film"] / converged - 1
        lines.append(f"| {eps:g} | {beta:.4g} | {st:g} | {d['film']:.5e} | {converged:.5e} | "
                     f"{err:+.2%} | {d['estimate'] / converged:.2%} | "
                     f"{abs(step) / converged:.2%} | {d['nodes']} | {d['steps']} | "
                     f"{d['run_s']:.2f} |")
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def main(argv=None):
    ap = _harness.parser(__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer St values, one ε")
    ap.add_argument("--collision", action="store_true",
                    help="only the collision film table (benchmarks/out/collision_film.md)")
    ap.add_argument("--out", default=None)
    args = _harness.parse(ap, argv)
    if args.collision:
        collisions(args.out or os.path.join(OUT, "collision_film.md"))
        return
    args.out = args.out or os.path.join(OUT, "drives.md")
    default = lubjax.Settings()
    lines = [f"Drives against converged runs; {time.strftime('%Y-%m-%d')}, {label()}.", ""]

    print("creep: reference runs (cached after the first time) ...", flush=True)
    ref = _cached("creep_ref", lambda: creep(REFERENCE))
    chk = _cached("creep_check", lambda: creep(CHECK))
    run = creep(default)
    a, ar, ac = (np.asarray(x["approach"]) for x in (run, ref, chk))
    h, hr, hc = (np.asarray(x["h0"]) for x in (run, ref, chk))
    final = ar[-1]
    lines += [
        f"Creep, {CREEP.load * 1e3:g} mN on the paper's tribometer (β = {CREEP.beta:.3g}, "
        f"z̄0 = {CREEP.z0_bar:.3g}, δ∞ = {CREEP.indent * 1e6:.3g} μm), t ∈ [0.05, 60] s:",
        "",
        "| run | max approach error / final approach | max pointwise h(0) error | steps | run_s |",
        "|---|---|---|---|---|",
        f"| default (rtol {default.rtol:g}) | {np.max(np.abs(a - ar)) / final:.2e} | "
        f"{np.max(np.abs(h / hr - 1)):.2e} | {run['steps']} | {run['run_s']:.2f} |",
        f"| reference check (rtol 3e-6) | {np.max(np.abs(ac - ar)) / final:.2e} | "
        f"{np.max(np.abs(hc / hr - 1)):.2e} | {chk['steps']} | {chk['run_s']:.1f} |",
        "",
    ]
    est = np.max(np.asarray(run["gap_error"]))
    lines += [f"Estimated gap error (Result.gap_error, max): {est / final:.2e} of the final "
              f"approach; true max error {np.max(np.abs(a - ar)) / final:.2e}.", ""]

    stokes = [3.0, 10.0, 30.0, 100.0, 300.0] if args.quick else [
        3.0, 10.0, 20.0, 50.0, 100.0, 300.0, 1000.0]
    epsilons = [1e-4] if args.quick else [1e-3, 1e-5]
    table = {}
    lines += ["Restitution e (read at the starting gap) against St:", "",
              "| ε | β | St | e default | e reference | e check | error | steps | run_s |",
              "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for eps in epsilons:
        beta = 2 / (3 * np.pi**2 * eps)
        for st in stokes:
            print(f"bounce ε={eps:g} St={st:g} ...", flush=True)
            r = _cached(f"bounce_{eps:g}_{st:g}_ref", partial(bounce, beta, st, REFERENCE))
            c = _cached(f"bounce_{eps:g}_{st:g}_chk", partial(bounce, beta, st, CHECK))
            d = bounce(beta, st, default)
            table[(eps, st)] = (d["e"], r["e"])
            err = abs(d["e"] - r["e"]) / r["e"] if np.isfinite(r["e"]) else float("nan")
            lines.append(f"| {eps:g} | {beta:.4g} | {st:g} | {d['e']:.4f} | {r['e']:.4f} | "
                         f"{c['e']:.4f} | {err:.1e} | {d['steps']} | {d['run_s']:.2f} |")
    lines.append("")
    lines.append("e = nan: no rebound to the starting gap within t̄ = 12 (x0/V units).")
    lines.append("")

    # Work against precision: the tolerance is the one knob (it also sets the mesh).
    wp_eps, wp_st = 1e-3, 50.0
    wp_beta = 2 / (3 * np.pi**2 * wp_eps)
    e_ref = _cached(f"bounce_{wp_eps:g}_{wp_st:g}_ref", partial(bounce, wp_beta, wp_st, REFERENCE))
    wp = {"creep": [], "bounce": []}
    lines += [f"Work against precision (creep as above; bounce ε = {wp_eps:g}, St = {wp_st:g}; "
              "run time without compilation, compile time apart):", "",
              "| rtol | creep error / final approach | steps | run_s | compile_s | "
              "bounce e error | steps | run_s | compile_s |", "|" + "---|" * 9]
    for rtol in (1e-2, 1e-3, 1e-4, 1e-5):
        print(f"work-precision rtol={rtol:g} ...", flush=True)
        st = lubjax.Settings(rtol=rtol, error_estimate=False)
        first = time.perf_counter()
        creep(st)
        compile_c = time.perf_counter() - first
        c = creep(st)
        compile_c -= c["run_s"]
        first = time.perf_counter()
        bounce(wp_beta, wp_st, st)
        compile_b = time.perf_counter() - first
        b = bounce(wp_beta, wp_st, st)
        compile_b -= b["run_s"]
        ce = np.max(np.abs(np.asarray(c["approach"]) - ar)) / final
        be = abs(b["e"] - e_ref["e"]) / e_ref["e"]
        wp["creep"].append((rtol, ce, c["run_s"]))
        wp["bounce"].append((rtol, be, b["run_s"]))
        lines.append(f"| {rtol:g} | {ce:.2e} | {c['steps']} | {c['run_s']:.2f} | {compile_c:.1f} "
                     f"| {be:.2e} | {b['steps']} | {b['run_s']:.2f} | {compile_b:.1f} |")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(16, 4))
    for eps in epsilons:
        # No rebound through the starting gap: e = 0 (open markers).
        e_def = np.nan_to_num([table[(eps, s)][0] for s in stokes], nan=0.0)
        e_ref = np.asarray([table[(eps, s)][1] for s in stokes])
        stuck = ~np.isfinite(e_ref)
        (line,) = ax[0].semilogx(stokes, np.nan_to_num(e_ref, nan=0.0), "o-",
                                 label=f"ε = {eps:g}, β = {2 / (3 * np.pi**2 * eps):.3g}")
        ax[0].semilogx(np.asarray(stokes)[stuck], np.zeros(stuck.sum()), "o", mfc="white",
                       color=line.get_color())
        ax[0].semilogx(stokes, e_def, "x", color=line.get_color(), ms=9)
    ax[0].plot([], [], "kx", label="default settings (o: reference, open: no rebound)")
    ax[0].set_xlabel("Stokes number St = mV/(6πηR²)")
    ax[0].set_ylabel("restitution e")
    ax[0].set_ylim(0, 1)
    ax[0].legend(fontsize=8)
    ax[0].set_title("free sphere on an elastic half-space through a film")
    tc = CREEP.time_scale
    ax[1].plot(CREEP_T, ar * 1e6, "k-", label="approach (reference)")
    ax[1].plot(CREEP_T, a * 1e6, "r--", label="approach (default)")
    ax[1].axhline((CREEP.gap + CREEP.indent) * 1e6, color="0.5", ls=":", label="z0 + δ∞ (Hertz)")
    ax[1].set_xlabel("t [s]")
    ax[1].set_ylabel("approach [μm]")
    ax[1].set_title(f"creep under {CREEP.load * 1e3:g} mN (t_c = {tc:g} s)")
    ax[1].legend(fontsize=8)
    for name, marker in (("creep", "o-"), ("bounce", "s-")):
        rtols, errs, secs = np.asarray(wp[name]).T
        ax[2].loglog(errs, secs, marker, label=name)
        for r, e, t in wp[name]:
            ax[2].annotate(f"{r:g}", (e, t), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ax[2].set_xlabel("error (creep: approach / final approach; bounce: e relative)")
    ax[2].set_ylabel("run time [s] (compilation excluded)")
    ax[2].set_title("work against precision (labels: rtol)")
    ax[2].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "restitution.png"), dpi=110)
    print(f"wrote {args.out} and {os.path.join(OUT, 'restitution.png')}")


if __name__ == "__main__":
    main()
