r"""Uncertainties and statistics of a least-squares fit: what the reported errors contain.

At the optimum x̂ with residuals r (in units of each trace's noise estimate) and Jacobian J:

* **Noise, white** (the textbook errors): Cov_white = s² (JᵀJ)⁻¹, s² = Σr²/(n - p) (the reduced
  χ²). Valid when the noise is independent from sample to sample.
* **Noise, AR(1)** (correlated noise, a load cell's low-pass filter or drift): per trace the
  noise's lag-1 correlation ρ (:func:`ar1_correlation`: the ρ whose residuals, after the fit
  absorbed part of the noise, would show the observed lag-1 ratio) defines the correlation
  matrix R_ij = ρ^|i-j|, and the covariance of the least-squares estimate is the sandwich
  Cov_AR1 = c s² (JᵀJ)⁻¹ (Jᵀ R J) (JᵀJ)⁻¹ (exact for AR(1) noise; R⁻¹ is tridiagonal, so R J is
  a banded solve; c = (n - p)/tr(M R M) undoes what the fit absorbs of the noise's variance,
  guarded at long correlations, :func:`ar1_scale`; ``stats["noise_scale"]``). For
  slowly varying J this is Cov_white × (1+ρ)/(1-ρ): the effective number of independent
  samples is n_eff = n (1-ρ)/(1+ρ), with that same corrected ρ (``stats["noise_correlation"]``;
  ``stats["autocorrelation_lag1"]`` is the residuals' own ρ̂). With ``noise="auto"`` the report
  uses it when the residuals are not white: |ρ̂| > 3/√n (three standard errors of ρ̂ under
  white noise).
* **Solver error** (the model is a discretisation): the error of the model response at the
  optimum is estimated as the solver estimates its own (``lubjax.Result.force_error``): the nested
  coarse mesh (every other node, second order: error ≈ (y_coarse - y)/3) plus the time error from
  the coarse mesh at 8·rtol (global error ∝ rtol^{2/3}: ≈ (y_coarse,8rtol - y_coarse)/3). This
  signed error m shifts the optimum by δx = -(JᵀJ)⁻¹Jᵀm; it is the same in every noise draw, a
  systematic error, so it enters as Cov_solver = δx δxᵀ. The reported covariance is
  Cov_noise + Cov_solver: if the estimate is right, the mean square of (x̂ - x_true) over noise
  draws equals its diagonal exactly (bias² + variance).

Identifiability: any |correlation| > ``MAX_CORRELATION`` or a correlation-matrix condition number
above ``MAX_CONDITION`` flags the fit ``identifiable=False``.

Model comparison (:func:`information`): Gaussian log-likelihood with the noise scale profiled
out, ℓ = -(n/2) ln(Σr²/n) + const, AIC = 2k - 2ℓ, BIC = k ln n - 2ℓ (k = p + 1).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import solve_banded
from scipy.optimize import brentq

MAX_CORRELATION = 0.999
#: The largest |ρ| the AR(1) noise model takes (R's condition grows like 2/(1 - ρ)).
MAX_NOISE_CORRELATION = 0.99
#: The largest ρ :func:`ar1_scale` corrects the noise's scale for (see there).
SCALE_CORRELATION = 0.9
MAX_CONDITION = 1e8
NOISE_MODELS = ("auto", "white", "ar1")
#: |ρ̂| above this many standard errors (1/√n) of a white-noise ρ̂ means "not white".
WHITE_THRESHOLD = 3.0


def lag1(r: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual sequence."""
    r = r - np.mean(r)
    den = float(r @ r)
    return float(r[1:] @ r[:-1]) / den if den > 0 else 0.0


def ar1_correlated(J: np.ndarray, rho: float) -> np.ndarray:
    """R J for R_ij = ρ^|i-j| (AR(1) correlation), by the tridiagonal R⁻¹:
    (1 - ρ²) R⁻¹ = tridiag(-ρ; 1, 1 + ρ², ..., 1 + ρ², 1; -ρ)."""
    n = J.shape[0]
    if n < 2 or rho == 0.0:
        return J.copy()
    ab = np.zeros((3, n))
    ab[0, 1:] = -rho
    ab[1, :] = 1 + rho**2
    ab[1, 0] = ab[1, -1] = 1.0
    ab[2, :-1] = -rho
    return solve_banded((1, 1), ab / (1 - rho**2), J)


