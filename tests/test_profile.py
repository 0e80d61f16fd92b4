"""A parameter the data bound from one side: LM stops at the bound, the profile of χ² gives its
interval and the other parameter's through it (fitting._optimisers' dry limit,
fitting._profile), on a stand-in problem whose profiles are known in closed form.

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
#: A film shape correlated with the constant (+0.79 on [0, 1]), as E* and z0 are with η near dry.
LEANING = np.exp(-3.0 * T)


def _problem(eta_true, seed, shape=SHAPE):
    y = 1.0 + AMP * eta_true**P * shape + np.random.default_rng(seed).normal(size=N)

    def one(x):
        film = AMP * np.exp(P * x[1]) * shape
        J = np.column_stack([np.ones(N), P * film])
        return x[0] + film - y, J, True

    def evaluate(xs, which=None):
        return [one(x) if which is None or k in which else None for k, x in enumerate(xs)]

    return evaluate, y


def test_a_capped_step_is_the_quadratic_models_least_value_in_the_box():
    """capped_step on a correlated 3-parameter model: each part within its cap, and no point of
    the box (a fine grid) lowers the model ½δᵀMδ + gᵀδ below it; the step within its caps
    is the Gauss–Newton step itself."""
    M = np.array([[4.0, 1.8, 0.5], [1.8, 1.0, 0.2], [0.5, 0.2, 2.0]])
    caps = np.array([1.0, 3.0, 1.0])

    def model(d):
        return 0.5 * d @ M @ d + g @ d

    for g in (np.array([-2.0, 9.0, 0.3]), np.array([10.0, -1.0, -6.0])):
        step = _optimisers.capped_step(M, g, lambda d: caps)
        assert np.all(np.abs(step) <= caps + 1e-12)
        grid = np.stack(np.meshgrid(*[np.linspace(-c, c, 41) for c in caps]), -1).reshape(-1, 3)
        assert model(step) <= min(model(d) for d in grid) + 1e-12
    g = np.array([0.2, -0.1, 0.05])
    np.testing.assert_allclose(_optimisers.capped_step(M, g, lambda d: caps),
                               -np.linalg.solve(M, g))


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
    """Data made at η = 0 (the dry limit): without the floor LM walks ln η down an e-fold per
    iteration on the draws whose optimum is the bound, until the film's force is lost in
    rounding (ln η ≈ -25, ≥ 20 iterations); with it, those stop, converged and saying so, in a
    few iterations, with c at its dry value (the mean of y - 0, within 0.1 of its standard
    error)."""
    evaluate, y = _problem(0.0, seed)
    plain, floored = _fit(evaluate, None), _fit(evaluate, [[1]])
    assert floored.converged, floored.message
    X = np.column_stack([np.ones(N), AMP * SHAPE])
    u_hat = np.linalg.lstsq(X, y, rcond=None)[0][1]
    if u_hat < 0:  # the optimum is the bound
        assert plain.iterations >= 20 and plain.x[1] < -20, plain.message
        assert "at the dry limit" in floored.message
        assert floored.iterations < 20
        assert abs(floored.x[0] - np.mean(y)) < 0.1 / math.sqrt(N)
    else:
        assert plain.converged


@pytest.mark.parametrize("seed", range(3))
def test_steps_that_lower_the_viscosity_may_span_floor_step_e_folds(seed, monkeypatch):
    """Data made at η = 0.05 and a start 6 e-folds above it (the near-dry start, at the bound
    the noise sets): LM reaches the same interior optimum with steps lowering ln η by up to
    ``FLOOR_STEP`` = 3 as with unit steps, in fewer iterations; a step raising η, and any
    other parameter's, keeps the unit cap."""
    caps = _optimisers.step_caps(np.array([-0.1, -2.0, 2.0]), [0, 1, 3], [1, 3])
    np.testing.assert_array_equal(caps, [1.0, _optimisers.FLOOR_STEP, 1.0])
    evaluate, _ = _problem(0.05, seed)
    start = [np.array([0.0, math.log(20.0)])]
    ends = []
    for cap in (1.0, _optimisers.FLOOR_STEP):
        monkeypatch.setattr(_optimisers, "FLOOR_STEP", cap)
        ends.append(_optimisers.lm(evaluate, start, [N], max_iter=60, tol=1e-4, floors=[[1]])[0])
    unit, long = ends
    assert unit.converged and long.converged
    assert long.iterations < unit.iterations
    # the same optimum, to the 1 % of a standard error the decrement tolerance leaves
    se = np.sqrt(np.diag(np.linalg.inv(unit.J.T @ unit.J)) * (unit.r @ unit.r) / (N - 2))
    assert np.all(np.abs(long.x - unit.x) < 0.03 * se), (long.x - unit.x) / se


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


