"""Two real-data results the AFM page once left unexplained, taken apart.

    python -m benchmarks.studies.afm_unexplained [--only chiaro,map]

Needs ``pip install lubjax[afm] nanite`` and the pinned sdists' instrument files (as
benchmarks/afm_real_data.py). Prints the numbers docs/guide/afm.md quotes and writes them to
benchmarks/out/afm_unexplained.md.

1. **The Chiaro curve**: nanite's Hertz fit "at lubjax's depth" gave E = 351 Pa against
   lubjax's film-free 130 Pa. nanite's ``range_type="relative cp"`` fits four times, each pass
   on a range placed relative to the contact point the pass before fitted; the passes are
   replayed here (range, forces in it, contact point, E), then nanite is fitted on the very
   samples lubjax fits (an absolute range of tip position over the same file times), and with
   its contact point held at lubjax's.
2. **The JPK reference-points map** (3 curves, R = 10 µm nominal): curve 2 ended "E* = 129.3 ±
   9.1e+07 MPa, NOT CONVERGED" and curves 0 and 1 differ 700×. Per curve: how far the force
   rises past contact and how much of that lubjax keeps within 0.2 R; nanite's whole-approach
   E; lubjax at 300 and 600 samples; and both tools at a nominal R large enough (50 µm) that
   the whole rise is within lubjax's 0.2 R.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from benchmarks import _harness

NU = 0.5
AF = "afmformats-0.18.7/tests/data/"
CHIARO = AF + "fmt-chiaro-txt_AEBP1_Indentation_002.txt"
MAP = AF + "fmt-jpk-fd_map-data-reference-points.jpk-force-map"


def _root():
    return os.environ.get("LUBJAX_TESTDATA", os.path.expanduser("~/.cache/lubjax/testdata"))


def _indentation(path, index=0):
    import nanite

    idnt = nanite.load_group(path)[index]
    idnt.apply_preprocessing(["compute_tip_position", "correct_force_offset",
                              "correct_tip_offset"])
    idnt.fit_properties["model_key"] = "hertz_para"
    idnt.fit_properties["segment"] = 0
    return idnt


def _nanite_fit(path, radius, index=0, range_x=None, contact_point=None, vary=False):
    """(E [Pa], contact point [m], the Indentation) of nanite's hertz_para fit on the approach,
    on an absolute range of tip position (``range_x``) or all of it; ``contact_point`` held
    there (or started there, ``vary``)."""
    idnt = _indentation(path, index)
    if range_x is not None:
        idnt.fit_properties["range_type"] = "absolute"
        idnt.fit_properties["range_x"] = tuple(range_x)
    params = idnt.get_initial_fit_parameters()
    params["R"].value = radius
    params["nu"].value = NU
    if contact_point is not None:
        params["contact_point"].value = contact_point
        params["contact_point"].vary = vary
    idnt.fit_model(params_initial=params)
    fitted = idnt.fit_properties["params_fitted"]
    return float(fitted["E"].value), float(fitted["contact_point"].value), idnt


def _rise(idnt):
    """How much nanite's fitted model changes over its fit range [N] (0: a constant)."""
    rows = np.asarray(idnt["fit range"])
    return float(np.ptp(np.asarray(idnt["fit"])[rows]))


def _settings(rtol=1e-3):
    import fitting

    return dataclasses.replace(fitting.FIT_SETTINGS, rtol=rtol)


