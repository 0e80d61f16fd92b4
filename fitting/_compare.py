r"""Is the richer model needed? Compare two fits of the same trace(s) by likelihood.

The default (elastic) model is nested in the richer one (a standard linear solid with E0/E∞ → 1,
or any spec with more parameters). Both are fitted to the same data; with Gaussian noise of
unknown scale the profile log-likelihood is ℓ = -(n/2) ln(χ²/n) (+ a constant common to both),
and

* the likelihood ratio LR = 2(ℓ_rich - ℓ_simple), with a nominal χ²(Δk) p-value: only a guide,
  since E0/E∞ = 1 lies on the boundary of the richer model and τ is then undefined (the
  classical χ² law does not hold there: Self & Liang 1987, Davies 1987);
* AIC = 2k - 2ℓ and BIC = k ln n - 2ℓ (k: fitted parameters + the noise scale).

Models with the same number of parameters (a layer of known thickness against the half-space)
are not nested: their ratio gets no p-value; the decision below is the same.

Decision: the richer model only when ΔBIC = BIC_simple - BIC_rich > ``BIC_MARGIN`` (10: "very
strong" evidence on Kass & Raftery's scale); BIC, unlike AIC, does not pick the larger model
more often as n grows when the smaller one is true. Where the residuals are correlated (AR(1)
noise model) the information is counted in effective samples: ℓ × n_eff/n.
"""

from __future__ import annotations

import dataclasses
import math

from . import _model, _scales
from ._fit import fit_traces
from ._start import Start

BIC_MARGIN = 10.0


def _information(results) -> dict:
    """ℓ, k, n (effective) of a fit: summed over separately fitted traces."""
    seen, ll, k, n, n_eff = set(), 0.0, 0, 0, 0.0
    for r in results:
        key = r.group or (r.name,)
        if key in seen:
            continue
        seen.add(key)
        st = r.stats
        scale = st["n_effective"] / st["n_samples"]
        ll += scale * st["log_likelihood"]
        k += st["n_parameters"] + 1
        n += st["n_samples"]
        n_eff += st["n_effective"]
    return dict(log_likelihood=ll, k=k, n=n, n_effective=n_eff,
                aic=2 * k - 2 * ll, bic=k * math.log(max(n_eff, 1.0)) - 2 * ll)  # ρ̂ → 1: n_eff → 0


def compare(simple_results, rich_results, simple_label="simple", rich_label="rich") -> dict:
    """The comparison report of two fits of the same traces (see module docstring)."""
    a, b = _information(simple_results), _information(rich_results)
    lr = 2 * (b["log_likelihood"] - a["log_likelihood"])
    dk = b["k"] - a["k"]
    from scipy.stats import chi2  # here, not at import: scipy.stats costs a fit 0.5 s to load

    nested = dk > 0
    # Same parameter count (a layer against the half-space): not nested, so no χ² law for the
    # ratio and nothing "extra"; the information criteria still compare them.
    p = float(chi2.sf(max(lr, 0.0), dk)) if nested else None
    d_aic, d_bic = a["aic"] - b["aic"], a["bic"] - b["bic"]
    rich_ok = all(r.converged for r in rich_results)
    use_rich = d_bic > BIC_MARGIN
    choice = rich_label if use_rich else simple_label
    if nested:
        verdict = ("the data ask for the extra parameters" if use_rich
                   else "the extra parameters are not needed")
        ratio = (f"likelihood ratio {lr:.2f} on {dk} extra parameter(s), nominal p = {p:.3g} "
                 "(boundary: a guide only)")
    else:
        verdict = (f"the data favour it over the {simple_label}" if use_rich
                   else f"not enough evidence for the {rich_label} over the {simple_label}")
        ratio = (f"likelihood ratio {lr:.2f} between models with the same number of "
                 "parameters (not nested: no p-value)")
    relation = ">" if use_rich else "<="
    report = [
        f"{simple_label}: log-likelihood {a['log_likelihood']:.2f}, k = {a['k']}, "
        f"AIC {a['aic']:.1f}, BIC {a['bic']:.1f}",
        f"{rich_label}: log-likelihood {b['log_likelihood']:.2f}, k = {b['k']}, "
        f"AIC {b['aic']:.1f}, BIC {b['bic']:.1f}"
        + ("" if rich_ok else " (fit not converged: its likelihood is a lower bound)"),
        ratio,
        f"decision: {choice} (delta BIC = {d_bic:.1f} {relation} {BIC_MARGIN:g}: {verdict})",
    ]
    return dict(simple=simple_label, rich=rich_label, likelihood_ratio=lr, extra_parameters=dk,
                p_value_nominal=p, delta_aic=d_aic, delta_bic=d_bic, bic_margin=BIC_MARGIN,
                choice=choice, rich_converged=rich_ok, report=report,
                simple_information=a, rich_information=b)


