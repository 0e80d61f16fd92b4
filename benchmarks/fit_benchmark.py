"""Fit cost: one fit cold and warm, 100 traces batched, and the optimisers compared.

    python -m benchmarks.fit_benchmark [--only single,batch,optimisers] [--batch 100]
        [--optimistix PATH]   # a folder with optimistix installed (benchmark only, not a dep)

1. ``single``: ``lubjax-fit data/paper_dc140.csv`` as a user runs it, each in a fresh process:
   cold (an empty persistent compilation cache: everything compiles), warm (the cache filled by
   the cold run), and with ``--no-cache``; plus the fit's own wall time (``wall_s``, without
   process start-up and imports).
2. ``batch``: ``--batch`` noise draws (1 % of the peak) of the three clean paper traces, fitted
   separately in one ``fit_traces`` call (one batched call over all traces per iteration), in a
   fresh process with a warm cache; total wall time and how many converged near the truth.
3. ``joint``: the three paper traces fitted separately and jointly (E*, η shared).
4. ``optimisers``: the hand-written Levenberg–Marquardt (``lm``) against
   ``scipy.optimize.least_squares`` (``trf``, with our Jacobian), ``optax.lbfgs`` (reverse-mode
   gradient) and, with ``--optimistix``, ``optimistix.LevenbergMarquardt`` (its own Jacobian by
   jax.jacfwd through the same model), from the physics start and from bad starts (each of E*,
   η, z0 off by a factor): model runs, iterations, wall time (compilation excluded: every
   method is warmed up first), final χ² against the best found, converged.

Writes benchmarks/out/fit_benchmark_<parts>.{json,md}; the machine and its load are in both.
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from benchmarks import _harness
from benchmarks._harness import OUT, ROOT

TRACE = os.path.join(ROOT, "data", "paper_dc140.csv")


def _machine():
    from benchmarks._harness import describe

    return describe()


def _cli(args, cache_dir, extra_env=None):
    env = dict(os.environ, PYTHONPATH=ROOT, LUBJAX_CACHE_DIR=cache_dir, **(extra_env or {}))
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "fit.json")
        start = time.perf_counter()
        cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        proc = subprocess.run([sys.executable, "-m", "fitting", *args, "--out", out, "--quiet"],
                              env=env, capture_output=True, text=True)
        wall = time.perf_counter() - start
        cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        # CPU seconds of the process: on a loaded machine the wall time measures the load.
        cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
        if proc.returncode not in (0, 1):
            raise RuntimeError(proc.stderr.strip().splitlines()[-1])
        res = json.load(open(out))
    res = res if isinstance(res, list) else [res]
    return dict(process_s=wall, process_cpu_s=cpu, fit_wall_s=res[0]["wall_s"],
                converged=res[0]["converged"])


def single():
    with tempfile.TemporaryDirectory() as cache:
        cold = _cli([TRACE], cache)
        warm = _cli([TRACE], cache)
        warm2 = _cli([TRACE], cache)
    with tempfile.TemporaryDirectory() as cache:
        off = _cli([TRACE, "--no-cache"], cache)
    return dict(trace=TRACE, cold=cold, warm=warm, warm_again=warm2, no_cache=off,
                uptime=os.getloadavg())


BATCH_CHILD = r"""
import json, sys, time, numpy as np
import fitting
from fitting._cache import enable_compilation_cache
enable_compilation_cache({cache!r})
stems = ["paper_dc126", "paper_dc140", "paper_dc154"]
clean = [fitting.read_trace(f"{root}/data/clean/{{s}}_clean.csv") for s in stems]
rng = np.random.default_rng(7)
traces = []
for k in range({n}):
    c = clean[k % 3]
    sigma = 0.01 * float(np.max(c.force))
    traces.append(c._replace(force=c.force + rng.normal(0, sigma, c.force.size), name=f"d{{k}}"))
