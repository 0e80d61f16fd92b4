"""Figures a user reads without the paper: axes and legends in words, the AFM fit against
indentation, titles in the command line's own option names. Each figure is built from stand-in
results (no solver run) and its matplotlib artists are read back."""

from __future__ import annotations

import importlib.util
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
