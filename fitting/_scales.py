r"""What a fit reads off a trace before any model run: its drive, scales, input history, noise.

Scales taken from the data (not from the user), for the input channel u(t) (travel or load):

* u_end = final input (median of the last 5 %), onset t_on = the last sample at rest
  (``lubjax._indenter.motion_start``: exactly still, else below 10⁻³ u_end), rate = median
  du/dt over the samples with 0.2 u_end < u < 0.8 u_end (the ramp),
  t_c = u_end/rate, end of the ramp = first sample after the last one off u_end by 10⁻³ u_end;
* d_c = final travel (travel, spring) or final approach (force control: the median of the last
  5 % of the displacement); t̄ = (t - t_on)/t_c.

The input u(t)/u_end from the last sample at rest on is the solver's history (:func:`history`);
the noise level σ of a channel comes from its successive differences (:func:`noise_level`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

import lubjax
from lubjax._fitting_api import motion_start

from ._trace import DRIVES, Trace, check_force_sign


class Scales(NamedTuple):
    """Nominal scales read off a trace (SI; :func:`scales_from_trace`).

    Attributes:
        indent: d_c [m], the final travel (or, under load control, the final approach).
        speed: d_c/t_c [m/s] (the ramp speed for a prescribed travel).
        radius: R, the sphere's radius [m].
        t_on: the motion's start [s]; t̄ = (t - t_on)/t_c.
        time_scale: t_c [s], the final input over the ramp's rate.
        t_end_motion: the end of the input's ramp, in t̄ (units of t_c).
        response_unit: y_u, the peak of |response| [N or m].
        input_end: u_end, the final travel [m] or final load [N].
    """

    indent: float
    speed: float
    radius: float
    t_on: float
    time_scale: float
    t_end_motion: float
    response_unit: float
    input_end: float

    def beta(self, E_star, viscosity):
        """β of a modulus and viscosity on these scales (eq 8e with v0 = d_c/t_c).

        Args:
            E_star: E*, plane-strain modulus [Pa].
            viscosity: η, film viscosity [Pa s].

        Returns:
            β = E* d_c^{3/2} t_c/(6π η R^{3/2}), dimensionless (``lubjax.si_scales``).
        """
        return lubjax.si_scales(E_star, self.radius, self.indent, speed=self.speed,
                                viscosity=viscosity)["beta"]

    def force_scale(self, E_star):
        """The force scale of a modulus on these scales (eq 11b).

        Args:
            E_star: E*, plane-strain modulus [Pa].

        Returns:
            F_s = F/F̄ = 2 E* d_c^{3/2} √R/π [N] (``lubjax.si_scales``).
        """
        return lubjax.si_scales(E_star, self.radius, self.indent, speed=self.speed)["force_N"]


def drive_of(trace: Trace, drive: str | None = None) -> str:
    """The trace's drive: ``drive`` if given, else its ``# drive:`` header, else "spring" when
    it gives ``# stiffness_N_m:``, else "travel"."""
    if drive is None:
        drive = trace.metadata.get("drive")
        if drive is None:
            drive = "spring" if "stiffness_N_m" in trace.metadata else "travel"
    if drive not in DRIVES:
        raise ValueError(f"{trace.name}: drive must be one of {', '.join(DRIVES)}, got {drive!r}")
    if drive == "spring" and trace.meta_float("stiffness_N_m") is None:
        raise ValueError(
            f"{trace.name}: drive 'spring' needs the instrument stiffness in the header "
            "('# stiffness_N_m: <N/m>')"
        )
    return drive


def common_drive(traces, drive: str | None = None) -> str:
    """The one drive of traces fitted together (:func:`drive_of` each); ValueError if they
    differ."""
    drives = {drive_of(t, drive) for t in traces}
    if len(drives) > 1:
        raise ValueError(f"traces fitted together must have one drive, got "
                         f"{', '.join(sorted(drives))}: fit them in separate calls")
    return drives.pop()


def channels(trace: Trace, drive: str):
    """(input, response, input column name, response column name)."""
    if drive == "force":
        return trace.force, trace.displacement, "force_N", "displacement_m"
    return trace.displacement, trace.force, "displacement_m", "force_N"



