r"""Least-squares fits of the lubjax model to traces: separate, joint and batched.

Loss. With the residuals r(θ) of :mod:`fitting._model` (misfit in units of each trace's noise
σ), minimise S = ½ Σ_k r_k², i.e. ½χ².

The fit composes the modules below it: the starting values (:mod:`fitting._start`), the
problems and their batched evaluator (:mod:`fitting._problem`), an optimiser
(:mod:`fitting._optimisers`), the uncertainties (:mod:`fitting._stats`) and whether the
model describes the data (:mod:`fitting._adequacy`).
"""

from __future__ import annotations

import math
import os
import time
from typing import NamedTuple

import numpy as np

import lubjax
from lubjax._fitting_api import sharding as _sharding

from . import _adequacy, _checks, _model, _profile, _scales, _stats
from ._model import ModelSpec
from ._optimisers import METHODS, OPTIMISERS
from ._problem import Evaluator, fit_mesh, make_layout, solver_error, stack_traces
from ._scales import Scales
from ._start import Start, prepare_starts
from ._trace import Trace


class FitResult(NamedTuple):
    """One fitted trace (:func:`fit_traces`). SI units throughout.

    The parameter names, ``spec.names``, are E_star (E* [Pa]), viscosity (η [Pa s]), z0 (the
    initial gap [m]), then stiffening (E0/E∞) and relaxation_time (τ [s]) for a viscoelastic
    solid, and offset (of the response channel [N or m]).

    Attributes:
        name: the trace's name (its file, or a label).
        spec: the fitted :class:`ModelSpec`.
        values: parameter name → fitted value [SI].
        stderr: parameter name → its reported 1-σ error [SI] (white noise, correlated noise
            and the solver's error, ``stats["error_parts"]``); 0 for a parameter held fixed.
        correlation: the parameters' correlation matrix over ``spec.names``; NaN rows and
            columns for parameters held fixed.
        shared: the parameters fitted jointly with the other traces of ``group`` (empty for a
            separate fit).
        group: the names of the traces of a joint fit (empty for a separate fit).
        scales: the :class:`Scales` read off the trace.
        stats: fit statistics (chi2, reduced_chi2, noise_model, autocorrelation_lag1 (the
            residuals'), noise_correlation (the noise's, AR(1) only), noise_scale (the AR(1)
            noise's variance over the reduced chi-square; 1 otherwise), n_effective,
            rms_residual, condition, max_correlation, error_parts, ...;
            ``fitting._stats.summarise``); where the data bound a parameter from one side
            (η near dry: its standard error exceeds it), ``undetermined`` (their names) and
            ``intervals``, {name: {"1sigma": (lo, hi), "2sigma": (lo, hi)}} [SI] from the
            profile of χ² (``fitting._profile``; lo = 0 where the interval reaches the dry
            limit).
        converged: whether the optimiser converged (the first flag says how).
        identifiable: whether the parameters are identifiable: max |correlation| and the
            condition number within ``fitting._stats``' limits.
        n_iterations: optimiser iterations.
        n_model_runs: model runs (each with its Jacobian).
        method: the optimiser: "lm", "trf" or "lbfgs".
        wall_s: wall time of the fit [s].
        start: the :class:`Start` the fit began from.
        flags: warnings in words: convergence, identifiability, the noise, implausible values.
        time: sample times [s].
        data: the measured response at the samples [N, or m under load control].
        model: the fitted response at the samples [N or m].
        metadata: the trace's ``# key: value`` metadata.
        fixed: the parameters held at given values (``fixed=``), stderr 0.
        input: the drive's measured input at the samples: the stage (indenter) travel [m], or
            the load [N] under load control (None where not recorded).
        adequacy: whether the model describes the data (``fitting._adequacy.Adequacy``: the
            residuals tested against their noise; None for a result made without it).
    """

    name: str
    spec: ModelSpec
    values: dict
    stderr: dict
    correlation: np.ndarray
    shared: tuple
    group: tuple
    scales: Scales
    stats: dict
    converged: bool
    identifiable: bool
    n_iterations: int
    n_model_runs: int
    method: str
    wall_s: float
    start: Start
    flags: tuple
    time: np.ndarray
    data: np.ndarray
    model: np.ndarray
    metadata: dict
    fixed: tuple = ()
    input: np.ndarray | None = None
    adequacy: _adequacy.Adequacy | None = None

    @property
    def E_star(self) -> float:
        """E*, the fitted plane-strain modulus [Pa] (the relaxed one, E*∞, when viscoelastic)."""
        return self.values["E_star"]

    @property
    def viscosity(self) -> float:
        """η, the fitted film viscosity [Pa s]."""
        return self.values["viscosity"]

    @property
    def z0(self) -> float:
        """z0, the fitted initial gap [m]."""
        return self.values["z0"]

    @property
    def offset(self) -> float:
        """The fitted offset of the response channel [N or m]."""
        return self.values["offset"]

    @property
    def beta(self) -> float:
        """β of the fitted values (eq 8e, with the trace's d_c and t_c), dimensionless."""
        return self.scales.beta(self.E_star, self.viscosity)

    @property
    def z0_over_dc(self) -> float:
        """z̄0 = z0/d_c of the fitted values (eq 8e), dimensionless."""
        return self.z0 / self.scales.indent

    @property
    def rms_residual(self) -> float:
        """The rms of data - model [N or m]."""
        return self.stats["rms_residual"]

