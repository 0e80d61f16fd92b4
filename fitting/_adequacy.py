r"""Does the fitted model describe the data? A judgement every fit makes, and says in words.

A fit's errors are honest only if what is left over, the residuals e_k = data - model, is
noise. This module tests that, per trace, against a noise model estimated from the residuals
themselves (the signal removed): stationary Gaussian noise with a lag-1 correlation ρ, AR(1),
the noise model of :mod:`fitting._stats` (white noise is ρ = 0).

**The noise, from the shortest lags.** With v1 = ½ mean (e_{k+1} - e_k)², v2 = ½ mean
(e_{k+2} - e_k)², AR(1) noise of marginal variance σ² gives v1 = σ²(1 - ρ), v2 = σ²(1 - ρ²), so

    ρ̂ = v2/v1 - 1,    σ̂² = v1/(1 - ρ̂).

A misfit that is smooth on the scale of two samples (a wrong relaxation, a wrong curvature)
hardly changes these differences, so it cannot pass itself off as noise. ρ̂ is kept within
±``RHO_MAX``: residuals smoother than that from one sample to the next are not the short-range
noise this judgement can tell from a misfit.

**Three tests**, each against the distribution it has when the model is right:

1. *Size* (reduced χ²): χ²_ν = Σe²/((n - p) σ̂²), p the fitted parameters. Its logarithm is
   near normal around 0, with a variance that has two parts: the sum of squares of correlated
   noise, and the estimate σ̂² made from the same residuals (with ρ̂). Both come from Bartlett's
   formula for the covariance of sample autocovariances, Cov(γ̂_i, γ̂_j) ≈ (1/n) Σ_k
   [γ(k)γ(k+j-i) + γ(k+j)γ(k-i)] with γ(k) = ρ̂^|k| (:func:`_moment_covariance`), carried to
   log χ²_ν, ρ̂ and the noise's long-run variance by the delta method (:func:`_spread`).
2. *Runs* (Wald–Wolfowitz) on the signs of the whitened residuals u_k = e_k - ρ̂ e_{k-1}: a
   systematic misfit keeps its sign over many samples, so it makes too few runs. With ρ̂ in
   place of ρ the whitened residuals keep a lag-1 correlation ≈ ρ - ρ̂, which moves the number of
   runs by (n/π)(ρ - ρ̂): the z-score's variance is 1 + (4n/π²) Var(ρ̂).
3. *Shape, per segment* (the approach, a dwell; a tribometer trace's rest, ramp and hold):
   means of the whitened residuals over blocks of L samples (L ≈ √(segment length), and at
   least two noise correlation lengths). Noise averages out over a block, a smooth misfit
   does not: X = Σ_j L b_j²/σ̂² is χ² on m blocks for noise, times the ratio of the noise's
   true long-run variance to the estimated one (log-variance from the delta method), taken
   to a z-score through the Wilson–Hilferty cube root.

Each test fails at z > z_crit (the runs test at z < -z_crit), z_crit = Φ⁻¹(1 - α/k) for k tests
(Bonferroni): a correctly specified model with AR(1) noise passes all of them with probability
at least 1 - α, α = ``ALPHA`` = 1 %. tests/test_adequacy.py checks that rate on simulated
noise of 300 samples, ρ = 0, 0.5, 0.8 (and that the variances above match simulation), and
both verdicts on fits. The delta method is asymptotic: 100 samples at ρ = 0.8, or ρ = 0.9 at
any length, fail 1.5-2.5 % of the time.

A failed judgement says what misfits (the size, the runs, the segments) and what could help:
a viscoelastic solid (``--compare`` tests it), a solid with a spread of relaxation times (a
power law: not in lubjax), a different drive for an AFM creep, or a tighter ``--rtol`` where the
solver's own error estimate explains the misfit. The film-free model is not suggested: it is
the η → 0 end of the film model, which a fit of η already reaches where the data ask for it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.special import ndtri

#: The false alarm rate of the whole judgement for a correctly specified model.
ALPHA = 0.01
#: |ρ̂| is kept below this: the noise's correlation this judgement can separate from a misfit.
RHO_MAX = 0.9
#: The noise's estimate leaves out successive differences beyond this many robust standard
#: deviations.
TRIM = 4.0
#: Fewer samples than this: no judgement.
MIN_SAMPLES = 20
#: A segment is judged on its shape only with at least this many blocks.
MIN_BLOCKS = 3
#: The spreads are taken at ρ̂ + UPPER standard deviations of ρ̂ (within RHO_MAX): at ρ̂ itself
#: an underestimated ρ̂ makes σ̂² and the spreads too small together, and noise with ρ = 0.8
#: failed 2-3 % of its judgements (tests/test_adequacy.py simulates it).
UPPER = 2.0


class SegmentCheck(NamedTuple):
    """The shape test of one segment of a trace.

    Attributes:
        name: the segment ("approach", "dwell", "ramp", "hold", ...).
        start, stop: its samples, ``slice(start, stop)``.
        blocks: the blocks its residual means were taken over (0: too short to test).
        z: the test's z-score (large: a systematic misfit); NaN when not tested.
        systematic: whether it fails (z > the critical z).
        misfit: the largest |block mean| of the residuals, the size of their systematic part
            [the response's unit]; NaN when not tested.
    """

    name: str
    start: int
    stop: int
    blocks: int
    z: float
    systematic: bool
    misfit: float


class Adequacy(NamedTuple):
    """Whether the fitted model describes a trace (:func:`judge`; the module docstring).

    Attributes:
        ok: True when every test passes, False when one fails, None when the trace is too short
            to judge (fewer than ``MIN_SAMPLES`` samples).
        reduced_chi2: Σe²/((n - p) σ̂²): the residuals' mean square against the noise's.
        chi2_z: its z-score (log χ²_ν over its standard deviation for noise).
        runs_z: the runs test's z-score (negative: too few sign changes).
        noise_sigma: σ̂, the noise's estimated standard deviation [the response's unit].
        noise_lag1: ρ̂, the noise's estimated lag-1 correlation.
        smooth: whether the residuals change more smoothly from one sample to the next than
            noise with |ρ| <= ``RHO_MAX`` can (a misfit at every scale).
        misfit: the rms of the residuals' systematic part, √(mean e² - σ̂²), as a fraction of
            the response's peak (``peak``).
        z_critical: the z a test must exceed to fail.
        segments: a :class:`SegmentCheck` per segment.
        solver_explains: True when the misfit passes as noise once the solver's own error
            estimate is taken off it (a tighter tolerance is the fix); None when not asked.
        message: the judgement in one line.
        advice: what could help, in words (empty when ``ok``).
    """

    ok: bool | None
    reduced_chi2: float
    chi2_z: float
    runs_z: float
    noise_sigma: float
    noise_lag1: float
    smooth: bool
    misfit: float
    z_critical: float
    segments: tuple
    solver_explains: bool | None
    message: str
    advice: tuple

    def to_dict(self) -> dict:
        """The record as JSON-ready plain values."""
        out = {k: getattr(self, k) for k in self._fields if k not in ("segments", "advice")}
        out["advice"] = list(self.advice)
        out["segments"] = [
            {**s._asdict(), "z": _finite(s.z), "misfit": _finite(s.misfit)}
            for s in self.segments]
        for k in ("reduced_chi2", "chi2_z", "runs_z", "noise_sigma", "noise_lag1", "misfit",
                  "z_critical"):
            out[k] = _finite(out[k])
        return out


def _finite(x):
    return None if x is None or not math.isfinite(x) else float(x)


# --------------------------------------------------------------------------- the noise


def _trimmed_square(d: np.ndarray) -> float:
    """Mean of d² over the samples within ``TRIM`` robust standard deviations (1.4826 MAD) of
    the median: Gaussian noise loses 1 sample in 16 000 to the cut, a misfit's sharp features
    (a kink, the start of a dwell) are left out of the noise."""
    med = float(np.median(d))
    scale = 1.4826 * float(np.median(np.abs(d - med)))
    keep = d[np.abs(d - med) <= TRIM * scale] if scale > 0 else d
    return float(np.mean(keep**2)) if keep.size else 0.0


def noise_estimate(e: np.ndarray) -> tuple[float, float, float]:
    """(σ̂², ρ̂, ρ̂ before clipping) of AR(1) noise from the residuals' lag-1 and lag-2
    differences (module docstring), ρ̂ within [0, ``RHO_MAX``]."""
    v1 = 0.5 * _trimmed_square(np.diff(e))
    v2 = 0.5 * _trimmed_square(e[2:] - e[:-2])
    if not v1 > 0:
        return 0.0, 0.0, 0.0
    raw = v2 / v1 - 1.0
    # the noise is no larger than the residuals: σ̂² = v1/(1 - ρ̂) <= mean e², ρ̂ <= 1 - v1/mean e²
    top = min(RHO_MAX, 1.0 - v1 / max(float(np.mean(e**2)), 1e-300))
    rho = float(np.clip(raw, 0.0, max(top, 0.0)))
    return v1 / (1.0 - rho), rho, raw


def _moment_covariance(rho: float, n: int) -> np.ndarray:
    """Bartlett's covariance of the sample autocovariances (γ̂0, γ̂1, γ̂2) of n samples of AR(1)
    noise with unit variance and lag-1 correlation ρ."""
    terms = math.ceil(math.log(1e-12) / math.log(max(abs(rho), 1e-3)))
    k = np.arange(-terms, terms + 3)

    def gamma(shift):
        return np.sign(rho) ** np.abs(k + shift) * abs(rho) ** np.abs(k + shift) if rho else (
            (k + shift == 0).astype(float))

    cov = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            cov[i, j] = float(np.sum(gamma(0) * gamma(j - i) + gamma(j) * gamma(-i))) / n
    return cov


def _estimates(g) -> dict:
    """log χ²_ν's numerator and denominator, ρ̂ and the long-run variance as functions of the
    autocovariances g = (γ0, γ1, γ2) (v1 = γ0 - γ1, v2 = γ0 - γ2)."""
    g0, g1, g2 = g
    v1, v2 = g0 - g1, g0 - g2
    rho = v2 / v1 - 1.0
    s2 = v1 / (1.0 - rho)
    return dict(log_chi2=math.log(g0 / s2), rho=rho,
                log_long_run=math.log(s2 * (1.0 + rho) / (1.0 - rho)))


def _spread(rho: float, n: int) -> dict:
    """Standard deviations of log χ²_ν, ρ̂ and the log long-run variance for noise (the delta
    method on :func:`_moment_covariance`)."""
    cov = _moment_covariance(rho, n)
    g = np.array([1.0, rho, rho * rho])
    h = 1e-6
    grads = {}
    for i in range(3):
        step = np.eye(3)[i] * h
        up, down = _estimates(g + step), _estimates(g - step)
        for key in up:
            grads.setdefault(key, np.zeros(3))[i] = (up[key] - down[key]) / (2 * h)
    return {key: math.sqrt(max(float(v @ cov @ v), 0.0)) for key, v in grads.items()}


# --------------------------------------------------------------------------- the tests


def runs_z(signs: np.ndarray) -> float:
    """Wald–Wolfowitz z-score of the runs of a ±1 sequence (negative: too few runs); 0 when one
    sign is missing."""
    s = signs[signs != 0]
    n_pos, n_neg = int(np.sum(s > 0)), int(np.sum(s < 0))
    n = n_pos + n_neg
    if n_pos == 0 or n_neg == 0 or n < 3:
        return 0.0
    runs = 1 + int(np.count_nonzero(s[1:] != s[:-1]))
    mean = 2.0 * n_pos * n_neg / n + 1.0
    var = 2.0 * n_pos * n_neg * (2.0 * n_pos * n_neg - n) / (n * n * (n - 1.0))
    return (runs - mean) / math.sqrt(var) if var > 0 else 0.0


def _whiten(e, rho):
    u = np.empty_like(e)
    u[0] = e[0]
    u[1:] = (e[1:] - rho * e[:-1]) / math.sqrt(1.0 - rho * rho)
    return u


def _block_test(e, u, s2, v_long, corr_len):
    """(blocks, z, largest |block mean of e|) of one segment's residuals e, whitened u."""
    n = u.size
    size = max(math.ceil(math.sqrt(n)), math.ceil(2 * corr_len), 2)
    m = n // size
    if m < MIN_BLOCKS:
        return 0, math.nan, math.nan
    edges = np.linspace(0, n, m + 1).astype(int)[:-1]
    lengths = np.diff(np.append(edges, n))
    sums = np.add.reduceat(u, edges)
    x = float(np.sum(sums**2 / lengths)) / s2
    cube = (x / m) ** (1.0 / 3.0)
    z = (cube - (1.0 - 2.0 / (9 * m))) / math.sqrt(2.0 / (9 * m) + v_long**2 / 9.0)
    return m, z, float(np.max(np.abs(np.add.reduceat(e, edges) / lengths)))


