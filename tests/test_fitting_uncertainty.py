"""Honest uncertainties: z-scores over seeded noise draws of a trace made by a much finer solver.

The draws are a clean trace of the fine generator (data/clean/: rtol 1e-7, 544 nodes) plus
noise; the fit runs at rtol 1e-3 (143 nodes) on the first t̄ ≤ 3 of the trace, so the solver's
own error is part of the budget (fitting.coverage; the fit_coverage benchmark runs the same
with more draws for the table of docs/accuracy.md). With N = 24 draws the rms z of honest errors
scatters by ≈ ±0.14 around 1, so the window 0.8–1.2 is about ±1.4 of that scatter: the seeds
are fixed, and the benchmark's 60 draws are the firmer number.
"""

import numpy as np
import pytest

import fitting
from fitting import _stats, coverage, noise_draws

from helpers import short_trace, truth

DRAWS = 24


def _print(label, out):
    print(f"\n{label}: lag-1 {out['lag1']:.3f} (noise's {out['noise_correlation']:.3f}), "
          f"noise models {out['noise_models']}")
    for name, t in out["table"].items():
        print(f"  {name:10s} rms z {t['rms_z']:.2f} (white only {t['rms_z_white']:.2f}), "
              f"bias/SE {t['mean_bias_over_se']:+.2f}, scatter/SE {t['scatter_over_se']:.2f}, "
              f"solver/SE {t['solver_over_se']:.2f}")


@pytest.mark.slow
def test_white_noise_errors_cover_the_truth():
    """24 draws of 1 % white noise: rms z of E*, η, z0 within 0.8–1.2, white noise detected."""
    clean, _ = short_trace("paper_dc154", 3.0)
    out = coverage(noise_draws(clean, DRAWS, rho=0.0, seed=11), truth(clean))
    _print("white", out)
    assert out["converged"] == DRAWS and out["noise_models"] == ["white"]
    for name, t in out["table"].items():
        assert 0.8 <= t["rms_z"] <= 1.2, (name, t)


@pytest.mark.slow
def test_ar1_noise_is_detected_and_its_errors_cover_the_truth():
    """24 draws of AR(1) noise with ρ = 0.8 (a load cell's low-pass filter): the report switches
    to the AR(1) sandwich by itself (noise="auto"), its rms z lies within 0.8–1.2, while the
    white-noise errors would be far too small (rms z > 1.6: (1+ρ)/(1-ρ) = 9, so ≈ 3 expected)."""
    clean, _ = short_trace("paper_dc154", 3.0)
    out = coverage(noise_draws(clean, DRAWS, rho=0.8, seed=12), truth(clean))
    _print("AR(1) 0.8", out)
    assert out["converged"] == DRAWS and out["noise_models"] == ["ar1"]
    assert out["lag1"] == pytest.approx(0.8, abs=0.05)
    for name, t in out["table"].items():
        assert 0.8 <= t["rms_z"] <= 1.2, (name, t)
        assert t["rms_z_white"] > 1.6, (name, t)


def test_ar1_sandwich_is_exact_for_a_linear_model():
    """For a linear model y = Xβ + AR(1) noise the sandwich c s²(XᵀX)⁻¹XᵀRX(XᵀX)⁻¹ equals the
    covariance of the estimate computed from the explicit correlation matrix (no fit)."""
    n, rho = 400, 0.7
    t = np.linspace(0, 1, n)
    X = np.stack([np.ones(n), t, np.sin(3 * t)], axis=1)
    R = rho ** np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    inv = np.linalg.inv(X.T @ X)
    exact = inv @ X.T @ R @ X @ inv
    np.testing.assert_allclose(X.T @ _stats.ar1_correlated(X, rho), X.T @ R @ X, rtol=1e-10)
    r = np.random.default_rng(0).normal(size=n)
    out = _stats.summarise(r, X, [(n, n)], ["a", "b", "c"], noise="ar1")
    s2 = out["stats"]["reduced_chi2"]
    noise_rho = _stats.ar1_correlation(r, X)
    R_hat = noise_rho ** np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    scale = out["stats"]["noise_scale"]
    assert scale == _stats.ar1_scale([X], [noise_rho])
    np.testing.assert_allclose(out["parts"]["ar1"], scale * s2 * inv @ X.T @ R_hat @ X @ inv,
                               rtol=1e-8)
    assert np.all(np.diag(exact) > np.diag(inv))  # positive correlation inflates the variance


