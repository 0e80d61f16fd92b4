"""Fit the lubjax soft-EHL model to tribometer traces: E*, η, z0 (and more) with honest errors.

Public API (see the module docstrings for the maths):

* :func:`read_trace`, :func:`parse_trace`, :func:`write_trace`, :func:`make_trace`, :class:`Trace`
  — the CSV format of ``data/README.md``; :func:`read_afm` — AFM and indenter vendor files
  (``pip install lubjax[afm]``);
* :class:`ModelSpec` — what is fitted: the drive (prescribed travel, a spring, force control),
  the substrate (half-space or layer, elastic or viscoelastic) and the offset;
* :func:`fit_traces` (separate, joint with ``shared=``, batched), :func:`fit_trace`,
  :func:`compare_models`, :func:`initial_guess`, :class:`FitResult`, :class:`Start`;
* :func:`scales_from_trace`, :class:`Scales`, :func:`predict`, :func:`residuals`,
  :func:`residuals_and_jacobian`, :func:`trace_data`, :func:`make_solver` — the model;
* :func:`result_to_dict`, :func:`fit_report`, :func:`plot_fit` — reports and the figure;
* :func:`noise_draws`, :func:`coverage` — are the reported errors honest (seeded noise draws)?
"""

import lubjax  # noqa: F401  (enables float64 in JAX)

from ._afm import read_afm
from ._compare import compare_models
from ._coverage import coverage, noise_draws
from ._csv import format_trace, parse_trace, read_trace, write_trace
from ._figure import plot_fit
from ._fit import FitResult, fit_trace, fit_traces
from ._model import (
    FIT_SETTINGS,
    ModelSpec,
    Solver,
    TraceData,
    make_solver,
    predict,
    residuals,
    residuals_and_jacobian,
    trace_data,
)
from ._report import fit_report, result_to_dict, summary_line, write_table
from ._scales import Scales, noise_level, scales_from_trace
from ._start import Start, initial_guess
from ._trace import Trace, make_trace

__all__ = [
    "FIT_SETTINGS",
    "FitResult",
    "ModelSpec",
    "Scales",
    "Solver",
    "Start",
    "Trace",
    "TraceData",
    "compare_models",
    "coverage",
    "fit_report",
    "fit_trace",
    "fit_traces",
    "format_trace",
    "initial_guess",
    "make_solver",
    "make_trace",
    "noise_level",
    "noise_draws",
    "parse_trace",
    "plot_fit",
    "predict",
    "read_afm",
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
