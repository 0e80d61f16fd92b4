"""Are the reported standard errors honest? Seeded noise draws of a clean trace, fitted.

:func:`noise_draws` adds stationary Gaussian noise (white, or AR(1) as a load cell's low-pass
filter makes it) to a noiseless trace; :func:`coverage` fits the draws in one batched call and
compares each estimate with the known truth: z = (estimate - truth) / reported error. Honest
errors give an rms z near 1 (N draws scatter it by about 1/√(2N)).
"""

from __future__ import annotations

import numpy as np

from ._fit import fit_traces
from ._model import FIT_SETTINGS
from ._profile import LEVELS
from ._report import sided_z
from ._scales import drive_of


def noise_draws(clean, n, rho=0.0, fraction=0.01, seed=2024):
    """Noisy copies of a clean trace: stationary AR(1) noise on the response channel (the
    force; the displacement under a prescribed load), n_k = ρ n_{k-1} + √(1-ρ²) σ ε_k with ε_k
    standard normal. Seeded: the same arguments give the same draws.

    Args:
        clean: the noiseless :class:`Trace`.
        n: the number of copies, ≥ 1.
        rho: ρ, the lag-1 autocorrelation, in [0, 1) (default 0: white noise).
        fraction: the marginal σ as a fraction of the response's largest magnitude (default
            0.01).
        seed: the random generator's seed (default 2024).

    Returns:
        A list of ``n`` traces named "draw0", "draw1", ...

    Raises:
        ValueError: ``rho`` not in [0, 1) or ``n`` < 1.
    """
    if not 0.0 <= rho < 1.0:
        raise ValueError(f"rho must lie in [0, 1), got {rho!r}")
    if n < 1:
        raise ValueError(f"n must be at least 1, got {n!r}")
    rng = np.random.default_rng(seed)
    channel = "displacement" if drive_of(clean) == "force" else "force"
    response = getattr(clean, channel)
    sigma = fraction * float(np.max(np.abs(response)))
    out = []
    for k in range(n):
        e = rng.normal(0.0, sigma, clean.force.size)
        noise = np.empty_like(e)
        noise[0] = e[0]
        for i in range(1, e.size):
            noise[i] = rho * noise[i - 1] + np.sqrt(1 - rho**2) * e[i]
        out.append(clean._replace(**{channel: response + noise}, name=f"draw{k}"))
    return out


def coverage(draws, truth, settings=FIT_SETTINGS, **fit_kwargs):
    """Whether the reported errors are honest: fit noise draws of a known truth and compare,
    z = (estimate - truth)/reported error (honest errors: rms z near 1).

    Args:
        draws: the traces (:func:`noise_draws`), fitted in one batched :func:`fit_traces` call.
        truth: parameter name → true value [SI].
        settings: the model's ``lubjax.Settings`` (default ``FIT_SETTINGS``).
        **fit_kwargs: passed on to :func:`fit_traces`.

    Returns:
        dict: ``table`` (per parameter of ``truth``: ``rms_z`` of the reported errors,
        ``within_1sigma`` and ``within_2sigma``, the fractions of draws with |z| ≤ 1 and ≤ 2
        (honest errors: 68 % and 95 %) or, where the fit gave the parameter a profile
        interval, with the truth inside it (``profiled``: how many; ``rms_z`` leaves out the
        one-sided intervals of a parameter the fit calls undetermined and takes z of another
        one over its 1σ half on the truth's side, as the report does), ``rms_z_white`` of
        their white-noise part alone, ``mean_bias_over_se``, ``scatter_over_se`` and
        ``solver_over_se``, each over the mean reported error),
        ``converged`` (how many), ``n``, ``noise_models`` (those chosen), ``lag1`` (the mean
        lag-1 autocorrelation of the residuals) and ``noise_correlation`` (the mean of the
        noise's ρ the AR(1) errors took, corrected for what the fit absorbs; 0 for white).
    """
    results = fit_traces(draws, settings=settings, **fit_kwargs)
    table = {}
    for name, true in truth.items():
        est = np.array([r.values[name] for r in results])
        se = np.array([r.stderr[name] for r in results])
        white = np.array([r.stats["error_parts"]["white"][name] for r in results])
        solver = np.array([r.stats["error_parts"].get("solver", {}).get(name, 0.0)
                           for r in results])
        # the report's z: over the 1σ interval's half on the truth's side where the parameter
        # has an interval through an undetermined one's profile
        z = np.array([sided_z(r, name, true) for r in results])
        within = {key: np.abs(z) <= level for key, level in LEVELS.items()}
        # where the data bound the parameter from one side, its interval is the profile's
        profiled = np.array([name in r.stats.get("intervals", {}) for r in results])
        one_sided = profiled & np.array([name in r.stats.get("undetermined", ())
                                         for r in results])
        for i in np.flatnonzero(profiled):
            interval = results[i].stats["intervals"][name]
            for key in LEVELS:
                within[key][i] = interval[key][0] <= true <= interval[key][1]
        table[name] = dict(
            rms_z=float(np.sqrt(np.mean(z[~one_sided] ** 2))) if (~one_sided).any() else np.nan,
            within_1sigma=float(np.mean(within["1sigma"])),
            within_2sigma=float(np.mean(within["2sigma"])),
            profiled=int(profiled.sum()),
            rms_z_white=float(np.sqrt(np.mean(((est - true) / white) ** 2))),
            mean_bias_over_se=float(np.mean(est - true) / np.mean(se)),
            scatter_over_se=float(np.std(est, ddof=1) / np.mean(se)),
            solver_over_se=float(np.mean(solver) / np.mean(se)),
        )
    models = sorted({r.stats["noise_model"] for r in results})
    return dict(table=table, converged=int(sum(r.converged for r in results)), n=len(results),
                noise_models=models,
                lag1=float(np.mean([r.stats["autocorrelation_lag1"] for r in results])),
                noise_correlation=float(np.mean([r.stats["noise_correlation"]
                                                 for r in results])))
