"""The figure of a fit: data and model, residuals, their autocorrelation and the fit report."""

from __future__ import annotations

import math
import os
import textwrap

import numpy as np

from lubjax._fitting_api import files as _files

from ._fit import FitResult
from ._report import fit_report

#: Units a figure may read values in (the one where the peak reads between 1 and 1000).
_FORCE_UNITS = (("N", 1.0), ("mN", 1e3), ("μN", 1e6), ("nN", 1e9))
_LENGTH_UNITS = (("m", 1.0), ("mm", 1e3), ("μm", 1e6), ("nm", 1e9))


def _unit(values, units) -> tuple[str, float]:
    """(unit, factor) in which the largest |value| reads between 1 and 1000 (mN and μm for a
    tribometer, nN for an AFM cantilever)."""
    peak = float(np.max(np.abs(values))) if np.size(values) else 0.0
    peak = peak if math.isfinite(peak) and peak > 0 else 1.0
    return next(((u, s) for u, s in units if peak * s >= 1.0), units[-1])


def _indentation(res: FitResult):
    """An AFM or indenter vendor file's fit against indentation: (indentation of the data, of
    the model, force of the data, of the model), the indentation being the tip's travel past
    the fitted contact point z0; None for other traces (or a result without its input)."""
    if "instrument_file" not in res.metadata or res.input is None:
        return None
    z0 = res.values["z0"]
    if res.spec.drive == "force":  # load control: the response is the tip's own travel
        return res.data - z0, res.model - z0, res.input, res.input
    k = float(res.metadata["stiffness_N_m"])  # the tip: the stage less the bending F/k
    return (res.input - res.data / k - z0, res.input - res.model / k - z0, res.data,
            res.model)


