"""AFM and indenter vendor files as traces, read by ``afmformats`` (``pip install lubjax[afm]``).

The instrument becomes the model's drive: the cantilever is a ``lubjax.Spring`` of the file's
spring constant k, the stage is the recorded height (the piezo's travel; JPK's closed-loop
"height (measured)", the Chiaro's piezo), the force is k times the deflection. Every segment
goes through the same drive: the approach is the ramp, a constant-height dwell (JPK
stress-relaxation) is relaxation through the spring, and a constant-force dwell (JPK
creep-compliance) is the stage moving under the instrument's force feedback, which the spring
drive takes as its measured input. Or, with ``drive="force"``, a constant-force dwell is creep
under load control (``lubjax.Load``): the input is the force from rest (the last sample within
the baseline's noise before contact), the response the tip's own travel (stage less F/k). The
retract is refused: adhesion (the tip sticking to the sample) and cavitation (the film tearing
under tension) are not modelled.

Conversion (afmformats gives SI: force N, height m, time s):

* displacement = h(t_0) - h(t), positive toward the sample, since the first row kept;
* force = the file's force (positive when the sample pushes back), less the baseline: the
  median force before contact ("offset", the default; the fit still fits a constant offset) or
  a straight line in the stage travel fitted to the samples before contact ("tilt", the drift
  and interference AFM users remove);
* the approach is cut to start a ``margin`` of the travel in contact before the contact
  estimate (the first sample after which the force stays above ``CONTACT_FRACTION`` of its
  peak above the baseline): the thin-film model needs travel ≪ R, and the far approach carries
  no information on E* (the fitted z0 is the contact point, measured from the first kept row);
* segments are decimated by block means to at most ``max_samples`` samples in all;
* for the spring drive the stage travel, the model's input, is a least-squares cubic spline
  per segment through the kept rows: the fewest knot intervals (4, 8, 16, ...; each over
  ``STAGE_MIN_ROWS`` rows at least) whose rms deviation from the measured stage is within
  ``STAGE_NOISE_FACTOR`` of the height sensor's white noise (its σ from the second
  differences). What the spline leaves out is that noise (about 1 nm on JPK's closed-loop
  height), not stage motion (a feedback-driven dwell, a vibration of the stage). Kept as
  measured, the noise would make the sampled input a line through 300 kinks whose speed
  jumps by ±50 % from one sample to the next; before contact the sphere follows such a stage
  through a thin film with a short lag, so every kink sets off a transient that the step
  control resolves (about 20 steps each: a film-free fit, β ~ 10⁴, runs out of the 5000-step
  budget at its start).
  The spline's rms deviation from the measured stage is in the metadata
  (``stage_smoothing_rms_m``); the force, the data, is not smoothed.

Tip radius: the file's (the Chiaro header's "Tip radius (um)"; afmformats reads none from JPK
or Igor files), else ``radius=`` (``--radius``) is required. Poisson ratio: ``poisson=``.
"""

from __future__ import annotations

import contextlib
import math
import os
import re

import numpy as np

from lubjax._fitting_api import checks as _checks

from ._csv import JPK_EXTENSIONS, unzipped, zip_export, zip_head
from ._trace import MAX_SPHERE_TRAVEL_OVER_RADIUS, TraceError, make_trace

#: File name endings read through afmformats (lower case).
AFM_EXTENSIONS = (*JPK_EXTENSIONS, ".ibw", ".h5", ".tab")
#: Segment names per afmformats modality, in the file's segment order.
SEGMENT_NAMES = {
    "force-distance": ("approach", "retract"),
    "creep-compliance": ("approach", "dwell", "retract"),
    "stress-relaxation": ("pause", "approach", "dwell", "retract"),
}
BASELINES = ("offset", "tilt")
#: The drives a vendor curve is read for: the cantilever as a spring, or load control.
DRIVES = ("spring", "force")
#: The contact estimate: the force stays above this fraction of its peak over the baseline.
CONTACT_FRACTION = 0.05
#: The cut keeps this fraction of the in-contact travel before the contact estimate.
MARGIN = 0.5
MAX_SAMPLES = 600
#: The stage spline (spring drive): each knot interval spans at least this many rows (a
#: segment with fewer keeps its stage as measured) ...
STAGE_MIN_ROWS = 8
#: ... and the spline's rms deviation from the measured stage is at most this factor times
#: the sensor's noise σ (or the knots are as dense as STAGE_MIN_ROWS allows).
STAGE_NOISE_FACTOR = 1.2
#: An approach-only trace is cut where the kept stage travel reaches this fraction of the
#: indenter's limit, MAX_TRAVEL_OVER_RADIUS·R for the paraboloid, MAX_SPHERE_TRAVEL_OVER_RADIUS·R
#: for the sphere (the cut is in the metadata: ``approach_cut_m``).
CAP = 0.95


