"""Reports of a fit: the JSON summary, the text report, the summary line and the CSV table."""

from __future__ import annotations

import csv
import math
import os
import textwrap

import numpy as np

import lubjax
from lubjax._fitting_api import files as _files

from ._checks import e_star_range, plausibility_flags
from ._fit import FitResult
from ._profile import LEVELS

#: (JSON key, display unit, display scale) of each parameter; the offset's depends on the channel.
_UNITS = {
    "E_star": ("E_star_Pa", "MPa", 1e6),
    "viscosity": ("viscosity_Pa_s", "Pa s", 1.0),
    "z0": ("z0_m", "um", 1e-6),
    "stiffening": ("stiffening", "", 1.0),  # E0/Einf: a ratio, no unit
    "relaxation_time": ("relaxation_time_s", "s", 1.0),
}
#: Parameters whose value can be near or at zero: their error is shown absolute only (a relative
#: error of an offset near zero is thousands of percent and says nothing).
NEAR_ZERO = ("offset",)
_TRUE_KEYS = {
    "E_star": "true_E_star_Pa",
    "viscosity": "true_viscosity_Pa_s",
    "z0": "true_z0_m",
    "stiffening": "true_stiffening",
    "relaxation_time": "true_relaxation_time_s",
}


#: Display units by magnitude: (smallest magnitude shown in it, unit, scale), largest first.
_E_DISPLAY = ((1e6, "MPa", 1e6), (1e3, "kPa", 1e3), (0.0, "Pa", 1.0))
_FORCE_DISPLAY = ((1e-3, "mN", 1e-3), (1e-6, "uN", 1e-6), (0.0, "nN", 1e-9))


def _by_magnitude(magnitude, table):
    return next((unit, scale) for lowest, unit, scale in table if magnitude >= lowest)


def units(res: FitResult, name: str):
    """(JSON key, display unit, display scale) of parameter ``name``: E* in MPa, kPa or Pa and
    a force offset in mN, uN or nN, whichever its size reads best in (a gel on an AFM is 100 Pa
    and 1 nN; the paper's tribometer 4 MPa and 30 mN)."""
    if name == "offset":
        if res.spec.response != "force":
            return "offset_m", "um", 1e-6
        size = max(abs(res.values[name]), abs(res.stderr[name]))
        return ("offset_N", *_by_magnitude(size if np.isfinite(size) else 1.0, _FORCE_DISPLAY))
    if name == "E_star":
        size = abs(res.values[name])
        return ("E_star_Pa", *_by_magnitude(size if np.isfinite(size) else 1e6, _E_DISPLAY))
    return _UNITS[name]


def truth(res: FitResult) -> dict:
    """True values from a synthetic trace's header, where present."""
    out = {}
    for name, key in _TRUE_KEYS.items():
        if name in res.values and key in res.metadata:
            try:
                out[name] = float(res.metadata[key])
            except (TypeError, ValueError):
                pass
    return out


def _finite(x):
    return None if x is None or not np.isfinite(x) else float(x)


