"""Generate the synthetic tribometer traces in data/ (run: ``python data/make_synthetic.py``).

They mimic the experiment of Liu, Dong, Jagota & Hui, Soft Matter 18 (2022) §3.2: a glass bead
R = 2 mm pushed at v0 = 0.1 mm/s into Sylgard-184 (E = 2.94 MPa, ν = 0.5, E* = E/(1-ν²) = 3.92 MPa)
through silicone oil η = 100 Pa·s from a gap z0 = 140 μm by dc = 126, 140, 154 μm, then held.
Besides these relaxation tests (prescribed travel) it makes:

* ``visco_dc140``: the same test on a viscoelastic solid, a standard linear solid with
  E0/E∞ = ``VISCO_STIFFENING`` and relaxation time τ = ``VISCO_TAU_S`` (E* in the header is the
  relaxed E*∞), to test the model comparison;
* ``spring_dc140``: the paper_dc140 test with the sphere on a load cell of stiffness
  ``SPRING_N_M`` (the stage travel is recorded; the sphere lags it by F/k; lubjax.Spring);
* ``creep_30mN``: a load-controlled (creep) test: the load is ramped to 30 mN in 1 s through the
  same first-order lag and held; the input is the load, the response the displacement.
* ``water_dc140``: a near-dry contact, the same bead and PDMS under water (η = 1e-3 Pa s) from
  a gap of 70 μm by 140 μm (β = 5.4·10⁶, z̄0 = 0.5): the film drains to ~(β t̄)^{-1/2} d_c and
  the force is Hertz's within ~10⁻⁴, so the viscosity is hardly in the trace. Generated with
  ``NEAR_DRY_FINE`` (``FINE``'s rtol of 1e-7 costs too many steps at this β; still 300× tighter
  than the fits' and a 2× finer mesh, refined at the contact's edge).

What a real tribometer adds, and how it is mimicked:

* a quiescent stretch (``QUIET_S``) before the stage moves;
* a stage (or load) that does not start or stop instantly: the commanded rate passes through a
  first-order lag of time constant ``LAG_S``, so the travel is d(t) = v0[s - τ(1 - e^{-s/τ})]
  during the command (s = t - t_on) and relaxes exponentially to exactly dc afterwards;
* sampling at ``RATE_HZ`` and Gaussian noise on the response channel of standard deviation
  ``noise`` × its peak (the input channel, travel or load, is taken as noiseless: the command).

The response comes from ``lubjax`` with ``FINE``, a mesh and tolerance much finer than any fit
uses (fits: rtol ≥ 3e-4, Δr̄ ≥ 0.014, 271 nodes or fewer; here rtol = 1e-7, Δr̄ = 0.01, growth 1.02,
L̄ = 1000, 544 nodes), with the input history sampled at 40,001 points of its closed form (the fit
sees only the 100 Hz record). The fine solution is read at the sample times by the stepper's own
interpolant (``Result.at``). The noiseless traces go to ``data/clean/`` (tests add their own
noise draws to them), the noisy ones to ``data/``. True values are in each file's header.

``python data/make_synthetic.py [STEM ...]`` writes the traces (all, or those named);
``python data/make_synthetic.py --compare [STEM ...]`` recomputes the clean ones and prints how far
the current solver is from the files, writing nothing.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

import lubjax  # noqa: E402
from fitting._csv import write_trace  # noqa: E402
from fitting._trace import make_trace  # noqa: E402
from lubjax._threads import single_threaded_blas  # noqa: E402

RADIUS = 2.0e-3
E_MODULUS = 2.94e6
POISSON = 0.5
SPEED = 1.0e-4
GAP = 140e-6
RATE_HZ = 100.0
QUIET_S = 1.0
LAG_S = 0.05
HOLD_S = 15.0
VISCO_STIFFENING = 1.5
VISCO_TAU_S = 0.5
SPRING_N_M = 5000.0
CREEP_LOAD_N = 0.03
CREEP_RAMP_S = 1.0
CREEP_HOLD_S = 29.0
FINE = lubjax.Settings(rtol=1e-7, atol=1e-16, dr=0.01, mesh_growth=1.02, length=1000.0,
                       max_steps=200_000, error_estimate=False)
NEAR_DRY_FINE = lubjax.Settings(rtol=1e-6, atol=1e-16, dr=0.007, mesh_growth=1.05,
                                length=1000.0, max_steps=400_000, error_estimate=False)
NEAR_DRY = dict(stem="water_dc140", indent=140e-6, gap=70e-6, viscosity=1e-3, noise=0.01,
                seed=1404)
GENERATOR = ("data/make_synthetic.py, lubjax Settings(rtol=1e-7, atol=1e-16, dr=0.01, "
             "mesh_growth=1.02, length=1000), input sampled at 40001 points")

# (file stem, indent dc [m], viscosity [Pa s], noise fraction of peak force, seed, substrate or
# drive: "" elastic, "visco" a standard linear solid, "spring" the load cell of SPRING_N_M,
# "layer:H" a bonded incompressible layer of thickness H [m] on a rigid base)
CASES = [
    ("paper_dc126", 126e-6, 100.0, 0.01, 126, ""),
    ("paper_dc140", 140e-6, 100.0, 0.01, 140, ""),
    ("paper_dc154", 154e-6, 100.0, 0.01, 154, ""),
    ("hard_dc140_noise5", 140e-6, 100.0, 0.05, 1405, ""),
    ("visco_dc140", 140e-6, 100.0, 0.01, 1401, "visco"),
    ("spring_dc140", 140e-6, 100.0, 0.01, 1402, "spring"),
    ("layer2mm_dc140", 140e-6, 100.0, 0.01, 1403, "layer:2e-3"),
]
#: noise of the creep trace's displacement, fraction of its final value, and the seed
CREEP_NOISE, CREEP_SEED = 0.002, 30


def lagged_ramp(t, amount, duration, t_on=QUIET_S, lag=LAG_S):
    """A command ramping by ``amount`` over ``duration`` from t_on, through a first-order lag."""
    rate = amount / duration
    s = np.clip(np.asarray(t, dtype=np.float64) - t_on, 0.0, None)
    during = rate * (s - lag * (1.0 - np.exp(-s / lag)))
    v_end = rate * (1.0 - math.exp(-duration / lag))
    d_end = rate * (duration - lag * (1.0 - math.exp(-duration / lag)))
    after = d_end + v_end * lag * (1.0 - np.exp(-np.clip(s - duration, 0.0, None) / lag))
    return np.where(s <= duration, during, after)


def travel(t, indent, speed=SPEED, t_on=QUIET_S, lag=LAG_S):
    """Stage travel [m] at times t [s]: a lagged ramp of duration indent/speed starting at t_on."""
    return lagged_ramp(t, indent, indent / speed, t_on, lag)


def _fine_history(shape, t_end_bar, time_scale, breakpoints):
    s = np.linspace(0.0, t_end_bar, 40001)
    return lubjax.SampledTravel(s, shape(QUIET_S + s * time_scale), breakpoints=breakpoints)


def clean_force(indent, viscosity, times, kind="", layer_m=None, gap=GAP, settings=FINE):
    """Noiseless force [N] at ``times`` [s] from a fine-grid lubjax run; ``layer_m``: a bonded
    incompressible layer of that thickness [m] on a rigid base instead of the half-space."""
    test = lubjax.RelaxationTest.from_E(
        E_MODULUS, POISSON, radius=RADIUS, viscosity=viscosity, speed=SPEED, indent=indent, gap=gap
    )
    tc = test.time_scale
    t_bar_end = (times[-1] - QUIET_S) / tc
    # The force is exactly zero before the stage moves: start the run at t_on.
    history = _fine_history(lambda t: travel(t, indent) / indent, t_bar_end, tc, (0.0, 1.0))
    substrate = (
        lubjax.Viscoelastic.standard_linear_solid(VISCO_STIFFENING, VISCO_TAU_S / tc)
        if kind == "visco" else None
    )
    if layer_m is not None:
        substrate = lubjax.Layer(lubjax.layer_thickness_bar(layer_m, RADIUS, indent), POISSON,
                                 "bonded")
    # K̄ = π k/(2E*√(R d_c)) (lubjax/_drives.py)
    stiffness = math.pi * SPRING_N_M / (2 * test.E_star * math.sqrt(RADIUS * indent))
    drive = lubjax.Spring(stiffness, history) if kind == "spring" else lubjax.Travel(history)
    res = lubjax.relax(test.beta, test.z0_bar, t_bar_end, drive=drive, substrate=substrate,
                       settings=settings)
    tb = (times - QUIET_S) / tc
    force = np.where(tb <= 0, 0.0, res.at(np.clip(tb, 0.0, t_bar_end)))
    return test, test.force_scale * force


def creep_displacement(times):
    """Noiseless approach [m] at ``times`` under the lagged 30 mN load ramp (lubjax.Load)."""
    creep = lubjax.CreepTest(lubjax.plane_strain_modulus(E_MODULUS, POISSON), RADIUS, 100.0,
                             CREEP_LOAD_N, CREEP_RAMP_S, GAP)
    tc = creep.time_scale
    t_bar_end = (times[-1] - QUIET_S) / tc
    shape = _fine_history(lambda t: lagged_ramp(t, 1.0, CREEP_RAMP_S), t_bar_end, tc, (0.0, 1.0))
    res = lubjax.relax(creep.beta, creep.z0_bar, t_bar_end, drive=creep.drive(shape),
                       settings=FINE)
    tb = (times - QUIET_S) / tc
    gap = np.where(tb <= 0, creep.z0_bar, res.at(np.clip(tb, 0.0, t_bar_end), "gap"))
    return creep, creep.indent * (creep.z0_bar - gap)


def _meta(stem, E_star, viscosity, extra, gap=GAP, generator=GENERATOR):
    meta = {
        "radius_m": f"{RADIUS:.6g}",
        "poisson_ratio": f"{POISSON:g}",
        "sample": f"synthetic {stem}: glass bead, PDMS, silicone oil (Liu et al. 2022)",
        "true_E_Pa": f"{E_MODULUS:.6g}",
        "true_E_star_Pa": f"{E_star:.6g}",
        "true_viscosity_Pa_s": f"{viscosity:.6g}",
        "true_z0_m": f"{gap:.6g}",
    }
    meta.update(extra)
    meta.update({"motion_start_s": f"{QUIET_S:g}", "stage_lag_s": f"{LAG_S:g}",
                 "sampling_hz": f"{RATE_HZ:g}", "generator": generator})
    return meta


def _write(stem, times, disp, force, meta, noisy_channel, sigma, seed, clean=True):
    if clean:
        write_trace(os.path.join(HERE, "clean", f"{stem}_clean.csv"),
                    make_trace(times, disp, force, RADIUS, dict(meta, noise_N="0")))
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, sigma, size=times.shape)
    key = "noise_N" if noisy_channel == "force" else "noise_m"
    meta = dict(meta, **{key: f"{sigma:.6g}", "noise_seed": str(seed)})
    if noisy_channel == "force":
        force = force + noise
    else:
        disp = disp + noise
    write_trace(os.path.join(HERE, f"{stem}.csv"), make_trace(times, disp, force, RADIUS, meta))


def compare(only=None):
    """Recompute the clean relaxation traces with the current solver and print how far each is
    from the file in data/clean/ (max |ΔF| over the samples, as a fraction of the peak); writes
    nothing. The creep trace (no clean file) is skipped."""
    from fitting import read_trace

    # the 5 mm layer's traces are benchmarks/studies/layer_fit_bias.py's, from clean_force too
    layer5mm = [(f"layer5mm_dc{um}", um * 1e-6, 100.0, 0.01, 0, "layer:5e-3")
                for um in (126, 140, 154)]
    for stem, indent, viscosity, _, _, kind in CASES + layer5mm:
        path = os.path.join(HERE, "clean", f"{stem}_clean.csv")
        if (only and stem not in only) or not os.path.exists(path):
            continue
        start = time.perf_counter()
        stored = read_trace(path)
        layer_m = float(kind.split(":")[1]) if kind.startswith("layer:") else None
        _, force = clean_force(indent, viscosity, stored.time, "" if layer_m else kind, layer_m)
        peak = float(np.max(np.abs(stored.force)))
        worst = float(np.max(np.abs(force - stored.force))) / peak
        print(f"{stem}: max |F - F_file| = {worst:.2e} of the peak "
              f"({time.perf_counter() - start:.1f} s)", flush=True)


def main(only=None):
    times = np.arange(0.0, QUIET_S + 154e-6 / SPEED + HOLD_S, 1.0 / RATE_HZ)
    cache = {}
    for stem, indent, viscosity, noise, seed, kind in CASES:
        if only and stem not in only:
            continue
        start = time.perf_counter()
        key = (indent, viscosity, kind)
        layer_m = float(kind.split(":")[1]) if kind.startswith("layer:") else None
        if key not in cache:
            cache[key] = clean_force(indent, viscosity, times, "" if layer_m else kind, layer_m)
        test, force = cache[key]
        extra = {"true_indent_m": f"{indent:.6g}", "true_speed_m_s": f"{SPEED:.6g}",
                 "true_beta": f"{test.beta:.6g}"}
        if kind == "spring":
            extra["stiffness_N_m"] = f"{SPRING_N_M:g}"
        if kind == "visco":
            extra.update(true_stiffening=f"{VISCO_STIFFENING:g}",
                         true_relaxation_time_s=f"{VISCO_TAU_S:g}")
        if layer_m is not None:
            hbar = lubjax.layer_thickness_bar(layer_m, RADIUS, indent)
            extra.update(substrate="bonded incompressible layer on a rigid base",
                         true_layer_thickness_m=f"{layer_m:g}",
                         true_layer_thickness_bar=f"{hbar:.6g}")
        meta = _meta(stem, test.E_star, viscosity, extra)
        meta["noise_fraction_of_peak"] = f"{noise:g}"
        _write(stem, times, travel(times, indent), force, meta, "force",
               noise * float(np.max(force)), seed, clean=noise == 0.01)
        print(f"{stem}: beta={test.beta:.4g} peak={np.max(force):.4g} N "
              f"({time.perf_counter() - start:.1f} s)", flush=True)
    if not only or NEAR_DRY["stem"] in only:
        near_dry(times)
    if not only or "creep_30mN" in only:
        start = time.perf_counter()
        ctimes = np.arange(0.0, QUIET_S + CREEP_RAMP_S + CREEP_HOLD_S, 1.0 / RATE_HZ)
        creep, disp = creep_displacement(ctimes)
        load = CREEP_LOAD_N * lagged_ramp(ctimes, 1.0, CREEP_RAMP_S)
        meta = _meta("creep_30mN", creep.E_star, 100.0, {
            "drive": "force", "true_load_N": f"{CREEP_LOAD_N:g}",
            "load_ramp_s": f"{CREEP_RAMP_S:g}", "true_beta_creep_scales": f"{creep.beta:.6g}",
            "noise_fraction_of_final_displacement": f"{CREEP_NOISE:g}"})
        _write("creep_30mN", ctimes, disp, load, meta, "displacement",
               CREEP_NOISE * float(disp[-1]), CREEP_SEED)
        print(f"creep_30mN: beta={creep.beta:.4g} final approach={disp[-1] * 1e6:.4g} um "
              f"({time.perf_counter() - start:.1f} s)", flush=True)


def near_dry(times):
    """The near-dry trace (``NEAR_DRY``), generated with ``NEAR_DRY_FINE``."""
    start = time.perf_counter()
    c = NEAR_DRY
    test, force = clean_force(c["indent"], c["viscosity"], times, gap=c["gap"],
                              settings=NEAR_DRY_FINE)
    extra = {"true_indent_m": f"{c['indent']:.6g}", "true_speed_m_s": f"{SPEED:.6g}",
             "true_beta": f"{test.beta:.6g}", "noise_fraction_of_peak": f"{c['noise']:g}"}
    generator = ("data/make_synthetic.py, lubjax Settings(rtol=1e-6, atol=1e-16, dr=0.007, "
                 "mesh_growth=1.05, length=1000), input sampled at 40001 points")
    meta = _meta(c["stem"], test.E_star, c["viscosity"], extra, c["gap"], generator)
    meta["sample"] = f"synthetic {c['stem']}: glass bead, PDMS, water (near-dry contact)"
    _write(c["stem"], times, travel(times, c["indent"]), force, meta, "force",
           c["noise"] * float(np.max(force)), c["seed"])
    print(f"{c['stem']}: beta={test.beta:.4g} peak={np.max(force):.4g} N "
          f"({time.perf_counter() - start:.1f} s)", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    with single_threaded_blas():
        if args[:1] == ["--compare"]:
            compare(args[1:])
        else:
            main(args)