def fit_figure(res: FitResult):
    """The figure of :func:`plot_fit` (a matplotlib Figure; close it when done)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    force = res.spec.response == "force"
    unit, scale = _unit(res.data, _FORCE_UNITS if force else _LENGTH_UNITS)
    label = "force" if force else "approach"
    against = _indentation(res)
    fig = plt.figure(figsize=(13, 8))
    gs = fig.add_gridspec(3, 2, width_ratios=[1.55, 1], height_ratios=[3, 1.3, 1.2],
                          hspace=0.55, wspace=0.08)
    name = os.path.basename(res.name) or "trace"
    if against is None:
        ax = fig.add_subplot(gs[0, 0])
        time_ax = ax
    else:
        # AFM users read force against indentation; the time view is kept beside it where a
        # dwell (relaxation or creep at a held height or force) is fitted
        dwell = "dwell" in res.metadata.get("segments", "")
        top = gs[0, 0].subgridspec(1, 2, wspace=0.3) if dwell else None
        ax = fig.add_subplot(top[0, 0] if dwell else gs[0, 0])
        x_data, x_model, f_data, f_model = against
        f_unit, f_scale = _unit(f_data, _FORCE_UNITS)
        x_unit, x_scale = _unit(np.concatenate([x_data, x_model]), _LENGTH_UNITS)
        ax.plot(x_data * x_scale, f_data * f_scale, ".", ms=2.0, color="0.6", label="data")
        ax.plot(x_model * x_scale, f_model * f_scale, "-", color="C3", lw=1.4,
                label="lubjax model (fit)")
        ax.axvline(0.0, color="k", lw=0.8, ls=":", label="fitted contact point (z0)")
        ax.set_xlabel(f"indentation: tip travel past contact [{x_unit}]")
        ax.set_ylabel(f"force [{f_unit}]")
        ax.legend(loc="upper left", fontsize=8)
        ax.grid(alpha=0.3)
        ax.set_title(name)
        time_ax = fig.add_subplot(top[0, 1]) if dwell else None
    if time_ax is not None:
        time_ax.plot(res.time, res.data * scale, ".", ms=2.0, color="0.6", label="data")
        time_ax.plot(res.time, res.model * scale, "-", color="C3", lw=1.4,
                     label="lubjax model (fit)")
        time_ax.set_ylabel(f"{label} [{unit}]")
        if time_ax is not ax:
            time_ax.set_xlabel("time [s]")
        time_ax.set_title(name if time_ax is ax else "against time")
        time_ax.legend(loc="best", fontsize=8 if against is not None else None)
        time_ax.grid(alpha=0.3)
    ax2 = fig.add_subplot(gs[1, 0], sharex=time_ax if time_ax is not None else None)
    resid = (res.data - res.model) * scale
    ax2.plot(res.time, resid, ".", ms=2.0, color="C0")
    ax2.axhline(0.0, color="k", lw=0.8)
    sigma = res.stats.get("noise_sigma", 0.0) * scale
    for s in (-2 * sigma, 2 * sigma):
        ax2.axhline(s, color="0.5", lw=0.6, ls="--")
    ax2.set_ylabel(f"data - model [{unit}]")
    ax2.set_xlabel("time [s]")
    ax2.grid(alpha=0.3)
    _adequacy_marks(ax2, res)
    ax4 = fig.add_subplot(gs[2, 0])
    r = resid - np.mean(resid)
    lags = np.arange(1, min(60, r.size // 4))
    acf = np.array([float(r[k:] @ r[: r.size - k]) for k in lags]) / max(float(r @ r), 1e-300)
    ax4.bar(lags, acf, width=0.8, color="C0")
    band = 2 / np.sqrt(r.size)
    ax4.axhspan(-band, band, color="0.85", zorder=0, label="±2/√n (white noise)")
    ax4.set_ylim(min(-3 * band, 1.1 * acf.min()), max(3 * band, 1.1 * acf.max()))
    ax4.set_xlabel("lag [samples]")
    ax4.set_ylabel("residual autocorr.")
    ax4.legend(loc="upper right", fontsize=8)
    ax4.grid(alpha=0.3)
    ax3 = fig.add_subplot(gs[:, 1])
    ax3.axis("off")
    ax3.text(0.0, 1.0, fit_report(res), transform=ax3.transAxes, va="top", ha="left",
             family="monospace", fontsize=6.8)
    return fig


def _adequacy_marks(ax, res: FitResult) -> None:
    """The residual panel's title says whether the model describes the data; the segments
    with systematic residuals are shaded."""
    adequacy = res.adequacy
    if adequacy is None or adequacy.ok is None:
        return
    t = res.time
    bad = [seg for seg in adequacy.segments if seg.systematic]
    for k, seg in enumerate(bad):
        ax.axvspan(t[seg.start], t[seg.stop - 1], color="C3", alpha=0.12, lw=0,
                   label="systematic residuals" if k == 0 else None)
    chi2 = f"reduced chi2 {adequacy.reduced_chi2:.3g} against the noise in the residuals"
    if adequacy.ok:
        title, color = f"the model describes these data ({chi2})", "C2"
    else:
        where = (" over the " + ", the ".join(seg.name for seg in bad)) if bad else ""
        title, color = (f"THE MODEL DOES NOT DESCRIBE THESE DATA: residuals systematic{where} "
                        f"({chi2})"), "C3"
    ax.set_title(textwrap.fill(title, 100), fontsize=8, color=color, loc="left")
    if bad:
        ax.legend(loc="best", fontsize=7)


def plot_fit(res: FitResult, path: str) -> None:
    """A figure of a fit: data and model, residuals (with their autocorrelation), and the fit
    report. An AFM or indenter vendor file's fit is drawn against indentation (the tip's travel
    past the fitted contact point), and against time too when it has a dwell.

    Written atomically in the format of ``path``'s extension (png, pdf, svg, ...).

    Args:
        res: the :class:`FitResult`.
        path: the file to write.
    """
    import matplotlib.pyplot as plt

    fig = fit_figure(res)
    try:
        _files.save_figure(fig, path, dpi=120, bbox_inches="tight")
    finally:
        plt.close(fig)