def result_to_dict(res: FitResult) -> dict:
    """A JSON-ready summary of a fit (SI units; keys as documented in data/README.md).

    Args:
        res: the :class:`FitResult`.

    Returns:
        A dict of plain numbers, strings, lists and dicts. Its ``plausible`` is False when E*,
        η or the ramp speed lies outside soft lubricated contact (``fitting._checks``; the
        flags then name the likely unit mistake), or when the model does not describe the
        data (``adequacy``, ``fitting._adequacy``; the flags say how and what could help).
    """
    names = res.spec.names
    resp_unit = "N" if res.spec.response == "force" else "m"
    out = {"trace": res.name}
    for n in names:
        out[units(res, n)[0]] = res.values[n]
    out["stderr"] = {units(res, n)[0]: res.stderr[n] for n in names}
    out["correlation"] = {
        "names": list(names),
        "matrix": [[_finite(x) for x in row] for row in res.correlation],
    }
    parts = res.stats.get("error_parts", {})
    out["error_budget"] = {
        part: {units(res, n)[0]: v for n, v in errs.items()} for part, errs in parts.items()
    }
    out.update(
        model={"drive": res.spec.drive, "substrate": res.spec.substrate_label(),
               "response": res.spec.response},
        shared=list(res.shared),
        group=list(res.group),
        beta=res.beta,
        z0_over_dc=res.z0_over_dc,
        indent_m=res.scales.indent,
        speed_m_s=res.scales.speed,
        time_scale_s=res.scales.time_scale,
        radius_m=res.scales.radius,
        **{f"rms_residual_{resp_unit}": res.rms_residual},
        statistics={k: v for k, v in res.stats.items() if k not in ("error_parts", "intervals")},
        # a parameter the data bound from one side: its profile-χ² interval (None: unbounded)
        intervals={units(res, n)[0]: {key: [_finite(b) for b in bounds]
                                      for key, bounds in levels.items()}
                   for n, levels in res.stats.get("intervals", {}).items()},
        converged=res.converged,
        identifiable=res.identifiable,
        condition_number=res.stats.get("condition"),
        n_iterations=res.n_iterations,
        n_model_runs=res.n_model_runs,
        method=res.method,
        wall_s=res.wall_s,
        flags=list(res.flags),
        fixed=list(res.fixed or ()),
        plausible=not plausibility_flags(
            {n: v for n, v in res.values.items() if n not in (res.fixed or ())
             and n not in res.stats.get("undetermined", ())}, res.scales.speed,
            e_star_range(res.metadata)) and not (res.adequacy and res.adequacy.ok is False),
        adequacy=None if res.adequacy is None else res.adequacy.to_dict(),
        start={**{units(res, n)[0]: res.start.values[n] for n in names},
               "notes": list(res.start.notes)},
        metadata=dict(res.metadata),
    )
    nu = None
    try:
        nu = float(res.metadata.get("poisson_ratio"))
    except (TypeError, ValueError):
        nu = None
    lo, hi = lubjax.POISSON_RANGE
    if nu is not None and lo < nu <= hi:
        out["E_Pa"] = res.E_star * (1 - nu**2)
        out["stderr"]["E_Pa"] = res.stderr["E_star"] * (1 - nu**2)
    true = truth(res)
    if true:
        out["vs_true"] = {
            units(res, n)[0]: {
                "true": v, "relative_error": res.values[n] / v - 1,
                "z_score": sided_z(res, n, v) if res.stderr[n] > 0 else None,
            }
            for n, v in true.items()
        }
    if "comparison" in res.stats:
        out["comparison"] = res.stats["comparison"]
    return out


def _value_line(res, n):
    key, unit, scale = units(res, n)
    v, e = res.values[n] / scale, res.stderr[n] / scale
    rel = f"({100 * e / abs(v):.2f}%)" if v and n not in NEAR_ZERO else ""
    tag = " (shared)" if n in res.shared else " (fixed)" if n in (res.fixed or ()) else ""
    start = res.start.values[n] / scale
    line = (f"    {n:<16s} = {v:<11.6g} +/- {e:<10.3g} {rel:<9s} {unit:<8s} "
            f"(init = {start:.5g}){tag}")
    t = truth(res).get(n)
    if t is not None and res.stderr[n] > 0:
        line += f"  [true {t / scale:.5g}, z = {sided_z(res, n, t):+.2f}]"
    interval = res.stats.get("intervals", {}).get(n)
    if interval is not None:
        line += "\n" + " " * 23 + "profile of chi2: " + ", ".join(
            f"{_interval_text(interval[key], scale)} at {LEVELS[key]:g} sigma" for key in interval)
    return line


def _interval_text(bounds, scale=1.0) -> str:
    lo, hi = bounds[0] / scale, bounds[1] / scale
    if lo == 0:
        return f"< {hi:.3g}"
    digits = _digits(max(abs(lo), abs(hi)), hi - lo)
    return f"{_shown(lo, digits)} to {_shown(hi, digits)}"


def _digits(value, width) -> int:
    """Significant digits that show ``width`` next to ``value`` to 2 digits (at least 3)."""
    return max(3, 2 + math.ceil(math.log10(abs(value) / max(width, 1e-300))))


def _shown(x, digits=2) -> str:
    """``x`` to ``digits`` significant digits, trailing zeros kept (0.30, not 0.3)."""
    return f"{x:#.{digits}g}".rstrip(".")


def sided_z(res, n, true):
    """(value - truth) over the reported error, or over the 1σ interval's half on the truth's
    side where the parameter has an interval through an undetermined one's profile (near dry:
    E* and z0 through η's). An undetermined parameter's own interval is one-sided: its z is
    over the reported error (:func:`fitting.coverage` leaves it out of the rms)."""
    v = res.values[n]
    interval = res.stats.get("intervals", {}).get(n)
    if interval is not None and n not in res.stats.get("undetermined", ()):
        lo, hi = interval["1sigma"]
        half = v - lo if true < v else hi - v
        return (v - true) / half if half > 0 else math.nan
    return (v - true) / res.stderr[n] if res.stderr[n] > 0 else math.nan


