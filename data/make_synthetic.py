"""Generate the synthetic tribometer traces in data/ (run: ``python data/make_synthetic.py``).

They mimic the experiment of Liu, Dong, Jagota & Hui, Soft Matter 18 (2022) §3.2: a glass bead
R = 2 mm pushed at v0 = 0.1 mm/s into Sylgard-184 (E = 2.94 MPa, ν = 0.5, E* = E/(1-ν²) = 3.92 MPa)
through silicone oil η = 100 Pa·s from a gap z0 = 140 μm by dc = 126, 140, 154 μm, then held.

What a real tribometer adds, and how it is mimicked:

* a quiescent stretch (``QUIET_S``) before the stage moves;
* a stage that does not start or stop instantly: the commanded velocity (v0 during dc/v0, else 0)
  passes through a first-order lag of time constant ``LAG_S``, so the travel is
  d(t) = v0[s - τ(1 - e^{-s/τ})] during the command (s = t - t_on) and relaxes exponentially to
  exactly dc afterwards;
* sampling at ``RATE_HZ`` and Gaussian load-cell noise of standard deviation ``noise`` × peak force
  (the position channel is taken as noiseless: an encoder, not a load cell).

The force comes from ``lubjax`` on a mesh much finer than any fit uses (``FINE``). The bundled files
were made by the earlier fixed-grid solver (Δr̄ = 0.01, mesh growth 1.02 to L̄ = 200, Δt̄ = 10⁻³
in the loading; the ``generator`` header line says so), which makes them an independent reference
for today's error-controlled model; rerunning this script uses the error-controlled solver at
rtol = 1e-7 instead. The fine solution is evaluated at the sample times by cubic interpolation.
The noiseless traces go to ``data/clean/`` (tests add their
own noise draws to them), the noisy ones to ``data/``. True values are in each file's header.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np
from scipy.interpolate import CubicSpline

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import lubjax  # noqa: E402
from fitting._io import make_trace, write_trace  # noqa: E402

RADIUS = 2.0e-3
E_MODULUS = 2.94e6
POISSON = 0.5
SPEED = 1.0e-4
GAP = 140e-6
RATE_HZ = 100.0
QUIET_S = 1.0
LAG_S = 0.05
HOLD_S = 15.0
FINE = lubjax.Settings(rtol=1e-7, atol=1e-16, dr=0.01, mesh_growth=1.02, length=1000.0,
                       max_steps=200_000, error_estimate=False)

# (file stem, indent dc [m], viscosity [Pa s], noise fraction of peak force, seed)
CASES = [
    ("paper_dc126", 126e-6, 100.0, 0.01, 126),
    ("paper_dc140", 140e-6, 100.0, 0.01, 140),
    ("paper_dc154", 154e-6, 100.0, 0.01, 154),
    ("hard_dc140_noise5", 140e-6, 100.0, 0.05, 1405),
]


def travel(t, indent, speed=SPEED, t_on=QUIET_S, lag=LAG_S):
    """Stage travel [m] at times t [s]: a lagged ramp of duration indent/speed starting at t_on."""
    s = np.clip(np.asarray(t, dtype=np.float64) - t_on, 0.0, None)
    ramp = indent / speed
    during = speed * (s - lag * (1.0 - np.exp(-s / lag)))
    v_end = speed * (1.0 - math.exp(-ramp / lag))
    d_end = speed * (ramp - lag * (1.0 - math.exp(-ramp / lag)))
    after = d_end + v_end * lag * (1.0 - np.exp(-np.clip(s - ramp, 0.0, None) / lag))
    return np.where(s <= ramp, during, after)


def clean_force(indent, viscosity, times):
    """Noiseless force [N] at ``times`` [s] from a fine-grid lubjax run."""
    test = lubjax.RelaxationTest.from_E(
        E_MODULUS, POISSON, radius=RADIUS, viscosity=viscosity, speed=SPEED, indent=indent, gap=GAP
    )
    tc = test.time_scale
    t_bar_end = (times[-1] - QUIET_S) / tc
    # The force is exactly zero before the stage moves: start the run at t_on.
    s = np.linspace(0.0, t_bar_end, 40001)
    d = travel(QUIET_S + s * tc, indent) / indent
    history = lubjax.SampledTravel(s, d, breakpoints=(0.0, 1.0))
    res = lubjax.relax(test.beta, test.z0_bar, t_bar_end, history=history, settings=FINE)
    spline = CubicSpline(res.t, res.force)
    tb = (times - QUIET_S) / tc
    force = np.where(tb <= 0, 0.0, spline(np.clip(tb, 0.0, None)))
    return test, test.force_scale * force


def main():
    times = np.arange(0.0, QUIET_S + 154e-6 / SPEED + HOLD_S, 1.0 / RATE_HZ)
    cache = {}
    for stem, indent, viscosity, noise, seed in CASES:
        start = time.perf_counter()
        key = (indent, viscosity)
        if key not in cache:
            cache[key] = clean_force(indent, viscosity, times)
        test, force = cache[key]
        disp = travel(times, indent)
        sigma = noise * float(np.max(force))
        meta = {
            "radius_m": f"{RADIUS:.6g}",
            "poisson_ratio": f"{POISSON:g}",
            "sample": f"synthetic {stem}: glass bead, PDMS, silicone oil (Liu et al. 2022)",
            "true_E_Pa": f"{E_MODULUS:.6g}",
            "true_E_star_Pa": f"{test.E_star:.6g}",
            "true_viscosity_Pa_s": f"{viscosity:.6g}",
            "true_z0_m": f"{GAP:.6g}",
            "true_indent_m": f"{indent:.6g}",
            "true_speed_m_s": f"{SPEED:.6g}",
            "true_beta": f"{test.beta:.6g}",
            "stage_lag_s": f"{LAG_S:g}",
            "motion_start_s": f"{QUIET_S:g}",
            "sampling_hz": f"{RATE_HZ:g}",
            "generator": "data/make_synthetic.py, lubjax Settings(rtol=1e-7, atol=1e-16, "
            "dr=0.01, mesh_growth=1.02, length=1000)",
        }
        if noise == 0.01:  # the 5 % case shares paper_dc140's clean trace
            clean_meta = dict(meta, noise_N="0")
            write_trace(
                os.path.join(HERE, "clean", f"{stem}_clean.csv"),
                make_trace(times, disp, force, RADIUS, clean_meta),
            )
        rng = np.random.default_rng(seed)
        noisy = force + rng.normal(0.0, sigma, size=force.shape)
        meta.update(
            noise_N=f"{sigma:.6g}", noise_fraction_of_peak=f"{noise:g}", noise_seed=str(seed)
        )
        write_trace(os.path.join(HERE, f"{stem}.csv"), make_trace(times, disp, noisy, RADIUS, meta))
        print(
            f"{stem}: beta={test.beta:.4g} peak={np.max(force):.4g} N "
            f"({time.perf_counter() - start:.1f} s)",
            flush=True,
        )


if __name__ == "__main__":
    main()