def _fit_basis(J: np.ndarray) -> np.ndarray:
    """An orthonormal basis Q of what a fit absorbs: the finite columns of J and the constants."""
    k = J.shape[0]
    basis = np.concatenate([J, np.ones((k, 1))], axis=1)
    basis = basis[:, np.all(np.isfinite(basis), axis=0)]
    u, sv, _ = np.linalg.svd(basis, full_matrices=False)
    return u[:, sv > sv[0] * 1e-10] if sv.size and sv[0] > 0 else np.zeros((k, 0))


def _projected_trace(q: np.ndarray, rho: float) -> float:
    """tr(M R(ρ) M) = tr(R) - tr(QᵀRQ), M = I - QQᵀ: E[Σr²]/σ² under AR(1) noise."""
    return q.shape[0] - float(np.trace(q.T @ ar1_correlated(q, rho)))


def ar1_correlation(r: np.ndarray, J: np.ndarray) -> float:
    """ρ of AR(1) noise e from the residuals r = (I - H) e of a least-squares fit.

    A fit absorbs the slow part of correlated noise into its parameters, so the residuals' own
    lag-1 autocorrelation understates the noise's (at ρ = 0.8 on a few hundred samples the
    errors came out 10-27 % too small). With M the projection off the columns of J and the
    constants, E[r rᵀ] = σ² M R(ρ) M, so ρ solves tr(S M R M)/tr(M R M) = Σ r_i r_{i+1}/Σ r_i²
    (S the shift), within [-0.99, 0.99]. The noise's σ² is :func:`ar1_scale`'s.
    """
    k = r.size
    r = r - np.mean(r)
    g0, g1 = float(r @ r), float(r[1:] @ r[:-1])
    if k < 3 or g0 <= 0:
        return 0.0
    q = _fit_basis(J)

    def ratio(rho):
        a = ar1_correlated(q, rho)  # R Q
        b = q.T @ a
        trace = k - np.trace(b)  # tr(M R M) = tr(R) - tr(QᵀRQ)
        shifted = ((k - 1) * rho - np.sum(q[1:] * a[:-1]) - np.sum(a[1:] * q[:-1])
                   + np.sum((q[1:] @ b) * q[:-1]))
        return shifted / trace

    observed = g1 / g0
    lo, hi = -MAX_NOISE_CORRELATION, MAX_NOISE_CORRELATION
    if ratio(lo) >= observed:
        return lo
    if ratio(hi) <= observed:
        return hi
    return float(brentq(lambda rho: ratio(rho) - observed, lo, hi, xtol=1e-10))


def ar1_scale(blocks_J, rhos) -> float:
    """The factor c that makes s² = Σr²/(n - p) the AR(1) noise's σ²: the fit absorbs the slow
    part of correlated noise, so E[Σr²] = σ² Σ tr(M R M) over the traces, less than σ² (n - p).
    c = Σ (n_b - rank_b) / Σ tr(M_b R(ρ_b) M_b), M_b the projection off trace b's columns and
    its constant (the projection :func:`ar1_correlation` uses; c = 1 at ρ = 0). Guarded: ρ is
    taken at most ``SCALE_CORRELATION`` here. Above it a correlation that long is as likely the
    model's misfit or drift as noise (a real AFM curve's residuals reach ρ̂ = 0.99), and the
    unguarded factor grows without bound as ρ → 1 (tr(M R M) → 0)."""
    plain = corrected = 0.0
    for J, rho in zip(blocks_J, rhos, strict=True):
        q = _fit_basis(J)
        plain += q.shape[0] - q.shape[1]
        corrected += _projected_trace(q, min(rho, SCALE_CORRELATION))
    return plain / corrected if corrected > 0 else 1.0


def _blocks(sizes):
    """(start, n_real) of each trace's block in the stacked residuals (blocks are padded)."""
    out, start = [], 0
    for length, n in sizes:
        out.append((start, n))
        start += length
    return out


