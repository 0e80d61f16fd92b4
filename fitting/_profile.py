r"""Intervals for a parameter the data bound from one side only: the profile of χ².

Near dry (the film's force below the noise) the viscosity η is determined only from above. Its
linearised error is a symmetric Gaussian on the fit's log scale and does not describe that: over
20 near-dry noise draws it left the truth beyond 2 reported errors in 30 % of the fits
(docs/accuracy.md). The interval comes from the profile of χ² instead (Wilks):

    Δχ²(x) = min over the other parameters of χ²(x, others) − min χ²,    x = ln η,

and the k-σ interval is where √(Δχ²/s²) ≤ k c, with s² the reduced χ² (the residuals are in
units of an estimated noise level) and c the ratio of the parameter's reported error to its
white-noise error (the AR(1) noise and the solver's error, ``fitting._stats``): the profile in
white-noise units, widened as the linearised errors are. Where the profile flattens below that
level on the way down (an e-fold of η changes χ² by less than ``FLAT`` s²: the film no longer
acts), or the model stops running there, the interval reaches 0.

Each point of the walk is one model run of the response alone (no Jacobian: about a quarter of
a fit's iteration): x is set, the other parameters start on the line through the two nearest
points of the profile's path (the others as the previous points left them; from the optimum,
along the slope of the others' linear optimum) and take one
Gauss–Newton step on the optimum's Jacobian (a chord step: they are well determined, and near
dry their columns change little with η): Δχ² + min χ² = |(I − P) r|², P the projection onto
their columns. The
walk goes both ways from the fit's optimum, in steps of ``WIDE_STEP`` while
√(Δχ²/s²) < 1/2 and of ``STEP`` after. A level is placed between the two points that bracket
it, on each side of the profile's lowest point, with √(Δχ²) a power of η between them (the
film's force is a power of η near dry; linear in x where the nearer point is the lowest); where
it starts at the lowest point or is wider than ``STEP``/2, one more point at that estimate
narrows it (at most ``REFINE``).

The other parameters (E* and z0, correlated with η at +0.74 and +0.78 near dry) get intervals
through η's profile (:func:`companion_intervals`): along its path each sits at its optimum
given η, with its conditional error about it, so its interval reaches down to its dry value
where η's reaches 0, asymmetric where a symmetric error would be too wide on one side and too
narrow on the other.
"""

from __future__ import annotations

import math

import numpy as np

#: The interval levels, in standard errors, and their keys in ``stats["intervals"]``.
LEVELS = {"1sigma": 1.0, "2sigma": 2.0}
STEP = 1.0
WIDE_STEP = 2.0
MAX_POINTS = 16
#: Points added inside a level's bracket while it is too coarse (``_coarse``).
REFINE = 3
FLAT = 0.01


def _linear_step(J, j):
    """r ↦ (the others' Gauss–Newton step on J's other columns, the residual it leaves)."""
    others = [i for i in range(J.shape[1]) if i != j]
    if not others:
        return lambda r: (np.zeros(0), r)
    q, R = np.linalg.qr(J[:, others])

    def step(r):
        qr = q.T @ r
        return -np.linalg.solve(R, qr), r - q @ qr

    return step


def _walk(at, x_hat, slope, j, direction, chi2_hat, s2, top):
    """Points (x_j, profile χ², x) from the optimum ``x_hat`` along ``direction`` (±1), ending
    past ``top`` (in √(Δχ²/s²) over ``chi2_hat``), where the profile flattens (downwards), where
    a run fails, or after MAX_POINTS. ``at(x)``: (x_j, profile χ², the others moved) at x with
    x_j set, or None; ``slope``: dx/dx_j along the profile at the optimum."""
    points, previous, height = [], chi2_hat, 0.0
    last = (float(x_hat[j]), chi2_hat, x_hat)
    for _ in range(MAX_POINTS):
        step = WIDE_STEP if height < 0.5 else STEP
        # the others start on the line through the last two points (the profile's path)
        before = points[-2] if len(points) > 1 else None
        x_j = last[0] + direction * step
        x = (_along(before, last, x_j, j) if before else last[2] + (x_j - last[0]) * slope)
        point = at(x)
        if point is None:
            break
        points.append(point)
        last, chi2 = point, point[1]
        height = math.sqrt(max(chi2 - chi2_hat, 0.0) / s2)
        if height >= top or (direction < 0 and abs(chi2 - previous) / (s2 * step) < FLAT):
            break
        previous = chi2
    return points


