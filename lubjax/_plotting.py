"""Figures for a single run (matplotlib, Agg backend; imported only when a plot is asked for)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._analytic import hertz_force, rigid_squeeze_force  # noqa: E402
from ._files import save_figure  # noqa: E402

HALF_SPACE = "elastic half-space"


def plot_result(res, path: str, test=None, substrate: str | None = None) -> None:
    """Force and minimum film against time, and the pressure / film profiles: in SI units
    (s, mN, μm, mm, kPa) when ``test`` (a :class:`lubjax.RelaxationTest`) is given, else
    dimensionless. The title names the drive and the substrate (``substrate``: its description,
    default the elastic half-space).

    Written atomically in the format of ``path``'s extension (png, pdf, svg, ...)."""
    si = test is not None
    # (time, force, film, radius, pressure) factors from the solver's units to the axes'
    if si:
        ts, fs, hs = test.time_scale, test.force_scale * 1e3, test.indent * 1e6
        rs, ps = test.length_scale * 1e3, test.pressure_scale / 1e3
        t_label, f_label, h_label = "t [s]", "force F [mN]", "film thickness h [μm]"
        r_label, p_label = "r [mm]", "pressure p [kPa]"
    else:
        ts = fs = hs = rs = ps = 1.0
        t_label, f_label, h_label, r_label, p_label = ("t̄", "F̄", "film thickness h̄", "r̄",
                                                       "pressure p̄")
    fig, ax = plt.subplots(1, 4, figsize=(18, 4))
    t = res.t
    ax[0].plot(t * ts, res.force * fs, "k-", label="lubjax")
    load = (t > 0.02) & (t < 1) & (res.z0 - t > 0.05)
    ax[0].plot(
        t[load] * ts, rigid_squeeze_force(res.z0 - t[load], -1.0, res.beta) * fs, "b:",
        label="rigid sphere squeezing the film (short-time limit)",
    )
    if res.z0 < 1:
        ax[0].axhline(hertz_force(res.z0) * fs, color="r", ls="--",
                      label="Hertz contact (long-time limit)")
    ax[0].set_ylim(0, 1.15 * np.nanmax(res.force) * fs)
    ax[0].set_ylabel(f_label)
    ax[0].legend(fontsize=8)
    ax[0].set_title(f"β = {res.beta:.3g}, z̄0 = {res.z0:.3g}", fontsize=9)
    ax[1].semilogy(t * ts, np.clip(res.film_min, 1e-12, None) * hs, "k-",
                   label="min h" if si else "min h̄")
    ax[1].semilogy(t * ts, np.clip(res.film_center, 1e-12, None) * hs, "g--",
                   label="h(0)" if si else "h̄(0)")
    ax[1].set_ylabel(h_label)
    ax[1].legend(fontsize=8)
    for a in ax[:2]:
        a.set_xlabel(t_label)
        if t[-1] > 20:
            a.set_xscale("symlog", linthresh=ts)
            a.set_xlim(0, t[-1] * ts)
    sel = res.r <= 2.5
    for tp, p, h in zip(res.profile_times, res.pressure, res.film):
        label = f"t = {tp * ts:.3g} s" if si else f"t̄ = {tp:g}"
        ax[2].plot(res.r[sel] * rs, p[sel] * ps, label=label)
        ax[3].plot(res.r[sel] * rs, h[sel] * hs, label=label)
    ax[2].set_ylabel(p_label)
    ax[2].legend(fontsize=7)
    ax[3].set_ylabel(h_label)
    ax[3].set_ylim(0, None)
    for a in ax[2:]:
        a.set_xlabel(r_label)
    where = f"substrate: {substrate or HALF_SPACE}"
    if si:
        title = (f"relax: travel ramped at --speed {test.speed:.3g} m/s to --indent "
                 f"{test.indent:.3g} m, then held; {where}\nE* = {test.E_star:.3g} Pa, "
                 f"--viscosity {test.viscosity:.3g} Pa s, --radius {test.radius:.3g} m, --gap "
                 f"{test.gap:.3g} m  (t_c = indent/speed = {test.time_scale:.3g} s, F scale = "
                 f"{test.force_scale:.3g} N)")
    else:
        title = (f"relax: travel ramped to d_c at t̄ = 1, then held; {where}\n(lengths in d_c, "
                 "times in t_c = d_c/v0)")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    try:
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)