def fit_report(res: FitResult, min_correl: float = 0.1) -> str:
    """A text report of a fit: statistics, variables with errors and starts, correlations,
    flags.

    Args:
        res: the :class:`FitResult`.
        min_correl: correlations of at most this |value| are left out (default 0.1).

    Returns:
        The report, several lines.
    """
    st = res.stats
    names = [n for n in res.spec.names if res.stderr.get(n, 0) > 0 or n != "offset"]
    lines = [
        f"[[Model]] {os.path.basename(res.name) or 'trace'}",
        f"    drive: {res.spec.drive}; substrate: {res.spec.substrate_label()}; "
        f"response: {res.spec.response}",
        "[[Fit Statistics]]",
        f"    # fitting method   = {res.method}",
        f"    # function evals   = {res.n_model_runs}",
        f"    # iterations       = {res.n_iterations}",
        f"    # data points      = {st['n_samples']}",
        f"    # variables        = {st['n_parameters']}",
        f"    chi-square         = {st['chi2']:.6g}",
        f"    reduced chi-square = {st['reduced_chi2']:.6g}",
        f"    Akaike info crit   = {st['aic']:.6g}",
        f"    Bayesian info crit = {st['bic']:.6g}",
        f"    residual lag-1 autocorrelation = {st['autocorrelation_lag1']:.3g} "
        f"(Durbin-Watson {st['durbin_watson']:.3g})",
        f"    noise model        = {st['noise_model']}"
        + (f" (noise ρ {st['noise_correlation']:.3g}, effective samples {st['n_effective']:.0f}, "
           f"noise variance {st['noise_scale']:.3g} × the reduced chi-square)"
           if st["noise_model"] == "ar1" else ""),
        f"    converged          = {res.converged}: {res.flags[0]}",
    ]
    if res.group:
        lines.append(f"    joint fit of       = {', '.join(res.group)}")
    lines.append("[[Variables]]")
    for n in names:
        lines.append(_value_line(res, n))
    ratio = "stiffening = E0/Einf, " if "stiffening" in names else ""
    lines.append(f"    ({ratio}beta = {res.beta:.5g}, z0/dc = {res.z0_over_dc:.5g}, d_c = "
                 f"{res.scales.indent * 1e6:.5g} um, t_c = {res.scales.time_scale:.4g} s)")
    parts = st.get("error_parts", {})
    if parts:
        lines.append("[[Error budget]] (1-sigma, per source; total = sqrt(noise^2 + solver^2))")
        for part, errs in parts.items():
            cells = []
            for n in names:
                if n in errs:
                    _, unit, scale = units(res, n)
                    cells.append(f"{n} {errs[n] / scale:.3g}")
            lines.append(f"    {part:<8s}: " + ", ".join(cells))
    lines.append(f"[[Correlations]] (unreported correlations are < {min_correl:.3f})")
    pairs = []
    idx = {n: i for i, n in enumerate(res.spec.names)}
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            c = res.correlation[idx[names[a]], idx[names[b]]]
            if np.isfinite(c) and abs(c) >= min_correl:
                pairs.append((abs(c), f"    C({names[a]}, {names[b]}) = {c:+.4f}"))
    lines += [p for _, p in sorted(pairs, reverse=True)]
    lines.append("[[Start values]]")
    lines += [f"    {note}" for note in res.start.notes]
    lines += _adequacy_lines(res)
    said = res.adequacy.message if res.adequacy is not None else None
    extra = [f for f in res.flags[1:] if f != said]
    if extra:
        lines.append("[[Flags]]")
        lines += [f"    {f}" for f in extra]
    if "comparison" in st:
        lines.append("[[Model comparison]]")
        lines += [f"    {x}" for x in st["comparison"]["report"]]
    return "\n".join(lines)


def _adequacy_lines(res: FitResult) -> list[str]:
    """The report's [[Model adequacy]] section (``fitting._adequacy``)."""
    a = res.adequacy
    if a is None:
        return []
    verdict = f"{'yes' if a.ok else 'NO' if a.ok is False else '?'}: " + a.message.split(
        "; what could help:")[0]
    lines = ["[[Model adequacy]]", *textwrap.wrap(verdict, 96, initial_indent="    ",
                                                   subsequent_indent="      ")]
    if a.ok is None:
        return lines
    unit = "N" if res.spec.response == "force" else "m"
    lines += [
        f"    noise in the residuals = {a.noise_sigma:.3g} {unit} (lag-1 correlation "
        f"{a.noise_lag1:.2f})",
        f"    reduced chi2 against it = {a.reduced_chi2:.4g} (z = {a.chi2_z:.2f})",
        f"    runs test z = {a.runs_z:.2f}",
    ]
    for seg in a.segments:
        shape = (f"z = {seg.z:.2f} on {seg.blocks} blocks, largest block mean {seg.misfit:.3g} "
                 f"{unit}"
                 if seg.blocks else "too short to test")
        mark = " (systematic)" if seg.systematic else ""
        lines.append(f"    {seg.name + ':':<20s} {shape}{mark}")
    lines.append(f"    a test fails beyond |z| = {a.z_critical:.2f} (1 % for the model that made "
                 "the data)")
    for x in a.advice:
        lines += textwrap.wrap(f"what could help: {x}", 96, initial_indent="    ",
                               subsequent_indent="      ")
    return lines