def _head(path, size: int = 4096) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError:
        return b""


def _is_vendor_export(name: str, head) -> bool:
    """A vendor file by its name (its extension; a ``.txt`` only when ``head()``, its first
    bytes, show an Optics11 Chiaro export)."""
    name = name.lower()
    if name.endswith(AFM_EXTENSIONS):
        return True
    if name.endswith(".txt"):
        first = head()
        return b"Chiaro" in first or b"Optics11" in first
    return False


def is_afm_file(path) -> bool:
    """Whether ``path`` is a vendor file read through afmformats (by its extension; a ``.txt``
    only when it is an Optics11 Chiaro export), or a zip archive holding one such file."""
    path = os.fspath(path)
    if _is_vendor_export(path, lambda: _head(path)):
        return True
    try:
        member = zip_export(path)
    except TraceError:
        return False  # read_trace names what the archive holds
    return member is not None and _is_vendor_export(member, lambda: zip_head(path, member))


def _afmformats():
    try:
        import afmformats
    except ImportError:
        raise TraceError(
            "reading AFM vendor files needs the afmformats package: pip install lubjax[afm]"
        ) from None
    return afmformats


def parse_segments(spec) -> tuple[str, ...]:
    """"approach,dwell" -> ("approach", "dwell"); ValueError naming the allowed names."""
    allowed = ("pause", "approach", "dwell", "retract")
    names = tuple(s.strip() for s in str(spec).split(",") if s.strip())
    bad = [s for s in names if s not in allowed]
    if bad or not names:
        raise ValueError(f"--segments: unknown segment(s) {', '.join(bad) or repr(spec)} "
                         f"(allowed: {', '.join(allowed)}, comma-separated)")
    return names


def _chiaro_radius(path) -> float | None:
    """The Chiaro header's "Tip radius (um)" in metres (afmformats does not read it)."""
    with open(path, "rb") as fh:
        head = fh.read(8192).decode("latin-1")
    m = re.search(r"Tip radius \(um\)\s+([0-9.eE+-]+)", head)
    return float(m.group(1)) * 1e-6 if m else None


def _vendor_e(path) -> dict:
    """The vendor's own E where the file gives it (Chiaro: E[eff] = E*, E[v=...])."""
    if not os.fspath(path).lower().endswith(".txt"):
        return {}
    with open(path, "rb") as fh:
        head = fh.read(8192).decode("latin-1")
    out = {}
    m = re.search(r"E\[eff\] \(Pa\)\s+([0-9.eE+-]+)", head)
    if m:
        out["vendor_E_star_Pa"] = m.group(1)
    m = re.search(r"Model:\s*(\S+)", head)
    if m:
        out["vendor_model"] = m.group(1)
    return out


def _block_mean(a: np.ndarray, n_out: int) -> np.ndarray:
    """Means over n_out consecutive blocks (the last takes the remainder)."""
    if a.size <= n_out:
        return a
    edges = np.linspace(0, a.size, n_out + 1).astype(int)
    return np.add.reduceat(a, edges[:-1]) / np.diff(edges)


def load_curves(path, name=None):
    """The afmformats curves of a file (a list; a force map gives one per point); ``name``: the
    file as messages name it (default ``path``)."""
    afmformats = _afmformats()
    try:
        return list(afmformats.load_data(os.fspath(path)))
    except (KeyboardInterrupt, SystemExit):
        raise
    except BaseException as exc:  # afmformats' MissingMetaDataError is a BaseException
        raise TraceError(f"{name or path}: afmformats cannot read it: {type(exc).__name__}: "
                         f"{exc}") from None