# --------------------------------------------------------------------------- public API


def _check_args(traces, method, max_iter, tol, starts, scales):
    if method not in METHODS:
        raise ValueError(
            f"method must be 'lm' (Levenberg-Marquardt), 'trf' (scipy least_squares) or "
            f"'lbfgs' (optax), got {method!r}"
        )
    if not traces:
        raise ValueError("traces must contain at least one trace")
    if not (isinstance(max_iter, int) and not isinstance(max_iter, bool) and max_iter >= 1):
        raise ValueError(f"max_iter must be a positive integer, got {max_iter!r}")
    if not (isinstance(tol, (int, float)) and tol > 0):
        raise ValueError(f"tol must be > 0, got {tol!r}")
    for name, given in (("starts", starts), ("scales", scales)):
        if given is not None and len(given) != len(traces):
            raise ValueError(f"{name} must have one entry per trace ({len(traces)}), got "
                             f"{len(given)}")


def _spec_for(traces, spec, drive, substrate_kw):
    if spec is not None:
        return spec
    return ModelSpec(drive=_scales.common_drive(traces, drive), **substrate_kw)


def fit_traces(
    traces: list[Trace],
    *,
    spec: ModelSpec | None = None,
    drive: str | None = None,
    layer=None,
    viscoelastic: bool = False,
    fit_offset: bool = True,
    shared=(),
    method: str = "lm",
    settings=None,
    max_iter: int = 60,
    tol: float = 1e-4,
    starts: list[Start] | None = None,
    scales: list[Scales] | None = None,
    noise: str = "auto",
    model_error: bool = True,
    progress=None,
    devices: int | None = None,
    batching: str = "auto",
    fixed: dict | None = None,
) -> list[FitResult]:
    """Fit traces: each on its own (default), or jointly with ``shared`` parameters.

    Every trace is evaluated in one compiled model/Jacobian call per iteration (each takes its
    own error-controlled steps on one shared mesh), the traces split over the devices (as
    ``lubjax.sweep``: one SPMD program, lubjax/_sharding.py) and mapped or vmap-ed on each
    (``batching``).

    Args:
        traces: :class:`fitting.Trace` objects (``read_trace``).
        spec: a :class:`ModelSpec`; or build one from ``drive``, ``layer``, ``viscoelastic``
            and ``fit_offset``.
        drive: the drive of the model built without ``spec`` (None: each trace's header).
        layer: (H [m], ν, "bonded" | "frictionless") for a layer on a rigid base, or None
            (a half-space).
        viscoelastic: a standard linear solid instead of an elastic one.
        fit_offset: also fit a constant offset of the response.
        shared: parameter names fitted once for all traces (a joint fit), e.g.
            ("E_star", "viscosity"); the others (z0, the offsets) are fitted per trace.
        method: "lm" (default), "trf" (scipy least_squares) or "lbfgs" (optax).
        settings: ``lubjax.Settings`` of the model (default ``fitting.FIT_SETTINGS``).
        max_iter: iteration limit (a positive integer).
        tol: convergence tolerance on the Gauss–Newton decrement/s² (> 0).
        starts: starting values per trace (default: :func:`initial_guess`).
        scales: each trace's :class:`Scales` for the spec's drive, where the caller has them
            already (default: ``scales_from_trace``).
        noise: "auto" (white unless the residuals are not), "white" or "ar1": the noise model
            of the covariance (:mod:`fitting._stats`).
        model_error: fold the solver's estimated error into the errors (:mod:`fitting._stats`).
        progress: optional callable(message) for progress lines (the CLI prints them).
        devices: how many of ``jax.devices()`` the trace batch is split over (default: all).
        batching: how each device evaluates its traces: "map" (one after another, each with its
            own steps, finished fits skipped), "vmap" (all at once) or "auto" (default: "map" on
            CPU, "vmap" on an accelerator; ``lubjax._sharding.batching_mode``).
        fixed: parameters held at known values, {name: SI value} (e.g. {"viscosity": 1e-3} when
            the medium is known): not fitted, their standard error 0; any of ``spec.names``
            except a shared one.

    Returns:
        list[FitResult]: one per trace, in the order of ``traces``, with the values and 1-σ
        errors in SI units (E* [Pa], η [Pa s], z0 [m], ...), the statistics, the flags and the
        model at the samples.

    Raises:
        ValueError: no traces, traces of different drives fitted together, an unknown
            ``method``, ``noise``, ``batching`` or ``shared`` name, a ``max_iter``, ``tol``,
            start or ``fixed`` value out of range (the message names the parameter).

    Example:
        ```python
        import dataclasses
        import fitting

        trace = fitting.read_trace("data/paper_dc140.csv")
        coarse = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3)
        (res,) = fitting.fit_traces([trace], settings=coarse)
        assert res.converged
        E_star, eta = res.values["E_star"], res.values["viscosity"]  # Pa, Pa s
        ```
    """
    _check_args(traces, method, max_iter, tol, starts, scales)
    _sharding.batching_mode(batching)
    n_dev = _sharding.device_count(devices)
    spec = _spec_for(traces, spec, drive,
                     dict(layer=layer, viscoelastic=viscoelastic, fit_offset=fit_offset))
    shared = tuple(shared)
    if noise not in _stats.NOISE_MODELS:
        raise ValueError(f"noise must be one of {', '.join(_stats.NOISE_MODELS)}, got {noise!r}")
    fixed, scales, starts = prepare_starts(traces, spec, shared, fixed, starts, scales)
    groups = [list(range(len(traces)))] if shared else [[t] for t in range(len(traces))]
    t0 = time.perf_counter()
    settings = _model.FIT_SETTINGS if settings is None else settings
    mesh = fit_mesh(traces, starts, scales, spec, settings)
    solver = _model.Solver(lubjax.stepper.discretise(mesh), settings.tolerance())
    data = stack_traces(traces, scales, spec, mesh)
    theta0 = np.array([[_model.to_theta(n, st.values[n], sc.response_unit) for n in spec.names]
                       for st, sc in zip(starts, scales, strict=True)])
    names = [_short_name(tr.name) for tr in traces]
    layout, x0s = make_layout(groups, spec, names, theta0, shared, tuple(fixed))
    evaluate = Evaluator(data, solver, spec, layout, groups, n_dev, batching)
    n_samples = [sum(traces[t].time.size for t in g) for g in groups]

    def report(it, cost, done):
        if progress is not None:
            progress(f"iteration {it}, chi2/2 {float(np.max(cost)):.6g}, "
                     f"{int(np.sum(done))}/{len(done)} done")

    floors = _profile.floors_of(layout.labels)
    outcomes = OPTIMISERS[method](evaluate, x0s, n_samples, max_iter=max_iter, tol=tol,
                                   progress=report, **(dict(floors=floors) if method == "lm"
                                                       else {}))
    xs = [o.x for o in outcomes]
    # The model at the optimum from its residuals (r = w (y - y_data)/σ): no separate prediction
    # function to trace, lower and load from the compilation cache.
    n_pad = data.weight.shape[1]
    r_all = np.zeros((len(traces), n_pad))
    for k, members in enumerate(groups):
        for j, t in enumerate(members):
            r_all[t] = outcomes[k].r[j * n_pad : (j + 1) * n_pad]
    model = np.asarray(data.response) + r_all * np.asarray(data.noise)[:, None]
    errors = solver_error(evaluate, xs, r_all, traces, scales, spec, settings, mesh, groups) if (
        model_error) else None
    # the solver's error estimate of each trace's model [its response's unit]
    model_errors = [None] * len(traces)
    for k, members in enumerate(groups if errors is not None else []):
        for j, t in enumerate(members):
            own = errors[k][j * n_pad : j * n_pad + traces[t].time.size]
            model_errors[t] = own * float(data.noise[t])
    summaries = [
        _stats.summarise(o.r, o.J, [(n_pad, traces[t].time.size) for t in members],
                         layout.labels[k], noise=noise,
                         solver_error=None if errors is None else errors[k])
        for k, (o, members) in enumerate(zip(outcomes, groups, strict=True))]
    intervals = _profile.one_sided_intervals(evaluate, outcomes, summaries, floors, progress)
    wall = (time.perf_counter() - t0) / len(traces)
    results = []
    for k, members in enumerate(groups):
        o, summary = outcomes[k], summaries[k]
        for j, t in enumerate(members):
            joint = shared if len(members) > 1 else ()
            start = _start_used(starts[t], spec, layout, t, x0s[k], scales[t], joint)
            results.append(_trace_result(traces[t], spec, scales[t], start, layout, t, o,
                                         summary, j, members, names, shared, method,
                                         evaluate.runs, wall, model[t, : traces[t].time.size],
                                         fixed, model_errors[t], intervals[k]))
    return results


