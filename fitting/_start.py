"""Starting values of a fit, from the physics of each trace, and their checks.

Relaxation test (position control): z0 and η from Reynolds' squeeze film on the loading, E*
from Hertz at the end of the hold or from the relaxation time; creep (load control): z0 and η
from the Reynolds drainage, E* from Hertz's indentation (:func:`initial_guess`).
:func:`prepare_starts` gives a fit its scales and starts, checked, with the values held fixed
put in.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

import lubjax

from . import _scales
from ._model import ModelSpec
from ._scales import Scales
from ._trace import Trace

#: t½ ≈ RELAX_CONSTANT · t_c/β (see :func:`initial_guess`).
RELAX_CONSTANT = 8.0


class Start(NamedTuple):
    """Starting values of a fit and how they were found (``start.E_star``, ``start.z0``, ...
    read ``values``).

    Attributes:
        values: parameter name (the spec's) → starting value [SI].
        notes: how each was found, in words.
    """

    values: dict
    notes: tuple

    def __getattr__(self, name):  # start.E_star, start.z0, ...
        try:
            return self.values[name]
        except KeyError:
            raise AttributeError(name) from None


def _travel_guess(t, d, f, scales: Scales, notes: list) -> dict:
    r"""Relaxation test (position control): Reynolds on the loading, then Hertz or t_R.

    1. Offset b0: median force over the quiescent samples (before t_on).
    2. Early loading, where the film is thick and the sphere is effectively rigid, follows
       Reynolds' squeeze film F = 6πηR² v/(z0 - d) (eq 12b). Writing it as F z0 - c v = F d
       with c = 6πηR² makes it linear in (z0, c): least squares over the loading samples with
       F between max(5 % of the peak, 3σ) and 40 % of the peak gives z0 and η.
    3. E* from the hold: if the film has drained to a Hertz contact (z0 < d_c) the end-of-hold
       force is F∞ = (4/3)E*√R(d_c - z0)^{3/2} (eq 16). This is only used when d_c - z0 is well
       determined (> 0.2 d_c); otherwise E* comes from the relaxation time t_R = t_c/β: the
       time t½ after the force peak for it to fall halfway to its final value is
       t½ ≈ C·t_c/β, hence β and then E* = 6πηv0R^{3/2}β/d_c^{5/2}. C = ``RELAX_CONSTANT`` = 8
       is the geometric mean over the noiseless paper traces; it drifts from 4 to 14 as
       z̄0 goes from 1.1 to 0.9 (the late hold is limited by drainage of the trapped film, not
       by t_R alone), so this start is good to a factor ~2 — enough for Levenberg–Marquardt.
    """
    R, dc, v0, tc = scales.radius, scales.indent, scales.speed, scales.time_scale
    quiet = t < scales.t_on
    offset = float(np.median(f[quiet])) if np.count_nonzero(quiet) >= 3 else 0.0
    fc = f - offset
    sigma = _scales.noise_level(f)
    smooth = np.convolve(fc, np.ones(5) / 5, mode="same")
    k_peak = int(np.argmax(smooth))
    f_peak = float(smooth[k_peak])
    v = np.gradient(d, t)
    idx = np.arange(t.size)
    sel = (
        (t > scales.t_on) & (idx < k_peak) & (fc > max(0.05 * f_peak, 3 * sigma))
        & (fc < 0.4 * f_peak) & (v > 0.5 * v0)
    )
    z0 = eta = None
    if np.count_nonzero(sel) >= 3:
        A = np.stack([fc[sel], -v[sel]], axis=1)
        (z0_ls, c), *_ = np.linalg.lstsq(A, fc[sel] * d[sel], rcond=None)
        if c > 0 and z0_ls > np.max(d[sel]):
            z0, eta = float(z0_ls), float(c / (6 * math.pi * R**2))
            notes.append(f"z0, eta from Reynolds' squeeze film on {np.count_nonzero(sel)} samples")
    loading = (t > scales.t_on) & (idx <= k_peak) & (fc > max(0.05 * f_peak, 3 * sigma))
    dry = _hertz_loading(d, fc, v, loading, sel, R, z0, eta)
    if dry is not None:
        z0, E_dry = dry
        # no squeeze film above the noise: η at the bound that sets, 3σ at a gap of 0.05 d_c
        eta = 3 * sigma * 0.05 * dc / (6 * math.pi * R**2 * v0)
        notes.append("z0, E* from Hertz on the loading (a near-dry contact: it fits the loading "
                     "better than Reynolds' squeeze film); eta at the bound the noise sets")
        return dict(E_star=E_dry, viscosity=float(eta), z0=float(z0), offset=offset)
    if z0 is None:
        z0 = dc
        eta = f_peak * 0.3 * dc / (6 * math.pi * R**2 * v0)
        notes.append("Reynolds fit failed: z0 = d_c, eta from the peak force with a 0.3 d_c gap")
    tail = max(3, t.size // 20)
    f_end = float(np.median(fc[-tail:]))
    E_star = None
    if dc - z0 > 0.2 * dc and f_end > 10 * sigma / math.sqrt(tail):
        E_star = 3 * f_end / (4 * math.sqrt(R) * (dc - z0) ** 1.5)
        notes.append("E* from the Hertz plateau (eq 16)")
    if E_star is None:
        half = f_end + 0.5 * (f_peak - f_end)
        after = np.flatnonzero((idx > k_peak) & (smooth < half))
        t_half = float(t[after[0]] - t[k_peak]) if after.size else tc
        beta = RELAX_CONSTANT * tc / max(t_half, 1e-3 * tc)
        E_star = lubjax.modulus_for_beta(beta, R, dc, speed=v0, viscosity=eta)
        notes.append(f"E* from the relaxation time t_R = t_c/beta (t_half = {t_half:.3g} s)")
    return dict(E_star=float(E_star), viscosity=float(eta), z0=float(z0), offset=offset)


def _hertz_loading(d, f, v, loading, window, R, z0_squeeze, eta):
    """(z0, E*) of Hertz's F = (4/3)E*√R (d - z0)^{3/2} (eq 14) fitted to the ``loading``
    samples, where its z0 lies between the start and the deepest travel and it fits the
    squeeze fit's ``window`` at least 3× better (rms) than the squeeze film F = 6πηR² v/(z0 - d)
    with ``z0_squeeze``, ``eta`` (None: the squeeze fit failed); else None. Linear in (k, k z0)
    for F^{2/3} = k (d - z0), k = ((4/3)E*√R)^{2/3}: the classical contact-point fit. A near-dry
    contact (β ≳ 10⁵) pushes the squeeze film's force below the noise before contact, so the
    loading is Hertz's and the squeeze fit's z0 is off."""
    if np.count_nonzero(loading) < 5:
        return None
    A = np.stack([d[loading], -np.ones(np.count_nonzero(loading))], axis=1)
    (k, kz0), *_ = np.linalg.lstsq(A, np.cbrt(f[loading]) ** 2, rcond=None)
    if k <= 0 or not 0.0 < kz0 / k < np.max(d[loading]):
        return None
    z0 = kz0 / k
    if z0_squeeze is not None and np.count_nonzero(window) >= 3:
        dw, fw = d[window], f[window]
        hertz = k**1.5 * np.clip(dw - z0, 0.0, None) ** 1.5
        squeeze = 6 * math.pi * eta * R**2 * v[window] / (z0_squeeze - dw)
        if np.sqrt(np.mean((hertz - fw) ** 2)) > np.sqrt(np.mean((squeeze - fw) ** 2)) / 3.0:
            return None
    return float(z0), float(0.75 * k**1.5 / math.sqrt(R))


def _creep_guess(t, load, d, scales: Scales, notes: list) -> dict:
    r"""Creep (load control): Reynolds drainage, then Hertz.

    1. Offset: median displacement over the quiescent samples.
    2. While the film is thick the sphere is effectively rigid and Reynolds' F = 6πηR²(-ż)/z
       integrates to z = z0 exp(-I(t)/(6πηR²)), I = ∫F dt: the approach d = z0(1 - e^{-aI}).
       For each z0 on a grid, a (hence η) by least squares of ln(z0/(z0 - d)) = aI over the
       samples with 5 % < d < 50 % of the final approach; the z0 with the smallest misfit of d.
    3. E* from Hertz: the final approach d_end = z0 + δ, δ ≈ (3F/(4E*√R))^{2/3} (an undrained
       film makes δ smaller, so this E* is high, typically by < 2×).
    """
    R = scales.radius
    quiet = t < scales.t_on
    offset = float(np.median(d[quiet])) if np.count_nonzero(quiet) >= 3 else 0.0
    dc = d - offset
    d_end = scales.indent
    impulse = np.concatenate([[0.0], np.cumsum(0.5 * (load[1:] + load[:-1]) * np.diff(t))])
    sel = (dc > 0.05 * d_end) & (dc < 0.5 * d_end) & (t > scales.t_on)
    best = None
    if np.count_nonzero(sel) >= 3:
        for z0 in np.geomspace(0.55, 1.0, 40) * d_end:
            if z0 <= np.max(dc[sel]):
                continue
            y = np.log(z0 / (z0 - dc[sel]))
            a = float(y @ impulse[sel] / (impulse[sel] @ impulse[sel]))
            if a <= 0:
                continue
            err = float(np.sum((dc[sel] - z0 * (1 - np.exp(-a * impulse[sel]))) ** 2))
            if best is None or err < best[0]:
                best = (err, z0, a)
    if best is not None:
        _, z0, a = best
        eta = 1.0 / (6 * math.pi * R**2 * a)
        notes.append(f"z0, eta from Reynolds drainage under the load on {np.count_nonzero(sel)}"
                     " samples")
    else:
        z0, eta = 0.8 * d_end, 1.0
        notes.append("Reynolds drainage fit failed: z0 = 0.8 of the final approach, eta = 1 Pa s")
    delta = max(d_end - z0, 0.1 * d_end)
    E_star = 3 * scales.input_end / (4 * math.sqrt(R) * delta**1.5)
    notes.append("E* from Hertz with the final approach less z0")
    return dict(E_star=float(E_star), viscosity=float(eta), z0=float(z0), offset=offset)


def initial_guess(trace: Trace, scales: Scales, spec: ModelSpec | None = None) -> Start:
    """Starting values from the physics, not from the user.

    Relaxation test: z0 and η from Reynolds' squeeze film on the loading, F = 6πηR² v/(z0 - d)
    (eq 12b), E* from Hertz at the end of the hold (eq 16) or from the relaxation time
    t_R = t_c/β; creep: z0 and η from the Reynolds drainage, E* from Hertz's indentation. For a
    sphere on a spring the sphere's own travel, stage travel less F/k, goes into the
    relaxation-test rules. A viscoelastic solid starts at E0/E∞ = 1.2 and τ = t_c
    (:func:`compare_models` starts it from the elastic fit instead, at three τ).

    Args:
        trace: the :class:`Trace`.
        scales: its :class:`Scales` (:func:`scales_from_trace`).
        spec: the :class:`ModelSpec`; None (default): the drive the trace's metadata names.

    Returns:
        Start: a value per parameter of ``spec.names`` [SI] and notes on how
        each was found.
    """
    spec = ModelSpec(drive=_scales.drive_of(trace)) if spec is None else spec
    notes: list[str] = []
    if spec.drive == "force":
        values = _creep_guess(trace.time, trace.force, trace.displacement, scales, notes)
    else:
        d = trace.displacement
        if spec.drive == "spring":
            d = d - trace.force / trace.meta_float("stiffness_N_m")
            notes.append("sphere travel = stage travel - F/k")
        values = _travel_guess(trace.time, d, trace.force, scales, notes)
    if spec.viscoelastic:
        values.update(stiffening=1.2, relaxation_time=scales.time_scale)
        notes.append("E0/Einf = 1.2, tau = t_c")
    if not spec.fit_offset:
        values["offset"] = 0.0
    return Start({n: values[n] for n in spec.names}, tuple(notes))


#: Where each parameter must lie: θ is its logarithm (E0/E∞ - 1 for the stiffening).
_LOWER = {"E_star": 0.0, "viscosity": 0.0, "z0": 0.0, "stiffening": 1.0,
          "relaxation_time": 0.0}


def check_value(name: str, value, what: str) -> float:
    """``value`` as a float inside its parameter's range (ValueError naming ``what`` if not)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    lo = _LOWER.get(name, -math.inf)
    if not (math.isfinite(v) and v > lo):
        rule = f"a finite number > {lo:g}" if math.isfinite(lo) else "a finite number"
        raise ValueError(f"{what}: {name} must be {rule} (SI units), got {value!r}")
    return v


def check_fixed(fixed, spec: ModelSpec, shared) -> dict:
    """``fixed`` as {name: SI value}, checked against the spec and ``shared``."""
    out = {}
    for name, value in dict(fixed or {}).items():
        if name not in spec.names:
            raise ValueError(f"fixed: unknown parameter {name!r} (allowed: "
                             f"{', '.join(spec.names)})")
        if name in shared:
            raise ValueError(f"fixed: {name} is also shared; a parameter is fitted jointly or "
                             "held fixed, not both")
        out[name] = check_value(name, value, "fixed")
    if all(n in out for n, a in zip(spec.names, spec.active, strict=True) if a):
        raise ValueError("fixed: every parameter is held fixed; nothing is left to fit")
    return out


def scales_and_starts(traces, spec: ModelSpec, scales=None, starts=None):
    """Each trace's :class:`Scales` and :class:`Start`, computed where not given.

    Args:
        traces: the :class:`Trace` s.
        spec: the :class:`ModelSpec` (its drive reads the scales, its names the starts).
        scales: the traces' scales, or None: ``scales_from_trace`` for the spec's drive.
        starts: their starting values, or None: :func:`initial_guess`.

    Returns:
        tuple: (scales, starts), two lists, one entry per trace.

    Raises:
        ValueError: a trace whose scales cannot be read (``scales_from_trace``).
    """
    if scales is None:
        scales = [_scales.scales_from_trace(tr, spec.drive) for tr in traces]
    if starts is None:
        starts = [initial_guess(tr, s, spec) for tr, s in zip(traces, scales, strict=True)]
    return list(scales), list(starts)


def prepare_starts(traces, spec, shared, fixed, starts, scales=None):
    """(fixed, scales, starts) of a fit, checked: the shared and fixed names, each trace's scales
    and starting values (:func:`scales_and_starts` where not given, fixed values put in), every
    one positive where θ takes its logarithm."""
    unknown = [n for n in shared if n not in spec.names or n == "offset"]
    if unknown:
        allowed = ", ".join(n for n in spec.names if n != "offset")
        raise ValueError(f"shared: unknown parameter(s) {', '.join(unknown)} (allowed: {allowed})")
    fixed = check_fixed(fixed, spec, shared)
    scales, starts = scales_and_starts(traces, spec, scales, starts)
    if fixed:
        note = "held fixed: " + ", ".join(f"{n} = {v:g}" for n, v in fixed.items())
        starts = [Start({**st.values, **fixed}, (*st.notes, note)) for st in starts]
    for tr, st in zip(traces, starts, strict=True):  # θ holds logarithms: no value <= 0 gets in
        for n in spec.names:
            if n != "stiffening":  # θ clamps E0/E∞ - 1 at 1e-6 (an elastic start is fine)
                check_value(n, st.values.get(n), f"{tr.name or 'trace'}: starting value")
    return fixed, scales, starts

