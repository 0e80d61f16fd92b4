"""Fit E*, η and z0 to tribometer relaxation traces with the lubjax solver.

Public API (see the module docstrings for the maths):

* :func:`read_trace`, :func:`parse_trace`, :func:`write_trace`, :func:`make_trace`, :class:`Trace`
  — the CSV format of ``data/README.md``;
* :func:`fit_trace`, :func:`fit_traces` (batched), :func:`initial_guess`, :class:`FitResult`,
  :class:`Start` — the least-squares fit (Levenberg–Marquardt by default, or optax L-BFGS);
* :func:`scales_from_trace`, :class:`Scales`, :func:`predict`, :func:`residuals`,
  :func:`residuals_and_jacobian` — the model: SI parameters to force at the samples, forward-mode
  Jacobian;
* :func:`result_to_dict`, :func:`plot_fit` — JSON-ready summaries and the figure.
"""

import lubjax  # noqa: F401  (enables float64 in JAX)

from ._cli import plot_fit, summary_line, write_table
from ._fit import (
    FitResult,
    Start,
    fit_trace,
    fit_traces,
    initial_guess,
    noise_level,
    result_to_dict,
)
from ._io import Trace, format_trace, make_trace, parse_trace, read_trace, write_trace
from ._model import (
    FIT_SETTINGS,
    Scales,
    Solver,
    TraceData,
    make_solver,
    predict,
    residuals,
    residuals_and_jacobian,
    scales_from_trace,
    trace_data,
)

__all__ = [
    "FIT_SETTINGS",
    "FitResult",
    "Scales",
    "Solver",
    "Start",
    "Trace",
    "TraceData",
    "fit_trace",
    "fit_traces",
    "format_trace",
    "initial_guess",
    "make_solver",
    "make_trace",
    "noise_level",
    "parse_trace",
    "plot_fit",
    "predict",
    "read_trace",
    "residuals",
    "residuals_and_jacobian",
    "result_to_dict",
    "scales_from_trace",
    "summary_line",
    "trace_data",
    "write_table",
    "write_trace",
]
