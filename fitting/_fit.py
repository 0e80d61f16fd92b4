r"""Least-squares fit of (E*, η, z0) and a force offset to relaxation traces.

Loss. With the residuals r(θ) of :mod:`fitting._model` (force misfit in units of the peak force
F_u, θ = (ln E*, ln η, ln z0, b/F_u)), minimise S(θ) = ½ Σ_k r_k².

Optimisers (``method=``):

* ``"lm"`` (default): Levenberg–Marquardt on the forward-mode Jacobian J = ∂r/∂θ (``jax.jvp``
  per parameter). Step (JᵀJ + λ diag JᵀJ) δ = -Jᵀr, accepted when S decreases (then λ ← λ/3,
  else λ ← 4λ), with |δ_i| ≤ 1 (a factor e per step in E*, η, z0). A step whose run makes the
  film negative or non-finite counts as rejected. Several traces are fitted together: one
  ``vmap``-ed Jacobian call per iteration for the whole batch, each trace with its own λ.
* ``"lbfgs"``: ``optax.lbfgs`` (zoom line search) on S. Its line search asks for
  ``jax.value_and_grad``; S carries a ``custom_vjp`` whose forward pass computes ∇S = Jᵀr by
  forward mode, so reverse mode never runs through the solver.

Why LM is the default: the problem is a small (4-parameter) nonlinear least-squares problem
whose Jacobian is needed anyway for the standard errors; Gauss–Newton uses the curvature JᵀJ,
which is what makes the strongly correlated directions (E* with η through β, z0 with E* through
the Hertz plateau) converge in a handful of steps. L-BFGS builds its curvature from gradients
only and needs several times more solver runs (each line-search trial is a value+gradient)
to reach the same tolerance. Measured on data/paper_dc126.csv (same start, same convergence test):
LM 3 iterations / 7 model runs, 59 s; L-BFGS 25 iterations, 222 s (both with compilation, on a
shared 2-core machine), same optimum to 4e-6 relative.

Convergence: the Gauss–Newton decrement gᵀ(JᵀJ)⁻¹g with g = Jᵀr, in units of the residual variance
σ̂² = 2S/(n - p), below ``tol`` (1e-4): the remaining step is under 1 % of a standard error.

Uncertainties at the optimum: Cov(θ) = σ̂² (JᵀJ)⁻¹; standard errors of E*, η, z0 by the delta
method (SE(x) = x·SE(ln x)); correlations Cov_ij/(SE_i SE_j). A fit is flagged
``identifiable=False`` if any |correlation| > 0.999 or the condition number of the correlation
matrix exceeds 1e8. These errors assume independent noise and a correct model: the
discretisation error of the model is not included (error-controlled at Settings.rtol = 1e-3).
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from . import _model
from ._io import Trace
from ._model import N_PARAMS, Scales, Solver, TraceData

MAX_CORRELATION = 0.999
STALL_RTOL = 1e-7
STALL_DECREMENT = 0.05
MAX_CONDITION = 1e8


class Start(NamedTuple):
    """Physics-based starting values [SI] and how they were obtained."""

    E_star: float
    viscosity: float
    z0: float
    offset: float
    notes: tuple


class FitResult(NamedTuple):
    """One fitted trace. SI units; ``stderr`` maps E_star, viscosity, z0, offset to 1-σ errors."""

    name: str
    E_star: float
    viscosity: float
    z0: float
    offset: float
    stderr: dict
    correlation: np.ndarray  # 4×4 (E*, η, z0, offset); offset row/col NaN if not fitted
    beta: float
    z0_over_dc: float
    indent: float
    speed: float
    radius: float
    rms_residual: float  # [N]
    converged: bool
    identifiable: bool
    condition: float
    n_iterations: int
    n_model_runs: int
    method: str
    wall_s: float
    start: Start
    flags: tuple
    time: np.ndarray  # sample times [s]
    force: np.ndarray  # measured force [N]
    model: np.ndarray  # fitted force at the samples [N]
    metadata: dict


# --------------------------------------------------------------------------- starting values


def noise_level(force: np.ndarray) -> float:
    """Robust noise σ from successive differences: 1.4826 · MAD(ΔF)/√2."""
    df = np.diff(force)
    return float(1.4826 * np.median(np.abs(df - np.median(df))) / math.sqrt(2.0))


def initial_guess(trace: Trace, scales: Scales) -> Start:
    r"""Starting values from the physics, not from the user.

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
       is the geometric mean over the noiseless traces of data/clean; it drifts from 4 to 14 as
       z̄0 goes from 1.1 to 0.9 (the late hold is limited by drainage of the trapped film, not
       by t_R alone), so this start is good to a factor ~2 — enough for Levenberg–Marquardt.
    """
    t, d, f = trace.time, trace.displacement, trace.force
    notes = []
    R, dc, v0, tc = scales.radius, scales.indent, scales.speed, scales.time_scale
    quiet = t < scales.t_on
    offset = float(np.median(f[quiet])) if np.count_nonzero(quiet) >= 3 else 0.0
    fc = f - offset
    sigma = noise_level(f)
    width = 5
    smooth = np.convolve(fc, np.ones(width) / width, mode="same")
    k_peak = int(np.argmax(smooth))
    f_peak = float(smooth[k_peak])
    v = np.gradient(d, t)
    idx = np.arange(t.size)
    sel = (
        (t > scales.t_on)
        & (idx < k_peak)
        & (fc > max(0.05 * f_peak, 3 * sigma))
        & (fc < 0.4 * f_peak)
        & (v > 0.5 * v0)
    )
    z0 = eta = None
    if np.count_nonzero(sel) >= 3:
        A = np.stack([fc[sel], -v[sel]], axis=1)
        (z0_ls, c), *_ = np.linalg.lstsq(A, fc[sel] * d[sel], rcond=None)
        if c > 0 and z0_ls > np.max(d[sel]):
            z0, eta = float(z0_ls), float(c / (6 * math.pi * R**2))
            notes.append(f"z0, eta from Reynolds' squeeze film on {np.count_nonzero(sel)} samples")
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
        E_star = beta * 6 * math.pi * eta * v0 * R**1.5 / dc**2.5
        notes.append(f"E* from the relaxation time t_R = t_c/beta (t_half = {t_half:.3g} s)")
    return Start(float(E_star), float(eta), float(z0), offset, tuple(notes))


#: t½ ≈ RELAX_CONSTANT · t_c/β (see :func:`initial_guess`).
RELAX_CONSTANT = 8.0


# --------------------------------------------------------------------------- statistics


def _covariance(r, J, active, n):
    """σ̂², Cov(θ) over the active parameters (NaN elsewhere), condition of the correlation."""
    p = int(np.count_nonzero(active))
    s2 = float(r @ r) / max(n - p, 1)
    Ja = J[:, active]
    A = Ja.T @ Ja
    cov = np.full((N_PARAMS, N_PARAMS), np.nan)
    try:
        inv = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return s2, cov, math.inf
    cov[np.ix_(active, active)] = s2 * inv
    dg = np.sqrt(np.diag(A))
    corr_a = A / np.outer(dg, dg)
    cond = float(np.linalg.cond(corr_a))
    return s2, cov, cond


def _decrement(r, J, active, s2):
    """Gauss–Newton decrement gᵀ(JᵀJ)⁻¹g / σ̂²."""
    Ja = J[:, active]
    g = Ja.T @ r
    try:
        step = np.linalg.solve(Ja.T @ Ja, g)
    except np.linalg.LinAlgError:
        return math.inf
    return float(g @ step) / max(s2, 1e-300)


# --------------------------------------------------------------------------- Levenberg–Marquardt


def _lm_batch(theta0, data, solver, active, n_samples, *, max_iter, tol, progress=None):
    """Batched LM. theta0 (B, 4); returns θ, r, J, iterations, converged, runs, messages."""
    res_fn, rj_fn, _ = _model.batched_functions()
    theta = np.array(theta0, dtype=np.float64)
    B = theta.shape[0]
    lam = np.full(B, 1e-3)
    done = np.zeros(B, bool)
    conv = np.zeros(B, bool)
    iters = np.zeros(B, int)
    runs = 0
    msgs = [""] * B
    stall = np.zeros(B, int)

    def evaluate_rj(th):
        r, J, film = rj_fn(jnp.asarray(th), data, solver)
        return np.array(r), np.array(J), np.array(film)

    r, J, film = evaluate_rj(theta)
    runs += 1
    bad0 = ~np.isfinite(r).all(axis=1) | ~(film > 0)
    for b in np.flatnonzero(bad0):
        done[b] = True
        msgs[b] = "the model run at the starting values failed (negative film or NaN)"
    cost = 0.5 * np.sum(r**2, axis=1)
    for it in range(1, max_iter + 1):
        if done.all():
            break
        trial = theta.copy()
        pred = np.zeros(B)
        for b in np.flatnonzero(~done):
            Ja = J[b][:, active]
            A = Ja.T @ Ja
            g = Ja.T @ r[b]
            s2 = 2 * cost[b] / max(n_samples[b] - Ja.shape[1], 1)
            if _decrement(r[b], J[b], active, s2) < tol:
                done[b], conv[b] = True, True
                msgs[b] = "converged (Gauss-Newton decrement below tolerance)"
                continue
            M = A + lam[b] * np.diag(np.diag(A))
            try:
                delta = -np.linalg.solve(M, g)
            except np.linalg.LinAlgError:
                delta = -g / (np.diag(M) + 1e-300)
            scale = max(1.0, float(np.max(np.abs(delta))))
            delta /= scale
            trial[b, active] += delta
            pred[b] = -(g @ delta) - 0.5 * delta @ A @ delta
            iters[b] = it
        if done.all():
            break
        r_try, film_try = res_fn(jnp.asarray(trial), data, solver)
        runs += 1
        r_try, film_try = np.asarray(r_try), np.asarray(film_try)
        ok = np.isfinite(r_try).all(axis=1) & (film_try > 0)
        cost_try = np.where(
            ok, 0.5 * np.sum(np.where(ok[:, None], r_try, 0.0) ** 2, axis=1), np.inf
        )
        accept = (~done) & (cost_try < cost)
        # An error-controlled model is smooth in θ only to its tolerance (step choices change
        # with θ), so near the optimum the cost stops decreasing before the Gauss-Newton
        # decrement reaches ``tol``. Stalled twice with the remaining step below
        # STALL_DECREMENT (in units of σ̂²) counts as converged, at the model's accuracy.
        small = ~done & (~accept | (cost - cost_try < STALL_RTOL * cost))
        stall = np.where(small, stall + 1, 0)
        for b in np.flatnonzero(stall >= 2):
            s2 = 2 * cost[b] / max(n_samples[b] - int(active.sum()), 1)
            dec = _decrement(r[b], J[b], active, s2)
            if dec < STALL_DECREMENT:
                done[b], conv[b] = True, True
                msgs[b] = (
                    f"converged to the model's accuracy (cost stalled; Gauss-Newton decrement "
                    f"{dec:.2g})"
                )
                accept[b] = False
        for b in np.flatnonzero(~done & ~accept):
            lam[b] *= 4.0
            if lam[b] > 1e12:
                done[b] = True
                msgs[b] = "stopped: no decreasing step (lambda > 1e12)"
        if accept.any():
            theta[accept] = trial[accept]
            lam[accept] = np.maximum(lam[accept] / 3.0, 1e-9)
            r_new, J_new, film_new = evaluate_rj(theta)
            runs += 1
            r[accept], J[accept] = r_new[accept], J_new[accept]
            cost[accept] = 0.5 * np.sum(r[accept] ** 2, axis=1)
        if progress is not None:
            progress(it, cost, done)
    for b in np.flatnonzero(~done):
        msgs[b] = f"not converged after {max_iter} iterations"
    # Final convergence test for the traces that stopped early for another reason.
    for b in range(B):
        if not conv[b] and np.isfinite(r[b]).all():
            s2 = 2 * cost[b] / max(n_samples[b] - int(active.sum()), 1)
            if _decrement(r[b], J[b], active, s2) < tol:
                conv[b] = True
                msgs[b] = "converged (Gauss-Newton decrement below tolerance)"
    return theta, r, J, iters, conv, runs, msgs


# --------------------------------------------------------------------------- L-BFGS (optax)


def _make_loss(data: TraceData, solver: Solver, active_mask):
    """S(θ) = ½|r|² with a custom VJP whose forward pass gets ∇S = Jᵀr by forward mode."""

    def value_and_grad(theta):
        r, J, film = _model.residuals_and_jacobian(theta, data, solver)
        bad = ~(jnp.all(jnp.isfinite(r)) & (film > 0))
        value = jnp.where(bad, jnp.inf, 0.5 * jnp.sum(r**2))
        grad = jnp.where(bad, 0.0, (J.T @ r) * active_mask)
        return value, grad

    @jax.custom_vjp
    def loss(theta):
        return value_and_grad(theta)[0]

    def fwd(theta):
        value, grad = value_and_grad(theta)
        return value, grad

    def bwd(grad, ct):
        return (ct * grad,)

    loss.defvjp(fwd, bwd)
    return loss


def _lbfgs_single(theta0, data, solver, active, n_samples, *, max_iter, tol, progress=None):
    active_mask = jnp.asarray(active, dtype=jnp.float64)
    loss = _make_loss(data, solver, active_mask)
    opt = optax.lbfgs()
    vg = optax.value_and_grad_from_state(loss)

    @jax.jit
    def one(params, state):
        value, grad = vg(params, state=state)
        updates, state = opt.update(grad, state, params, value=value, grad=grad, value_fn=loss)
        return optax.apply_updates(params, updates), state, value

    params = jnp.asarray(theta0)
    state = opt.init(params)
    _, rj_fn, _ = _model.batched_functions()
    it = 0
    conv = False
    msg = f"not converged after {max_iter} iterations"
    prev = np.inf
    for it in range(1, max_iter + 1):
        params, state, value = one(params, state)
        value = float(value)
        if progress is not None:
            progress(it, np.array([value]), np.array([False]))
        if not math.isfinite(value):
            msg = "stopped: non-finite loss (negative film or NaN)"
            break
        if it % 5 == 0 or abs(prev - value) <= 1e-12 * abs(value):
            r, J, _ = _model.residuals_and_jacobian(params, data, solver)
            r, J = np.asarray(r), np.asarray(J)
            s2 = float(r @ r) / max(n_samples - int(active.sum()), 1)
            if _decrement(r, J, active, s2) < tol:
                conv, msg = True, "converged (Gauss-Newton decrement below tolerance)"
                break
        prev = value
    r, J, _ = rj_fn(params[None], jax.tree_util.tree_map(lambda a: a[None], data), solver)
    return np.asarray(params), np.asarray(r[0]), np.asarray(J[0]), it, conv, msg


# --------------------------------------------------------------------------- public API


def _check_method(method):
    if method not in ("lm", "lbfgs"):
        raise ValueError(f"method must be 'lm' (Levenberg-Marquardt) or 'lbfgs', got {method!r}")


def fit_traces(
    traces: list[Trace],
    *,
    method: str = "lm",
    fit_offset: bool = True,
    settings=None,
    max_iter: int = 60,
    tol: float = 1e-4,
    starts: list[Start] | None = None,
    progress=None,
) -> list[FitResult]:
    """Fit several traces, together: one vmap-ed model/Jacobian call per LM iteration for the
    whole batch (each trace takes its own error-controlled steps, on one shared mesh).

    Args:
        traces: :class:`fitting.Trace` objects (``read_trace``).
        method: "lm" (default, Levenberg–Marquardt) or "lbfgs" (optax L-BFGS).
        fit_offset: also fit a constant force offset b (default True).
        settings: ``lubjax.Settings`` of the model (tolerance and mesh; default
            ``fitting.FIT_SETTINGS``, the solver's defaults).
        max_iter: iteration limit; tol: convergence tolerance on the Gauss–Newton decrement/σ̂².
        starts: starting values per trace (default: :func:`initial_guess`).
        progress: optional callable(message) for progress lines (the CLI prints them).
    """
    _check_method(method)
    if not traces:
        raise ValueError("traces must contain at least one trace")
    for name, v in [("max_iter", max_iter)]:
        if not (isinstance(v, int) and v >= 1):
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
    if not (isinstance(tol, (int, float)) and tol > 0):
        raise ValueError(f"tol must be > 0, got {tol!r}")
    if starts is not None and len(starts) != len(traces):
        raise ValueError(f"starts must have one entry per trace ({len(traces)}), got {len(starts)}")
    active = np.array([True, True, True, bool(fit_offset)])
    scales = [_model.scales_from_trace(tr) for tr in traces]
    starts = (
        [initial_guess(tr, s) for tr, s in zip(traces, scales, strict=True)]
        if starts is None
        else starts
    )
    results: list[FitResult | None] = [None] * len(traces)
    solver = _model.make_solver(settings)
    # All traces go in one batch: each takes its own steps, so they need not share a time grid.
    for members in [list(range(len(traces)))]:
        t0 = time.perf_counter()
        n_pad = max(traces[i].time.size for i in members)
        n_hist = max(_model.history_size(traces[i], scales[i]) for i in members)
        datas = [_model.trace_data(traces[i], scales[i], n_pad, n_hist) for i in members]
        n_samples = np.array([traces[i].time.size for i in members])
        theta0 = np.array(
            [
                [
                    math.log(starts[i].E_star),
                    math.log(starts[i].viscosity),
                    math.log(starts[i].z0),
                    (starts[i].offset if fit_offset else 0.0) / scales[i].force_unit,
                ]
                for i in members
            ]
        )

        def report(it, cost, done, members=members):
            if progress is not None:
                names = ", ".join(traces[i].name or "trace" for i in members)
                progress(
                    f"{names}: iteration {it}, loss {float(np.max(cost)):.4g}, "
                    f"{int(np.sum(done))}/{len(done)} done"
                )

        if method == "lm":
            data = _model.stack(datas)
            theta, r, J, iters, conv, runs, msgs = _lm_batch(
                theta0, data, solver, active, n_samples, max_iter=max_iter, tol=tol,
                progress=report,
            )
        else:
            out = [
                _lbfgs_single(
                    theta0[j],
                    datas[j],
                    solver,
                    active,
                    n_samples[j],
                    max_iter=max_iter,
                    tol=tol,
                    progress=report,
                )
                for j in range(len(members))
            ]
            theta = np.stack([o[0] for o in out])
            r = np.stack([o[1] for o in out])
            J = np.stack([o[2] for o in out])
            iters = np.array([o[3] for o in out])
            conv = np.array([o[4] for o in out])
            msgs = [o[5] for o in out]
            runs = None
        _, _, pred_fn = _model.batched_functions()
        model, _ = pred_fn(jnp.asarray(theta), _model.stack(datas), solver)
        model = np.asarray(model)
        wall = (time.perf_counter() - t0) / len(members)
        for j, i in enumerate(members):
            results[i] = _summarise(
                traces[i],
                scales[i],
                starts[i],
                theta[j],
                r[j],
                J[j],
                active,
                int(iters[j]),
                bool(conv[j]),
                msgs[j],
                runs if runs is not None else -1,
                method,
                wall,
                model[j, : n_samples[j]],
            )
    return results


def fit_trace(trace: Trace, **kwargs) -> FitResult:
    """Fit one trace; keyword arguments as :func:`fit_traces`."""
    return fit_traces([trace], **kwargs)[0]


def _summarise(
    trace, scales, start, theta, r, J, active, iters, conv, msg, runs, method, wall, model
) -> FitResult:
    n = trace.time.size
    s2, cov, cond = _covariance(r[:n], J[:n], active, n)
    fu = scales.force_unit
    se_log = np.sqrt(np.diag(cov))
    E, eta, z0 = (math.exp(x) for x in theta[:3])
    stderr = {
        "E_star": E * se_log[0],
        "viscosity": eta * se_log[1],
        "z0": z0 * se_log[2],
        "offset": fu * se_log[3] if active[3] else 0.0,
    }
    corr = cov / np.outer(se_log, se_log)
    flags = [msg]
    off = np.abs(corr[np.ix_(active, active)] - np.eye(int(active.sum())))
    identifiable = bool(np.nanmax(off) <= MAX_CORRELATION and cond <= MAX_CONDITION)
    if not identifiable:
        flags.append(
            f"parameters not identifiable: max |correlation| = {np.nanmax(off):.6f}, "
            f"condition number {cond:.3g}"
        )
    if not conv:
        flags.append("fit did not converge: treat the values and errors as unreliable")
    return FitResult(
        name=trace.name,
        E_star=E,
        viscosity=eta,
        z0=z0,
        offset=float(theta[3] * fu),
        stderr={k: float(v) for k, v in stderr.items()},
        correlation=corr,
        beta=float(scales.beta(E, eta)),
        z0_over_dc=z0 / scales.indent,
        indent=scales.indent,
        speed=scales.speed,
        radius=scales.radius,
        rms_residual=float(fu * math.sqrt(np.mean(r[:n] ** 2))),
        converged=conv,
        identifiable=identifiable,
        condition=cond,
        n_iterations=iters,
        n_model_runs=runs,
        method=method,
        wall_s=wall,
        start=start,
        flags=tuple(flags),
        time=trace.time,
        force=trace.force,
        model=model,
        metadata=dict(trace.metadata),
    )


def result_to_dict(res: FitResult) -> dict:
    """A JSON-ready summary of a fit (SI units; keys as documented in data/README.md)."""
    nu = None
    try:
        nu = float(res.metadata.get("poisson_ratio"))
    except (TypeError, ValueError):
        nu = None
    out = {
        "trace": res.name,
        "E_star_Pa": res.E_star,
        "viscosity_Pa_s": res.viscosity,
        "z0_m": res.z0,
        "offset_N": res.offset,
        "stderr": {
            "E_star_Pa": res.stderr["E_star"],
            "viscosity_Pa_s": res.stderr["viscosity"],
            "z0_m": res.stderr["z0"],
            "offset_N": res.stderr["offset"],
        },
        "correlation": {
            "names": ["E_star", "viscosity", "z0", "offset"],
            "matrix": [
                [None if not np.isfinite(x) else float(x) for x in row] for row in res.correlation
            ],
        },
        "beta": res.beta,
        "z0_over_dc": res.z0_over_dc,
        "indent_m": res.indent,
        "speed_m_s": res.speed,
        "radius_m": res.radius,
        "rms_residual_N": res.rms_residual,
        "converged": res.converged,
        "identifiable": res.identifiable,
        "condition_number": res.condition,
        "n_iterations": res.n_iterations,
        "n_model_runs": res.n_model_runs,
        "method": res.method,
        "wall_s": res.wall_s,
        "flags": list(res.flags),
        "start": {
            "E_star_Pa": res.start.E_star,
            "viscosity_Pa_s": res.start.viscosity,
            "z0_m": res.start.z0,
            "offset_N": res.start.offset,
            "notes": list(res.start.notes),
        },
        "metadata": dict(res.metadata),
    }
    if nu is not None and -1 < nu <= 0.5:
        out["E_Pa"] = res.E_star * (1 - nu**2)
        out["stderr"]["E_Pa"] = res.stderr["E_star"] * (1 - nu**2)
    truth = {}
    for key, meta_key, value in [
        ("E_star_Pa", "true_E_star_Pa", res.E_star),
        ("viscosity_Pa_s", "true_viscosity_Pa_s", res.viscosity),
        ("z0_m", "true_z0_m", res.z0),
    ]:
        try:
            true = float(res.metadata[meta_key])
        except (KeyError, TypeError, ValueError):
            continue
        truth[key] = {"true": true, "relative_error": value / true - 1}
    if truth:
        out["vs_true"] = truth
    return out