def _along(p0, p1, x_j, j):
    """x on the line through points p0 and p1 (their moved x) where its component j is x_j."""
    t = (x_j - p0[0]) / (p1[0] - p0[0])
    x = p0[2] + t * (p1[2] - p0[2])
    x[j] = x_j
    return x


def _bracket(side, chi2_min, s2, level):
    """The first index a along ``side`` (points from the lowest outwards) where √(Δχ²/s²)
    reaches ``level``, and the x_j placed there between points a-1 and a (with √Δχ² a power of
    η between them; linear in x_j where point a-1 is the lowest); None where it does not."""
    heights = [math.sqrt(max(c - chi2_min, 0.0) / s2) for _, c, _ in side]
    for a in range(1, len(side)):
        if heights[a] >= level:
            x0, x1 = side[a - 1][0], side[a][0]
            h0, h1 = heights[a - 1], heights[a]
            if h0 > 0.0 and h1 > h0:  # exact for Δχ² a power of η: u = η^p near dry
                return a, x0 + (x1 - x0) * math.log(level / h0) / math.log(h1 / h0)
            return a, x0 + (x1 - x0) * (level - h0) / max(h1 - h0, 1e-300)
    return None


def _coarse(side, a, path) -> bool:
    """Whether the bracket ending at side[a] is too coarse to interpolate: it starts at the
    profile's lowest point (where √Δχ² is no power of η) or is wider than STEP."""
    lowest = min(c for _, c, _ in path)
    return side[a - 1][1] == lowest or abs(side[a][0] - side[a - 1][0]) > STEP / 2


def profile_interval(residuals, x_hat, r_hat, J_hat, j, s2, widen=1.0) -> dict:
    """The profile-χ² intervals of x_j (a log-scaled positive parameter) of one problem.

    Args:
        residuals: x ↦ the problem's residuals at x (the response alone), or None where the
            run fails (``fitting._problem.Evaluator.residuals``).
        x_hat, r_hat, J_hat: x, the residuals and the Jacobian at the optimum.
        j: the parameter's index in x.
        s2: the reduced χ² at the optimum.
        widen: c, the parameter's reported error over its white-noise error.

    Returns:
        dict: for each key of ``LEVELS``, (lo, hi) in x: lo is -inf where the walk down did
        not reach the level (the profile flattened: the interval reaches the parameter's 0; or
        a run failed or the points ran out first: 0 is then the safe side), hi is +inf where
        the walk up did not (a failed run or the point budget);
        ``"runs"``, the model runs taken; ``"path"``, the walk's points (x_j, χ², x) sorted by
        x_j, x with the others moved (:func:`companion_intervals`).
    """
    chi2_hat = float(r_hat @ r_hat)
    s2 = max(s2, 1e-300)
    top = max(LEVELS.values()) * widen
    linear_step = _linear_step(J_hat, j)
    others = [i for i in range(len(x_hat)) if i != j]
    runs = 0

    def at(x):
        # the others' linear step from x on the optimum's Jacobian: Δχ² + min χ² = |(I - P) r|²
        nonlocal runs
        runs += 1
        r = residuals(x)
        if r is None:
            return None
        shift, left = linear_step(r)
        moved = x.copy()
        moved[others] += shift
        return float(x[j]), float(left @ left), moved

    x_hat = np.asarray(x_hat, dtype=float)
    slope = np.zeros_like(x_hat)  # the others' linear optimum moves with x_j by -J_o⁺ J_j
    slope[j] = 1.0
    slope[others] = linear_step(J_hat[:, j])[0]
    path = [*_walk(at, x_hat, slope, j, +1, chi2_hat, s2, top),
            *_walk(at, x_hat, slope, j, -1, chi2_hat, s2, top)]
    path = sorted([*path, (float(x_hat[j]), chi2_hat, x_hat)], key=lambda p: p[0])
    out = {}
    for key, level in LEVELS.items():
        ends = []
        for upwards in (True, False):
            for attempt in range(REFINE + 1):
                lowest = int(np.argmin([c for _, c, _ in path]))
                side = path[lowest:] if upwards else path[lowest::-1]
                found = _bracket(side, path[lowest][1], s2, level * widen)
                if found is None or attempt == REFINE or not _coarse(side, found[0], path):
                    break
                # refine: one more point at the estimate, a tenth of the bracket from its ends
                a, guess = found
                x0, x1 = side[a - 1][0], side[a][0]
                guess = min(max(guess, min(x0, x1) + 0.1 * abs(x1 - x0)),
                            max(x0, x1) - 0.1 * abs(x1 - x0))
                point = at(_along(side[a - 1], side[a], guess, j))
                if point is None:
                    break
                path = sorted([*path, point], key=lambda p: p[0])
            ends.append(None if found is None else found[1])
        hi, lo = ends
        out[key] = (-math.inf if lo is None else lo, math.inf if hi is None else hi)
    out["runs"] = runs
    out["path"] = path
    return out