def short_value(res: FitResult, n: str) -> str:
    _, unit, scale = units(res, n)
    v, e = res.values[n] / scale, res.stderr[n] / scale
    if n in (res.fixed or ()):
        return f"{v:.4g} {unit} (fixed)" if unit else f"{v:.4g} (fixed)"
    text = f"{v:.4g} ± {e:.2g}" if not math.isnan(e) else f"{v:.4g}"
    interval = res.stats.get("intervals", {}).get(n)
    if interval is not None and n in res.stats.get("undetermined", ()):
        # the data bound it from one side: its profile interval instead
        text = f"{_interval_text(interval['2sigma'], scale)} (2 sigma)"
    elif interval is not None:  # asymmetric, through η's profile near dry: the 1σ interval
        lo, hi = interval["1sigma"][0] / scale, interval["1sigma"][1] / scale
        text = f"{_shown(v, _digits(v, hi - lo))} +{_shown(hi - v)}/-{_shown(v - lo)}"
    return f"{text} {unit}" if unit else text


def summary_line(res: FitResult) -> str:
    """One line on a fit, as ``lubjax-fit`` prints it.

    Args:
        res: the :class:`FitResult`.

    Returns:
        The trace's name, the fitted values, β, z̄0, the rms residual, the reduced χ², whether
        it converged, is identifiable and describes the data (``res.adequacy``), the
        iterations and the wall time.
    """
    status = "converged" if res.converged else "NOT CONVERGED"
    if not res.identifiable:
        status += ", NOT IDENTIFIABLE"
    if res.adequacy is not None and res.adequacy.ok is not None:
        status += (", the model describes the data" if res.adequacy.ok
                   else ", THE MODEL DOES NOT DESCRIBE THE DATA")
    labels = {"E_star": "E*", "viscosity": "eta", "relaxation_time": "tau",
              "stiffening": "E0/Einf"}
    values = ", ".join(
        f"{labels.get(n, n)} = {short_value(res, n)}" for n in res.spec.names if n != "offset"
    )
    unit = "N" if res.spec.response == "force" else "m"
    return (
        f"{os.path.basename(res.name) or 'trace'}: {values}; beta = {res.beta:.4g}, "
        f"z0/dc = {res.z0_over_dc:.4g}, rms residual = {res.rms_residual:.3g} {unit}, "
        f"reduced chi2 = {res.stats['reduced_chi2']:.3g}; "
        f"{status} ({res.n_iterations} iterations, {res.wall_s:.1f} s)"
    )


def write_table(results, path: str) -> None:
    """A CSV table of fits, one row per trace: fitted values, errors (and the 2σ ends of the
    profile-χ² intervals where a fit has them: near dry), statistics and flags (written
    atomically).

    Args:
        results: the :class:`FitResult` of each trace.
        path: the file to write.
    """
    names = []
    for r in results:
        names += [n for n in r.spec.names if n not in names]
    # a parameter with a profile-χ² interval in any fit (near dry): its 2σ ends as well
    profiled = [n for n in names if any(n in r.stats.get("intervals", {}) for r in results)]
    cols = ["trace", "drive", "substrate"]
    for n in names:
        cols += [n, f"{n}_se"] + ([f"{n}_2sigma_lo", f"{n}_2sigma_hi"] if n in profiled else [])
    cols += ["beta", "z0_over_dc", "rms_residual", "reduced_chi2", "noise_model", "converged",
             "identifiable", "adequate", "adequacy_reduced_chi2", "n_iterations", "wall_s"]
    with _files.atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in results:
            row = [r.name, r.spec.drive, r.spec.substrate_label()]
            for n in names:
                row += [r.values.get(n, ""), r.stderr.get(n, "")]
                if n in profiled:
                    interval = r.stats.get("intervals", {}).get(n)
                    row += list(interval["2sigma"]) if interval else ["", ""]
            adequacy = r.adequacy
            row += [r.beta, r.z0_over_dc, r.rms_residual, r.stats["reduced_chi2"],
                    r.stats["noise_model"], r.converged, r.identifiable,
                    "" if adequacy is None or adequacy.ok is None else adequacy.ok,
                    "" if adequacy is None else adequacy.reduced_chi2, r.n_iterations,
                    r.wall_s]
            w.writerow(row)
