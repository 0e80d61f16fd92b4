"""Real AFM and indenter curves: nanite's Hertz fit against lubjax on the same approach segments.

    python benchmarks/afm_real_data.py [--out benchmarks/out/afm_real_data.md]

Needs ``pip install lubjax[afm] nanite`` (nanite only here, a benchmark dependency) and the
instrument files of the pinned afmformats/nanite sdists, fetched as tests/test_afm_files.py does
(into ``LUBJAX_TESTDATA``, default ~/.cache/lubjax/testdata).

For each curve, Young's modulus E (ν = 0.5, E = 0.75 E*):

* nanite 4.2.3, model ``hertz_para`` (Hertz, paraboloid), its default preprocessing
  (tip position, force offset, contact point), on the whole approach;
* nanite the same, restricted to the travel lubjax sees (``range_type="relative cp"``, from
  half the fitted depth before the contact point to lubjax's cut);
* the vendor's E where the file gives one (the Chiaro export's E[v=0.500]);
* lubjax (``lubjax-fit``: the cantilever as the spring drive, the approach cut near contact
  and at MAX_TRAVEL_OVER_RADIUS·R, 300 samples, rtol 1e-3): elastic half-space under a water
  film whose η is fitted, with β = E* d_c^{3/2} t_c/(6π η R^{3/2}) of each curve.

The files of JPK and Igor give no tip radius: those rows use a nominal R (stated), the same for
both fits (E scales as R^{-1/2} in both, so their ratio does not depend on it).
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import fitting  # noqa: E402
from fitting import _afm  # noqa: E402

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")
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
     AF + "fmt-jpk-cc_pr14-brain-2021.06.30.jpk-force", 0, 10e-6, "nominal"),
    ("cell, stress-relaxation approach (JPK)", AF + "fmt-jpk-sr_cell1-0008.jpk-force", 0,
     10e-6, "nominal"),
]


def nanite_E(path, index, radius, depth=None):
    """nanite's Hertz (paraboloid) E on the approach; ``depth``: fit only to that indentation."""
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
    idnt.fit_properties["model_key"] = "hertz_para"
    idnt.fit_properties["segment"] = 0
    if depth is not None:
        idnt.fit_properties["range_type"] = "relative cp"
        # from lubjax's margin before contact (half the depth) to its cut (tip position < 0)
        idnt.fit_properties["range_x"] = (-depth, 0.5 * depth)
    params = idnt.get_initial_fit_parameters()
    params["R"].value = radius
    params["nu"].value = NU
    idnt.fit_model(params_initial=params)
    return float(idnt.fit_properties["params_fitted"]["E"].value)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(OUT, "afm_real_data.md"))
    args = ap.parse_args(argv)
    root = os.environ.get("LUBJAX_TESTDATA", os.path.expanduser("~/.cache/lubjax/testdata"))
    settings = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3)
    rows = []
    for label, rel, index, radius, rnote in CURVES:
        path = os.path.join(root, rel)
        (tr,) = _afm.read_afm(path, radius=radius, poisson=NU, max_samples=300, curves=[index])
        R = tr.radius
        t0 = time.perf_counter()
        (res,) = fitting.fit_traces([tr], settings=settings)
        wall = time.perf_counter() - t0
        cut = tr.meta_float("approach_cut_m")
        end = float(np.max(tr.displacement)) if cut is None else cut
        depth = end - tr.meta_float("contact_estimate_m")  # stage travel past contact
        e_full = nanite_E(path, index, R)
        e_cut = nanite_E(path, index, R, depth)
        vendor = tr.meta_float("vendor_E_star_Pa")
        rows.append(dict(
            curve=label, R_um=R * 1e6, R_from=rnote,
            depth_um=depth * 1e6,
            E_nanite_full=e_full, E_nanite_same_depth=e_cut,
            E_vendor=None if vendor is None else vendor * (1 - NU**2),
            E_lubjax=res.E_star * (1 - NU**2), E_lubjax_err=res.stderr["E_star"] * (1 - NU**2),
            eta_mPa_s=res.values["viscosity"] * 1e3, beta=res.beta, z0_um=res.values["z0"] * 1e6,
            red_chi2=res.stats["reduced_chi2"], converged=res.converged, wall_s=wall))
        print(f"{label}: nanite {e_full:.4g} Pa (same depth {e_cut:.4g}), lubjax "
              f"{rows[-1]['E_lubjax']:.4g} ± {rows[-1]['E_lubjax_err']:.2g} Pa, beta "
              f"{res.beta:.3g}, eta {rows[-1]['eta_mPa_s']:.3g} mPa s ({wall:.1f} s)", flush=True)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(os.path.splitext(args.out)[0] + ".csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    head = ("| curve | R [µm] (from) | stage travel past contact fitted by lubjax [µm] | "
            "E nanite, whole approach "
            "[Pa] | E nanite, same depth [Pa] | E vendor [Pa] | E lubjax [Pa] | η [mPa s] | β | "
            "reduced χ² |")
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        vendor = "—" if r["E_vendor"] is None else f"{r['E_vendor']:.4g}"
        lines.append(
            f"| {r['curve']} | {r['R_um']:.4g} ({r['R_from']}) | {r['depth_um']:.3g} | "
            f"{r['E_nanite_full']:.4g} | {r['E_nanite_same_depth']:.4g} | {vendor} | "
            f"{r['E_lubjax']:.4g} ± {r['E_lubjax_err']:.2g} | {r['eta_mPa_s']:.3g} | "
            f"{r['beta']:.3g} | {r['red_chi2']:.3g}"
            + ("" if r["converged"] else " (NOT CONVERGED)") + " |")
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