def _naming(progress, spec):
    """``progress`` with each message prefixed by the model it comes from (two fits run)."""
    if progress is None:
        return None
    label = spec.substrate_label()
    return lambda message: progress(f"{label}: {message}")


def compare_models(traces, *, simple=None, rich=None, tau_start=1.0, **fit_kwargs):
    """Fit the default and a richer model to the same traces and compare them.

    The comparison (module docstring of :mod:`fitting._compare`): the likelihood ratio with a
    nominal χ² p-value, ΔAIC and ΔBIC; the richer model is chosen only when ΔBIC = BIC_simple -
    BIC_rich > ``BIC_MARGIN`` (10).

    Args:
        traces: the traces (fitted separately, or jointly with ``shared=`` in ``fit_kwargs``).
        simple: the default :class:`ModelSpec` (default: the traces' drive, elastic half-space).
        rich: the richer spec (default: ``simple`` with a viscoelastic solid).
        tau_start: the richer model's start for τ, in units of t_c; its other parameters start
            at the simple fit's optimum (E0/E∞ at 1.2).
        **fit_kwargs: passed to :func:`fitting.fit_traces`; ``starts`` to the simple fit only
            (the richer one starts from its optimum).

    Returns:
        tuple: (simple results, rich results, comparison dict), two lists of :class:`FitResult`, one
        per trace, and the dict of the comparison (``likelihood_ratio``, ``p_value_nominal``,
        ``delta_aic``, ``delta_bic``, ``choice``, the text ``report``, ...); the dict is also
        in each result's ``stats["comparison"]``.

    Raises:
        ValueError: as :func:`fitting.fit_traces`, for either fit.

    Example:
        ```python
        import dataclasses
        import fitting

        trace = fitting.read_trace("data/paper_dc140.csv")
        coarse = dataclasses.replace(fitting.FIT_SETTINGS, rtol=1e-3)
        simple, rich, comparison = fitting.compare_models([trace], settings=coarse)
        assert comparison["choice"] in (comparison["simple"], comparison["rich"])
        for line in comparison["report"]:  # the likelihoods, AIC, BIC and the decision
            print(line)
        ```
    """
    if simple is None:
        drive = _scales.drive_of(traces[0], fit_kwargs.pop("drive", None))
        simple = _model.ModelSpec(drive=drive, fit_offset=fit_kwargs.pop("fit_offset", True),
                                  layer=fit_kwargs.pop("layer", None))
    rich = dataclasses.replace(simple, viscoelastic=True) if rich is None else rich
    progress = fit_kwargs.pop("progress", None)
    base = fit_traces(traces, spec=simple, starts=fit_kwargs.pop("starts", None),
                      progress=_naming(progress, simple), **fit_kwargs)
    starts = []
    for r in base:
        values = {n: r.values.get(n) for n in rich.names}
        note = f"from the {simple.substrate_label()} fit"
        if rich.viscoelastic and not simple.viscoelastic:
            values.update(stiffening=1.2, relaxation_time=tau_start * r.scales.time_scale)
            note += f"; E0/Einf = 1.2, tau = {tau_start:g} t_c"
        starts.append(Start(values, (note,)))
    richer = fit_traces(traces, spec=rich, starts=starts, progress=_naming(progress, rich),
                        **fit_kwargs)
    comparison = compare(base, richer, simple.substrate_label(), rich.substrate_label())
    for r in base + richer:
        r.stats["comparison"] = comparison
    return base, richer, comparison