def _tests(e, segments, n_params):
    """The tests on residuals e (the module docstring); a dict of their values, or None for
    residuals without noise."""
    n = e.size
    s2, rho, raw = noise_estimate(e)
    if not s2 > 0:
        return None
    # The spreads grow with ρ: taken at ρ̂'s upper confidence limit (UPPER).
    rho_up = min(rho + UPPER * _spread(rho, n)["rho"], RHO_MAX)
    spread = _spread(rho_up, n)
    corr_len = (1.0 + rho) / (1.0 - rho)
    u = _whiten(e, rho)
    segs = [(name, a, b, *_block_test(e[a:b], u[a:b], s2, spread["log_long_run"], corr_len))
            for name, a, b in segments]
    k = 3 + sum(1 for s in segs if s[3] > 0)
    z_crit = float(ndtri(1.0 - ALPHA / k))
    # Residuals smoother from one sample to the next than AR(1) noise with ρ <= RHO_MAX can be
    # (ρ̂ > 1, differences that are positively correlated, is no AR(1) at all): the noise cannot
    # be told from the misfit by these residuals, and that smoothness is itself a misfit. Their
    # size is then measured against the sample-to-sample scatter alone (ρ = 0).
    smooth_z = (raw - RHO_MAX) / _spread(RHO_MAX, n)["rho"]
    smooth = smooth_z > z_crit
    if smooth:
        s2 = s2 * (1.0 - rho)
    chi2 = float(e @ e) / (max(n - n_params, 1) * s2)
    chi2_z = math.log(max(chi2, 1e-300)) / max(spread["log_chi2"], 1e-12)
    runs = runs_z(np.sign(u[1:])) / math.sqrt(1.0 + 4.0 * n * spread["rho"] ** 2 / math.pi**2)
    return dict(s2=s2, rho=rho, raw_rho=raw, smooth=smooth, smooth_z=smooth_z, chi2=chi2,
                chi2_z=chi2_z, runs_z=runs, z_crit=z_crit, segments=segs)