def test_ar1_correlation_undoes_what_the_fit_absorbs():
    """A fit absorbs the slow part of AR(1) noise, so its residuals' lag-1 autocorrelation
    understates the noise's ρ and Σr²/(n - p) its σ²; ``ar1_correlation`` (the ρ whose
    projected residuals show the observed lag-1 ratio) is unbiased to within its scatter, and
    ``ar1_scale`` restores the variance. 400 draws of n = 100, ρ = 0.8, a three-column linear
    model: the raw lag-1 averages 0.71, the corrected 0.79 (± 0.004); the sandwich's rms z of
    the three coefficients is 1.50 with the raw ρ, 1.29 with the corrected, 1.14 with the scale
    too, its 2σ coverage 82, 89 and 91 %."""
    n, rho, draws = 100, 0.8, 400
    rng = np.random.default_rng(3)
    t = np.linspace(0, 3, n)
    X = np.stack([1 - np.exp(-t), t * np.exp(-t), np.exp(-3 * t) * np.sin(2 * t)], axis=1)
    inv = np.linalg.inv(X.T @ X)
    raw, corrected, z = [], [], {"raw": [], "corrected": [], "scaled": []}
    for _ in range(draws):
        e = np.empty(n)
        e[0] = rng.normal()
        for i in range(1, n):
            e[i] = rho * e[i - 1] + np.sqrt(1 - rho**2) * rng.normal()
        x = inv @ X.T @ e
        r = e - X @ x
        raw.append(_stats.lag1(r))
        corrected.append(_stats.ar1_correlation(r, X))
        s2 = r @ r / (n - 3)
        scale = _stats.ar1_scale([X], [corrected[-1]])
        for q, c, key in ((raw[-1], 1.0, "raw"), (corrected[-1], 1.0, "corrected"),
                          (corrected[-1], scale, "scaled")):
            cov = c * s2 * inv @ (X.T @ _stats.ar1_correlated(X, q)) @ inv
            z[key].append(x / np.sqrt(np.diag(cov)))
    scatter = np.std(corrected) / np.sqrt(draws)
    assert abs(np.mean(corrected) - rho) < 3 * scatter + 0.01
    assert np.mean(raw) < rho - 0.05  # what it corrects
    rms = {k: np.sqrt(np.mean(np.square(v))) for k, v in z.items()}
    assert rms["corrected"] < rms["raw"] - 0.05
    assert rms["scaled"] < rms["corrected"] - 0.05
    # the rms z of 1200 values is known to ~2 %; what is left is s²'s own scatter (70
    # effective degrees of freedom), which the normal quantiles do not allow for
    assert 1.0 < rms["scaled"] < 1.2
    assert np.mean(np.abs(np.asarray(z["scaled"])) < 2) > 0.9


def test_ar1_scale_is_one_for_white_noise_and_guarded_near_one():
    """ρ = 0: the factor is 1 (the white s² is unbiased). ρ → 1: E[Σr²] → 0 with the fit's
    constant column absorbing everything, so the unguarded factor has no bound; it is taken at
    ρ = SCALE_CORRELATION from there on."""
    t = np.linspace(0, 1, 200)
    X = np.stack([t, np.exp(-3 * t)], axis=1)
    assert _stats.ar1_scale([X], [0.0]) == pytest.approx(1.0, rel=1e-12)
    cap = _stats.ar1_scale([X], [_stats.SCALE_CORRELATION])
    assert _stats.ar1_scale([X], [0.99]) == cap
    assert 1.0 < _stats.ar1_scale([X], [0.5]) < cap < 3.0


