"""Real AFM and indenter curves: nanite's Hertz fit against lubjax on the same approach segments.

    python -m benchmarks.afm_real_data [--only a0,d1] [--out benchmarks/out/afm_real_data.md]

Needs ``pip install lubjax[afm] nanite`` (nanite only here, a benchmark dependency) and the
instrument files of the pinned afmformats/nanite sdists, fetched as tests/test_afm_files.py does
(into ``LUBJAX_TESTDATA``, default ~/.cache/lubjax/testdata).

For each curve, Young's modulus E (ν = 0.5, E = 0.75 E*):

* nanite 4.2.3, model ``hertz_para`` (Hertz, paraboloid), its default preprocessing
  (tip position, force offset, contact point), on the whole approach;
* nanite the same on the samples lubjax fits (the file's times from the trace's first row,
  its ``start_time_s``, to its last: from half the in-contact travel before the contact
  estimate to lubjax's cut), an absolute range of nanite's tip position, its contact point
  started from the whole-approach fit's. (Started from nanite's own initial value, 25 µm
  away on the Chiaro curve, the fit ends with the contact point beyond the range, the model
  a constant over it and E wherever the optimiser left it; nanite's
  ``range_type="relative cp"`` walks off the same way:
  ``python -m benchmarks.studies.afm_unexplained``.)
* the vendor's E where the file gives one (the Chiaro export's E[v=0.500]);
* lubjax (``lubjax-fit``: the cantilever as the spring drive, the approach cut near contact
  and at MAX_TRAVEL_OVER_RADIUS·R, 300 samples, rtol 1e-3): elastic half-space under a film
  whose η is fitted, with β = E* d_c^{3/2} t_c/(6π η R^{3/2}) of each curve; and without the
  film (η held where β = 10⁴ at the film fit's E*: Hertz through the spring).

Dwell rows (``DWELLS``, out/afm_real_data_dwell.md): approach and dwell fitted with a standard
linear solid (E∞, E0/E∞, τ), the stress relaxation through the spring, the creep under load
control, beside nanite's Hertz E on the approach.

``--only a0,d1`` recomputes those rows and keeps the others from the CSVs (each part well
under a minute on 2 cores; all rows ~3 min).

The files of JPK and Igor give no tip radius: those rows use a nominal R (stated), the same for
both fits (E scales as R^{-1/2} in both, so their ratio does not depend on it).
"""

from __future__ import annotations

import csv
import dataclasses
import os
import time

import numpy as np

import fitting
from benchmarks import _harness
from fitting import _afm

AF = "afmformats-0.18.7/tests/data/"
NU = 0.5
#: (label, file under the cache, curve index, radius [m] or None for the file's, radius note)
CURVES = [
    ("Chiaro indentation (cell)", AF + "fmt-chiaro-txt_AEBP1_Indentation_002.txt", 0, None,
     "file"),
    ("zebrafish gray matter (JPK)",
     "nanite-4.2.3/examples/data/zebrafish-head-section-gray-matter.jpk-force", 0, 18.64e-6,
     "nanite example"),
    ("force map 2x2, curve 0 (JPK)", AF + "fmt-jpk-fd_map2x2_extracted.jpk-force-map", 0,
     10e-6, "nominal"),
    ("force map 2x2, curve 3 (JPK)", AF + "fmt-jpk-fd_map2x2_extracted.jpk-force-map", 3,
     10e-6, "nominal"),
    ("polymer gel, creep-compliance approach (JPK)",
     AF + "fmt-jpk-cc_pr14-polymergel-2021.06.30.jpk-force", 0, 10e-6, "nominal"),
    ("brain tissue, creep-compliance approach (JPK)",
     AF + "fmt-jpk-cc_pr14-brain-2021.06.30.jpk-force", 0, 75e-6, "nominal"),
    ("cell, stress-relaxation approach (JPK)", AF + "fmt-jpk-sr_cell1-0008.jpk-force", 0,
     150e-6, "nominal"),
]


def nanite_E(path, index, radius, window=None, model="hertz_para"):
    """nanite's E on the approach by its ``model`` (default ``hertz_para``, Hertz's paraboloid;
    ``sneddon_spher`` needs the nanite-model-sneddon-spher package); ``window``: (first, last)
    time [s] of the samples to fit (the file's time), else the whole approach."""
    import nanite

    group = nanite.load_group(path)
    if len(group):
        idnt = group[index]
    else:  # nanite loads force-distance curves only: hand it the approach as one
        import afmformats

        curve = afmformats.load_data(path)[index]
        sel = np.asarray(curve["segment"]) == _afm.SEGMENT_NAMES[
            curve.metadata["imaging mode"]].index("approach")
        data = {k: np.asarray(curve[k])[sel] for k in ("force", "height (measured)", "time")}
        data["segment"] = np.zeros(int(sel.sum()), dtype=np.uint8)
        md = dict(curve.metadata, **{"imaging mode": "force-distance", "segment count": 1,
                                     "point count": int(sel.sum())})
        idnt = nanite.Indentation(data, md)
    idnt.apply_preprocessing(["compute_tip_position", "correct_force_offset",
                              "correct_tip_offset"])
    idnt.fit_properties["model_key"] = model
    idnt.fit_properties["segment"] = 0
    params = idnt.get_initial_fit_parameters()
    params["R"].value = radius
    params["nu"].value = NU
    if window is not None:
        idnt.fit_model(params_initial=params)  # the whole approach: where contact starts
        params["contact_point"].value = idnt.fit_properties["params_fitted"][
            "contact_point"].value
        time = np.asarray(idnt["time"])
        rows = (np.asarray(idnt["segment"]) == 0) & (time >= window[0]) & (time <= window[1])
        tip = np.asarray(idnt["tip position"])[rows]
        idnt.fit_properties["range_type"] = "absolute"
        idnt.fit_properties["range_x"] = (float(np.min(tip)), float(np.max(tip)))
    idnt.fit_model(params_initial=params)
    return float(idnt.fit_properties["params_fitted"]["E"].value)


