"""Fit cost and forward-mode gradient memory.

    python benchmarks/fit_benchmark.py [--trace data/paper_dc140.csv] [--steps 5000] [--reverse]

1. Wall time of one fit of a bundled trace (``fitting.fit_trace``): the first call includes the
   XLA compilation of the model and its Jacobian, the second reuses it; compile ≈ difference.
2. Peak resident memory (``resource.getrusage(...).ru_maxrss``, each in a fresh subprocess) of
   a 5,000-step run: the forward force curve alone, and its Jacobian with respect to (β, z̄0) by
   forward mode (``jax.jacfwd``). With ``--reverse`` also ``jax.jacrev`` for contrast (reverse
   mode stores one LU factorisation per step: ~8 N² bytes × steps).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

CHILD = r"""
import json, resource, sys, time
sys.path.insert(0, {root!r})
import jax, jax.numpy as jnp, numpy as np
import lubjax
mode, steps = {mode!r}, {steps}
settings = lubjax.Settings(dr=0.03, mesh_growth=1.1)
mesh = settings.mesh()
t = np.linspace(0.0, 5.0, steps + 1)
plan = lubjax.Plan(lubjax.discretise(mesh), lubjax.bdf_coefficients(t), t,
                   jnp.asarray(lubjax.RampHold().travel(t)), mesh)
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
f = lambda p: lubjax.force_curve(plan, p[0], p[1])
fn = {{"forward": f, "jacfwd": jax.jacfwd(f), "jacrev": jax.jacrev(f)}}[mode]
fn = jax.jit(fn)
p = jnp.array([54.0, 1.0])
start = time.perf_counter()
out = jax.block_until_ready(fn(p))
first = time.perf_counter() - start
start = time.perf_counter()
out = jax.block_until_ready(fn(p))
run = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps(dict(mode=mode, steps=steps, nodes=int(plan.disc.r.shape[0]),
      peak_rss_MiB=peak / 1024, rss_before_MiB=base / 1024, first_call_s=first, run_s=run,
      finite=bool(np.all(np.isfinite(np.asarray(out)))))))
"""


def memory(mode: str, steps: int) -> dict:
    code = CHILD.format(root=ROOT, mode=mode, steps=steps)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if out.returncode != 0:
        tail = (out.stderr.strip().splitlines() or ["?"])[-1]
        return dict(mode=mode, steps=steps, error=tail)
    return json.loads(out.stdout.strip().splitlines()[-1])


def fit_timing(path: str) -> dict:
    sys.path.insert(0, ROOT)
    import fitting

    trace = fitting.read_trace(path)
    start = time.perf_counter()
    first = fitting.fit_trace(trace)
    first_s = time.perf_counter() - start
    start = time.perf_counter()
    second = fitting.fit_trace(trace)
    second_s = time.perf_counter() - start
    return dict(
        trace=path,
        fit_with_compile_s=first_s,
        fit_cached_s=second_s,
        compile_s=first_s - second_s,
        iterations=second.n_iterations,
        model_runs=second.n_model_runs,
        converged=second.converged,
        E_star_Pa=second.E_star,
        viscosity_Pa_s=second.viscosity,
        z0_m=second.z0,
        same_as_first=bool(abs(first.E_star / second.E_star - 1) < 1e-9),
    )


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trace", default=os.path.join(ROOT, "data", "paper_dc140.csv"))
    p.add_argument("--steps", type=int, default=5000)
    p.add_argument("--reverse", action="store_true", help="also measure jax.jacrev")
    p.add_argument("--skip-fit", action="store_true")
    args = p.parse_args(argv)
    report = {}
    if not args.skip_fit:
        report["fit"] = fit_timing(args.trace)
        print(json.dumps(report["fit"], indent=2), flush=True)
    modes = ["forward", "jacfwd"] + (["jacrev"] if args.reverse else [])
    report["memory"] = []
    for mode in modes:
        m = memory(mode, args.steps)
        report["memory"].append(m)
        print(json.dumps(m), flush=True)
    return report


if __name__ == "__main__":
    main()