def fit_trace(trace: Trace, **kwargs) -> FitResult:
    """Fit one trace.

    Args:
        trace: the :class:`Trace`.
        **kwargs: as :func:`fit_traces`.

    Returns:
        FitResult: the fit.

    Raises:
        ValueError: as :func:`fit_traces`.
    """
    return fit_traces([trace], **kwargs)[0]


def _short_name(path):
    return os.path.splitext(os.path.basename(path))[0] or "trace"


def _trace_result(trace, spec, scales, start, layout, t, outcome, summary, j, members, names,
                  shared, method, runs, wall, model, fixed=None, model_error=None,
                  intervals=None) -> FitResult:
    """Map a problem's x, covariance and statistics onto trace t's parameters (SI), and judge
    whether the model describes the trace (``fitting._adequacy``)."""
    M = layout.M[t]
    theta = layout.base[t] + M @ outcome.x
    values, stderr, deriv = {}, {}, np.zeros(len(spec.names))
    fixed = fixed or {}
    for i, n in enumerate(spec.names):
        values[n], deriv[i] = _model.to_physical(n, float(theta[i]), scales.response_unit)
    values.update(fixed)  # exactly as given, not through exp(log(value))
    cov_theta = M @ summary["covariance"] @ M.T
    active = layout.active
    cov_theta[~active, :] = np.nan
    cov_theta[:, ~active] = np.nan

    def errors_of(cov):
        # A near-singular JᵀJ can leave a variance <= 0 or NaN: no standard error, not an error.
        return {n: (abs(deriv[i]) * math.sqrt(cov[i, i]) if cov[i, i] >= 0 else math.nan)
                if active[i] else 0.0 for i, n in enumerate(spec.names)}

    stderr = errors_of(cov_theta)
    se = np.sqrt(np.diag(cov_theta))
    corr = cov_theta / np.outer(se, se)
    held = _profile.undetermined_names(values, stderr, fixed)
    held_map = _profile.held_map(spec.names, active, cov_theta, held)
    free_stderr = stderr
    if held_map is not None:
        stderr = errors_of(held_map @ cov_theta @ held_map.T)
    parts = {}
    for part, cov in summary["parts"].items():
        c = M @ cov @ M.T
        if held_map is not None:
            c = held_map @ c @ held_map.T
        parts[part] = {n: float(abs(deriv[i]) * math.sqrt(max(c[i, i], 0.0)))
                       for i, n in enumerate(spec.names) if active[i]}
    n = trace.time.size
    first = sum(length for length, _ in summary["sizes"][:j])
    r_t = outcome.r[first : first + n]
    stats = dict(summary["stats"])
    profiled = _profile.physical_intervals(spec.names, M, intervals or {})
    if profiled:
        stats["intervals"] = profiled
    stats.update(
        rms_residual=float(np.sqrt(np.mean((model - _channel(trace, spec)) ** 2))),
        autocorrelation_lag1_trace=float(_stats.lag1(r_t)),
        error_parts=parts,
        noise_sigma=float(_scales.noise_level(_channel(trace, spec))),
        condition=summary["condition"],
        max_correlation=summary["max_correlation"],
    )
    flags = [outcome.message]
    identifiable = bool(summary["max_correlation"] <= _stats.MAX_CORRELATION
                        and summary["condition"] <= _stats.MAX_CONDITION)
    if not identifiable:
        flags.append(
            f"parameters not identifiable: max |correlation| = {summary['max_correlation']:.6f}, "
            f"condition number {summary['condition']:.3g}"
        )
    if not outcome.converged:
        flags.append("fit did not converge: treat the values and errors as unreliable")
    flags += _profile.undetermined_flags(held, values, free_stderr, profiled)
    if held_map is not None:
        others = [n for i, n in enumerate(spec.names)
                  if active[i] and n not in held and n != "offset"]
        free = ", ".join(f"{n} ± {free_stderr[n]:.3g}" for n in others)
        spread = ("their intervals follow its profile (the report's profile of chi2)"
                  if all(n in profiled for n in others) else "theirs follows it only in part")
        flags.append(
            f"the errors of {', '.join(others)} hold {', '.join(held)} fixed (with it free, "
            f"symmetric errors: {free}): {held[0]} cannot fall below 0, so its spread is "
            f"one-sided; {spread}")
    flags += summary["flags"]
    if held:
        stats["undetermined"] = list(held)
    # an undetermined value (η at the dry limit) says nothing of the units
    flags += _checks.plausibility_flags(
        {n: v for n, v in values.items() if n not in fixed and n not in held}, scales.speed,
        _checks.e_star_range(trace.metadata))
    adequacy = judge_adequacy(trace, spec, scales, model, int(np.count_nonzero(M.any(axis=1))),
                              model_error)
    if adequacy.ok is False:
        flags.append(adequacy.message)
    return FitResult(
        name=trace.name, spec=spec, values=values, stderr=stderr, correlation=corr,
        shared=tuple(s for s in shared if len(members) > 1),
        group=tuple(names[m] for m in members) if len(members) > 1 else (),
        scales=scales, stats=stats, converged=outcome.converged, identifiable=identifiable,
        n_iterations=outcome.iterations, n_model_runs=runs, method=method, wall_s=wall,
        start=start, flags=tuple(flags), time=trace.time, data=_channel(trace, spec),
        model=model, metadata=dict(trace.metadata), fixed=tuple(fixed),
        input=trace.force if spec.drive == "force" else trace.displacement,
        adequacy=adequacy,
    )