def test_solver_error_enters_as_its_parameter_shift():
    """A known model error m shifts a linear least-squares estimate by -(XᵀX)⁻¹Xᵀm exactly;
    the budget adds that shift squared."""
    rng = np.random.default_rng(1)
    n = 200
    X = rng.normal(size=(n, 2))
    m = 0.01 * rng.normal(size=n)
    r = rng.normal(size=n)
    out = _stats.summarise(r, X, [(n, n)], ["a", "b"], noise="white", solver_error=m)
    shift = -np.linalg.solve(X.T @ X, X.T @ m)
    np.testing.assert_allclose(out["parts"]["solver"], np.outer(shift, shift), rtol=1e-12)
    np.testing.assert_allclose(out["covariance"], out["parts"]["white"] + np.outer(shift, shift))


def test_noise_draws_are_seeded_ar1_of_the_given_size():
    """Each draw adds stationary AR(1) noise: marginal σ = fraction × peak, lag-1 correlation
    ρ (checked on a long trace: 20000 samples put both within a few percent), same seed, same
    draws; a correlation outside [0, 1) is refused by name."""
    n = 20_000
    t = np.linspace(0.0, 1.0, n)
    clean = fitting.make_trace(t, 1e-5 * t, np.ones(n), 1e-3)
    a, b = noise_draws(clean, 2, rho=0.8, fraction=0.01, seed=5)
    noise = a.force - clean.force
    assert np.std(noise) == pytest.approx(0.01, rel=0.1)
    assert np.corrcoef(noise[1:], noise[:-1])[0, 1] == pytest.approx(0.8, abs=0.02)
    assert not np.array_equal(a.force, b.force)  # independent draws
    again = noise_draws(clean, 2, rho=0.8, fraction=0.01, seed=5)
    np.testing.assert_array_equal(again[1].force, b.force)
    white = noise_draws(clean, 1, rho=0.0, seed=5)[0].force - clean.force
    assert abs(np.corrcoef(white[1:], white[:-1])[0, 1]) < 0.03
    with pytest.raises(ValueError, match="rho"):
        noise_draws(clean, 1, rho=1.0)


def test_noise_draws_go_on_the_response_channel():
    """Under a prescribed load the force is the command and the displacement the measured
    response: the noise goes there, σ = fraction × its largest magnitude; otherwise on the force."""
    n = 2000
    t = np.linspace(0.0, 1.0, n)
    creep = fitting.make_trace(t, 2e-5 * t, np.ones(n), 1e-3, metadata={"drive": "force"})
    draw = noise_draws(creep, 1, fraction=0.01, seed=3)[0]
    np.testing.assert_array_equal(draw.force, creep.force)
    assert np.std(draw.displacement - creep.displacement) == pytest.approx(2e-7, rel=0.1)
    travel = fitting.make_trace(t, 2e-5 * t, np.ones(n), 1e-3)
    draw = noise_draws(travel, 1, fraction=0.01, seed=3)[0]
    np.testing.assert_array_equal(draw.displacement, travel.displacement)
    assert np.std(draw.force - travel.force) == pytest.approx(0.01, rel=0.1)


@pytest.mark.parametrize("noise", ["auto", "ar1"])
def test_a_non_finite_jacobian_is_flagged_not_raised(noise):
    """A model run that failed at the optimum leaves NaN in the Jacobian: the summary says so
    and gives no standard errors, where the condition number's SVD raised and lost every fit
    of the batch."""
    n = 100
    X = np.stack([np.ones(n), np.linspace(0, 1, n)], axis=1)
    X[7, 1] = np.nan
    out = _stats.summarise(np.random.default_rng(2).normal(size=n), X, [(n, n)], ["a", "b"],
                           noise=noise, solver_error=np.zeros(n))
    assert any("not finite" in f for f in out["flags"])
    assert np.all(np.isnan(out["covariance"])) and out["condition"] == np.inf