def _passes(t) -> bool:
    zc = t["z_crit"]
    return (not t["smooth"] and t["chi2_z"] <= zc and t["runs_z"] >= -zc
            and all(not (s[3] > 0 and s[4] > zc) for s in t["segments"]))


# --------------------------------------------------------------------------- segments


def segments_of(time, metadata, t_on, t_motion_end) -> list:
    """(name, start, stop) of a trace's segments: an AFM file's approach and dwell (its
    ``dwell_start_s``), else the rest before the motion, the ramp and the hold."""
    n = time.size
    meta = metadata or {}
    if "instrument_file" in meta:
        names = [s for s in str(meta.get("segments", "approach")).split(",") if s]
        if "dwell" in names and "dwell_start_s" in meta:
            k = int(np.searchsorted(time, float(meta["dwell_start_s"]) - 1e-12))
            if 0 < k < n:
                return [("approach", 0, k), ("dwell", k, n)]
        return [("approach", 0, n)]
    a = int(np.searchsorted(time, t_on, side="right"))
    b = int(np.searchsorted(time, t_motion_end, side="right"))
    out = [("rest before the motion", 0, a), ("ramp", a, b), ("hold", b, n)]
    return [s for s in out if s[2] - s[1] >= 2]


# --------------------------------------------------------------------------- the judgement


