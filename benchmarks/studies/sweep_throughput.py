"""Throughput of ``lubjax.sweep`` (cases per second) against batch size, compile time apart.

    python -m benchmarks.sweep_throughput [--sizes 1 2 4 8 16 32] [--t-end 5] [--replot]

The baseline is the largest batch's cases run one at a time through ``lubjax.relax`` (compiled
once) in the same process, so the speed-up is a ratio measured in one run (smaller batches are
other random cases of the same range: their cost per case scatters). Both use the settings a
sweep runs (``SETTINGS``: the default tolerance, the plain mesh and no error estimate, since a
sweep shares one mesh and does not estimate), so the ratio compares like with like. With forced
host devices (``XLA_FLAGS=--xla_force_host_platform_device_count=N PJRT_NPROC=N+1``) the batch
is split over them. Both batchings are measured (``sweep(..., batching="map")``: each device
runs its pairs one after another, the CPU default; ``"vmap"``: all at once, the accelerator
default). Writes benchmarks/out/sweep_throughput.{csv,png}, the machine and JAX devices named in
the CSV; ``--replot`` redraws the PNG from the CSV.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time

import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import lubjax
from benchmarks.machine import cpu_model

SETTINGS = lubjax.Settings(error_estimate=False, contact_radius=None)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32, 64])
    ap.add_argument("--t-end", type=float, default=5.0)
    ap.add_argument("--out", default="benchmarks/out/sweep_throughput")
    ap.add_argument("--replot", action="store_true", help="redraw the PNG from the CSV")
    args = ap.parse_args(argv)
    if args.replot:
        with open(args.out + ".csv") as fh:
            rows = [dict(r, batch=int(r["batch"]), cases_per_s=float(r["cases_per_s"]),
                         speedup_vs_single=float(r["speedup_vs_single"]))
                    for r in csv.DictReader(fh)]
        plot(rows, rows[0]["cases_per_s"] / rows[0]["speedup_vs_single"], args.t_end, args.out)
        return
    rng = np.random.default_rng(0)
    devices = jax.devices()
    machine = (f"{cpu_model()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
               f"JAX {jax.__version__} on {len(devices)}× {devices[0].platform}")
    print(machine, file=sys.stderr)
    # The same random cases for every row: each batch size draws its own, both batchings run
    # them, and the baseline runs the largest batch's cases one at a time through relax (after
    # its compilation), so every ratio compares the same work.
    cases = {size: (10 ** rng.uniform(0, 3, size), rng.uniform(0.5, 2.0, size))
             for size in args.sizes}
    lubjax.relax(100.0, 0.5, args.t_end, settings=SETTINGS)
    biggest = cases[max(args.sizes)]
    start = time.perf_counter()
    for b, z in zip(*biggest, strict=True):
        lubjax.relax(b, z, args.t_end, settings=SETTINGS)
    single_rate = biggest[0].size / (time.perf_counter() - start)
    print(f"one at a time: {single_rate:.2f} cases/s", file=sys.stderr)
    rows = []
    for mode in ("map", "vmap"):
        for size in args.sizes:
            beta, z0 = cases[size]
            res = lubjax.sweep(beta, z0, args.t_end, settings=SETTINGS, batching=mode)
            rate = size / res.run_s
            rows.append(dict(batching=mode, batch=size, cases_per_s=rate, run_s=res.run_s,
                             compile_s=res.compile_s, speedup_vs_single=rate / single_rate,
                             all_ok=bool(res.ok.all()), devices=res.devices, machine=machine))
            print(f"{mode} batch {size:4d}: {rate:8.2f} cases/s  (run {res.run_s:.2f} s, compile "
                  f"{res.compile_s:.1f} s, {rate / single_rate:.2f}× one-at-a-time)",
                  file=sys.stderr, flush=True)
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out + ".csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    plot(rows, single_rate, args.t_end, args.out)


def plot(rows, single_rate, t_end, out):
    """Cases per second against batch size for both batchings, and the one-at-a-time rate.
    The machine is named once, in the CSV and the page's caption, not in the picture."""
    fig, ax = plt.subplots(figsize=(6, 4))
    for mode, marker in (("map", "o-"), ("vmap", "s--")):
        mine = [r for r in rows if r["batching"] == mode]
        ax.semilogx([r["batch"] for r in mine], [r["cases_per_s"] for r in mine], marker,
                  label=f"lubjax.sweep (batching={mode!r})")
    ax.axhline(single_rate, color="k", ls="--", label="lubjax.relax one at a time")
    ax.set_xlabel("batch size")
    ax.set_ylim(bottom=0)
    ax.set_ylabel(f"cases per second (t̄ ∈ [0, {t_end:g}], run time only)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(out + ".png", dpi=110)
    print(f"wrote {out}.csv and .png")


if __name__ == "__main__":
    main()