def test_errors_held_at_an_undetermined_parameter_are_the_conditional_ones():
    """An undetermined positive parameter (standard error above its value) is held: the
    others' covariance becomes the Schur complement Cov_oo - Cov_ou Cov_uu⁻¹ Cov_uo, its own
    row is kept, and nothing is held when every parameter is determined."""
    from fitting._profile import held_map, undetermined_names

    names = ("E_star", "viscosity", "z0", "offset")
    cov = np.array([[4.0, 3.0, 1.0, 0.1], [3.0, 9.0, 2.0, 0.0], [1.0, 2.0, 2.0, 0.2],
                    [0.1, 0.0, 0.2, 1.0]])
    active = np.array([True, True, True, True])
    values = dict(E_star=4e6, viscosity=1e-3, z0=7e-5, offset=0.0)
    stderr = dict(E_star=1e4, viscosity=3e-3, z0=2e-7, offset=1e-4)
    assert undetermined_names(values, stderr, {}) == ["viscosity"]
    assert undetermined_names(values, stderr, {"viscosity": 1e-3}) == []
    T = held_map(names, active, cov, ["viscosity"])
    held = T @ cov @ T.T
    o = [0, 2, 3]
    schur = cov[np.ix_(o, o)] - np.outer(cov[o, 1], cov[1, o]) / cov[1, 1]
    np.testing.assert_allclose(held[np.ix_(o, o)], schur, rtol=1e-12)
    assert held[1, 1] == cov[1, 1]
    assert held_map(names, active, cov, []) is None


def test_coverage_reads_intervals_as_the_report_does(monkeypatch):
    """``coverage`` takes z as the report does (fitting._report.sided_z): a parameter with an
    interval through an undetermined one's profile gets z over the 1σ interval's half on the
    truth's side and counts in the rms; the undetermined parameter's own one-sided interval
    counts for "within" but not for the rms, even where its 1σ end is above 0."""
    from types import SimpleNamespace

    from fitting import _coverage

    def result(e_star, eta, interval_e, interval_eta):
        return SimpleNamespace(
            values=dict(E_star=e_star, viscosity=eta), stderr=dict(E_star=1.0, viscosity=2.0),
            converged=True,
            stats=dict(error_parts={"white": dict(E_star=1.0, viscosity=2.0)},
                       intervals=dict(E_star=interval_e, viscosity=interval_eta),
                       undetermined=["viscosity"], noise_model="white",
                       autocorrelation_lag1=0.0, noise_correlation=0.0))

    results = [
        # truth 10 below the estimate 12: z = 2/(12 - 11) = 2, inside the 2σ interval
        result(12.0, 0.5, {"1sigma": (11.0, 15.0), "2sigma": (9.0, 20.0)},
               {"1sigma": (0.1, 1.0), "2sigma": (0.0, 3.0)}),
        # truth 10 above the estimate 8: z = -2/(10 - 8) = -1, inside both
        result(8.0, 0.2, {"1sigma": (6.0, 10.0), "2sigma": (5.0, 13.0)},
               {"1sigma": (0.0, 0.6), "2sigma": (0.0, 1.5)}),
    ]
    monkeypatch.setattr(_coverage, "fit_traces", lambda draws, **kwargs: results)
    out = coverage([None, None], dict(E_star=10.0, viscosity=0.8))
    e_star, eta = out["table"]["E_star"], out["table"]["viscosity"]
    assert e_star["rms_z"] == pytest.approx(np.sqrt((2.0**2 + 1.0**2) / 2))
    assert (e_star["within_1sigma"], e_star["within_2sigma"]) == (0.5, 1.0)
    assert np.isnan(eta["rms_z"])  # both one-sided (undetermined): no two-sided z
    assert (eta["within_1sigma"], eta["within_2sigma"]) == (0.5, 1.0)
    assert e_star["profiled"] == eta["profiled"] == 2