def companion_intervals(path, j, s2, widen, cov, levels=None) -> dict:
    r"""The intervals of the other parameters through x_j's profile: {i: {level: (lo, hi)}}.

    Along the profile's path each other parameter o sits at its optimum o(x_j) given x_j, and
    about it its spread is the conditional one, σ_c² = C_oo − C_oj² / C_jj (C the fit's
    covariance, as reported). The profile of χ² in o is then (in reported errors)

        P(o) = min over x_j of  D(x_j) + (o − o(x_j))² / σ_c²,    D = Δχ²_j / (s² c²),

    and its k-σ interval, where P ≤ k², is the union over x_j of o(x_j) ± σ_c √(k² − D(x_j)):
    for a Gaussian problem exactly ô ± k √(σ_c² + (∂o/∂x_j)² σ_j²), the marginal error. Where
    x_j is bounded (η near dry: the profile flattens down to the dry limit, o goes to its dry
    value) the interval is asymmetric: it reaches down to the others' dry values, which a
    symmetric error built on η's linearised one cannot do. √D is interpolated linearly
    between the path's points (exact where D is quadratic in x_j), o linearly.

    Args:
        path: the points (x_j, χ², x) of :func:`profile_interval`'s walk, sorted by x_j.
        j: the profiled parameter's index in x.
        s2: the reduced χ² at the optimum.
        widen: c, x_j's reported error over its white-noise error (as in
            :func:`profile_interval`).
        cov: the fit's covariance of x, as reported.
        levels: {key: k}, default ``LEVELS``.

    Returns:
        dict: per other index i whose conditional variance is positive, {key: (lo, hi)} in x.
    """
    levels = LEVELS if levels is None else levels
    chi2 = np.array([p[1] for p in path])
    xs = np.array([p[2] for p in path])
    height = np.sqrt(np.maximum(chi2 - chi2.min(), 0.0) / max(s2, 1e-300)) / widen
    # 32 points in each gap of the path
    t = np.linspace(0.0, 1.0, 33)[:-1]
    fine = np.append((np.arange(len(path) - 1)[:, None] + t).ravel(), len(path) - 1.0)
    index = np.arange(len(path), dtype=float)
    h = np.interp(fine, index, height)
    out = {}
    for i in range(xs.shape[1]):
        if i == j or not np.isfinite(cov[i, i]) or cov[j, j] <= 0:
            continue
        conditional = cov[i, i] - cov[i, j] ** 2 / cov[j, j]
        if not conditional > 0:
            continue
        o = np.interp(fine, index, xs[:, i])
        sigma = math.sqrt(conditional)
        found = {}
        for key, k in levels.items():
            inside = h <= k
            half = sigma * np.sqrt(np.maximum(k * k - h[inside] ** 2, 0.0))
            found[key] = (float(np.min(o[inside] - half)), float(np.max(o[inside] + half)))
        out[i] = found
    return out


#: Parameters bounded below by 0 where the data may stop bounding them: the viscosity (near dry).
BOUNDED_BELOW = ("viscosity",)


def floors_of(labels) -> list[list[int]]:
    """Per problem (its x's ``labels``), the indices of the parameters of ``BOUNDED_BELOW``
    (a joint fit's per-trace labels carry a "[trace]" suffix)."""
    return [[j for j, label in enumerate(names) if label.split("[")[0] in BOUNDED_BELOW]
            for names in labels]


def undetermined_names(values, stderr, fixed) -> list[str]:
    """The positive parameters whose standard error exceeds them: the data bound them from above
    only (the viscosity of a near-dry trace, whose film force is below the noise)."""
    return [name for name, value in values.items()
            if name != "offset" and name not in fixed and value > 0 and stderr[name] > value]


