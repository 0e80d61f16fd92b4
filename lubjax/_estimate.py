"""The Richardson error estimate of a run: the nested coarse mesh at rtol and at a looser rtol."""

from __future__ import annotations

import numpy as np

from ._controller import LOOSENING
from ._discretisation import discretise
from ._output import evaluate_host

#: The series whose global error a run estimates (``Result.force_error`` and the others).
ESTIMATED = ("force", "gap", "film_center", "film_min")
#: The scheme's observed orders of global error: in the mesh spacing 2 on smooth films and 3/2
#: where the √ edge of a Hertz contact limits it (tests/test_analytic_limits.py); in rtol 2/3 for
#: BDF2 and 1/2 for backward Euler, which starts each segment (tests/test_stepper.py).
SMOOTH_SPACE_ORDER, EDGE_SPACE_ORDER = 2.0, 1.5
BDF2_TIME_ORDER, EULER_TIME_ORDER = 2.0 / 3.0, 0.5
#: :func:`error_estimate`, a pointwise bound, takes the lower orders: it is conservative.
SPACE_ORDER, TIME_ORDER = EDGE_SPACE_ORDER, EULER_TIME_ORDER
#: Each estimate is the largest over this many accepted steps either side: the error and its
#: estimate change sign at different times.
ESTIMATE_WINDOW = 2
#: Roache's two-grid safety factor (Roache 1998); docs/accuracy.md measures what it covers.
SAFETY_FACTOR = 3.0


def estimate_runs(mesh, substrate, indenter, tol, ptimes) -> list:
    """The estimate's two runs beside a run on ``mesh`` at ``tol``, as (discretisation,
    tolerance, profile times) each: the nested coarse mesh (every other node) at rtol and at
    8 rtol (``Tolerance.loosened``), without profiles."""
    coarse = discretise(mesh.coarsened(), substrate, indenter)
    loose = tol.loosened()
    return [(coarse, tol, ptimes[:0]), (coarse, loose, ptimes[:0])]


def richardson(difference, ratio, order):
    """Richardson's estimate of the error of the finer of two runs whose mesh spacing (or rtol)
    differs by ``ratio``, for a global error ∝ spacing^``order``: difference/(ratio^order - 1).

    Args:
        difference: the coarser run's value less the finer one's (or its magnitude).
        ratio: the coarser run's spacing (or rtol) over the finer one's, > 1.
        order: the global error's order in that spacing.

    Returns:
        The finer run's error (signed as ``difference``).
    """
    return difference / (ratio**order - 1.0)


def error_estimate(value, coarse, loose):
    """Estimated global error of ``value`` (a run on the mesh at rtol) from the same quantity on
    the nested coarse mesh (every other node) at rtol (``coarse``) and at 8 rtol (``loose``):

        e_space = |y - y_coarse| / (2^{3/2} - 1),   e_time = |y_coarse - y_loose| / (8^{1/2} - 1),

    Richardson's estimates at the orders :data:`SPACE_ORDER` and :data:`TIME_ORDER`, summed,
    times :data:`SAFETY_FACTOR`, spread over ±``ESTIMATE_WINDOW`` steps."""
    space = richardson(np.abs(value - coarse), 2.0, SPACE_ORDER)
    time_ = richardson(np.abs(coarse - loose), LOOSENING, TIME_ORDER)
    total = SAFETY_FACTOR * (space + time_)
    padded = np.pad(total, ESTIMATE_WINDOW, mode="edge")
    n = total.size
    # (fmax: the NaN of times the coarse runs did not reach stays there, not spread before it)
    spread = np.fmax.reduce([padded[k:k + n] for k in range(2 * ESTIMATE_WINDOW + 1)], axis=0)
    return np.where(np.isnan(total), np.nan, spread)


def errors_of(series, trajs) -> dict:
    """Each estimated series' error from the estimate's coarse runs (NaN where they were not
    run), on the host: with jax it would compile ~40 small programs."""
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