#: Dwell fits: (label, file, curve, radius [m], radius note, drive) — approach and dwell,
#: viscoelastic (standard linear solid); their depth needs a larger R than the approach rows.
DWELLS = [
    ("cell, stress relaxation (spring drive)", AF + "fmt-jpk-sr_cell1-0008.jpk-force", 0,
     150e-6, "nominal", "spring"),
    ("polymer gel, creep (load control)", AF + "fmt-jpk-cc_pr14-polymergel-2021.06.30.jpk-force",
     0, 10e-6, "nominal", "force"),
    ("brain tissue, creep (load control)", AF + "fmt-jpk-cc_pr14-brain-2021.06.30.jpk-force", 0,
     75e-6, "nominal", "force"),
]
#: "Without the film": the viscosity held where β is this large at the film fit's E* (the
#: film drained at once: a Hertz contact through the spring).
NO_FILM_BETA = 1e4


def _fit(tr, settings, **kw):
    t0 = time.perf_counter()
    (res,) = fitting.fit_traces([tr], settings=settings, **kw)
    return res, time.perf_counter() - t0


def _e(res):
    return res.E_star * (1 - NU**2), res.stderr["E_star"] * (1 - NU**2)


def approach_row(root, settings, label, rel, index, radius, rnote):
    path = os.path.join(root, rel)
    (tr,) = _afm.read_afm(path, radius=radius, poisson=NU, max_samples=300, curves=[index])
    R = tr.radius
    res, wall = _fit(tr, settings)
    eta_bare = res.values["viscosity"] * res.beta / NO_FILM_BETA
    bare, wall_bare = _fit(tr, settings, fixed={"viscosity": eta_bare})
    cut = tr.meta_float("approach_cut_m")
    end = float(np.max(tr.displacement)) if cut is None else cut
    depth = end - tr.meta_float("contact_estimate_m")  # stage travel past contact
    e_full = nanite_E(path, index, R)
    start = tr.meta_float("start_time_s")
    e_cut = nanite_E(path, index, R, (start, start + float(tr.time[-1])))
    vendor = tr.meta_float("vendor_E_star_Pa")
    (e, de), (e0, de0) = _e(res), _e(bare)
    print(f"{label}: nanite {e_full:.4g} Pa (same samples {e_cut:.4g}), lubjax {e:.4g} ± {de:.2g} "
          f"Pa (no film {e0:.4g}), beta {res.beta:.3g} ({wall + wall_bare:.1f} s)", flush=True)
    return dict(
        curve=label, R_um=R * 1e6, R_from=rnote, depth_um=depth * 1e6,
        E_nanite_full=e_full, E_nanite_same_depth=e_cut,
        E_vendor=None if vendor is None else vendor * (1 - NU**2),
        E_lubjax=e, E_lubjax_err=de, eta_mPa_s=res.values["viscosity"] * 1e3, beta=res.beta,
        z0_um=res.values["z0"] * 1e6, red_chi2=res.stats["reduced_chi2"],
        converged=res.converged, E_no_film=e0, E_no_film_err=de0,
        red_chi2_no_film=bare.stats["reduced_chi2"], converged_no_film=bare.converged,
        adequate=_adequate(res), adequate_no_film=_adequate(bare), wall_s=wall + wall_bare)


def dwell_row(root, settings, label, rel, index, radius, rnote, drive):
    path = os.path.join(root, rel)
    (tr,) = _afm.read_afm(path, radius=radius, poisson=NU, max_samples=400, curves=[index],
                          segments=("approach", "dwell"), drive=drive)
    res, wall = _fit(tr, settings, viscoelastic=True)
    e, de = _e(res)
    e_nanite = nanite_E(path, index, tr.radius)
    print(f"{label}: E_inf {e:.4g} ± {de:.2g} Pa, E0/Einf {res.values['stiffening']:.3g}, tau "
          f"{res.values['relaxation_time']:.3g} s, nanite (approach) {e_nanite:.4g} Pa "
          f"({wall:.1f} s)", flush=True)
    return dict(
        curve=label, R_um=tr.radius * 1e6, R_from=rnote, drive=drive, E_inf=e, E_inf_err=de,
        stiffening=res.values["stiffening"], tau_s=res.values["relaxation_time"],
        eta_mPa_s=res.values["viscosity"] * 1e3, beta=res.beta,
        red_chi2=res.stats["reduced_chi2"], converged=res.converged,
        E_nanite_approach=e_nanite, adequate=_adequate(res), wall_s=wall)


