"""The Richardson error estimate of a run: the nested coarse mesh at rtol and at a looser rtol."""

from __future__ import annotations

import numpy as np

from ._discretisation import discretise
from ._output import evaluate_host

#: The series whose global error a run estimates (``Result.force_error`` and the others).
ESTIMATED = ("force", "gap", "film_center", "film_min")
#: The error estimate's observed orders: space 3/2 (the √ edge of a Hertz contact limits the
#: second order of the scheme, tests/test_analytic_limits.py), time 1/2 in rtol (each segment
#: starts with backward Euler; BDF2 alone gives 2/3). The lower orders make it conservative.
SPACE_ORDER, TIME_ORDER = 1.5, 0.5
#: Each estimate is the largest over this many accepted steps either side: the true error and
#: its estimate change sign at different times, and a pointwise bound must cover both.
ESTIMATE_WINDOW = 2
#: The safety factor of Roache's grid convergence index for two grids (Roache, Verification and
#: Validation in Computational Science and Engineering, 1998). The estimates are two-level at
#: assumed orders, and the errors are not always in their asymptotic range (the coarse mesh's
#: error can be 1.5× the fine one's, not 2^{3/2}); with this factor the estimate bounds the
#: force's error at every output time of the accuracy table's 20 cases, at 4.3-8.5× the largest
#: error (docs/accuracy.md).
SAFETY_FACTOR = 3.0


def estimate_runs(mesh, substrate, tol, ptimes) -> list:
    """The estimate's two runs beside a run on ``mesh`` at ``tol``, as (discretisation,
    tolerance, profile times) each: the nested coarse mesh (every other node) at rtol and at
    8 rtol (``Tolerance.loosened``), without profiles."""
    coarse = discretise(mesh.coarsened(), substrate)
    loose = tol.loosened()
    return [(coarse, tol, ptimes[:0]), (coarse, loose, ptimes[:0])]


def error_estimate(value, coarse, loose):
    """Estimated global error of ``value`` (a run on the mesh at rtol) from the same quantity on
    the nested coarse mesh (every other node) at rtol (``coarse``) and at 8 rtol (``loose``):

        e_space = |y - y_coarse| / (2^{3/2} - 1),   e_time = |y_coarse - y_loose| / (8^{1/2} - 1),

    Richardson's estimates at the orders :data:`SPACE_ORDER` and :data:`TIME_ORDER` (global
    error ∝ Δr̄^{3/2} and ∝ rtol^{1/2}), summed, times :data:`SAFETY_FACTOR`, and spread over
    ±``ESTIMATE_WINDOW`` steps. Measured against converged runs (benchmarks/accuracy.py): the
    force's estimate bounds its error at ≥ 95 % of the output times in every case of the table,
    and overestimates the largest error 4-9 times."""
    space = np.abs(value - coarse) / (2.0**SPACE_ORDER - 1.0)
    time_ = np.abs(coarse - loose) / (8.0**TIME_ORDER - 1.0)
    total = SAFETY_FACTOR * (space + time_)
    padded = np.pad(total, ESTIMATE_WINDOW, mode="edge")
    n = total.size
    return np.max([padded[k:k + n] for k in range(2 * ESTIMATE_WINDOW + 1)], axis=0)


def errors_of(series, trajs) -> dict:
    """Each estimated series' error from the estimate's coarse runs (NaN where they were not
    run). On the host (evaluate_host): evaluating with jax compiles ~40 small programs."""
    if len(trajs) == 1:
        return {f: np.full_like(series[f], np.nan) for f in ESTIMATED}
    coarse, loose = (tr.steps for tr in trajs[1:])
    return {
        f: error_estimate(
            series[f],
            evaluate_host(coarse, series["t"], f),
            evaluate_host(loose, series["t"], f),
        )
        for f in ESTIMATED
    }
