"""Model adequacy (fitting._adequacy): the judgement's false alarms on noise, its statistics
against simulation, and both verdicts on fits.

The noise tests simulate residuals directly (no fit: cheap); the fit tests fit noise draws of
clean traces made by data/make_synthetic.py's fine generator (rtol 1e-7, 544 nodes) at the fit's
own coarser settings, so the model that made the data is the fitted one up to the solver's
accuracy, as on a real instrument.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.stats import binom

import fitting
from fitting import _adequacy
from fitting._report import summary_line

from helpers import short_trace


def _ar1(rng, draws, n, rho):
    """``draws`` records of n samples of stationary AR(1) noise, unit variance."""
    white = rng.normal(size=(draws, n + 200))
    return lfilter([math.sqrt(1 - rho**2)], [1, -rho], white, axis=-1)[:, 200:]


@pytest.mark.parametrize("rho", [0.0, 0.5])
def test_delta_method_spreads_match_simulation(rho):
    """The spreads of ρ̂ and log χ²_ν that the tests use (Bartlett's formula carried by the
    delta method) are those of 4000 simulated noise records within 10 %."""
    n, draws = 300, 4000
    e = _ar1(np.random.default_rng(1), draws, n, rho)
    v1 = 0.5 * np.mean(np.diff(e, axis=-1) ** 2, axis=-1)
    v2 = 0.5 * np.mean((e[:, 2:] - e[:, :-2]) ** 2, axis=-1)
    rho_hat = v2 / v1 - 1
    log_chi2 = np.log(np.mean(e**2, axis=-1) * (1 - rho_hat) / v1)
    spread = _adequacy._spread(rho, n)
    assert np.std(rho_hat) == pytest.approx(spread["rho"], rel=0.1)
    assert np.std(log_chi2) == pytest.approx(spread["log_chi2"], rel=0.1)


@pytest.mark.parametrize("rho", [0.0, 0.5, 0.8])
def test_noise_alone_is_judged_adequate_at_the_stated_rate(rho):
    """1000 records of AR(1) noise (300 samples, an approach and a dwell) taken as residuals:
    the judgement fails no more often than ALPHA = 1 % allows (the count within the binomial's
    99.9 % quantile for 1 %)."""
    draws, n = 1000, 300
    segments = [("approach", 0, 75), ("dwell", 75, n)]
    e = _ar1(np.random.default_rng(7), draws, n, rho)
    fails = sum(not _adequacy.judge(x, segments, 3).ok for x in e)
    assert fails <= binom.ppf(0.999, draws, _adequacy.ALPHA), fails


def test_a_smooth_misfit_of_the_noises_size_fails_with_its_segment_named():
    """White noise plus a relaxation the model missed, 1.5 noise σ at the dwell's start and
    decaying over a third of it (half that is caught about half the time): the dwell is named,
    the approach is not."""
    n = 400
    segments = [("approach", 0, 100), ("dwell", 100, n)]
    rng = np.random.default_rng(3)
    misfit = np.zeros(n)
    misfit[100:] = 1.5 * np.exp(-np.arange(n - 100) / 100.0)
    passed = failed = 0
    for _ in range(20):
        noise = rng.normal(size=n)
        passed += bool(_adequacy.judge(noise, segments, 3).ok)
        a = _adequacy.judge(noise + misfit, segments, 3, viscoelastic=False)
        failed += a.ok is False
        assert not a.segments[0].systematic
    assert passed == 20
    assert failed >= 18
    assert "residuals systematic over the dwell" in a.message
    assert "a viscoelastic solid" in a.message


def test_runs_z_is_wald_wolfowitz():
    """Two runs of ten (the fewest) and twenty runs of one (the most), against the textbook
    mean 2 n+ n-/n + 1 = 11 and variance 2 n+ n- (2 n+ n- - n)/(n² (n - 1)) = 4.737."""
    sd = math.sqrt(2 * 100 * (200 - 20) / (400 * 19))
    assert _adequacy.runs_z(np.r_[np.ones(10), -np.ones(10)]) == pytest.approx((2 - 11) / sd)
    assert _adequacy.runs_z(np.tile([1.0, -1.0], 10)) == pytest.approx((20 - 11) / sd)
    assert _adequacy.runs_z(np.ones(10)) == 0.0


def test_a_misfit_the_solvers_error_accounts_for_points_to_the_tolerance():
    """A misfit that is the model's own discretisation error, given as the solver's error
    estimate: the judgement fails and names a tighter --rtol instead of another model."""
    n = 400
    segments = [("ramp", 0, 100), ("hold", 100, n)]
    error = 3.0 * np.exp(-np.arange(n) / 150.0)
    noise = np.random.default_rng(5).normal(size=n)
    a = _adequacy.judge(noise + error, segments, 3, model_error=-error)
    assert a.ok is False and a.solver_explains
    assert a.advice == ("a tighter --rtol (the solver's own error estimate accounts for the "
                        "misfit)",)


def test_too_short_a_trace_is_not_judged():
    a = _adequacy.judge(np.ones(10), [("approach", 0, 10)], 3)
    assert a.ok is None and "not judged" in a.message


def test_fits_of_the_right_and_the_wrong_model():
    """One batched elastic fit (rtol 1e-3, a coarse mesh) of two traces with 1 % white noise,
    both cut to t̄ <= 3: the paper's elastic trace, which the model describes, and the
    viscoelastic one (E0/E∞ = 1.5, τ = 0.5 s), which it cannot. The first passes with no flag
    and stays plausible; the second fails in every output (the summary line, the flags,
    ``plausible``, the report), with the advice to try a viscoelastic solid and --compare."""
    elastic, _ = short_trace("paper_dc154", 3.0)
    visco, _ = short_trace("visco_dc140", 3.0)
    draws = [fitting.noise_draws(tr, 1, seed=s)[0]._replace(name=tr.name)
             for tr, s in ((elastic, 11), (visco, 5))]
    settings = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3, dr=0.05, mesh_growth=1.2,
                                   length=100.0)
    good, bad = fitting.fit_traces(draws, settings=settings)
    assert good.converged and bad.converged
    assert good.adequacy.ok is True
    assert good.adequacy.reduced_chi2 == pytest.approx(1.0, abs=0.15)
    d = fitting.result_to_dict(good)
    assert d["plausible"] and d["adequacy"]["ok"]
    assert not any("does not describe" in f for f in good.flags)
    assert "the model describes the data" in summary_line(good)

    a = bad.adequacy
    assert a.ok is False and not a.solver_explains
    assert any(s.name == "hold" and s.systematic for s in a.segments)
    assert a.message in bad.flags
    assert "residuals systematic over" in a.message and "the hold" in a.message
    assert "a viscoelastic solid" in a.message and "--compare" in a.message
    d = fitting.result_to_dict(bad)
    assert not d["plausible"] and not d["adequacy"]["ok"]
    assert "THE MODEL DOES NOT DESCRIBE THE DATA" in summary_line(bad)
    report = fitting.fit_report(bad)
    assert "[[Model adequacy]]" in report and "(systematic)" in report