def scales_from_trace(trace: Trace, drive: str | None = None) -> Scales:
    """The scales of a trace, read off its input channel (the module docstring of
    :mod:`fitting._scales`): u_end, the onset t_on, t_c = u_end/rate, the ramp's end, d_c.

    Args:
        trace: the :class:`Trace`.
        drive: "travel", "spring" or "force"; None (default): the trace's ``# drive:``
            metadata, else "travel".

    Returns:
        Scales: the trace's scales.

    Raises:
        ValueError: the input does not ramp up (and, under load control, settle into a hold),
            the response is never positive, the final approach under a load is not positive,
            or the force is negative in compression (the message names the column).
    """
    drive = drive_of(trace, drive)
    check_force_sign(trace, drive)
    t = trace.time
    u, y, ucol, ycol = channels(trace, drive)
    n = t.size
    tail = max(3, n // 20)
    u_end = float(np.median(u[-tail:]))
    what = "final travel" if drive != "force" else "final load"
    if not u_end > 0:
        raise ValueError(
            f"{trace.name}: column {ucol}: the {what} is {u_end:g}; it must be positive "
            "(toward the substrate, since the first row)"
        )
    moving = np.flatnonzero(u > 1e-3 * u_end)
    k = int(moving[0])
    # The last sample at rest: where the record is exactly still before the motion (a
    # noiseless encoder), else the last one below 10⁻³ u_end (lubjax's own breakpoint rule).
    t_on = float(motion_start(t, u)) if k > 0 else float(t[0])
    mid = 0.5 * (u[1:] + u[:-1])
    rate_all = np.diff(u) / np.diff(t)
    ramp = (mid > 0.2 * u_end) & (mid < 0.8 * u_end)
    rate = float(np.median(rate_all[ramp])) if np.count_nonzero(ramp) >= 2 else float(
        np.max(rate_all)
    )
    if not rate > 0:
        raise ValueError(f"{trace.name}: column {ucol}: no ramp found (rate {rate:g})")
    tc = u_end / rate
    settled = np.flatnonzero(np.abs(u - u_end) > 1e-3 * u_end)
    end = float(t[min(settled[-1] + 1, n - 1)]) if settled.size else float(t[k])
    if end >= t[-1] and drive == "force":
        raise ValueError(f"{trace.name}: column {ucol}: the input never settles into a hold")
    # Position control may end on its ramp (an AFM approach): the motion ends with the record.
    end = min(end, float(t[-1]))
    if drive == "force":
        indent = float(np.median(y[-tail:]))
        if not indent > 0:
            raise ValueError(
                f"{trace.name}: column {ycol}: the final approach is {indent:g} m; under a load "
                "toward the substrate it must be positive"
            )
    else:
        indent = u_end
    peak = float(np.max(np.abs(y)))
    if not float(np.max(y)) > 0:
        raise ValueError(f"{trace.name}: column {ycol}: the response is never positive")
    return Scales(indent, indent / tc, trace.radius, t_on, tc, (end - t_on) / tc, peak, u_end)


def noise_level(values: np.ndarray) -> float:
    """The noise of a sampled channel, robustly, from successive differences.

    The smooth signal changes little between samples; white noise adds variance 2σ² to Δy.

    Args:
        values: the samples y_k (1-D, in any unit).

    Returns:
        σ = 1.4826·MAD(Δy)/√2, in the unit of ``values``.
    """
    dy = np.diff(values)
    return float(1.4826 * np.median(np.abs(dy - np.median(dy))) / math.sqrt(2.0))


def history(trace: Trace, scales: Scales, drive: str) -> lubjax.SampledTravel:
    """The measured input u(t)/u_end on t̄ = (t - t_on)/t_c, from the last sample at rest on.

    The run starts at rest there. Where the record is exactly still before the motion (an
    encoder, a commanded load) t_on is the sample where the motion truly starts; a noisy input
    falls back to the last sample below 10⁻³ u_end, and the model then misses the force of the
    motion before it (1.6 % of the peak at the first moving sample of paper_dc140 with that
    rule, 0.16 % with the exact one)."""
    u = channels(trace, drive)[0]
    tb = (trace.time - scales.t_on) / scales.time_scale
    keep = tb >= 0
    return lubjax.SampledTravel(
        tb[keep], u[keep] / scales.input_end, breakpoints=(0.0, scales.t_end_motion)
    )



def history_size(trace: Trace, scales: Scales) -> int:
    """Number of input samples :func:`trace_data` uses for ``trace`` before padding."""
    return int(np.count_nonzero(trace.time >= scales.t_on))



def drive_unit(trace: Trace, scales: Scales, drive: str) -> float:
    """The drive's number at E* = 1 Pa (the model divides it by the fitted E*): the load
    F_end/``force_scale(1)`` under load control, the spring's K̄ at E* = 1 for a spring, 0 for
    a prescribed travel."""
    if drive == "force":
        return scales.input_end / scales.force_scale(1.0)
    if drive == "spring":
        return lubjax.spring_stiffness_bar(trace.meta_float("stiffness_N_m"), 1.0,
                                           scales.radius, scales.indent)
    return 0.0



def cut_trace(trace: Trace, t_bar: float) -> Trace:
    """The trace up to t̄ = ``t_bar``: its samples before t_on + ``t_bar`` t_c (its own scales,
    its drive from its header), a shorter record of the same test.

    Args:
        trace: the :class:`Trace`.
        t_bar: where to cut, in units of the trace's t_c after its start t_on.

    Returns:
        Trace: the samples before the cut, with the trace's metadata and name.
    """
    sc = scales_from_trace(trace)
    keep = trace.time < sc.t_on + t_bar * sc.time_scale
    return trace._replace(time=trace.time[keep], displacement=trace.displacement[keep],
                          force=trace.force[keep])
