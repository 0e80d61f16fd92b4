"""Figures a user reads without the paper: axes and legends in words, the AFM fit against
indentation, titles in the command line's own option names. Each figure is built from stand-in
results (no solver run) and its matplotlib artists are read back."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _paper_figures():
    spec = importlib.util.spec_from_file_location(
        "paper_figures", ROOT / "examples" / "paper_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _texts(fig) -> list[str]:
    """Every label, title and legend entry of a figure."""
    out = [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        out += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()]
        legend = ax.get_legend()
        if legend is not None:
            out += [t.get_text() for t in legend.get_texts()]
    return [t for t in out if t]


def _profile_results(pf) -> dict:
    r = np.linspace(0.0, 3.0, 60)
    results = {}
    for z0 in (0.5, 1.0, 2.0):
        times = np.array(pf.profile_times(pf.BETA, z0))
        shape = (times.size, r.size)
        results[z0] = SimpleNamespace(r=r, profile_times=times, pressure=np.ones(shape),
                                      film=np.ones(shape), displacement=-np.ones(shape))
    return results


@pytest.mark.parametrize("k", range(3))
def test_the_readme_figure_says_its_axes_and_limits_in_words(k):
    pf = _paper_figures()
    name, field, label = pf.PROFILES[k]
    fig = pf.profile_figure(_profile_results(pf), field, label)
    try:
        texts = _texts(fig)
        for ax in fig.axes:
            assert ax.get_xlabel() == "radius  r̄ = r / √(R d_c)"
            assert ax.get_ylabel() == label
        assert {ax.get_title() for ax in fig.axes} >= {"initial gap z̄0 = 0.5",
                                                      "initial gap z̄0 = 1"}
        assert "pushed in to depth d_c" in fig.texts[0].get_text()
        # no equation numbers of the paper, which a reader of the README does not have
        assert not [t for t in texts if "eq " in t], texts
        if field == "pressure":
            assert label.startswith("film pressure  p̄ = p / ((2E*/π)")
            assert {"Hertz contact (long-time limit)",
                    "rigid sphere squeezing the film (short-time limit)"} <= set(texts)
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------- lubjax-fit --plot

K = 0.05  # the cantilever's spring constant [N/m]
Z0 = 0.4e-6  # the fitted contact point [m]


def _fit(metadata: dict, drive: str = "spring"):
    """A stand-in fit of an approach (1 s) and a dwell (1 s) at 20 nN/μm of tip travel."""
    from test_cli_errors import _fake_fit

    from fitting import make_trace
    from fitting._model import ModelSpec

    t = np.linspace(0.0, 2.0, 200)
    stage = 2e-6 * np.minimum(t, 1.0)
    force = 0.02 * np.maximum(stage - Z0, 0.0) / (1 + 0.02 / K) + 1e-10 * np.sin(40 * t)
    tr = make_trace(t, stage, force, 20e-6, metadata)
    (res,) = _fake_fit([tr])
    res = res._replace(input=tr.displacement, values={**res.values, "z0": Z0})
    if drive == "force":  # load control: the force is the input, the tip's travel the response
        tip = stage - force / K
        res = res._replace(spec=ModelSpec(drive="force"), input=force, data=tip, model=tip)
    return res


def _figure(res):
    from fitting._figure import fit_figure

    return fit_figure(res)


AFM = {"drive": "spring", "stiffness_N_m": repr(K), "instrument_file": "cell.jpk-force"}


def test_an_afm_fit_is_drawn_against_indentation():
    res = _fit({**AFM, "segments": "approach"})
    fig = _figure(res)
    try:
        ax = fig.axes[0]
        assert ax.get_xlabel() == "indentation: tip travel past contact [μm]"
        assert ax.get_ylabel() == "force [nN]"
        data = ax.lines[0]
        # the tip: the stage less the cantilever's bending F/k, from the fitted contact point
        np.testing.assert_allclose(data.get_xdata(), (res.input - res.data / K - Z0) * 1e6)
        np.testing.assert_allclose(data.get_ydata(), res.data * 1e9)
        # approach only: no time view of the data beside it (the residuals keep time)
        assert [a.get_xlabel() for a in fig.axes if a.lines and a is not ax] == ["time [s]"]
    finally:
        plt.close(fig)


@pytest.mark.parametrize("drive", ["spring", "force"])
def test_an_afm_fit_with_a_dwell_keeps_the_time_view(drive):
    res = _fit({**AFM, "segments": "approach,dwell"}, drive)
    fig = _figure(res)
    try:
        (ind,) = [a for a in fig.axes if a.get_xlabel().startswith("indentation: tip travel")]
        (time_view,) = [a for a in fig.axes if a.get_title() == "against time"]
        assert time_view.get_xlabel() == "time [s]"
        np.testing.assert_allclose(time_view.lines[0].get_xdata(), res.time)
        if drive == "force":  # the response is the tip's travel, the force the input
            np.testing.assert_allclose(ind.lines[0].get_xdata(), (res.data - Z0) * 1e6)
            np.testing.assert_allclose(ind.lines[0].get_ydata(), res.input * 1e9)
    finally:
        plt.close(fig)


def test_a_tribometer_fit_stays_against_time():
    res = _fit({"sample": "bead 3"})
    fig = _figure(res)
    try:
        assert not [a for a in fig.axes if "indentation" in a.get_xlabel()]
        np.testing.assert_allclose(fig.axes[0].lines[0].get_xdata(), res.time)
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------- lubjax's figures


def _run(n=30):
    t = np.linspace(0.0, 3.0, n)
    r = np.linspace(0.0, 3.0, 40)
    return SimpleNamespace(
        t=t, gap=1.0 - t / 2, velocity=-np.ones(n), force=np.linspace(0.0, 1.0, n),
        film_min=np.linspace(1.0, 0.1, n), film_center=np.linspace(1.0, 0.2, n), r=r,
        profile_times=np.array([1.0, 3.0]), pressure=np.ones((2, r.size)),
        film=np.ones((2, r.size)), force_error=np.full(n, 1e-4), beta=53.9, z0=1.0)


def _title(monkeypatch, draw) -> str:
    """The title of the figure ``draw()`` writes (the file is not written)."""
    from lubjax import _plotting

    seen = []
    monkeypatch.setattr(_plotting, "save_figure", lambda fig, *a, **k: seen.append(fig))
    draw(_plotting)
    (fig,) = seen
    title = fig._suptitle.get_text()
    plt.close(fig)
    return title


def test_si_titles_name_the_command_line_options(monkeypatch):
    """The values a user gave are named by the options they gave them with (not the paper's
    x0, V, v0, d_c, z0)."""
    from lubjax._units import Collision, CreepTest, RelaxationTest

    bounce = Collision(1e6, 2e-3, 0.01, 2.6e-4, 0.05, 50e-6, 0.0)
    creep = CreepTest(3.92e6, 2e-3, 100.0, 0.03, 1.0, 140e-6)
    relax = RelaxationTest(3.92e6, 2e-3, 100.0, 1e-4, 140e-6, 140e-6)
    titles = [_title(monkeypatch, lambda p: p.plot_drive(_run(), "b.png", "bounce", bounce)),
              _title(monkeypatch, lambda p: p.plot_drive(_run(), "c.png", "creep", creep)),
              _title(monkeypatch, lambda p: p.plot_result(_run(), "r.png", test=relax))]
    assert titles[0].startswith(
        "bounce: a sphere of mass 0.00026 kg at --speed 0.05 m/s from --gap 5e-05 m; E* = 1e+06 "
        "Pa, --viscosity 0.01 Pa s, --radius 0.002 m")
    assert "--viscosity 100 Pa s, --radius 0.002 m, --gap 0.00014 m" in titles[1]
    assert titles[2].startswith(
        "relax: travel ramped at --speed 0.0001 m/s to --indent 0.00014 m")
    assert "--gap 0.00014 m" in titles[2]
    for title in titles:
        assert not re.search(r"\b(x0|V|v0|d_c|z0|η|R) =", title), title


def test_the_relax_figure_names_its_limits_in_words(monkeypatch):
    from lubjax import _plotting

    seen = []
    monkeypatch.setattr(_plotting, "save_figure", lambda fig, *a, **k: seen.append(fig))
    res = _run()
    res.z0 = 0.5
    _plotting.plot_result(res, "r.png")
    (fig,) = seen
    try:
        legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
        assert legend == ["lubjax", "rigid sphere squeezing the film (short-time limit)",
                          "Hertz contact (long-time limit)"]
    finally:
        plt.close(fig)