def held_map(names, active, cov, held):
    """The linear map of the fit's errors e ↦ e_o - B e_u (B = Cov_ou Cov_uu⁻¹, u the
    parameters in ``held``, o the other active ones; e_u kept): applied to a covariance it gives
    the others' errors conditional on the held ones. None when nothing is held.

    Why: an undetermined positive parameter (η near dry) is bounded below by 0, so its spread is
    one-sided, mostly at the bound, while its linearised error is a symmetric Gaussian that the
    others' errors share through their correlation (0.74-0.93 for E* and z0 near dry). Over 20
    near-dry noise draws their marginal errors were twice their scatter (rms z 0.51); the
    conditional ones are a little small, since a draw whose η lands high carries E* and z0 with
    it, which their intervals through η's profile hold (:func:`companion_intervals`,
    docs/accuracy.md)."""
    if not held:
        return None
    u = [names.index(n) for n in held]
    o = [i for i in range(len(names)) if active[i] and i not in u]
    cov_uu = cov[np.ix_(u, u)]
    if not (np.all(np.isfinite(cov_uu)) and np.all(np.isfinite(cov[np.ix_(o, u)]))):
        return None
    T = np.eye(len(names))
    T[np.ix_(o, u)] = -cov[np.ix_(o, u)] @ np.linalg.pinv(cov_uu)
    return T


def physical_intervals(names, M, intervals) -> dict:
    """Problem intervals {x index: {level: (lo, hi)}} (on the log scale) as this trace's
    {name: {level: (lo, hi)}} in SI, 0 for a lower end at -inf."""
    out = {}
    for i, name in enumerate(names):
        if name in ("offset", "stiffening"):  # not on a log scale
            continue
        cols = np.flatnonzero(M[i])
        if cols.size == 1 and int(cols[0]) in intervals:
            found = intervals[int(cols[0])]
            out[name] = {key: (math.exp(found[key][0]), math.exp(found[key][1]))
                         for key in LEVELS}
    return out


def undetermined_flags(names, values, stderr, intervals=None) -> list[str]:
    """A flag for each of ``names`` (:func:`undetermined_names`), with its profile interval
    where there is one."""
    out = []
    for name in names:
        value = values[name]
        hint = (" (a near-dry contact: the film's force is below the noise; fix it where the "
                "medium is known, --fix viscosity=...)") if name == "viscosity" else ""
        found = (intervals or {}).get(name)
        if found is None:
            bound = "read it as an upper bound"
        else:
            lo, hi = found["2sigma"]
            bound = (f"from the profile of chi2, {name} < {hi:.3g}" if lo == 0 else
                     f"from the profile of chi2, {lo:.3g} < {name} < {hi:.3g}") + " at 2 sigma"
        out.append(f"{name} is not determined by the data: its standard error is "
                   f"{100 * stderr[name] / value:.0f} % of it; {bound}{hint}")
    return out


def one_sided_intervals(evaluate, outcomes, summaries, floors, progress=None):
    """Per problem, {x index: :func:`profile_interval`} of each parameter of ``floors`` whose
    reported error on its log scale exceeds 1 (it exceeds the value: the data bound it from
    above only, :func:`undetermined_names`), and for the other parameters their intervals
    through its profile (:func:`companion_intervals`)."""
    xs = [o.x for o in outcomes]
    out = []
    for k, (o, summary) in enumerate(zip(outcomes, summaries, strict=True)):
        found, companions = {}, {}
        cov, white = summary["covariance"], summary["parts"]["white"]
        for j in floors[k]:
            if not (np.isfinite(o.r).all() and cov[j, j] > 1.0 and white[j, j] > 0):
                continue
            if progress is not None:
                progress(f"{summary['labels'][j]}: its profile (the data bound it from one side)")

            def residuals(x, k=k):
                return evaluate.residuals([x if i == k else xi for i, xi in enumerate(xs)], k)

            s2, widen = summary["stats"]["reduced_chi2"], math.sqrt(cov[j, j] / white[j, j])
            found[j] = profile_interval(residuals, o.x, o.r, o.J, j, s2, widen)
            path = found[j].pop("path")
            if all(math.isfinite(found[j][key][1]) for key in LEVELS):
                # (where the walk up stopped short, the others' upper path is unknown: they
                # keep their conditional errors)
                for i, levels in companion_intervals(path, j, s2, widen, cov).items():
                    if i not in floors[k]:
                        companions.setdefault(i, []).append(levels)
        for i, each in companions.items():  # several profiled: the union of their intervals
            found[i] = {key: (min(c[key][0] for c in each), max(c[key][1] for c in each))
                        for key in LEVELS}
        out.append(found)
    return out