def _exact_c_interval(y, level, s2):
    """The interval of c at ``level`` standard errors from its closed-form profile: at fixed c,
    χ² is least over u ≥ 0 at u(c) = max(0, (a g)·(y - c)/|a g|²)."""
    film = AMP * LEANING

    def chi2(c):
        u = np.maximum(0.0, (y[None] - c[:, None]) @ film / (film @ film))
        r = c[:, None] + u[:, None] * film - y[None]
        return np.sum(r * r, axis=1)

    c = np.mean(y) + np.linspace(-1.0, 1.0, 40001)
    height = np.sqrt(np.maximum(chi2(c) - chi2(c).min(), 0.0) / s2)
    inside = c[height <= level]
    assert inside[0] > c[0] and inside[-1] < c[-1]  # the grid holds the interval
    return inside[0], inside[-1]


@pytest.mark.parametrize("eta_true, seed", [(0.0, 0), (0.0, 1), (0.0, 3), (0.01, 2),
                                            (0.05, 4), (0.05, 5), (0.1, 6), (0.1, 7)])
def test_companion_interval_matches_the_closed_form(eta_true, seed):
    """The other parameter's interval through η's profile (fitting._profile.companion_intervals)
    against c's own closed-form profile (min over u = η^p ≥ 0), with a film shape that leans
    on c as E* and z0 do on η near dry: both ends at 1σ and 2σ within 0.1 of c's conditional
    error (c is linear in u, not in ln η, between the walk's points; the draws give ≤ 0.05),
    where the symmetric errors miss by more: the conditional one (η held) misses an end at 2σ
    by 0.2 to 1.2 of it, the marginal one (η free, linearised) by 0.3 to 1.1 wherever η's
    interval reaches 0."""
    evaluate, y = _problem(eta_true, seed, LEANING)
    out = _fit(evaluate, [[1]])
    r = out.r
    s2 = float(r @ r) / (N - 2)
    cov = s2 * np.linalg.inv(out.J.T @ out.J)
    found = _profile.profile_interval(lambda x: evaluate([x])[0][0], out.x, r, out.J, 1, s2)
    companion = _profile.companion_intervals(found["path"], 1, s2, 1.0, cov)
    conditional = math.sqrt(cov[0, 0] - cov[0, 1] ** 2 / cov[1, 1])
    assert conditional == pytest.approx(math.sqrt(s2 / N), rel=1e-9)
    c_hat = out.x[0]
    for key, level in _profile.LEVELS.items():
        lo, hi = companion[0][key]
        lo_exact, hi_exact = _exact_c_interval(y, level, s2)
        assert abs(lo - lo_exact) < 0.1 * conditional, (key, lo, lo_exact)
        assert abs(hi - hi_exact) < 0.1 * conditional, (key, hi, hi_exact)

        def misses(sigma, lo_exact=lo_exact, hi_exact=hi_exact, level=level):
            return max(abs(c_hat - level * sigma - lo_exact),
                       abs(c_hat + level * sigma - hi_exact)) / conditional

        if key == "2sigma":
            assert misses(conditional) > 0.15
            if found[key][0] == -math.inf:
                assert misses(math.sqrt(cov[0, 0])) > 0.15