def curve_arrays(curve, name: str = "curve") -> dict:
    """SI arrays of one afmformats curve: time, height (the stage), force, segment names."""
    md = curve.metadata
    modality = md.get("imaging mode", "force-distance")
    names = SEGMENT_NAMES.get(modality)
    if names is None:
        raise TraceError(f"{name}: imaging mode {modality!r} is not supported (supported: "
                         f"{', '.join(SEGMENT_NAMES)})")
    cols = curve.columns
    chiaro = md.get("instrument") == "Chiaro"
    hcol = "height (piezo)" if chiaro or "height (measured)" not in cols else "height (measured)"
    if hcol not in cols:
        raise TraceError(f"{name}: no height column (has {', '.join(cols)})")
    force = np.asarray(curve["force"], dtype=np.float64)
    height = np.asarray(curve[hcol], dtype=np.float64)
    seg = np.asarray(curve["segment"], dtype=int)
    if "time" in cols:
        time = np.asarray(curve["time"], dtype=np.float64)
    else:
        rate = md.get("rate approach")
        if not rate:
            raise TraceError(f"{name}: the file has no time column and no sampling rate")
        time = np.arange(force.size) / float(rate)
    k = md.get("spring constant")
    if not (k and math.isfinite(float(k)) and float(k) > 0):
        raise TraceError(f"{name}: the file gives no cantilever spring constant")
    labels = np.array([names[i] if i < len(names) else f"segment{i}" for i in seg])
    return dict(time=time, height=height, force=force, segment=labels, stiffness=float(k),
                modality=modality, height_column=hcol)


def _contact_index(d: np.ndarray, f: np.ndarray) -> int:
    """First sample after which the force stays above CONTACT_FRACTION of its peak."""
    above = f > CONTACT_FRACTION * float(np.max(f))
    below = np.flatnonzero(~above[: int(np.argmax(f)) + 1])
    return int(below[-1]) + 1 if below.size else 0


def _check_options(drive, baseline, max_samples) -> None:
    if drive not in DRIVES:
        raise ValueError(f"drive must be one of {', '.join(DRIVES)}, got {drive!r}")
    if baseline not in BASELINES:
        raise ValueError(f"baseline must be one of {', '.join(BASELINES)}, got {baseline!r}")
    if not (isinstance(max_samples, int) and max_samples >= 20):
        raise ValueError(f"max_samples must be an integer >= 20, got {max_samples!r}")


def _tip_radius(curve, radius, name):
    """(R, where it came from): ``radius`` if given, else the file's (a Chiaro export)."""
    r = radius
    where = "--radius"
    if r is None:
        path = curve.metadata.get("path")
        r = _chiaro_radius(path) if path and str(path).lower().endswith(".txt") else None
        where = "the file's tip radius"
    if r is None:
        raise TraceError(f"{name}: the file gives no tip radius: pass --radius R (metres)")
    return r, where


def _segment_order(a, segments, drive, name) -> list:
    """The segments fitted, in the curve's order; refuses what the model cannot fit."""
    present = [s for s in dict.fromkeys(a["segment"])]
    missing = [s for s in segments if s not in present]
    if missing:
        raise TraceError(f"{name}: no {', '.join(missing)} segment in this {a['modality']} "
                         f"curve (it has {', '.join(present)})")
    if "retract" in segments:
        raise TraceError(f"{name}: the retract is not fitted: adhesion (the tip sticking to the "
                         "sample) and cavitation (the film tearing under tension) are not "
                         "modelled; fit the approach (and dwell)")
    order = [s for s in present if s in segments]
    if "approach" not in order:
        raise TraceError(f"{name}: the segments must include the approach (the ramp)")
    if drive == "force" and order != ["approach", "dwell"]:
        raise TraceError(f"{name}: load control (drive force) fits the approach and a "
                         "constant-force dwell: --segments approach,dwell")
    return order


def _smooth_stage(t, d, lab, order):
    """The stage travel as a least-squares cubic spline per segment (see the module docstring),
    and the rms of its deviation from the measured travel."""
    from scipy.interpolate import make_lsq_spline

    out = d.copy()
    for s in order:
        idx = np.flatnonzero(lab == s)
        most = idx.size // STAGE_MIN_ROWS
        if most < 1:
            continue
        x, y = t[idx], d[idx]
        d2 = np.diff(y, 2)
        sigma = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
        n_int, fit = min(4, most), y
        while True:
            inner = np.linspace(x[0], x[-1], n_int + 1)[1:-1]
            try:
                fit = make_lsq_spline(x, y, np.r_[[x[0]] * 4, inner, [x[-1]] * 4], k=3)(x)
            except (ValueError, np.linalg.LinAlgError):
                break  # a knot interval without rows (gaps in time): keep the coarser fit
            rms = float(np.sqrt(np.mean((fit - y) ** 2)))
            if rms <= STAGE_NOISE_FACTOR * sigma or n_int == most:
                break
            n_int = min(2 * n_int, most)
        out[idx] = fit
    return out, float(np.sqrt(np.mean((out - d) ** 2)))


def _decimate(t, d, f, lab, order, max_samples):
    """Block means per segment, the segments' shares of ``max_samples`` in proportion to
    their counts; the segment name of each mean comes along."""
    parts = []
    for s in order:
        idx = np.flatnonzero(lab == s)
        n_out = max(10, int(round(max_samples * idx.size / lab.size)))
        means = [_block_mean(x[idx], n_out) for x in (t, d, f)]
        parts.append([*means, np.full(means[0].size, s)])
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(4))