def judge(residual, segments, n_params, *, peak=None, model_error=None, viscoelastic=False,
          layer=False, drive="travel", metadata=None) -> Adequacy:
    """Whether a fitted model describes a trace (the module docstring).

    Args:
        residual: data - model at the samples, in time order [the response's unit].
        segments: (name, start, stop) of each segment (:func:`segments_of`).
        n_params: the parameters fitted to this trace.
        peak: the size of the response the systematic misfit is measured against (default:
            the largest |residual|).
        model_error: the solver's signed error estimate of the model at the samples (the
            same unit), or None: then the judgement does not ask whether it explains a misfit.
        viscoelastic, layer, drive: the fitted model (for the advice).
        metadata: the trace's metadata (an AFM file's modality, for the advice).

    Returns:
        Adequacy: the record, its one-line ``message`` and ``advice``.
    """
    e = np.asarray(residual, dtype=np.float64)
    nan = math.nan
    if e.size < MIN_SAMPLES or not np.all(np.isfinite(e)):
        why = (f"fewer than {MIN_SAMPLES} samples" if e.size < MIN_SAMPLES
               else "non-finite residuals")
        return Adequacy(None, nan, nan, nan, nan, nan, False, nan, nan, (), None,
                        f"model adequacy not judged ({why})", ())
    t = _tests(e, segments, n_params)
    if t is None:
        return Adequacy(True, 0.0, -math.inf, 0.0, 0.0, 0.0, False, 0.0, nan, (), None,
                        "the model describes these data exactly (no residual)", ())
    checks = tuple(SegmentCheck(name, a, b, m, z, bool(m > 0 and z > t["z_crit"]), mis)
                   for name, a, b, m, z, mis in t["segments"])
    ok = _passes(t)
    solver = None
    if not ok and model_error is not None:
        m_err = np.asarray(model_error, dtype=np.float64)
        if m_err.shape == e.shape and np.all(np.isfinite(m_err)) and np.any(m_err != 0):
            alt = _tests(e + m_err, segments, n_params)
            solver = bool(alt is not None and _passes(alt))
    peak = float(np.max(np.abs(e))) if peak is None else float(peak)
    excess = float(np.mean(e**2)) - t["s2"]
    misfit = math.sqrt(max(excess, 0.0)) / peak if peak > 0 else nan
    message, advice = _words(ok, t, checks, misfit, solver, viscoelastic, layer, drive,
                             metadata or {})
    return Adequacy(ok, t["chi2"], t["chi2_z"], t["runs_z"], math.sqrt(t["s2"]), t["rho"],
                    bool(t["smooth"]), misfit, t["z_crit"], checks, solver, message,
                    tuple(advice))