def _adequate(res):
    """The adequacy judgement in a table cell: "yes" or "no", its reduced χ² against the noise
    left in the residuals, and the misfitting segments (fitting._adequacy)."""
    a = res.adequacy
    bad = [s.name for s in a.segments if s.systematic]
    why = f"χ² {a.reduced_chi2:.3g}" + (", " + ", ".join(bad) if bad else "") + (
        ", smooth" if a.smooth else "")
    return f"{'yes' if a.ok else 'no'} ({why})"


def _flag(ok):
    return "" if ok in (True, "True") else " (NOT CONVERGED)"


def _g(x, fmt=".4g"):
    return "—" if x in (None, "") else format(float(x), fmt)


def approach_table(rows):
    lines = ["| curve | R [µm] (from) | stage travel past contact [µm] | E nanite, whole "
             "approach | E nanite, same samples | E vendor | E lubjax, with the film | η [mPa s] "
             "| β | reduced χ² | describes the data | E lubjax, no film | reduced χ², no film "
             "| describes the data, no film |",
             "|" + "---|" * 14]
    for r in rows:
        lines.append(
            f"| {r['curve']} | {_g(r['R_um'])} ({r['R_from']}) | {_g(r['depth_um'], '.3g')} | "
            f"{_g(r['E_nanite_full'])} | {_g(r['E_nanite_same_depth'])} | {_g(r['E_vendor'])} | "
            f"{_g(r['E_lubjax'])} ± {_g(r['E_lubjax_err'], '.2g')} | {_g(r['eta_mPa_s'], '.3g')}"
            f" | {_g(r['beta'], '.3g')} | {_g(r['red_chi2'], '.3g')}{_flag(r['converged'])} | "
            f"{r.get('adequate') or '—'} | "
            f"{_g(r['E_no_film'])} ± {_g(r['E_no_film_err'], '.2g')} | "
            f"{_g(r['red_chi2_no_film'], '.3g')}{_flag(r['converged_no_film'])} | "
            f"{r.get('adequate_no_film') or '—'} |")
    return lines


def dwell_table(rows):
    lines = ["| curve | R [µm] (from) | E∞ lubjax [Pa] | E0/E∞ | τ [s] | η [mPa s] | β | "
             "reduced χ² | describes the data | E nanite, approach [Pa] |", "|" + "---|" * 10]
    for r in rows:
        lines.append(
            f"| {r['curve']} | {_g(r['R_um'])} ({r['R_from']}) | {_g(r['E_inf'])} ± "
            f"{_g(r['E_inf_err'], '.2g')} | {_g(r['stiffening'], '.3g')} | {_g(r['tau_s'], '.3g')}"
            f" | {_g(r['eta_mPa_s'], '.3g')} | {_g(r['beta'], '.3g')} | "
            f"{_g(r['red_chi2'], '.3g')}{_flag(r['converged'])} | {r.get('adequate') or '—'} | "
            f"{_g(r['E_nanite_approach'])} |")
    return lines


def _load(path):
    if not os.path.exists(path):
        return {}
    with open(path, newline="") as fh:
        return {r["curve"]: r for r in csv.DictReader(fh)}


def _save(path, rows: dict, order):
    rows = [rows[k] for k in order if k in rows]
    if rows:
        with open(path, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    return rows


def main(argv=None):
    ap = _harness.parser(__doc__, "afm_real_data.md")
    ap.add_argument("--only", help="rows to (re)compute, e.g. a0,a1,d2 (a: approach rows, d: "
                    "dwell rows, from 0; the others are kept from the CSVs); default all")
    args = _harness.parse(ap, argv)
    root = os.environ.get("LUBJAX_TESTDATA", os.path.expanduser("~/.cache/lubjax/testdata"))
    settings = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3)
    base = os.path.splitext(args.out)[0]
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    only = None if args.only is None else {x.strip() for x in args.only.split(",")}
    appr, dwell = _load(base + ".csv"), _load(base + "_dwell.csv")
    for i, spec in enumerate(CURVES):
        if only is None or f"a{i}" in only:
            appr[spec[0]] = approach_row(root, settings, *spec)
    for i, spec in enumerate(DWELLS):
        if only is None or f"d{i}" in only:
            dwell[spec[0]] = dwell_row(root, settings, *spec)
    a_rows = _save(base + ".csv", appr, [c[0] for c in CURVES])
    d_rows = _save(base + "_dwell.csv", dwell, [c[0] for c in DWELLS])
    with open(args.out, "w") as fh:
        fh.write("\n".join(approach_table(a_rows)) + "\n")
    with open(base + "_dwell.md", "w") as fh:
        fh.write("\n".join(dwell_table(d_rows)) + "\n")
    print(f"wrote {args.out} and {base}_dwell.md")


if __name__ == "__main__":
    main()