def curve_to_trace(curve, *, radius=None, poisson=None, segments=("approach",),
                   baseline: str = "offset", max_samples: int = MAX_SAMPLES, name: str = "curve",
                   extra_metadata=None, drive: str = "spring", indenter: str = "paraboloid"):
    """One afmformats curve as a :class:`fitting.Trace` (see the module docstring): for the
    spring drive (default), or for load control (``drive="force"``, a constant-force dwell as
    creep: the input is the force, the response the tip's approach). ``indenter``: the
    travel limit the approach is cut to and checked against, the paraboloid's (default) or
    the sphere's (``--indenter sphere``: to its full depth, up to 1 R)."""
    _check_options(drive, baseline, max_samples)
    a = curve_arrays(curve, name)
    r, where = _tip_radius(curve, radius, name)
    order = _segment_order(a, segments, drive, name)
    keep = np.isin(a["segment"], order)
    t, h, f, lab = a["time"][keep], a["height"][keep], a["force"][keep], a["segment"][keep]
    d = h[0] - h
    appr = np.flatnonzero(lab == "approach")
    # A file that records the way back in its approach segment (Igor): the approach ends at
    # the turning point.
    turn = appr[0] + int(np.argmax(d[appr]))
    if turn < appr[-1]:
        keep_rows = (np.arange(t.size) <= turn) | (lab != "approach")
        t, d, f, lab = t[keep_rows], d[keep_rows], f[keep_rows], lab[keep_rows]
        appr = np.flatnonzero(lab == "approach")
    if d[appr[-1]] - d[appr[0]] <= 0:
        raise TraceError(f"{name}: the height does not fall over the approach (column "
                         f"{a['height_column']}): not an approach toward the sample")
    base = np.full_like(f, float(np.median(f[appr][: max(3, appr.size // 10)])))
    ic = appr[0] + _contact_index(d[appr], f[appr] - base[appr])
    if baseline == "tilt":
        # a line in the travel through the samples well before contact, then contact again
        pre = appr[d[appr] < d[ic] - MARGIN * (d[appr[-1]] - d[ic])]
        if pre.size < 10:
            raise TraceError(f"{name}: baseline 'tilt' needs the approach before contact "
                             f"(>= 10 samples well before it), has {pre.size}")
        slope, icpt = np.polyfit(d[pre], f[pre], 1)
        base = slope * d + icpt
        ic = appr[0] + _contact_index(d[appr], f[appr] - base[appr])
    d_contact = float(d[ic])
    d_in = float(d[appr[-1]]) - d_contact
    limit = _checks.max_travel_over_radius(indenter)
    cap = CAP * limit * r / (1 + MARGIN)
    cut = None
    if d_in > cap and order == ["approach"]:
        # Only the start of a deep approach is within the thin-film model's travel ≪ R.
        d_in = cap
        last = appr[0] + int(np.searchsorted(d[appr], d_contact + d_in, side="right"))
        cut = float(d[last - 1])
        t, d, f, lab, base = t[:last], d[:last], f[:last], lab[:last], base[:last]
        appr = appr[appr < last]
    start = int(np.searchsorted(d[appr], d_contact - MARGIN * d_in))
    start = appr[0] + min(start, ic - appr[0])
    if baseline == "offset" and start - appr[0] >= 3:
        base = np.full_like(f, float(np.median(f[appr[0]:start])))
    f = f - base
    if drive == "force":
        # Load control starts at rest under no load: from the last sample before the contact
        # estimate within the baseline's noise (3σ, at least 1 % of the peak); the response is
        # the tip's own travel.
        pre = f[appr[0]:start]
        noise = 1.4826 * np.median(np.abs(np.diff(pre))) / math.sqrt(2) if pre.size > 3 else 0.0
        level = max(3 * noise, 0.01 * float(np.max(f[appr])))
        low = np.flatnonzero(f[appr[0]:ic + 1] <= level)
        start = appr[0] + int(low[-1]) if low.size else ic
        d = d - f / a["stiffness"]
    sel = np.arange(start, t.size)
    d_first = float(d[start])
    contact = d_contact - d_first
    t, d, f, lab = t[sel], d[sel] - d[start], f[sel], lab[sel]
    smoothing = None
    if drive == "spring":
        d, smoothing = _smooth_stage(t, d, lab, order)
    t, d, f, lab = _decimate(t, d, f, lab, order, max_samples)
    d = d - d[0]  # the first block's mean: travel since the first row kept
    reach = float(np.max(np.abs(d)))
    what = ("the stage travel kept ({:.3g} m: the indentation, the cantilever's bending F/k "
            "and the margin before contact)" if drive == "spring" else
            "the tip's travel from contact ({:.3g} m)").format(reach)
    if reach > limit * r:
        fix = ("--indenter sphere models it to 1 R (the sphere's true profile)"
               if indenter == "paraboloid" and reach <= MAX_SPHERE_TRAVEL_OVER_RADIUS * r else
               "a deeper indentation is beyond every indenter the model has")
        raise TraceError(
            f"{name}: {what} is {reach / r:.3g} R with R = {r:.3g} m "
            f"({where}); the {indenter} indenter models travel <= {limit:g} R: {fix}")
    meta = {
        "drive": drive, "stiffness_N_m": repr(a["stiffness"]), "instrument_file": str(name),
        "modality": a["modality"], "segments": ",".join(order), "baseline": baseline,
        "stage_column": a["height_column"], "contact_estimate_m": repr(contact),
    }
    if smoothing is not None:
        meta["stage_smoothing_rms_m"] = repr(smoothing)
    if cut is not None:
        meta["approach_cut_m"] = repr(cut - float(d_first))
    if "dwell" in order:  # where the dwell begins, for the segments of the adequacy judgement
        meta["dwell_start_s"] = repr(float(t[np.argmax(lab == "dwell")] - t[0]))
    meta["start_time_s"] = repr(float(t[0]))  # the file's time of the trace's t = 0
    if poisson is not None:
        meta["poisson_ratio"] = repr(float(poisson))
    meta.update(extra_metadata or {})
    return make_trace(t - t[0], d, f, r, meta, name)


def read_afm(path, *, radius=None, poisson=None, segments=("approach",), baseline="offset",
             max_samples: int = MAX_SAMPLES, curves=None, drive: str = "spring",
             indenter: str = "paraboloid"):
    """The traces of an AFM or indenter vendor file, read through afmformats (a list: a force
    map gives one per curve), SI, ready for :func:`fit_traces` (see the module docstring).

    Args:
        path: a JPK ``.jpk-force``/``.jpk-force-map``/``.jpk-qi-*``, Igor ``.ibw``, afmformats
            ``.h5``/``.tab`` or Optics11 Chiaro ``.txt`` file, or a zip archive holding one
            (read as the file inside, named ``path/file`` in the traces).
        radius: tip radius R [m]; None takes the file's (Chiaro), else a TraceError.
        poisson: the sample's Poisson ratio (kept in the metadata: E = E*(1 - ν²) in reports).
        segments: "pause", "approach", "dwell", "retract"; the approach is required.
        baseline: "offset" (median force before contact) or "tilt" (a line in the travel).
        max_samples: samples per curve after block means (≥ 20).
        curves: indices of the curves to keep (default all).
        drive: "spring" (the cantilever; default) or "force" (load control of a
            constant-force dwell: segments approach and dwell).
        indenter: "paraboloid" (default: the approach cut to, and the travel refused beyond,
            0.2 R) or "sphere" (the full depth, to 1 R; fit with the same ``indenter``).

    Returns:
        list[Trace]: one per curve kept (a force map gives one per curve).

    Raises:
        TraceError: afmformats not installed (``pip install lubjax[afm]``), a file it
            cannot read, a zip archive that does not hold exactly one file, an unsupported
            imaging mode, no radius, a missing segment, a curve
            index the file lacks, or a curve the checks of :func:`make_trace` refuse.
    """
    path = os.fspath(path)
    # JPK files are zip archives themselves: only another file is looked into
    files = (contextlib.nullcontext((path, path)) if path.lower().endswith(AFM_EXTENSIONS)
             else unzipped(path))
    with files as (file, label):
        all_curves = load_curves(file, label)
        pick = range(len(all_curves)) if curves is None else curves
        out = []
        extra = _vendor_e(file)
        for i in pick:
            if not 0 <= i < len(all_curves):
                raise TraceError(f"{label}: curve {i} does not exist (the file has "
                                 f"{len(all_curves)} curve(s), 0 to {len(all_curves) - 1})")
            name = label if len(all_curves) == 1 else f"{label}#{i}"
            out.append(curve_to_trace(all_curves[i], radius=radius, poisson=poisson,
                                      segments=segments, baseline=baseline,
                                      max_samples=max_samples, name=name, extra_metadata=extra,
                                      drive=drive, indenter=indenter))
    return out
