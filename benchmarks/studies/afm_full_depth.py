"""Real AFM curves fitted to their full depth with the sphere's true profile, against nanite's
whole-approach Sneddon sphere and Hertz paraboloid and the Chiaro vendor value.

    python -m benchmarks.studies.afm_full_depth [--nanite-site DIR] [--only 0,4]

The approach curves of ``benchmarks.afm_real_data`` (its ``CURVES``), read with
``indenter="sphere"`` (the approach to 0.95 R of stage travel instead of 0.95 × 0.2 R) at a
nominal R = 10 µm for the JPK files (the file's for the Chiaro, nanite's example value for the
zebrafish), 300 samples, rtol 1e-3, and fitted by lubjax-fit with the sphere (elastic
half-space under a film whose η is fitted). Beside it: lubjax with the default paraboloid on the
0.2 R cut (what ``afm_real_data`` fits, at the same R), nanite 4.2.3 on the whole approach with
``sneddon_spher`` (nanite-model-sneddon-spher 1.0.2: Sneddon's rigid sphere, as lubjax's dry
limit) and ``hertz_para``, and the vendor's E where the file has one. E = 0.75 E* (ν = 0.5).

nanite is a benchmark dependency only, never lubjax's: install it apart (a virtual environment
of its own with ``pip install nanite==4.2.3 nanite-model-sneddon-spher==1.0.2``) and give its
site-packages with ``--nanite-site``: they are appended to the path, after lubjax's own
packages. The instrument files as ``benchmarks.afm_real_data`` (``LUBJAX_TESTDATA``). Writes
benchmarks/out/afm_full_depth.{md,csv}.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import sys
import time

import numpy as np

import fitting
from benchmarks import _harness
from benchmarks.afm_real_data import CURVES, NU, nanite_E
from fitting import _afm

#: The JPK files carry no radius: one nominal R for all (E scales as R^{-1/2} in every model).
NOMINAL_R = 10e-6
KEEP_R = {"file", "nanite example"}


def _fit(trace, settings, indenter):
    start = time.perf_counter()
    (res,) = fitting.fit_traces([trace], settings=settings,
                                spec=fitting.ModelSpec(drive="spring", indenter=indenter))
    return res, time.perf_counter() - start


def row(root, settings, label, rel, index, radius, rnote):
    path = os.path.join(root, rel)
    radius = radius if rnote in KEEP_R else NOMINAL_R
    read = dict(radius=radius, poisson=NU, max_samples=300, curves=[index])
    (deep,) = _afm.read_afm(path, indenter="sphere", **read)
    (cut,) = _afm.read_afm(path, **read)
    sphere, wall = _fit(deep, settings, "sphere")
    paraboloid, wall_p = _fit(cut, settings, "paraboloid")
    R = deep.radius
    contact = deep.meta_float("contact_estimate_m")
    depths = [(float(np.max(tr.displacement)) if tr.meta_float("approach_cut_m") is None
               else tr.meta_float("approach_cut_m")) - contact for tr in (deep, cut)]
    vendor = deep.meta_float("vendor_E_star_Pa")
    out = dict(
        curve=label, R_um=R * 1e6, R_from=rnote if rnote in KEEP_R else "nominal",
        depth_um=depths[0] * 1e6, depth_over_R=depths[0] / R,
        E_sphere=sphere.E_star * (1 - NU**2), E_sphere_err=sphere.stderr["E_star"] * (1 - NU**2),
        beta=sphere.beta, red_chi2=sphere.stats["reduced_chi2"], converged=sphere.converged,
        cut_depth_um=depths[1] * 1e6, E_paraboloid_cut=paraboloid.E_star * (1 - NU**2),
        converged_paraboloid=paraboloid.converged,
        E_nanite_sneddon=nanite_E(path, index, R, model="sneddon_spher"),
        E_nanite_hertz=nanite_E(path, index, R),
        E_vendor=None if vendor is None else vendor * (1 - NU**2), wall_s=wall + wall_p)
    print(f"{label}: R {R * 1e6:.3g} um, depth {depths[0] / R:.2f} R: lubjax sphere "
          f"{out['E_sphere']:.4g} Pa, paraboloid (0.2 R cut) {out['E_paraboloid_cut']:.4g} Pa, "
          f"nanite sneddon {out['E_nanite_sneddon']:.4g} Pa, hertz {out['E_nanite_hertz']:.4g}"
          f" Pa ({out['wall_s']:.0f} s)", flush=True)
    return out


def _g(x, fmt=".4g"):
    return "—" if x in (None, "") else format(float(x), fmt)


def table(rows, command):
    lines = [
        "# AFM curves to their full depth: the sphere against nanite", "",
        f"`{command}`; {_harness.label()}", "",
        "E in Pa (ν = 0.5). lubjax sphere: the approach to its full depth (at most 0.95 R of "
        "stage travel), film fitted; lubjax paraboloid: the same curve cut at 0.95 × 0.2 R; "
        "nanite: the whole approach.", "",
        "| curve | R (µm) | stage travel past contact (µm, /R) | lubjax sphere | β | "
        "reduced χ² | lubjax paraboloid, 0.2 R cut | nanite sneddon_spher | nanite hertz_para | "
        "vendor |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        flag = "" if r["converged"] in (True, "True") else " (NOT CONVERGED)"
        flag_p = "" if r["converged_paraboloid"] in (True, "True") else " (NOT CONVERGED)"
        lines.append(
            f"| {r['curve']} | {_g(r['R_um'], '.4g')} ({r['R_from']}) | "
            f"{_g(r['depth_um'], '.3g')} ({_g(r['depth_over_R'], '.2f')}) | "
            f"{_g(r['E_sphere'])} ± {_g(r['E_sphere_err'], '.2g')}{flag} | "
            f"{_g(r['beta'], '.3g')} | "
            f"{_g(r['red_chi2'], '.3g')} | {_g(r['E_paraboloid_cut'])}{flag_p} | "
            f"{_g(r['E_nanite_sneddon'])} | {_g(r['E_nanite_hertz'])} | {_g(r['E_vendor'])} |")
    return lines


def main(argv=None):
    ap = _harness.parser(__doc__, "afm_full_depth.md")
    ap.add_argument("--nanite-site", help="site-packages of an environment with nanite and "
                    "nanite-model-sneddon-spher (appended to the path)")
    ap.add_argument("--only", help="curve indices of afm_real_data.CURVES, e.g. 0,4 (default "
                    "all)")
    args = _harness.parse(ap, argv)
    if args.nanite_site:
        sys.path.append(args.nanite_site)
    root = os.environ.get("LUBJAX_TESTDATA", os.path.expanduser("~/.cache/lubjax/testdata"))
    settings = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3)
    pick = range(len(CURVES)) if args.only is None else [int(i) for i in args.only.split(",")]
    rows = [row(root, settings, *CURVES[i]) for i in pick]
    base = os.path.splitext(args.out)[0]
    with open(base + ".csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    _harness.write_report(args.out, table(rows, _harness.command(argv)))


if __name__ == "__main__":
    main()
