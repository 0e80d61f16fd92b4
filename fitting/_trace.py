"""A force trace in SI units, and the checks every trace passes however it was read.

A :class:`Trace` holds time [s], the indenter's travel [m], the force [N], the sphere's radius
[m] and the file's ``# key: value`` metadata. Every malformed trace raises :class:`TraceError`
(a ``ValueError``) naming the file, the line (1-based) and, for cell errors, the column. Scales
the thin-film model cannot describe (travel beyond ``MAX_SPHERE_TRAVEL_OVER_RADIUS`` R, |force|
above ``MAX_FORCE_N``, R outside ``RADIUS_RANGE_M``) are refused the same way, with the likely
unit mistake (:func:`check_scales`); a fit with the default paraboloid refuses travel beyond
``MAX_TRAVEL_OVER_RADIUS`` R (naming ``--indenter sphere``), and a force negative in
compression is refused (:func:`check_force_sign`, once the drive is known). The readers
(:mod:`fitting._csv`, :mod:`fitting._afm`) build their traces through :func:`make_trace`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lubjax._fitting_api import checks as _checks

MAX_TRAVEL_OVER_RADIUS = _checks.MAX_TRAVEL_OVER_RADIUS
MAX_SPHERE_TRAVEL_OVER_RADIUS = _checks.MAX_SPHERE_TRAVEL_OVER_RADIUS

COLUMNS = ("time_s", "displacement_m", "force_N")
MIN_ROWS = 10
#: Sphere radii outside this range [m] are refused (a radius in mm reads as metres: R > 1 m).
RADIUS_RANGE_M = (1e-7, 1.0)
#: |force| above this [N] is refused: far beyond a soft lubricated contact (a wrong unit).
MAX_FORCE_N = 1e3


class TraceError(ValueError):
    """A trace that cannot be used; the message names the file, line and column."""


class Trace(NamedTuple):
    """One measured (or synthetic) relaxation trace in SI units.

    Attributes:
        time: sample times t_k [s], strictly increasing.
        displacement: indenter travel d(t_k) toward the substrate [m].
        force: normal force F(t_k) [N].
        radius: sphere (or reduced) radius R [m].
        metadata: the ``# key: value`` header lines (values as strings), ``radius_m`` included.
        name: where the trace came from (file path or a label).
    """

    time: np.ndarray
    displacement: np.ndarray
    force: np.ndarray
    radius: float
    metadata: dict
    name: str = ""

    def meta_float(self, key: str, default=None):
        """A metadata value as a float.

        Args:
            key: the metadata key (``radius_m``, ``speed_m_s``, ...).
            default: what to return when the key is absent or its value is not a number
                (default None).

        Returns:
            The value as a float, or ``default``.
        """
        try:
            return float(self.metadata[key])
        except (KeyError, TypeError, ValueError):
            return default


def positive_radius(value, where: str) -> float:
    try:
        r = float(value)
    except (TypeError, ValueError):
        raise TraceError(
            f"{where}: radius_m must be a positive number in metres, got {value!r}"
        ) from None
    if not (math.isfinite(r) and r > 0):
        raise TraceError(f"{where}: radius_m must be finite and > 0 (metres), got {value!r}")
    lo, hi = RADIUS_RANGE_M
    if not lo <= r <= hi:
        hint = "millimetres" if r > hi else "another unit"
        raise TraceError(
            f"{where}: radius_m = {r:g} m is outside [{lo:g}, {hi:g}] m, the sphere radii the "
            f"model is meant for: is it in {hint} instead of metres?"
        )
    return r


def poisson_ratio(value, where: str) -> float:
    """A header's Poisson ratio (a string) in the solver's range (lubjax.POISSON_RANGE)."""
    try:
        return _checks.check_poisson("poisson_ratio", float(value))
    except (TypeError, ValueError):
        lo, hi = _checks.POISSON_RANGE
        raise TraceError(
            f"{where}: poisson_ratio must be a number in ({lo:g}, {hi:g}], got {value!r}"
        ) from None


#: The drives a fit knows: the values of the ``# drive:`` header key and of ``--drive``.
DRIVES = ("travel", "spring", "force")


def check_model_keys(metadata: dict, where) -> None:
    """``drive`` one of DRIVES and ``stiffness_N_m`` a positive number; ``where(key)``
    names the place (file and line)."""
    if "drive" in metadata and metadata["drive"] not in DRIVES:
        raise TraceError(
            f"{where('drive')}: drive must be one of {', '.join(DRIVES)} (force: load "
            f"control, the displacement is the response), got {metadata['drive']!r}"
        )
    if "stiffness_N_m" in metadata:
        try:
            k = float(metadata["stiffness_N_m"])
        except (TypeError, ValueError):
            k = math.nan
        if not (math.isfinite(k) and k > 0):
            raise TraceError(
                f"{where('stiffness_N_m')}: stiffness_N_m (the instrument's load-cell "
                f"stiffness) must be a finite number > 0 in N/m, got {metadata['stiffness_N_m']!r}"
            )


def check_scales(trace: Trace, indenter: str = "paraboloid") -> None:
    """TraceError unless the trace's scales fit the thin-film model (see module docstring).

    The model needs travel d ≪ R (and gap z0 ≪ R): a trace whose |displacement| exceeds
    ``MAX_TRAVEL_OVER_RADIUS`` R is refused for the paraboloid (the message names the fix,
    ``--indenter sphere``), more than ``MAX_SPHERE_TRAVEL_OVER_RADIUS`` R for the sphere, as is
    |force| > ``MAX_FORCE_N``. Both catch a column in the wrong unit (mm or μm for m, mN for N)
    that would otherwise fit to nonsense. The readers check for the sphere, the widest limit;
    a fit checks again for its own indenter (``fitting._model.trace_data``).
    """
    name = trace.name or "trace"
    r = float(trace.radius)
    travel = float(np.max(np.abs(trace.displacement))) if trace.displacement.size else 0.0
    limit = _checks.max_travel_over_radius(indenter)
    if travel > MAX_SPHERE_TRAVEL_OVER_RADIUS * r:
        raise TraceError(
            f"{name}: column displacement_m: the travel reaches {travel:.4g} m, "
            f"{travel / r:.3g} times the radius R = {r:g} m; the thin-film model needs travel "
            f"≪ R and refuses more than {limit:g} R. Is displacement_m in "
            "millimetres or micrometres instead of metres? Declare it: --units displacement=um "
            "(or a '# units: displacement=um' line)"
        )
    problem = _checks.travel_over_radius_problem(f"{name}: the travel", travel, r, indenter,
                                                 "radius_m")
    if problem:
        raise TraceError(problem)
    peak = float(np.max(np.abs(trace.force))) if trace.force.size else 0.0
    if peak > MAX_FORCE_N:
        raise TraceError(
            f"{name}: column force_N: |force| reaches {peak:.4g} N, above {MAX_FORCE_N:g} N, "
            "far beyond a soft lubricated contact. Is force_N in another unit (mN, μN)? "
            "Declare it: --units force=mN (or a '# units: force=mN' line)"
        )


#: A force falling as the travel rises this strongly over the loading (Pearson correlation) is
#: a force recorded negative in compression: a film or a solid only pushes back.
NEGATIVE_CORRELATION = -0.5


def check_force_sign(trace: Trace, drive: str = "travel") -> None:
    """TraceError if the force is negative in compression (an instrument's sign convention).

    Position control (``travel``, ``spring``): refused when, over the loading (travel from 5 %
    to 95 % of its final value, up to where it first reaches 95 %), the force falls as the
    travel rises (correlation below ``NEGATIVE_CORRELATION``) and the force's largest excursion
    from its value at rest is negative. Load control (``force``): refused when the final load is
    negative. Either is caught here, before any fitting; the fix is ``--force-sign -1``."""
    name = trace.name or "trace"
    f, d = trace.force, trace.displacement
    n = f.size
    tail = max(3, n // 20)
    fix = ("flip it with --force-sign -1 (force_sign=-1 in read_trace), or record the force "
           "positive when the sphere is pushed back")
    if drive == "force":
        load = float(np.median(f[-tail:]))
        if load < 0 and load < -0.5 * float(np.max(np.abs(f))):
            raise TraceError(
                f"{name}: column force_N: the load the instrument holds is {load:.4g} N, "
                f"negative: the force is negative in compression; {fix}"
            )
        return
    d_end = float(np.median(d[-tail:]))
    if not d_end > 0:
        return  # no travel toward the substrate: scales_from_trace names that
    reached = np.flatnonzero(d >= 0.95 * d_end)
    stop = int(reached[0]) + 1 if reached.size else n
    load = np.flatnonzero(d[:stop] > 0.05 * d_end)
    rest = f[: max(int(load[0]) if load.size else 0, 1)]
    excursion = f - float(np.median(rest))
    if load.size < 5 or np.ptp(f[load]) == 0 or np.ptp(d[load]) == 0:
        corr = -1.0 if excursion.min() < -excursion.max() else 1.0
    else:
        corr = float(np.corrcoef(d[load], f[load])[0, 1])
    if corr < NEGATIVE_CORRELATION and excursion.min() < -excursion.max():
        raise TraceError(
            f"{name}: column force_N: the force falls as the travel rises (correlation "
            f"{corr:.2f} over the loading) and swings to {float(excursion.min()):.4g} N from rest: "
            f"the force is negative in compression; {fix}"
        )


def make_trace(time, displacement, force, radius, metadata=None, name: str = "") -> Trace:
    """A validated :class:`Trace` from arrays (the file reader's checks).

    Args:
        time: sample times t_k [s], 1-D, finite, strictly increasing, at least ``MIN_ROWS``.
        displacement: the indenter's travel d(t_k) toward the substrate [m], as many.
        force: the normal force F(t_k) [N], positive in compression, as many.
        radius: R, the sphere (or reduced) radius [m], > 0.
        metadata: ``# key: value`` metadata (values as strings or numbers); None: none.
        name: where the trace came from (a label; default "").

    Returns:
        Trace: the trace (``radius_m`` added to its metadata).

    Raises:
        TraceError: a column not numeric, not 1-D, not finite, of another length or with a
            time that does not increase (the message names row and column), too few rows, a
            radius not > 0, a Poisson's ratio out of range, or implausible scales.
    """
    label = name or "trace"
    arrays = []
    for col, values in zip(COLUMNS, (time, displacement, force), strict=True):
        try:
            a = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise TraceError(f"{label}: column {col!r} is not numeric ({exc})") from None
        if a.ndim != 1:
            raise TraceError(f"{label}: column {col!r} must be 1-D, got shape {a.shape}")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise TraceError(
                f"{label}: row {bad[0]}, column {col!r}: value {a[bad[0]]} is not finite"
            )
        arrays.append(a)
    t, d, f = arrays
    if not (t.size == d.size == f.size):
        raise TraceError(f"{label}: columns have different lengths {t.size}, {d.size}, {f.size}")
    if t.size < MIN_ROWS:
        raise TraceError(f"{label}: need at least {MIN_ROWS} data rows, got {t.size}")
    step = np.flatnonzero(np.diff(t) <= 0)
    if step.size:
        k = step[0] + 1
        raise TraceError(
            f"{label}: row {k}, column 'time_s': time {float(t[k])!r} does not increase "
            f"(previous {float(t[k - 1])!r})"
        )
    meta = dict(metadata or {})
    r = positive_radius(radius, label)
    if "poisson_ratio" in meta:
        poisson_ratio(meta["poisson_ratio"], label)
    check_model_keys(meta, lambda key: label)
    meta.setdefault("radius_m", repr(r))
    trace = Trace(t, d, f, r, meta, name)
    check_scales(trace, "sphere")
    return trace