def plot_drive(res, path: str, kind: str, test, substrate: str | None = None,
               profile_notes=None) -> None:
    """A creep or bounce run in SI units: the sphere's position, the force (and velocity), the
    film, and the pressure profiles (``profile_notes``: a note per profile time for its label,
    e.g. "impact"). The title names the drive and the substrate (``substrate``: its
    description, default the elastic half-space)."""
    sc = test.scales
    d, ts, fs = sc["gap_m"], sc["time_s"], sc["force_N"]
    t = res.t * ts
    fig, ax = plt.subplots(1, 4, figsize=(18, 4))
    if kind == "creep":
        ax[0].plot(t, (test.gap - res.gap * d) * 1e6, "k-", label="approach z0 - z")
        ax[0].axhline((test.gap + test.indent) * 1e6, color="r", ls="--",
                      label="Hertz: z0 + δ∞")
        ax[0].set_ylabel("approach [μm]")
        ax[1].plot(t, res.force * fs * 1e3, "k-", label="load")
        ax[1].set_ylabel("force [mN]")
        title = (f"creep: load {test.load:.3g} N, E* = {test.E_star:.3g} Pa, --viscosity "
                 f"{test.viscosity:.3g} Pa s, --radius {test.radius:.3g} m, --gap {test.gap:.3g} m"
                 f"  (β = {test.beta:.3g}, z̄0 = {test.z0_bar:.3g})")
    else:
        ax[0].plot(t, res.gap * d * 1e6, "k-", label="sphere position z (rigid body)")
        ax[0].axhline(0, color="0.6", lw=0.5, label="undeformed surface")
        ax[0].set_ylabel("sphere position z [μm]")
        ax[1].plot(t, res.velocity * test.speed, "b-", label="velocity dz/dt [m/s]")
        ax[1].set_ylabel("velocity [m/s]", color="b")
        twin = ax[1].twinx()
        twin.plot(t, res.force * fs * 1e3, "k-", lw=0.8)
        twin.set_ylabel("film force [mN] (black)")
        title = (f"bounce: a sphere of mass {test.mass:.3g} kg at --speed {test.speed:.3g} m/s "
                 f"from --gap {test.gap:.3g} m; E* = {test.E_star:.3g} Pa, --viscosity "
                 f"{test.viscosity:.3g} Pa s, --radius {test.radius:.3g} m  (Stokes number "
                 f"{test.stokes:.3g}, β = {test.beta:.3g})")
    for a in ax[:3]:
        a.set_xlabel("t [s]")
    if kind == "creep":
        # Creep spans decades (the elastic indentation in the ramp, the drainage after it).
        for a in (ax[0], ax[2]):
            a.set_xscale("log")
            a.set_xlim(max(t[1], 1e-3 * t[-1]), t[-1])
    ax[0].legend(fontsize=8)
    ax[2].semilogy(t, np.clip(res.film_min * d, 1e-15, None), "k-", label="min h")
    ax[2].semilogy(t, np.clip(res.film_center * d, 1e-15, None), "g--", label="h(0)")
    ax[2].set_ylabel("film thickness [m]")
    ax[2].legend(fontsize=8)
    r = res.r * sc["length_m"] * 1e3
    sel = res.r <= 3.0
    notes = profile_notes or [""] * len(res.profile_times)
    for tp, p, note in zip(res.profile_times, res.pressure, notes):
        label = f"t = {tp * ts:.3g} s" + (f" ({note})" if note else "")
        ax[3].plot(r[sel], p[sel] * sc["pressure_Pa"] / 1e3, label=label)
    ax[3].axhline(0, color="0.6", lw=0.5)
    ax[3].set_xlabel("r [mm]")
    ax[3].set_ylabel("pressure [kPa]")
    ax[3].legend(fontsize=8)
    fig.suptitle(f"{title}\nsubstrate: {substrate or HALF_SPACE}", fontsize=9)
    fig.tight_layout()
    try:
        save_figure(fig, path, dpi=110)
    finally:
        plt.close(fig)
