r"""Least-squares fits of the lubjax model to traces: separate, joint and batched.

Loss. With the residuals r(θ) of :mod:`fitting._model` (misfit in units of each trace's noise
σ), minimise S = ½ Σ_k r_k², i.e. ½χ².

Problems. A fit is a set of *problems*, each a parameter vector x and the traces it explains:
trace t of problem k uses θ_t = θ_t⁰ + M_t x (M_t a 0/1 selection, θ_t⁰ the values held fixed).
Separate fits are one problem per trace; a joint fit (``shared=``) is one problem whose x holds
the shared parameters once and the other parameters once per trace. Every trace of every problem
is evaluated in one ``vmap``-ed call, and each problem keeps its own optimiser state.

Optimisers (``method=``):

* ``"lm"`` (default): Levenberg–Marquardt on the forward-mode Jacobian J = ∂r/∂x. Step
  (JᵀJ + λ diag JᵀJ) δ = -Jᵀr, accepted when S decreases (then λ ← λ/3, else λ ← 4λ), with
  |δ_i| ≤ 1 (a factor e per step in E*, η, z0). A step whose run makes the film negative or
  non-finite counts as rejected. The Jacobian comes with the residuals at about the cost of one
  run (the tangents reuse the step's factorisation), so every trial evaluates both: one model run
  per iteration.
* ``"trf"``: ``scipy.optimize.least_squares`` (trust-region reflective) on the same residuals
  and Jacobian, one problem after another (benchmarks/fit_benchmark.py compares the two).
* ``"lbfgs"``: ``optax.lbfgs`` on S with reverse-mode ``jax.grad`` (the stepper's checkpointed
  scan), one problem after another. Its line search needs a smoother S than LM does: S is
  smooth in θ only to the model's tolerance (the steps the controller takes change with θ), and
  from data/paper_dc140.csv's physics start the zoom line search stalls in that roughness at
  FIT_SETTINGS' rtol 3e-4, χ² 5.8 above the optimum after 60 iterations (not converged); with
  ``settings=dataclasses.replace(FIT_SETTINGS, rtol=1e-5)`` (CLI: ``--rtol 1e-5``) it converges
  in 20 (benchmarks/fit_benchmark.py --only optimisers, docs/accuracy.md, "Optimisers").

Convergence: the Gauss–Newton decrement gᵀ(JᵀJ)⁻¹g with g = Jᵀr, in units of the residual variance
s² = 2S/(n - p), below ``tol`` (1e-4): the remaining step is under 1 % of a standard error. An
error-controlled model is smooth in θ only to its tolerance (the step choices change with θ), so
the cost may stall first: stalled twice with the decrement below ``STALL_DECREMENT``, or no
decreasing step at all (λ > 1e12) with the decrement below ``NOISE_DECREMENT``, counts as
converged, at the model's accuracy (the message says which and gives the decrement).

Uncertainties: :mod:`fitting._stats`.
"""

from __future__ import annotations

import math
import os
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

import lubjax
from lubjax._fitting_api import compiler as _compiler
from lubjax._fitting_api import sharding as _sharding
from lubjax._fitting_api import single_threaded_blas

from . import _adequacy, _cache, _checks, _model, _stats
from ._io import Trace
from ._model import ModelSpec, Scales

STALL_RTOL = 1e-7
STALL_DECREMENT = 0.05
#: Where not even a short gradient step (λ > 1e12) lowers the cost, the cost is rough on a finer
#: scale than the step the quadratic model predicts: the model's own noise. With the decrement
#: below this the optimum it predicts is within half a standard error (√0.25): converged at the
#: model's accuracy. Seen on one of 100 noise draws (benchmarks/fit_benchmark.py --only batch):
#: stuck at decrement 0.096 (0.3 SE), while compiling the model with other (equally valid)
#: rounding converged 0.2 SE away in 14 iterations.
NOISE_DECREMENT = 0.25
METHODS = ("lm", "trf", "lbfgs")


class Start(NamedTuple):
    """Starting values of a fit and how they were found (``start.E_star``, ``start.z0``, ...
    read ``values``).

    Attributes:
        values: parameter name (the spec's) → starting value [SI].
        notes: how each was found, in words.
    """

    values: dict
    notes: tuple

    def __getattr__(self, name):  # start.E_star, start.z0, ...
        try:
            return self.values[name]
        except KeyError:
            raise AttributeError(name) from None


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
        stats: fit statistics (chi2, reduced_chi2, noise_model, autocorrelation_lag1,
            rms_residual, condition, max_correlation, error_parts, ...;
            ``fitting._stats.summarise``).
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


# --------------------------------------------------------------------------- starting values