fitting.fit_traces(traces, max_iter=1)  # compile everything at this batch size (not timed)
start, cpu = time.perf_counter(), time.process_time()
res = fitting.fit_traces(traces)
wall, cpu = time.perf_counter() - start, time.process_time() - cpu
true = [float(c.metadata["true_E_star_Pa"]) for c in clean]
z = [abs(r.E_star - true[k % 3]) / r.stderr["E_star"] for k, r in enumerate(res)]
print(json.dumps(dict(traces=len(traces), wall_s=wall, cpu_s=cpu, per_trace_s=wall / len(traces),
      converged=int(sum(r.converged for r in res)), within_3se=int(sum(v < 3 for v in z)),
      iterations_max=int(max(r.n_iterations for r in res)), model_runs=res[0].n_model_runs)))
"""


def batch(n):
    with tempfile.TemporaryDirectory() as cache:
        code = BATCH_CHILD.format(root=ROOT, cache=cache, n=n)
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              env=dict(os.environ, PYTHONPATH=ROOT))
        if proc.returncode != 0:
            raise RuntimeError(proc.stderr[-2000:])
        out = json.loads(proc.stdout.strip().splitlines()[-1])
        out["process_s_including_compile_and_warmup"] = time.perf_counter() - start
    out["uptime"] = os.getloadavg()
    return out


#: (label, factors on E*, η, z0 of the physics start)
STARTS = [
    ("physics start", (1.0, 1.0, 1.0)),
    ("E* x3", (3.0, 1.0, 1.0)),
    ("E* /3", (1 / 3, 1.0, 1.0)),
    ("eta x3", (1.0, 3.0, 1.0)),
    ("eta /3", (1.0, 1 / 3, 1.0)),
    ("z0 x1.3", (1.0, 1.0, 1.3)),
    ("z0 /1.3", (1.0, 1.0, 1 / 1.3)),
    ("all off", (2.5, 0.4, 1.2)),
]


def _optimistix_runner(trace):
    """optimistix.LevenbergMarquardt on the same residuals (its Jacobian by forward mode through
    the same model), compiled once for all starts."""
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    import fitting
    from fitting import _model
    from lubjax._threads import single_threaded_blas

    spec = fitting.ModelSpec()
    sc = fitting.scales_from_trace(trace)
    solver = fitting.make_solver()
    data = fitting.trace_data(trace, sc, spec)

    def fn(x, _):
        r, film = fitting.residuals(x, data, solver, spec)
        return jnp.where(film > 0, r, 1e3)

    # Stop when no component of θ moves by more than 1e-4 (≈ 0.3 standard errors of ln z0,
    # 0.01 of ln E*), as tight as the stall test of our LM; rtol 1e-8 ran 46 steps to the same
    # optimum (chi2 within 0.02), chasing the error-controlled model's own noise.
    lm = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-4)
    def solve(x):
        sol = optx.least_squares(fn, lm, x, options=dict(jac="fwd"), max_steps=60, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    run = jax.jit(solve)
    residual = jax.jit(lambda x: fn(x, None))

    def fit(start):
        x0 = jnp.array([_model.to_theta(n, start.values[n], sc.response_unit)
                        for n in spec.names])
        with single_threaded_blas():
            t0 = time.perf_counter()
            value, ok, steps = jax.block_until_ready(run(x0))
            wall = time.perf_counter() - t0
            r = np.asarray(residual(value))
        return dict(chi2=float(r @ r), iterations=int(steps), model_runs=None, wall_s=wall,
                    converged=bool(ok))

    return fit


def optimisers(optimistix_path=None, methods=("lm", "trf", "lbfgs", "optimistix"), rtol=None,
               starts=None):
    """Each method from each start (``starts``: labels to keep; all by default), the model at
    ``fitting.FIT_SETTINGS`` with ``rtol`` (its own 3e-4 if None; not for optimistix)."""
    import dataclasses

    import fitting

    settings = None if rtol is None else dataclasses.replace(fitting.FIT_SETTINGS, rtol=rtol)

    trace = fitting.read_trace(TRACE)
    sc = fitting.scales_from_trace(trace)
    base = fitting.initial_guess(trace, sc)
    methods = [m for m in methods if m != "optimistix" or optimistix_path]
    if optimistix_path:
        sys.path.insert(0, optimistix_path)
    rows = []
    for method in methods:
        if method == "optimistix":
            runner = _optimistix_runner(trace)
            runner(base)  # compile outside the timings
        else:  # compile outside the timings
            fitting.fit_trace(trace, method=method, max_iter=2, model_error=False,
                              settings=settings)
        for label, (fe, fv, fz) in STARTS:
            if starts and label not in starts:
                continue
            values = dict(base.values, E_star=base.values["E_star"] * fe,
                          viscosity=base.values["viscosity"] * fv, z0=base.values["z0"] * fz)
            start = fitting.Start(values, (label,))
            t0 = time.perf_counter()
            if method == "optimistix":
                row = runner(start)
            else:
                res = fitting.fit_trace(trace, method=method, starts=[start], model_error=False,
                                        settings=settings)
                row = dict(chi2=res.stats["chi2"], iterations=res.n_iterations,
                           model_runs=res.n_model_runs, wall_s=time.perf_counter() - t0,
                           converged=res.converged)
            row.update(method=method, start=label)
            rows.append(row)
            print(json.dumps(row), flush=True)
    best = min(r["chi2"] for r in rows if math.isfinite(r["chi2"]))
    for r in rows:
        # "reached": χ² within 0.25 of the best found, i.e. the parameters within about half a
        # standard error of it (LM stops once the remaining step is < 5 % of σ² in χ², at the
        # error-controlled model's accuracy, so repeated fits end within ~0.1 of each other)
        r["reached_optimum"] = bool(r["chi2"] - best < 0.25)
        r["chi2_above_best"] = r["chi2"] - best
    return dict(rows=rows, best_chi2=best, uptime=os.getloadavg())


def joint():
    """The three paper traces separately and jointly (E*, η shared): values and errors."""
    import fitting

    traces = [fitting.read_trace(os.path.join(ROOT, "data", f"{s}.csv"))
              for s in ("paper_dc126", "paper_dc140", "paper_dc154")]
    rows = []
    for label, kw in [("separate", {}), ("joint E*, eta", dict(shared=("E_star", "viscosity")))]:
        for r in fitting.fit_traces(traces, **kw):
            rows.append(dict(fit=label, trace=os.path.basename(r.name),
                             **{n: [r.values[n], r.stderr[n]] for n in ("E_star", "viscosity",
                                                                         "z0")},
                             converged=r.converged))
            print(json.dumps(rows[-1]), flush=True)
    return dict(rows=rows, uptime=os.getloadavg())


def _markdown(report):
    lines = [f"# Fit benchmark ({report['machine']})", ""]
    env = {k: v for k, v in report.get("environment", {}).items() if v}
    if env:
        lines += ["environment: " + ", ".join(f"`{k}={v}`" for k, v in env.items()), ""]
    if "single" in report:
        s = report["single"]
        lines += ["## One fit of data/paper_dc140.csv (`lubjax-fit`, fresh process each)", "",
                  "| run | process wall [s] | process CPU [s] | fit wall_s [s] |",
                  "|---|---|---|---|"]
        for key in ("cold", "warm", "warm_again", "no_cache"):
            lines.append(f"| {key} | {s[key]['process_s']:.1f} | "
                         f"{s[key].get('process_cpu_s', float('nan')):.1f} | "
                         f"{s[key]['fit_wall_s']:.2f} |")
        lines += ["", f"load average during the runs: {s['uptime']}", ""]
    if "batch" in report:
        b = report["batch"]
        lines += [f"## {b['traces']} traces in one call (warm cache)", "",
                  f"wall {b['wall_s']:.1f} s ({b['per_trace_s']:.2f} s per trace; CPU "
                  f"{b.get('cpu_s', float('nan')):.1f} s), "
                  f"{b['converged']} converged, {b['within_3se']} with E* within 3 standard "
                  f"errors of the truth, {b['iterations_max']} iterations at most, "
                  f"{b['model_runs']} batched model runs; load {b['uptime']}", ""]
    if "joint" in report:
        lines += ["## Separate and joint fits of the paper traces", "",
                  "| fit | trace | E* [MPa] | η [Pa s] | z0 [μm] |", "|---|---|---|---|---|"]
        for r in report["joint"]["rows"]:
            e, v, z = r["E_star"], r["viscosity"], r["z0"]
            lines.append(f"| {r['fit']} | {r['trace']} | {e[0] / 1e6:.4f} ± {e[1] / 1e6:.4f} | "
                         f"{v[0]:.2f} ± {v[1]:.2f} | {z[0] * 1e6:.3f} ± {z[1] * 1e6:.3f} |")
        lines += ["", f"load average: {report['joint']['uptime']}", ""]
    if "optimisers" in report:
        o = report["optimisers"]
        tol = f", model at rtol {report['rtol']:g}" if report.get("rtol") else ""
        lines += [f"## Optimisers on data/paper_dc140.csv (compilation excluded{tol})", "",
                  "| method | start | model runs | iterations | wall [s] | chi2 - best | "
                  "converged | reached optimum |", "|---|---|---|---|---|---|---|---|"]
        for r in o["rows"]:
            lines.append(f"| {r['method']} | {r['start']} | {r['model_runs']} | "
                         f"{r['iterations']} | {r['wall_s']:.2f} | {r['chi2_above_best']:.3g} |"
                         f" {r['converged']} | {r['reached_optimum']} |")
        lines += ["", f"load average: {o['uptime']}", ""]
    return "\n".join(lines) + "\n"


def main(argv=None):
    p = _harness.parser(__doc__)
    p.add_argument("--only", default="single,batch,joint,optimisers")
    p.add_argument("--batch", type=int, default=100)
    p.add_argument("--optimistix", help="folder with optimistix installed (benchmark only)")
    p.add_argument("--methods", default="lm,trf,lbfgs,optimistix")
    p.add_argument("--rtol", type=float, help="optimisers: the model's tolerance (default: "
                   "fitting.FIT_SETTINGS'); the outputs get a _rtol<value> suffix")
    p.add_argument("--starts", help="optimisers: comma-separated start labels to run (default: "
                   "all), e.g. 'physics start'")
    args = _harness.parse(p, argv)
    parts = args.only.split(",")
    # The device layout is the environment's (forced host devices need XLA_FLAGS and
    # PJRT_NPROC before JAX starts): record it with the figures.
    report = {"machine": _machine(), "environment": {
        k: os.environ.get(k, "") for k in ("XLA_FLAGS", "PJRT_NPROC")}}
    if "single" in parts:
        report["single"] = single()
        print(json.dumps(report["single"]), flush=True)
    if "batch" in parts:
        report["batch"] = batch(args.batch)
        print(json.dumps(report["batch"]), flush=True)
    if "joint" in parts:
        report["joint"] = joint()
    if "optimisers" in parts:
        report["optimisers"] = optimisers(
            args.optimistix, args.methods.split(","), rtol=args.rtol,
            starts=args.starts.split(",") if args.starts else None)
    os.makedirs(OUT, exist_ok=True)
    stem = os.path.join(OUT, "fit_benchmark_" + "_".join(parts))
    if args.rtol is not None:
        stem += f"_rtol{args.rtol:g}"
        report["rtol"] = args.rtol
    with open(stem + ".json", "w") as fh:
        json.dump(report, fh, indent=2)
    with open(stem + ".md", "w") as fh:
        fh.write(_markdown(report))
    print(_markdown(report))


if __name__ == "__main__":
    main()
