"""A parameter the data bound from one side: LM stops at the bound, the profile of χ² gives its
interval (fitting._optimisers' dry limit, fitting._profile), on a stand-in problem whose
profile is known in closed form.

The stand-in is the near-dry contact's shape: the response is c + a η^p g(t) with the film's
force a η^p g below the noise at the truth, fitted in x = (c, ln η) like the lubjax fits. In
u = η^p the model is linear, so the profile of χ² is the parabola of linear least squares in
u, cut at u = 0: Δχ²(u) = ((u - û)² - (u* - û)²)/V with û the unconstrained estimate,
u* = max(û, 0) and V = ((XᵀX)⁻¹)_uu, X = [1, a g]."""

import math

import numpy as np
import pytest

from fitting import _optimisers, _profile

P, AMP, N = 0.7, 3.0, 200
T = np.linspace(0.0, 1.0, N)
SHAPE = np.exp(-3.0 * T) - 0.3


def _problem(eta_true, seed):
    y = 1.0 + AMP * eta_true**P * SHAPE + np.random.default_rng(seed).normal(size=N)

    def one(x):
        film = AMP * np.exp(P * x[1]) * SHAPE
        J = np.column_stack([np.ones(N), P * film])
        return x[0] + film - y, J, True

    def evaluate(xs, which=None):
        return [one(x) if which is None or k in which else None for k, x in enumerate(xs)]

    return evaluate, y


def _exact_interval(y, level, s2):
    """The interval of η at ``level`` standard errors, from the closed-form profile."""
    X = np.column_stack([np.ones(N), AMP * SHAPE])
    c, u_hat = np.linalg.lstsq(X, y, rcond=None)[0]
    V = np.linalg.inv(X.T @ X)[1, 1]
    u_star = max(u_hat, 0.0)
    # (u - û)² = (u* - û)² + level² s² V on each side of û, cut at 0
    half = math.sqrt((u_star - u_hat) ** 2 + level**2 * s2 * V)
    lo, hi = max(u_hat - half, 0.0), u_hat + half
    return lo ** (1 / P), hi ** (1 / P)


def _fit(evaluate, floors):
    return _optimisers.lm(evaluate, [np.array([0.0, math.log(0.5)])], [N], max_iter=60,
                          tol=1e-4, floors=floors)[0]


@pytest.mark.parametrize("seed", range(6))
def test_lm_stops_at_the_dry_limit_where_it_walked_on(seed):
    """Data made at η = 0 (the dry limit): without the floor LM walks ln η down for its whole
    budget on the draws whose optimum is the bound (not converged); with it, those stop,
    converged and saying so, in a few iterations, with c at its dry value (the mean of y - 0,
    within 0.1 of its standard error)."""
    evaluate, y = _problem(0.0, seed)
    plain, floored = _fit(evaluate, None), _fit(evaluate, [[1]])
    assert floored.converged, floored.message
    X = np.column_stack([np.ones(N), AMP * SHAPE])
    u_hat = np.linalg.lstsq(X, y, rcond=None)[0][1]
    if u_hat < 0:  # the optimum is the bound
        assert not plain.converged and plain.iterations == 60, plain.message
        assert "at the dry limit" in floored.message
        assert floored.iterations < 20
        assert abs(floored.x[0] - np.mean(y)) < 0.1 / math.sqrt(N)
    else:
        assert plain.converged


@pytest.mark.parametrize("eta_true, seed", [(0.0, 0), (0.0, 1), (0.0, 3), (0.01, 2),
                                            (0.05, 4), (0.05, 5), (0.1, 6), (0.1, 7)])
def test_profile_interval_matches_the_closed_form(eta_true, seed):
    """Both ends at 1σ and 2σ within 5 % of η (on its ln scale: 0.05) of the closed form's
    (the walk's steps are an e-fold, refined once or twice; 15 runs at most here),
    the lower end 0 where the closed form's is, and the truth inside the 2σ interval; at η =
    0.1 (u = η^p about three of its errors from 0) the 1σ interval's lower end is above 0."""
    evaluate, y = _problem(eta_true, seed)
    out = _fit(evaluate, [[1]])
    r = out.r
    s2 = float(r @ r) / (N - 2)
    found = _profile.profile_interval(lambda x: evaluate([x])[0][0], out.x, r, out.J, 1, s2)
    assert found["runs"] <= 15
    for key, level in _profile.LEVELS.items():
        lo, hi = (math.exp(b) for b in found[key])
        lo_exact, hi_exact = _exact_interval(y, level, s2)
        assert abs(math.log(hi / hi_exact)) < 0.05, (key, hi, hi_exact)
        if lo_exact == 0.0:
            assert lo == 0.0, (key, lo)
        else:
            assert abs(math.log(lo / lo_exact)) < 0.05, (key, lo, lo_exact)
    lo, hi = (math.exp(b) for b in found["2sigma"])
    assert lo <= eta_true <= hi
    if eta_true == 0.1:
        assert found["1sigma"][0] > -math.inf