def summarise(r, J, sizes, labels, *, noise="auto", solver_error=None) -> dict:
    """Covariance of x̂ and the fit statistics (see module docstring).

    Args:
        r, J: stacked residuals and Jacobian of one problem (trace blocks, each padded).
        sizes: (block length, real samples) per trace.
        labels: names of x's components.
        noise: "auto", "white" or "ar1".
        solver_error: the signed error of the model in residual units (same shape as r), or None.
    """
    blocks = _blocks(sizes)
    rows = np.concatenate([np.arange(s, s + n) for s, n in blocks])
    rr, JJ = r[rows], J[rows]
    n, p = rr.size, JJ.shape[1]
    dof = max(n - p, 1)
    chi2 = float(rr @ rr)
    s2 = chi2 / dof
    A = JJ.T @ JJ
    flags = []
    finite = bool(np.all(np.isfinite(A)) and np.isfinite(chi2))
    if not finite:
        # a model run that failed at the optimum (NaN in its response or Jacobian): say so
        # rather than let the linear algebra below raise and lose the fit
        inv = np.full_like(A, np.nan)
        flags.append("the model's residuals or Jacobian are not finite at the optimum: "
                     "no standard errors")
    else:
        try:
            inv = np.linalg.inv(A)
        except np.linalg.LinAlgError:
            inv = np.full_like(A, np.nan)
            flags.append("JᵀJ is singular: no standard errors")
    cov_white = s2 * inv
    rhos = [lag1(r[s : s + k]) for s, k in blocks]
    rho = float(np.sum([k * q for (_, k), q in zip(blocks, rhos)]) / n)
    correlated = abs(rho) > WHITE_THRESHOLD / math.sqrt(n)
    use = noise if noise != "auto" else ("ar1" if correlated else "white")
    parts = {"white": cov_white}
    noise_rhos = []  # the noise's ρ per trace, corrected for what the fit absorbs (AR(1) only)
    noise_scale = 1.0  # and what it absorbs of the noise's variance (ar1_scale)
    if use == "ar1" and not finite:
        cov_noise = parts["ar1"] = np.full_like(A, np.nan)
    elif use == "ar1":
        meat = np.zeros_like(A)
        for s, k in blocks:
            Jb = J[s : s + k]
            noise_rhos.append(ar1_correlation(r[s : s + k], Jb))
            meat += Jb.T @ ar1_correlated(Jb, noise_rhos[-1])
        noise_scale = ar1_scale([J[s : s + k] for s, k in blocks], noise_rhos)
        cov_noise = noise_scale * s2 * inv @ meat @ inv
        parts["ar1"] = cov_noise
    else:
        cov_noise = cov_white
    if correlated and use == "white":
        flags.append(f"residuals are not white (lag-1 autocorrelation {rho:.3g}); the white-noise "
                     "errors are too small: use noise='ar1'")
    cov = cov_noise
    if solver_error is not None:
        shift = -inv @ (JJ.T @ solver_error[rows])
        cov_solver = np.outer(shift, shift)
        parts["solver"] = cov_solver
        cov = cov_noise + cov_solver
    parts["total"] = cov
    se = np.sqrt(np.abs(np.diag(cov)))
    corr = cov / np.outer(se, se)
    off = np.abs(corr - np.eye(p))
    dg = np.sqrt(np.abs(np.diag(A)))
    with np.errstate(invalid="ignore", divide="ignore"):
        scaled_ok = finite and np.all(dg > 0)
        cond = float(np.linalg.cond(A / np.outer(dg, dg))) if scaled_ok else math.inf
    if noise_rhos:  # the effective sample count of the noise the errors assume, trace by trace
        n_eff = sum(k * (1 - q) / (1 + q) for (_, k), q in zip(blocks, noise_rhos))
        noise_rho = float(np.sum([k * q for (_, k), q in zip(blocks, noise_rhos)]) / n)
    elif use == "ar1":  # no finite Jacobian to correct with: the residuals' own lag-1
        n_eff, noise_rho = n * (1 - rho) / (1 + rho), rho
    else:
        n_eff, noise_rho = float(n), 0.0
    stats = dict(
        n_samples=int(n), n_parameters=int(p), dof=int(dof), chi2=chi2, reduced_chi2=s2,
        autocorrelation_lag1=rho, durbin_watson=float(np.sum(np.diff(rr) ** 2) / max(chi2, 1e-300)),
        noise_model=use, noise_correlation=noise_rho, noise_scale=float(noise_scale),
        n_effective=float(n_eff),
        **information(chi2, n, p),
    )
    return dict(
        covariance=cov, parts=parts, stats=stats, labels=list(labels), sizes=list(sizes),
        max_correlation=float(np.nanmax(off)) if p > 1 else 0.0, condition=cond, flags=flags,
        correlation=corr,
    )


def information(chi2: float, n: int, p: int) -> dict:
    """Profile log-likelihood (up to a constant common to models of the same data), AIC, BIC."""
    k = p + 1  # the noise scale
    loglik = -0.5 * n * math.log(max(chi2, 1e-300) / n)
    return dict(log_likelihood=loglik, aic=2 * k - 2 * loglik, bic=k * math.log(n) - 2 * loglik)