def _join(names):
    names = [f"the {n}" for n in names]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _words(ok, t, checks, misfit, solver, viscoelastic, layer, drive, meta):
    """The one-line message and the advice of a judgement."""
    chi2 = f"reduced chi2 {t['chi2']:.3g} against the noise in the residuals"
    if ok:
        return (f"the model describes these data ({chi2}, no systematic residuals)", [])
    what = []
    if t["chi2_z"] > t["z_crit"] or t["smooth"]:
        what.append(chi2)
    bad = [c.name for c in checks if c.systematic]
    if bad:
        what.append(f"residuals systematic over {_join(bad)}")
    if t["smooth"]:
        what.append("residuals that change smoothly from sample to sample, as short-range "
                    "noise does not")
    if t["runs_z"] < -t["z_crit"]:
        what.append(f"residual signs in long runs (runs test z = {t['runs_z']:.1f})")
    if math.isfinite(misfit):
        what.append(f"a systematic part of {100 * misfit:.2g} % of the peak, rms")
    advice = []
    if solver:
        advice.append("a tighter --rtol (the solver's own error estimate accounts for the "
                      "misfit)")
    else:
        held = any(n in ("dwell", "hold") for n in bad)
        if not viscoelastic:
            advice.append("a viscoelastic solid (--substrate viscoelastic"
                          + ("; --compare tells whether the data ask for it)" if not layer
                             else ")"))
            if not layer and "instrument_file" not in meta and "ramp" in bad and not held:
                advice.append("a layer on a rigid base, if the sample is one (--substrate "
                              "layer --thickness H --compare)")
        elif held:
            advice.append("a solid with a spread of relaxation times (a power-law solid; "
                          "lubjax fits one relaxation time)")
        if "instrument_file" in meta:
            if any(n == "approach" for n in bad) or not bad:
                advice.append("another depth range (a modulus that changes with depth misfits "
                              "a deep approach; the toe of a long force rise alone does not "
                              "hold E*)")
            if held and meta.get("modality") == "creep-compliance":
                advice.append("the other drive for the constant-force dwell (--drive "
                              + ("spring)" if drive == "force" else "force, load control)"))
    message = "the model does not describe these data (" + ", ".join(what) + ")"
    if advice:
        message += "; what could help: " + "; ".join(advice)
    return message, advice