def chiaro(root, out):
    import afmformats

    import fitting
    from fitting import _afm

    path = os.path.join(root, CHIARO)
    (tr,) = _afm.read_afm(path, poisson=NU, max_samples=300)
    R, k = tr.radius, float(tr.metadata["stiffness_N_m"])
    cut, contact = tr.meta_float("approach_cut_m"), tr.meta_float("contact_estimate_m")
    depth = cut - contact
    out.append(f"## Chiaro indentation (R = {R * 1e6:g} µm from the file, k = {k:g} N/m)\n")
    e_all, cp_all, idnt = _nanite_fit(path, R)
    out.append(f"nanite, whole approach: E = {e_all:.4g} Pa, contact point (tip position) "
               f"{cp_all * 1e6:.2f} µm\n")
    # nanite's relative-cp: a pass on the whole approach, then three on range_x + the last cp
    tip = np.asarray(idnt["tip position"])
    force = np.asarray(idnt["force"])
    appr = np.asarray(idnt["segment"]) == 0
    rel = (-depth, 0.5 * depth)
    out.append(f"nanite's range_type='relative cp' with range_x = ({rel[0] * 1e6:.2f}, "
               f"{rel[1] * 1e6:.2f}) µm (lubjax's depth, the benchmark's old call), its passes:\n")
    out.append("| pass | range of tip position [µm] | force in it [nN] | contact point [µm] "
               "| the model's rise over the range [nN] | E [Pa] |\n" + "|---" * 6 + "|")
    cp = cp_all
    for k_pass in range(1, 4):
        lo, hi = rel[0] + cp, rel[1] + cp
        inside = appr & (tip >= lo) & (tip <= hi)
        e, cp, fit = _nanite_fit(path, R, range_x=(lo, hi))
        out.append(f"| {k_pass + 1} | {lo * 1e6:.2f} to {hi * 1e6:.2f} | "
                   f"{force[inside].min() * 1e9:.1f} to {force[inside].max() * 1e9:.1f} | "
                   f"{cp * 1e6:.2f} | {_rise(fit) * 1e9:.3g} | {e:.4g} |")
    out.append("\n(pass 1 is the whole approach above; the tip position falls as the tip goes "
               "down.)\n")
    settings = _settings()
    (film,) = fitting.fit_traces([tr], settings=settings)
    eta = film.values["viscosity"] * film.beta / 1e4  # the film-free fit of afm_real_data
    (free,) = fitting.fit_traces([tr], settings=settings, fixed={"viscosity": eta})
    # lubjax's samples in nanite's tip position: the same file times
    curve = afmformats.load_data(path)[0]
    time = np.asarray(curve["time"])
    start = tr.meta_float("start_time_s")
    rows = appr & (time >= start) & (time <= start + float(tr.time[-1]))
    window = (float(tip[rows].min()), float(tip[rows].max()))
    e_same, cp_same, same = _nanite_fit(path, R, range_x=window)
    # lubjax's contact point in tip position: the tip travels z0 (the stage less F/k) from
    # the first row; nanite's tip position falls as the tip goes down (height + F/k)
    first = int(np.flatnonzero(rows)[0])
    cp_lubjax = float(tip[first]) - free.z0
    e_fixed, _, held = _nanite_fit(path, R, range_x=window, contact_point=cp_lubjax)
    e_start, cp_start, started = _nanite_fit(path, R, range_x=window, contact_point=cp_all,
                                             vary=True)
    E = (1 - NU**2)
    out += [
        f"lubjax's samples: tip position {window[0] * 1e6:.2f} to {window[1] * 1e6:.2f} µm "
        f"(stage travel {depth * 1e6:.2f} µm past its contact estimate, 300 samples)\n",
        "| fit on lubjax's samples | E [Pa] | contact point (tip position) [µm] | the model's "
        "rise over them [nN] |", "|---|---|---|---|",
        f"| lubjax, with the film | {film.E_star * E:.4g} | "
        f"{(float(tip[first]) - film.z0) * 1e6:.2f} | {np.ptp(film.model) * 1e9:.3g} |",
        f"| lubjax, without the film (β = 10⁴) | {free.E_star * E:.4g} | {cp_lubjax * 1e6:.2f} "
        f"| {np.ptp(free.model) * 1e9:.3g} |",
        f"| nanite, contact point fitted (nanite's start) | {e_same:.4g} | {cp_same * 1e6:.2f} | "
        f"{_rise(same) * 1e9:.3g} |",
        f"| nanite, contact point fitted from its whole-approach one | {e_start:.4g} | "
        f"{cp_start * 1e6:.2f} | {_rise(started) * 1e9:.3g} |",
        f"| nanite, contact point held at lubjax's film-free one | {e_fixed:.4g} | "
        f"{cp_lubjax * 1e6:.2f} | {_rise(held) * 1e9:.3g} |",
        "",
    ]


def reference_map(root, out):
    import afmformats

    import fitting
    from fitting import _afm

    path = os.path.join(root, MAP)
    curves = afmformats.load_data(path)
    out.append("## JPK reference-points map (3 curves)\n")
    out.append("| curve | grid position | stage travel from contact estimate to peak [µm] | "
               "peak force [nN] | kept at R = 10 µm: stage travel [µm], force reached [nN] | "
               "nanite E, R = 10 µm [Pa] | nanite E, R = 50 µm [Pa] |\n" + "|---" * 7 + "|")
    kept = _afm.read_afm(path, radius=10e-6, max_samples=300)
    for i, (curve, tr) in enumerate(zip(curves, kept, strict=True)):
        a = _afm.curve_arrays(curve)
        sel = a["segment"] == "approach"
        d, f = a["height"][sel][0] - a["height"][sel], a["force"][sel]
        f = f - np.median(f[: f.size // 10])
        ic = _afm._contact_index(d, f)
        md = curve.metadata
        e10 = _nanite_fit(path, 10e-6, index=i)[0]
        e50 = _nanite_fit(path, 50e-6, index=i)[0]
        out.append(f"| {i} | ({md['grid index x']}, {md['grid index y']}) | "
                   f"{(d[-1] - d[ic]) * 1e6:.2f} | {f.max() * 1e9:.2f} | "
                   f"{tr.displacement.max() * 1e6:.2f}, {tr.force.max() * 1e9:.2f} | "
                   f"{e10:.4g} | {e50:.4g} |")
    out.append("")
    out.append("| lubjax-fit, the map's 3 curves | curve | E [Pa] | z0/d_c | converged | "
               "describes the data |\n|---|---|---|---|---|---|")
    cases = [("R = 10 µm, 600 samples, rtol 3e-4 (the defaults)", 10e-6, 600, 3e-4),
             ("R = 10 µm, 300 samples, rtol 1e-3", 10e-6, 300, 1e-3),
             ("R = 50 µm, 300 samples, rtol 1e-3", 50e-6, 300, 1e-3)]
    for label, radius, samples, rtol in cases:
        traces = _afm.read_afm(path, radius=radius, max_samples=samples)
        for i, res in enumerate(fitting.fit_traces(traces, settings=_settings(rtol))):
            out.append(f"| {label} | {i} | {res.E_star * (1 - NU**2):.4g} ± "
                       f"{res.stderr['E_star'] * (1 - NU**2):.2g} | {res.z0_over_dc:.3g} | "
                       f"{res.converged} | {res.adequacy.ok} |")
    out.append("")


def main(argv=None):
    ap = _harness.parser(__doc__, "afm_unexplained.md")
    ap.add_argument("--only", default="chiaro,map", help="parts: chiaro, map (default both)")
    args = _harness.parse(ap, argv)
    root = _root()
    out = [f"*`{_harness.command(argv)}` — {_harness.label()}*\n"]
    parts = {x.strip() for x in args.only.split(",")}
    if "chiaro" in parts:
        chiaro(root, out)
    if "map" in parts:
        reference_map(root, out)
    text = "\n".join(out) + "\n"
    print(text)
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "w") as fh:
        fh.write(text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