def judge_adequacy(trace, spec, scales, model, n_params, model_error=None):
    """Whether ``model`` (the fitted response at the trace's samples) describes the trace:
    ``fitting._adequacy.judge`` on its residuals, by the trace's segments.

    Args:
        trace: the :class:`Trace`.
        spec: the fitted :class:`ModelSpec`.
        scales: the trace's :class:`Scales`.
        model: the fitted response at the samples [N, or m under load control].
        n_params: the parameters fitted to this trace.
        model_error: the solver's error estimate of ``model`` (same unit), or None.

    Returns:
        fitting._adequacy.Adequacy: the judgement.
    """
    data = _channel(trace, spec)
    segments = _adequacy.segments_of(trace.time, trace.metadata, scales.t_on,
                                     scales.t_on + scales.t_end_motion * scales.time_scale)
    return _adequacy.judge(data - model, segments, n_params, peak=float(np.ptp(data)),
                           model_error=model_error, viscoelastic=spec.viscoelastic,
                           layer=spec.layer is not None, drive=spec.drive,
                           metadata=trace.metadata)


def _start_used(start, spec, layout, t, x0, scales, shared) -> Start:
    """Trace t's start with each shared parameter at the value the joint fit started from: one
    for the whole group (the mean of the traces' own starts on the fit's log scale)."""
    if not shared:
        return start
    theta = layout.base[t] + layout.M[t] @ x0
    values = dict(start.values)
    for n in shared:
        i = spec.names.index(n)
        values[n] = _model.to_physical(n, float(theta[i]), scales.response_unit)[0]
    note = (f"shared {', '.join(shared)}: one start for all traces, the mean of their own "
            "starts on a log scale")
    return Start(values, (*start.notes, note))


def _channel(trace, spec):
    return trace.displacement if spec.drive == "force" else trace.force