def _travel_guess(t, d, f, scales: Scales, notes: list) -> dict:
    r"""Relaxation test (position control): Reynolds on the loading, then Hertz or t_R.

    1. Offset b0: median force over the quiescent samples (before t_on).
    2. Early loading, where the film is thick and the sphere is effectively rigid, follows
       Reynolds' squeeze film F = 6πηR² v/(z0 - d) (eq 12b). Writing it as F z0 - c v = F d
       with c = 6πηR² makes it linear in (z0, c): least squares over the loading samples with
       F between max(5 % of the peak, 3σ) and 40 % of the peak gives z0 and η.
    3. E* from the hold: if the film has drained to a Hertz contact (z0 < d_c) the end-of-hold
       force is F∞ = (4/3)E*√R(d_c - z0)^{3/2} (eq 16). This is only used when d_c - z0 is well
       determined (> 0.2 d_c); otherwise E* comes from the relaxation time t_R = t_c/β: the
       time t½ after the force peak for it to fall halfway to its final value is
       t½ ≈ C·t_c/β, hence β and then E* = 6πηv0R^{3/2}β/d_c^{5/2}. C = ``RELAX_CONSTANT`` = 8
       is the geometric mean over the noiseless paper traces; it drifts from 4 to 14 as
       z̄0 goes from 1.1 to 0.9 (the late hold is limited by drainage of the trapped film, not
       by t_R alone), so this start is good to a factor ~2 — enough for Levenberg–Marquardt.
    """
    R, dc, v0, tc = scales.radius, scales.indent, scales.speed, scales.time_scale
    quiet = t < scales.t_on
    offset = float(np.median(f[quiet])) if np.count_nonzero(quiet) >= 3 else 0.0
    fc = f - offset
    sigma = _model.noise_level(f)
    smooth = np.convolve(fc, np.ones(5) / 5, mode="same")
    k_peak = int(np.argmax(smooth))
    f_peak = float(smooth[k_peak])
    v = np.gradient(d, t)
    idx = np.arange(t.size)
    sel = (
        (t > scales.t_on) & (idx < k_peak) & (fc > max(0.05 * f_peak, 3 * sigma))
        & (fc < 0.4 * f_peak) & (v > 0.5 * v0)
    )
    z0 = eta = None
    if np.count_nonzero(sel) >= 3:
        A = np.stack([fc[sel], -v[sel]], axis=1)
        (z0_ls, c), *_ = np.linalg.lstsq(A, fc[sel] * d[sel], rcond=None)
        if c > 0 and z0_ls > np.max(d[sel]):
            z0, eta = float(z0_ls), float(c / (6 * math.pi * R**2))
            notes.append(f"z0, eta from Reynolds' squeeze film on {np.count_nonzero(sel)} samples")
    loading = (t > scales.t_on) & (idx <= k_peak) & (fc > max(0.05 * f_peak, 3 * sigma))
    dry = _hertz_loading(d, fc, v, loading, sel, R, z0, eta)
    if dry is not None:
        z0, E_dry = dry
        # no squeeze film above the noise: η at the bound that sets, 3σ at a gap of 0.05 d_c
        eta = 3 * sigma * 0.05 * dc / (6 * math.pi * R**2 * v0)
        notes.append("z0, E* from Hertz on the loading (a near-dry contact: it fits the loading "
                     "better than Reynolds' squeeze film); eta at the bound the noise sets")
        return dict(E_star=E_dry, viscosity=float(eta), z0=float(z0), offset=offset)
    if z0 is None:
        z0 = dc
        eta = f_peak * 0.3 * dc / (6 * math.pi * R**2 * v0)
        notes.append("Reynolds fit failed: z0 = d_c, eta from the peak force with a 0.3 d_c gap")
    tail = max(3, t.size // 20)
    f_end = float(np.median(fc[-tail:]))
    E_star = None
    if dc - z0 > 0.2 * dc and f_end > 10 * sigma / math.sqrt(tail):
        E_star = 3 * f_end / (4 * math.sqrt(R) * (dc - z0) ** 1.5)
        notes.append("E* from the Hertz plateau (eq 16)")
    if E_star is None:
        half = f_end + 0.5 * (f_peak - f_end)
        after = np.flatnonzero((idx > k_peak) & (smooth < half))
        t_half = float(t[after[0]] - t[k_peak]) if after.size else tc
        beta = RELAX_CONSTANT * tc / max(t_half, 1e-3 * tc)
        E_star = lubjax.modulus_for_beta(beta, R, dc, speed=v0, viscosity=eta)
        notes.append(f"E* from the relaxation time t_R = t_c/beta (t_half = {t_half:.3g} s)")
    return dict(E_star=float(E_star), viscosity=float(eta), z0=float(z0), offset=offset)


def _hertz_loading(d, f, v, loading, window, R, z0_squeeze, eta):
    """(z0, E*) of Hertz's F = (4/3)E*√R (d - z0)^{3/2} (eq 14) fitted to the ``loading``
    samples, where its z0 lies between the start and the deepest travel and it fits the
    squeeze fit's ``window`` at least 3× better (rms) than the squeeze film F = 6πηR² v/(z0 - d)
    with ``z0_squeeze``, ``eta`` (None: the squeeze fit failed); else None. Linear in (k, k z0)
    for F^{2/3} = k (d - z0), k = ((4/3)E*√R)^{2/3}: the classical contact-point fit. A near-dry
    contact (β ≳ 10⁵) pushes the squeeze film's force below the noise before contact, so the
    loading is Hertz's and the squeeze fit's z0 is off."""
    if np.count_nonzero(loading) < 5:
        return None
    A = np.stack([d[loading], -np.ones(np.count_nonzero(loading))], axis=1)
    (k, kz0), *_ = np.linalg.lstsq(A, np.cbrt(f[loading]) ** 2, rcond=None)
    if k <= 0 or not 0.0 < kz0 / k < np.max(d[loading]):
        return None
    z0 = kz0 / k
    if z0_squeeze is not None and np.count_nonzero(window) >= 3:
        dw, fw = d[window], f[window]
        hertz = k**1.5 * np.clip(dw - z0, 0.0, None) ** 1.5
        squeeze = 6 * math.pi * eta * R**2 * v[window] / (z0_squeeze - dw)
        if np.sqrt(np.mean((hertz - fw) ** 2)) > np.sqrt(np.mean((squeeze - fw) ** 2)) / 3.0:
            return None
    return float(z0), float(0.75 * k**1.5 / math.sqrt(R))


def _creep_guess(t, load, d, scales: Scales, notes: list) -> dict:
    r"""Creep (load control): Reynolds drainage, then Hertz.

    1. Offset: median displacement over the quiescent samples.
    2. While the film is thick the sphere is effectively rigid and Reynolds' F = 6πηR²(-ż)/z
       integrates to z = z0 exp(-I(t)/(6πηR²)), I = ∫F dt: the approach d = z0(1 - e^{-aI}).
       For each z0 on a grid, a (hence η) by least squares of ln(z0/(z0 - d)) = aI over the
       samples with 5 % < d < 50 % of the final approach; the z0 with the smallest misfit of d.
    3. E* from Hertz: the final approach d_end = z0 + δ, δ ≈ (3F/(4E*√R))^{2/3} (an undrained
       film makes δ smaller, so this E* is high, typically by < 2×).
    """
    R = scales.radius
    quiet = t < scales.t_on
    offset = float(np.median(d[quiet])) if np.count_nonzero(quiet) >= 3 else 0.0
    dc = d - offset
    d_end = scales.indent
    impulse = np.concatenate([[0.0], np.cumsum(0.5 * (load[1:] + load[:-1]) * np.diff(t))])
    sel = (dc > 0.05 * d_end) & (dc < 0.5 * d_end) & (t > scales.t_on)
    best = None
    if np.count_nonzero(sel) >= 3:
        for z0 in np.geomspace(0.55, 1.0, 40) * d_end:
            if z0 <= np.max(dc[sel]):
                continue
            y = np.log(z0 / (z0 - dc[sel]))
            a = float(y @ impulse[sel] / (impulse[sel] @ impulse[sel]))
            if a <= 0:
                continue
            err = float(np.sum((dc[sel] - z0 * (1 - np.exp(-a * impulse[sel]))) ** 2))
            if best is None or err < best[0]:
                best = (err, z0, a)
    if best is not None:
        _, z0, a = best
        eta = 1.0 / (6 * math.pi * R**2 * a)
        notes.append(f"z0, eta from Reynolds drainage under the load on {np.count_nonzero(sel)}"
                     " samples")
    else:
        z0, eta = 0.8 * d_end, 1.0
        notes.append("Reynolds drainage fit failed: z0 = 0.8 of the final approach, eta = 1 Pa s")
    delta = max(d_end - z0, 0.1 * d_end)
    E_star = 3 * scales.input_end / (4 * math.sqrt(R) * delta**1.5)
    notes.append("E* from Hertz with the final approach less z0")
    return dict(E_star=float(E_star), viscosity=float(eta), z0=float(z0), offset=offset)


def initial_guess(trace: Trace, scales: Scales, spec: ModelSpec | None = None) -> Start:
    """Starting values from the physics, not from the user.

    Relaxation test: z0 and η from Reynolds' squeeze film on the loading, F = 6πηR² v/(z0 - d)
    (eq 12b), E* from Hertz at the end of the hold (eq 16) or from the relaxation time
    t_R = t_c/β; creep: z0 and η from the Reynolds drainage, E* from Hertz's indentation. For a
    sphere on a spring the sphere's own travel, stage travel less F/k, goes into the
    relaxation-test rules. A viscoelastic solid starts at E0/E∞ = 1.2 and τ = t_c
    (:func:`compare_models` starts it from the elastic fit instead, at three τ).

    Args:
        trace: the :class:`Trace`.
        scales: its :class:`Scales` (:func:`scales_from_trace`).
        spec: the :class:`ModelSpec`; None (default): the drive the trace's metadata names.

    Returns:
        Start: a value per parameter of ``spec.names`` [SI] and notes on how
        each was found.
    """
    spec = ModelSpec(drive=_model.drive_of(trace)) if spec is None else spec
    notes: list[str] = []
    if spec.drive == "force":
        values = _creep_guess(trace.time, trace.force, trace.displacement, scales, notes)
    else:
        d = trace.displacement
        if spec.drive == "spring":
            d = d - trace.force / trace.meta_float("stiffness_N_m")
            notes.append("sphere travel = stage travel - F/k")
        values = _travel_guess(trace.time, d, trace.force, scales, notes)
    if spec.viscoelastic:
        values.update(stiffening=1.2, relaxation_time=scales.time_scale)
        notes.append("E0/Einf = 1.2, tau = t_c")
    if not spec.fit_offset:
        values["offset"] = 0.0
    return Start({n: values[n] for n in spec.names}, tuple(notes))


#: t½ ≈ RELAX_CONSTANT · t_c/β (see :func:`initial_guess`).
RELAX_CONSTANT = 8.0


# --------------------------------------------------------------------------- problems


class _Layout(NamedTuple):
    """Where each trace's θ comes from: θ_t = base[t] + M[t] @ x of its problem."""

    problem: np.ndarray  # (T,) problem index of each trace
    base: np.ndarray  # (T, P)
    M: list  # per trace (P, n_k)
    labels: list  # per problem: parameter labels of x
    active: np.ndarray  # (P,) which θ components are fitted (not held fixed)


def _layout(groups, spec: ModelSpec, names_of_traces, theta0, shared,
            fixed=()) -> tuple[_Layout, list]:
    """Parameter layout and starting x for problems ``groups`` (lists of trace indices); the
    ``fixed`` parameters stay at their θ0 like an offset that is not fitted."""
    P = len(spec.names)
    active = spec.active & np.array([n not in fixed for n in spec.names])
    T = theta0.shape[0]
    problem = np.zeros(T, int)
    base = np.where(active, 0.0, theta0)
    M = [None] * T
    labels, x0s = [], []
    for k, members in enumerate(groups):
        sh = [i for i, n in enumerate(spec.names) if active[i] and n in shared and len(members) > 1]
        own = [i for i in range(P) if active[i] and i not in sh]
        n = len(sh) + len(own) * len(members)
        lab = [spec.names[i] for i in sh]
        x0 = [float(np.mean(theta0[members, i])) for i in sh]
        for j, t in enumerate(members):
            problem[t] = k
            m = np.zeros((P, n))
            for a, i in enumerate(sh):
                m[i, a] = 1.0
            for a, i in enumerate(own):
                m[i, len(sh) + j * len(own) + a] = 1.0
            M[t] = m
            suffix = f"[{names_of_traces[t]}]" if len(members) > 1 else ""
            lab += [spec.names[i] + suffix for i in own]
            x0 += [float(theta0[t, i]) for i in own]
        labels.append(lab)
        x0s.append(np.array(x0))
    return _Layout(problem, base, M, labels, active), x0s


class _Evaluator:
    """(r, J, film) of every problem at given x, in one call over all traces (mapped or vmap-ed:
    ``lubjax._sharding.batching_mode``).

    The trace axis is split over ``devices`` devices (lubjax/_sharding.py): the stacked data
    and θ are padded to a multiple of the device count (repeating the last trace) and laid out
    with ``NamedSharding(mesh, P("batch"))``, the solver (mesh arrays) replicated, and the one
    jit-ed call is a ``shard_map`` of the vmap-ed model over the devices; the padded rows are
    cut off. With one device nothing is padded or placed: the call is the plain jit of
    before."""

    def __init__(self, data, solver, spec, layout: _Layout, groups, devices: int = 1,
                 batching: str = "auto"):
        self.data, self.solver, self.spec = data, solver, spec
        self.layout, self.groups = layout, groups
        self.mesh = _sharding.batch_mesh(devices)
        self.mode = _sharding.batching_mode(batching)
        self.rj = self.batched(0, "residuals_and_jacobian")
        self.runs = 0
        self.n_traces = len(layout.M)
        self.pad = _sharding.padding(self.n_traces, devices)
        self._placed = self.place(data, solver)  # the data do not change between iterations

    def place(self, data, solver):
        """(data, solver) padded and put on the mesh (unchanged with one device)."""
        return (_sharding.shard_batch(_sharding.pad_leading(data, self.pad), self.mesh),
                _sharding.replicate(solver, self.mesh))

    def batched(self, which: int, name: str):
        """The batched model function ``which`` (0: (r, J, film), 1: (y, film)), through the
        stored-program cache."""
        return _cache.exported(f"{name} {self.mode} {self.spec!r}",
                               _model.batched_functions(self.spec, self.mesh, self.mode)[which])

    def run(self, theta, placed=None, fn=None, active=None):
        """``fn`` (default the model's (r, J, film)) of all traces at θ (n_traces × p) as NumPy
        arrays, on ``placed`` data and solver (default: the fit's own). ``active`` (bool per
        trace, default all): with batching "map" the others are skipped and come back as
        zeros; "vmap" computes them all."""
        data, solver = self._placed if placed is None else placed
        fn = self.rj if fn is None else fn
        active = np.ones(self.n_traces, bool) if active is None else np.asarray(active, bool)
        # Padding rows repeat the last trace; they are skipped under "map".
        active = np.concatenate([active, np.zeros(self.pad, bool)])
        theta = _sharding.pad_leading(np.asarray(theta), self.pad)
        theta, active = (_sharding.shard_batch(jnp.asarray(a), self.mesh) for a in (theta, active))
        with single_threaded_blas():
            out = fn(theta, data, solver, active)
            return tuple(_sharding.to_host(a)[: self.n_traces] for a in out)

    def thetas(self, xs):
        lay = self.layout
        return np.stack([lay.base[t] + lay.M[t] @ xs[lay.problem[t]] for t in range(len(lay.M))])

    def __call__(self, xs, problems=None):
        """(r, J, ok) per problem at x; only ``problems`` (indices; default all) are computed
        where the batching can skip (the others' entries are then None)."""
        wanted = np.zeros(len(self.groups), bool)
        wanted[slice(None) if problems is None else list(problems)] = True
        active = np.zeros(self.n_traces, bool)
        for k in np.flatnonzero(wanted):
            active[self.groups[k]] = True
        r, J, film = self.run(self.thetas(xs), active=active)
        self.runs += 1
        out = []
        for k, members in enumerate(self.groups):
            if not wanted[k] and self.mode == "map":
                out.append(None)
                continue
            rk = np.concatenate([r[t] for t in members])
            Jk = np.concatenate([J[t] @ self.layout.M[t] for t in members])
            ok = bool(np.isfinite(rk).all() and np.isfinite(Jk).all() and all(
                film[t] > 0 for t in members))
            out.append((rk, Jk, ok))
        return out


def _decrement(r, J, s2):
    """Gauss–Newton decrement gᵀ(JᵀJ)⁻¹g / s²."""
    g = J.T @ r
    try:
        step = np.linalg.lstsq(J.T @ J, g, rcond=None)[0]
    except np.linalg.LinAlgError:
        return math.inf
    return float(g @ step) / max(s2, 1e-300)


class _Outcome(NamedTuple):
    x: np.ndarray
    r: np.ndarray
    J: np.ndarray
    iterations: int
    converged: bool
    message: str


# --------------------------------------------------------------------------- Levenberg–Marquardt


def _lm(evaluate: _Evaluator, x0s, n_samples, *, max_iter, tol, progress=None):
    """Levenberg–Marquardt for every problem at once (one model run per iteration)."""
    K = len(x0s)
    xs = [x.copy() for x in x0s]
    lam = np.full(K, 1e-3)
    done = np.zeros(K, bool)
    conv = np.zeros(K, bool)
    iters = np.zeros(K, int)
    stall = np.zeros(K, int)
    msgs = [""] * K
    cur = evaluate(xs)
    cost = np.array([0.5 * float(rk @ rk) if ok else np.inf for rk, _, ok in cur])
    for k, (_, _, ok) in enumerate(cur):
        if not ok:
            done[k] = True
            msgs[k] = ("the model run at the starting values failed (a negative film, NaN, or "
                       "a run that stopped before the trace's end: the step budget ran out or "
                       "the steps collapsed)")

    def s2_of(k):
        return 2 * cost[k] / max(n_samples[k] - xs[k].size, 1)

    for it in range(1, max_iter + 1):
        trial = [x.copy() for x in xs]
        for k in np.flatnonzero(~done):
            r, J, _ = cur[k]
            if _decrement(r, J, s2_of(k)) < tol:
                done[k], conv[k] = True, True
                msgs[k] = "converged (Gauss-Newton decrement below tolerance)"
                continue
            A = J.T @ J
            g = J.T @ r
            M = A + lam[k] * np.diag(np.diag(A))
            try:
                delta = -np.linalg.solve(M, g)
            except np.linalg.LinAlgError:
                delta = -g / (np.diag(M) + 1e-300)
            delta /= max(1.0, float(np.max(np.abs(delta))))
            trial[k] = xs[k] + delta
            iters[k] = it
        if done.all():
            break
        new = evaluate(trial, np.flatnonzero(~done))
        for k in np.flatnonzero(~done):
            r_try, _, ok = new[k]
            cost_try = 0.5 * float(r_try @ r_try) if ok else np.inf
            accept = cost_try < cost[k]
            small = (not accept) or (cost[k] - cost_try < STALL_RTOL * cost[k])
            stall[k] = stall[k] + 1 if small else 0
            if stall[k] >= 2:
                dec = _decrement(cur[k][0], cur[k][1], s2_of(k))
                if dec < STALL_DECREMENT:
                    done[k], conv[k] = True, True
                    msgs[k] = (f"converged to the model's accuracy (cost stalled; Gauss-Newton "
                               f"decrement {dec:.2g})")
                    continue
            if accept:
                xs[k], cur[k], cost[k] = trial[k], new[k], cost_try
                lam[k] = max(lam[k] / 3.0, 1e-9)
            else:
                lam[k] *= 4.0
                if lam[k] > 1e12:
                    done[k] = True
                    dec = _decrement(cur[k][0], cur[k][1], s2_of(k))
                    if dec < NOISE_DECREMENT:
                        conv[k] = True
                        msgs[k] = (f"converged to the model's accuracy (no decreasing step; "
                                   f"Gauss-Newton decrement {dec:.2g})")
                    else:
                        msgs[k] = (f"stopped: no decreasing step (lambda > 1e12) with the "
                                   f"Gauss-Newton decrement at {dec:.2g}")
        if progress is not None:
            progress(it, cost, done)
    out = []
    for k in range(K):
        r, J, _ = cur[k]
        if not done[k]:
            msgs[k] = f"not converged after {max_iter} iterations"
        if not conv[k] and np.isfinite(r).all() and _decrement(r, J, s2_of(k)) < tol:
            conv[k], msgs[k] = True, "converged (Gauss-Newton decrement below tolerance)"
        out.append(_Outcome(xs[k], r, J, int(iters[k]), bool(conv[k]), msgs[k]))
    return out


# --------------------------------------------------------------------------- scipy, optax


def _single(evaluate: _Evaluator, k, x0s):
    """(r, J, ok) of problem k alone at x (the others held at their start)."""
    xs = list(x0s)

    def at(x):
        xs[k] = x
        return evaluate(xs, [k])[k]

    return at


def _trf(evaluate, x0s, n_samples, *, max_iter, tol, progress=None):
    """scipy.optimize.least_squares (trust-region reflective) per problem, our Jacobian."""
    from scipy.optimize import least_squares

    out = []
    for k in range(len(x0s)):
        at = _single(evaluate, k, x0s)
        cache = {}

        def fun(x, at=at, cache=cache):
            key = x.tobytes()
            if key not in cache:
                cache.clear()
                r, J, ok = at(x)
                if not ok:  # a failed run: a large residual makes the trust region shrink
                    r, J = np.full_like(r, 1e6), np.zeros_like(J)
                cache[key] = (r, J)
            return cache[key][0]

        def jac(x, fun=fun, cache=cache):
            fun(x)
            return cache[x.tobytes()][1]

        sol = least_squares(fun, x0s[k], jac=jac, method="trf", x_scale="jac",
                            max_nfev=max_iter, ftol=1e-10, xtol=1e-10, gtol=1e-10)
        r, J, ok = at(sol.x)
        s2 = float(r @ r) / max(n_samples[k] - sol.x.size, 1)
        dec = _decrement(r, J, s2) if ok else math.inf
        conv = ok and dec < STALL_DECREMENT
        msg = f"scipy least_squares: {sol.message} (Gauss-Newton decrement {dec:.2g})"
        out.append(_Outcome(sol.x, r, J, int(sol.nfev), conv, msg))
        if progress is not None:
            progress(sol.nfev, np.array([sol.cost]), np.array([True]))
    return out


def _lbfgs(evaluate, x0s, n_samples, *, max_iter, tol, progress=None):
    """optax L-BFGS per problem on S = ½|r|², gradient by reverse mode (jax.grad)."""
    import optax

    spec, solver, lay = evaluate.spec, evaluate.solver, evaluate.layout
    out = []
    for k, members in enumerate(evaluate.groups):
        datas = [jax.tree_util.tree_map(lambda a, t=t: a[t], evaluate.data) for t in members]
        base = [jnp.asarray(lay.base[t]) for t in members]
        Ms = [jnp.asarray(lay.M[t]) for t in members]

        def loss(x, datas=datas, base=base, Ms=Ms):
            total = 0.0
            for d, b, m in zip(datas, base, Ms):
                y, film = _model.predict(b + m @ x, d, solver, spec)
                r = d.weight * (y - d.response) / d.noise
                total = total + jnp.where(film > 0, 0.5 * jnp.sum(r**2), jnp.inf)
            return total

        opt = optax.lbfgs()
        vg = optax.value_and_grad_from_state(loss)

        @_compiler.jit
        def one(x, state, vg=vg, opt=opt, loss=loss):
            value, grad = vg(x, state=state)
            updates, state = opt.update(grad, state, x, value=value, grad=grad, value_fn=loss)
            return optax.apply_updates(x, updates), state, value

        x = jnp.asarray(x0s[k])
        state = opt.init(x)
        at = _single(evaluate, k, x0s)
        conv, it = False, 0
        msg = (f"not converged after {max_iter} iterations (L-BFGS's line search stalls where "
               "the error-controlled model is not smooth: a tighter tolerance, settings with "
               "rtol=1e-5 or the CLI's --rtol 1e-5, or method 'lm')")
        for it in range(1, max_iter + 1):
            with single_threaded_blas():
                x, state, value = one(x, state)
            if progress is not None:
                progress(it, np.array([float(value)]), np.array([False]))
            if not math.isfinite(float(value)):
                msg = "stopped: non-finite loss (negative film or NaN)"
                break
            if it % 5 == 0:
                r, J, ok = at(np.asarray(x))
                s2 = float(r @ r) / max(n_samples[k] - x.size, 1)
                if ok and _decrement(r, J, s2) < STALL_DECREMENT:
                    conv, msg = True, "converged (Gauss-Newton decrement below tolerance)"
                    break
        r, J, _ = at(np.asarray(x))
        out.append(_Outcome(np.asarray(x), r, J, it, conv, msg))
    return out


_OPTIMISERS = {"lm": _lm, "trf": _trf, "lbfgs": _lbfgs}


# --------------------------------------------------------------------------- public API


def _check_args(traces, method, max_iter, tol, starts):
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
    if starts is not None and len(starts) != len(traces):
        raise ValueError(f"starts must have one entry per trace ({len(traces)}), got {len(starts)}")


#: Where each parameter must lie: θ is its logarithm (E0/E∞ - 1 for the stiffening).
_LOWER = {"E_star": 0.0, "viscosity": 0.0, "z0": 0.0, "stiffening": 1.0,
          "relaxation_time": 0.0}


def _check_value(name: str, value, what: str) -> float:
    """``value`` as a float inside its parameter's range (ValueError naming ``what`` if not)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    lo = _LOWER.get(name, -math.inf)
    if not (math.isfinite(v) and v > lo):
        rule = f"a finite number > {lo:g}" if math.isfinite(lo) else "a finite number"
        raise ValueError(f"{what}: {name} must be {rule} (SI units), got {value!r}")
    return v


def _check_fixed(fixed, spec: ModelSpec, shared) -> dict:
    """``fixed`` as {name: SI value}, checked against the spec and ``shared``."""
    out = {}
    for name, value in dict(fixed or {}).items():
        if name not in spec.names:
            raise ValueError(f"fixed: unknown parameter {name!r} (allowed: "
                             f"{', '.join(spec.names)})")
        if name in shared:
            raise ValueError(f"fixed: {name} is also shared; a parameter is fitted jointly or "
                             "held fixed, not both")
        out[name] = _check_value(name, value, "fixed")
    if all(n in out for n, a in zip(spec.names, spec.active, strict=True) if a):
        raise ValueError("fixed: every parameter is held fixed; nothing is left to fit")
    return out


def _spec_for(traces, spec, drive, substrate_kw):
    if spec is not None:
        return spec
    drives = {_model.drive_of(tr, drive) for tr in traces}
    if len(drives) > 1:
        raise ValueError(
            f"traces fitted together must have one drive, got {', '.join(sorted(drives))}"
        )
    return ModelSpec(drive=drives.pop(), **substrate_kw)


def _prepare(traces, spec, shared, fixed, starts):
    """(fixed, scales, starts) of a fit, checked: the shared and fixed names, each trace's scales,
    the starting values (:func:`initial_guess` where not given, fixed values put in), every one
    positive where θ takes its logarithm."""
    unknown = [n for n in shared if n not in spec.names or n == "offset"]
    if unknown:
        allowed = ", ".join(n for n in spec.names if n != "offset")
        raise ValueError(f"shared: unknown parameter(s) {', '.join(unknown)} (allowed: {allowed})")
    fixed = _check_fixed(fixed, spec, shared)
    scales = [_model.scales_from_trace(tr, spec.drive) for tr in traces]
    if starts is None:
        starts = [initial_guess(tr, s, spec) for tr, s in zip(traces, scales, strict=True)]
    if fixed:
        note = "held fixed: " + ", ".join(f"{n} = {v:g}" for n, v in fixed.items())
        starts = [Start({**st.values, **fixed}, (*st.notes, note)) for st in starts]
    for tr, st in zip(traces, starts, strict=True):  # θ holds logarithms: no value <= 0 gets in
        for n in spec.names:
            if n != "stiffening":  # θ clamps E0/E∞ - 1 at 1e-6 (an elastic start is fine)
                _check_value(n, st.values.get(n), f"{tr.name or 'trace'}: starting value")
    return fixed, scales, starts


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
    _check_args(traces, method, max_iter, tol, starts)
    _sharding.batching_mode(batching)
    n_dev = _sharding.device_count(devices)
    spec = _spec_for(traces, spec, drive,
                     dict(layer=layer, viscoelastic=viscoelastic, fit_offset=fit_offset))
    shared = tuple(shared)
    if noise not in _stats.NOISE_MODELS:
        raise ValueError(f"noise must be one of {', '.join(_stats.NOISE_MODELS)}, got {noise!r}")
    fixed, scales, starts = _prepare(traces, spec, shared, fixed, starts)
    groups = [list(range(len(traces)))] if shared else [[t] for t in range(len(traces))]
    t0 = time.perf_counter()
    settings = _model.FIT_SETTINGS if settings is None else settings
    mesh = fit_mesh(traces, starts, scales, spec, settings)
    solver = _model.Solver(lubjax.stepper.discretise(mesh), settings.tolerance())
    data = _stack_traces(traces, scales, spec, mesh)
    theta0 = np.array([[_model.to_theta(n, st.values[n], sc.response_unit) for n in spec.names]
                       for st, sc in zip(starts, scales, strict=True)])
    names = [_short_name(tr.name) for tr in traces]
    layout, x0s = _layout(groups, spec, names, theta0, shared, tuple(fixed))
    evaluate = _Evaluator(data, solver, spec, layout, groups, n_dev, batching)
    n_samples = [sum(traces[t].time.size for t in g) for g in groups]

    def report(it, cost, done):
        if progress is not None:
            progress(f"iteration {it}, chi2/2 {float(np.max(cost)):.6g}, "
                     f"{int(np.sum(done))}/{len(done)} done")

    outcomes = _OPTIMISERS[method](evaluate, x0s, n_samples, max_iter=max_iter, tol=tol,
                                   progress=report)
    xs = [o.x for o in outcomes]
    # The model at the optimum from its residuals (r = w (y - y_data)/σ): no separate prediction
    # function to trace, lower and load from the compilation cache.
    n_pad = data.weight.shape[1]
    r_all = np.zeros((len(traces), n_pad))
    for k, members in enumerate(groups):
        for j, t in enumerate(members):
            r_all[t] = outcomes[k].r[j * n_pad : (j + 1) * n_pad]
    model = np.asarray(data.response) + r_all * np.asarray(data.noise)[:, None]
    errors = _solver_error(evaluate, xs, r_all, traces, scales, spec, settings, mesh, groups) if (
        model_error) else None
    # the solver's error estimate of each trace's model [its response's unit]
    model_errors = [None] * len(traces)
    for k, members in enumerate(groups if errors is not None else []):
        for j, t in enumerate(members):
            own = errors[k][j * n_pad : j * n_pad + traces[t].time.size]
            model_errors[t] = own * float(data.noise[t])
    wall = (time.perf_counter() - t0) / len(traces)
    results = []
    for k, members in enumerate(groups):
        o = outcomes[k]
        summary = _stats.summarise(o.r, o.J, [(n_pad, traces[t].time.size) for t in members],
                                   layout.labels[k], noise=noise,
                                   solver_error=None if errors is None else errors[k])
        for j, t in enumerate(members):
            joint = shared if len(members) > 1 else ()
            start = _start_used(starts[t], spec, layout, t, x0s[k], scales[t], joint)
            results.append(_trace_result(traces[t], spec, scales[t], start, layout, t, o,
                                         summary, j, members, names, shared, method,
                                         evaluate.runs, wall, model[t, : traces[t].time.size],
                                         fixed, model_errors[t]))
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


def _solver_error(evaluate, xs, r_fit, traces, scales, spec, settings, mesh, groups):
    """Signed error of the model response at the optimum, per problem in residual units.

    One extra run on the nested coarse mesh (every other node) at ``Tolerance.loosened()``
    (8·rtol): taking the spatial error as second order (×4 at twice the spacing) and the global
    time error ∝ rtol^{2/3} (×4 at 8·rtol), both grow by the same factor and
    y_coarse,8rtol - y ≈ 3 (error of y), so the error is (y_coarse,8rtol - y)/3. This is not
    ``lubjax.relax``'s estimate (``lubjax._solve.error_estimate``: two runs, separate space and
    time parts at the lower orders 3/2 and 1/2, times a safety factor of 3), which bounds the
    error pointwise; here the signed error enters the budget as a parameter shift
    (:func:`fitting._stats.summarise`), where a bound would be too large. In residual units
    (r = w (y - y_data)/σ) it is (r_coarse,8rtol - r)/3; the run is the fit's own model (the
    response only: no Jacobian) on the other solver."""
    mesh = mesh.coarsened()
    tol = settings.tolerance()
    loose = _model.Solver(lubjax.stepper.discretise(mesh), tol.loosened())
    data = _stack_traces(traces, scales, spec, mesh)
    # The response alone (no Jacobian): a forward run, a quarter of the cost and of the tracing.
    predict = evaluate.batched(1, "predict")
    y_loose = evaluate.run(evaluate.thetas(xs), evaluate.place(data, loose), predict)[0]
    r_loose = np.array(data.weight * (y_loose - data.response) / data.noise[:, None])
    err = (r_loose - r_fit) / 3.0
    err[~np.isfinite(err)] = 0.0
    return [np.concatenate([err[t] for t in g]) for g in groups]


def _short_name(path):
    return os.path.splitext(os.path.basename(path))[0] or "trace"


def fit_mesh(traces, starts, scales, spec, settings) -> lubjax.Mesh:
    """The mesh a fit runs on: the one :func:`lubjax.mesh_for` gives a relax run of each trace
    at its starting values (β, z̄0), refined at the contact's edge where the run ends in a
    contact whose neck needs it (near-dry traces, β ≳ 10⁵), where every trace of the batch
    asks for the same mesh; else ``settings.mesh()`` (the batch shares one mesh).

    Args:
        traces: the :class:`Trace` s fitted together.
        starts: their :class:`Start` values.
        scales: their :class:`Scales`.
        spec: the :class:`ModelSpec`.
        settings: the fit's ``lubjax.Settings``.

    Returns:
        lubjax.Mesh: the shared mesh.
    """
    meshes = []
    for trace, start, sc in zip(traces, starts, scales, strict=True):
        E_star = start.values["E_star"]
        beta = lubjax.si_scales(E_star, sc.radius, sc.indent, t_c=sc.time_scale,
                                viscosity=start.values["viscosity"])["beta"]
        hist = _model.history(trace, sc, spec.drive)
        drive = _model.make_drive(spec.drive, _model.drive_unit(trace, sc, spec.drive), hist,
                                  E_star)
        try:
            meshes.append(lubjax.mesh_for(settings, drive=drive, beta=beta,
                                          z0=start.values["z0"] / sc.indent,
                                          t_end=float(hist.t[-1])))
        except ValueError:  # a start outside the solver's (β, z̄0) range: the shared mesh
            return settings.mesh()
    return meshes[0] if all(m == meshes[0] for m in meshes) else settings.mesh()


def _stack_traces(traces, scales, spec, mesh):
    n_pad = max(tr.time.size for tr in traces)
    n_hist = max(_model.history_size(tr, s) for tr, s in zip(traces, scales, strict=True))
    return _model.stack([_model.trace_data(tr, s, spec, mesh, n_pad, n_hist)
                         for tr, s in zip(traces, scales, strict=True)])


def _trace_result(trace, spec, scales, start, layout, t, outcome, summary, j, members, names,
                  shared, method, runs, wall, model, fixed=None, model_error=None) -> FitResult:
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
    for i, n in enumerate(spec.names):
        # A near-singular JᵀJ can leave a variance <= 0 or NaN: no standard error, not an error.
        var = float(cov_theta[i, i])
        stderr[n] = (abs(deriv[i]) * math.sqrt(var) if var >= 0 else math.nan) if active[i] else 0.0
    se = np.sqrt(np.diag(cov_theta))
    corr = cov_theta / np.outer(se, se)
    parts = {}
    for part, cov in summary["parts"].items():
        c = M @ cov @ M.T
        parts[part] = {n: float(abs(deriv[i]) * math.sqrt(max(c[i, i], 0.0)))
                       for i, n in enumerate(spec.names) if active[i]}
    n = trace.time.size
    first = sum(length for length, _ in summary["sizes"][:j])
    r_t = outcome.r[first : first + n]
    stats = dict(summary["stats"])
    stats.update(
        rms_residual=float(np.sqrt(np.mean((model - _channel(trace, spec)) ** 2))),
        autocorrelation_lag1_trace=float(_stats.lag1(r_t)),
        error_parts=parts,
        noise_sigma=float(_model.noise_level(_channel(trace, spec))),
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
    flags += _undetermined(values, stderr, fixed)
    flags += summary["flags"]
    flags += _checks.plausibility_flags(
        {n: v for n, v in values.items() if n not in fixed}, scales.speed,
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


def _undetermined(values, stderr, fixed) -> list[str]:
    """A flag for each positive parameter whose standard error exceeds it: the data bound it
    from above only (the viscosity of a near-dry trace, whose film force is below the noise)."""
    out = []
    for name, value in values.items():
        if name == "offset" or name in fixed or not value > 0 or not stderr[name] > value:
            continue
        hint = (" (a near-dry contact: the film's force is below the noise; fix it where the "
                "medium is known, --fix viscosity=...)") if name == "viscosity" else ""
        out.append(f"{name} is not determined by the data: its standard error is "
                   f"{100 * stderr[name] / value:.0f} % of it; read it as an upper bound{hint}")
    return out


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
