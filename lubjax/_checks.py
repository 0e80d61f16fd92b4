"""Validation at the library's boundaries: numbers, ranges and choices, each with an error that
names the parameter and what it may be.

Every check lets a JAX tracer through (:func:`is_traced`): a value is checked where it is built
from concrete numbers, and the pytrees that carry it are unflattened under ``jit``/``vmap``
with tracers (or placeholders) that cannot be checked and need not be.

The solver's ranges live here too: β and z̄0 (:data:`BETA_RANGE`, :data:`Z0_RANGE`), t̄_end
(:data:`T_END_MAX`), Poisson's ratio (:data:`POISSON_RANGE`) and the bases a layer may rest on
(:data:`LAYER_BASES`).
"""

from __future__ import annotations

import math
import numbers

import jax
import numpy as np

BETA_RANGE = (1e-4, 1e9)
"""(lowest, highest) β (eq 8e) the solver accepts, both included. Inside the ranges the stepper
was mapped (README, stability map: β ∈ [0.1, 10⁶] × z̄0 ∈ [0.05, 5] to t̄ = 10⁶); outside them
the thin-film scales overflow float64 long before any physics changes."""
Z0_RANGE = (1e-4, 1e3)
"""(lowest, highest) z̄0 = z0/d_c (eq 8e) the solver accepts, both included (see
``BETA_RANGE``)."""
T_END_MAX = 1e9
"""The longest run, in t̄ (units of t_c)."""
POISSON_RANGE = (-1.0, 0.5)
"""Poisson's ratio ν ∈ (-1, 0.5] (0.5: incompressible): open below, closed above."""
LAYER_BASES = ("bonded", "frictionless")
"""How a layer rests on its rigid base: no slip ("bonded"), or free to slide ("frictionless")."""
FILM_ERRORS = ("auto", "relative", "force")
"""What a film's local error may be measured against (``Settings.film_error``)."""
MAX_TRAVEL_OVER_RADIUS = 0.2
"""The paraboloid (eq 8a) needs travel and gap ≪ R: SI inputs with d_c or z0 above this × R are
refused with the paraboloid, and the message names the fix, the sphere's true profile
(``lubjax.Sphere``, ``--indenter sphere``)."""
MAX_SPHERE_TRAVEL_OVER_RADIUS = 1.0
"""The sphere's own limit (``lubjax.Sphere``): travel and gap at most R. Sneddon's rigid sphere on
the half-space has its contact on the lower hemisphere, a < R; at δ = R it reaches a = 0.83 R,
the surface at its edge already at 56° from the plane. Deeper, the substrate would have to wrap
toward the equator, where neither a flat half-space's elasticity nor a film thin against the
contact radius describes it."""


def is_traced(value) -> bool:
    """Whether ``value`` is a JAX tracer (checked where it was built, not here)."""
    return isinstance(value, jax.core.Tracer)


def concrete(tree):
    """The value of a tree of numbers where it is known now, or None.

    Outside ``jit`` and ``vmap`` a value being differentiated (``jvp``, ``grad``) still has a
    known primal: each leaf comes back as a NumPy array of it, the derivative stripped. Under
    ``jit`` or ``vmap`` nothing is known until the program runs: None."""
    def value(x):
        return np.asarray(jax.lax.stop_gradient(x)) if is_traced(x) else x

    try:
        return jax.tree_util.tree_map(value, tree)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


def any_traced(tree) -> bool:
    """Whether any leaf of ``tree`` is a JAX tracer."""
    return any(is_traced(x) for x in jax.tree_util.tree_leaves(tree))


def _is_real(value) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def check_number(name, value, lo=None, hi=None, lo_open=False):
    """A concrete real scalar, finite, ≥ ``lo`` (> with ``lo_open``) and ≤ ``hi``; tracers
    pass."""
    if is_traced(value):
        return
    if isinstance(value, bool) or np.ndim(value) != 0:
        raise ValueError(f"{name} must be a scalar number, got {value!r}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise ValueError(f"{name} must be {'>' if lo_open else '>='} {lo:g}, got {value!r}")
    if hi is not None and v > hi:
        raise ValueError(f"{name} must be <= {hi:g}, got {value!r}")


def check_positive(name, value, unit: str | None = None) -> float:
    """A finite real number > 0, as a float: "``name`` must be a finite number > 0 (unit)"."""
    if not (_is_real(value) and math.isfinite(value) and value > 0):
        where = f" ({unit})" if unit else ""
        raise ValueError(f"{name} must be a finite number > 0{where}, got {value!r}")
    return float(value)


def check_quantity(name, value, unit: str, zero: bool = False) -> float:
    """A physical quantity in SI (anything ``float`` reads), finite and > 0 (≥ 0 with
    ``zero``), as a float; tracers pass (a derivative in it is being taken)."""
    if is_traced(value):
        return value
    try:
        v = float(value)
    except (TypeError, ValueError):
        kind = "a number" if zero else "a positive number"
        raise ValueError(f"{name} must be {kind} in {unit}, got {value!r}") from None
    if not (math.isfinite(v) and (v >= 0 if zero else v > 0)):
        raise ValueError(f"{name} must be finite and {'>=' if zero else '>'} 0 ({unit}), "
                         f"got {value!r}")
    return v


def check_positive_or_none(name, value):
    """None (the default applies) or a real number > 0."""
    if value is not None and not (isinstance(value, numbers.Real) and value > 0):
        raise ValueError(f"{name} must be > 0 or None, got {value!r}")
    return value


def check_auto_none_or_below(name, value, bound, bound_name: str):
    """"auto", None, or a real number in [0, ``bound``) (named ``bound_name`` in the message)."""
    if not (value is None or value == "auto" or (
        isinstance(value, numbers.Real) and not isinstance(value, bool) and 0 <= value < bound
    )):
        raise ValueError(
            f"{name} must be 'auto', None or in [0, {bound_name} = {bound:g}), got {value!r}"
        )
    return value


def check_int_at_least(name, value, lo: int) -> int:
    """A Python int (not a bool) ≥ ``lo``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}, got {value!r}")
    return value


_SHOW = object()


def check_finite_array(name, value, lo=None, lo_open=False, shown=_SHOW) -> np.ndarray:
    """``value`` as a float64 array, every entry finite and ≥ ``lo`` (> with ``lo_open``):
    "``name`` must be finite [and > lo], got ..." showing the array, or ``shown`` (None: no
    "got")."""
    arr = np.asarray(value, dtype=np.float64)
    good = np.isfinite(arr)
    if lo is not None:
        good &= arr > lo if lo_open else arr >= lo
    if not np.all(good):
        bound = "" if lo is None else f" and {'>' if lo_open else '>='} {lo:g}"
        got = "" if shown is None else f", got {arr if shown is _SHOW else shown}"
        raise ValueError(f"{name} must be finite{bound}{got}")
    return arr


def check_increasing(name, arr: np.ndarray) -> np.ndarray:
    """A 1-D array whose entries strictly increase."""
    if np.any(np.diff(arr) <= 0):
        raise ValueError(f"{name} must be strictly increasing")
    return arr


def check_t_end(t_end, t_start) -> float:
    """A scalar end time in (``t_start``, :data:`T_END_MAX`], as a float."""
    if isinstance(t_end, bool) or not isinstance(t_end, (numbers.Real, np.ndarray, jax.Array)):
        raise ValueError(f"t_end must be a number, got {t_end!r}")
    if np.ndim(t_end) != 0:
        raise ValueError(f"t_end must be a scalar, got shape {np.shape(t_end)}")
    value = float(t_end)
    if not (math.isfinite(value) and t_start < value <= T_END_MAX):
        # + 0.0: a start of -0.0 reads as 0
        raise ValueError(
            f"t_end must be finite and in ({t_start + 0.0:g}, {T_END_MAX:g}], got {t_end!r}"
        )
    return value


def check_times(times, name, t_start, t_end) -> np.ndarray:
    """Output times: a 1-D float64 array (a scalar becomes one entry), finite, in
    [``t_start``, ``t_end``]."""
    try:
        arr = np.asarray(times, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 1-D sequence of numbers, got {times!r}") from None
    arr = np.atleast_1d(arr)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr[~np.isfinite(arr)][:3]}")
    if arr.size and (arr.min() < t_start or arr.max() > t_end):
        raise ValueError(f"{name} must lie in [{t_start + 0.0:g}, {t_end:g}], got {arr}")
    return arr


def check_poisson(name, value) -> float:
    """Poisson's ratio in :data:`POISSON_RANGE`, as a float."""
    lo, hi = POISSON_RANGE
    if not (_is_real(value) and lo < value <= hi):
        raise ValueError(f"{name} must be in ({lo:g}, {hi:g}], got {value!r}")
    return float(value)


def _listed(choices) -> str:
    words = [repr(c) for c in choices]
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} or {words[-1]}"


def check_choice(name, value, choices):
    """``value`` one of ``choices``: "``name`` must be 'a', 'b' or 'c', got ..."."""
    if value not in choices:
        raise ValueError(f"{name} must be {_listed(choices)}, got {value!r}")
    return value


def check_layer_base(name, value) -> str:
    """One of :data:`LAYER_BASES`."""
    return check_choice(name, value, LAYER_BASES)


def check_in_range(name, value, bounds):
    """A real number (not a bool) in the closed interval ``bounds``."""
    lo, hi = bounds
    if isinstance(value, bool):
        raise ValueError(f"{name} must be a number in [{lo:g}, {hi:g}], got {value!r}")
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [{lo:g}, {hi:g}], got {value!r}") from None
    if not (math.isfinite(f) and lo <= f <= hi):
        raise ValueError(f"{name} must be finite and in [{lo:g}, {hi:g}], got {value!r}")
    return f


def check_parameters(beta, z0):
    """Check that β and z̄0 lie in the solver's ranges.

    Args:
        beta: β (eq 8e), dimensionless, in ``BETA_RANGE``; a JAX tracer passes unchecked.
        z0: z̄0 = z0/d_c (eq 8e), dimensionless, in ``Z0_RANGE``; a tracer passes unchecked.

    Raises:
        ValueError: β or z̄0 not a finite scalar in its range (the message names it).
    """
    check_in_range("beta", beta, BETA_RANGE)
    check_in_range("z0", z0, Z0_RANGE)


def check_parameter_arrays(beta: np.ndarray, z0: np.ndarray):
    """:func:`check_parameters` for every member of a batch (float arrays)."""
    for name, v, (lo, hi) in (("beta", beta, BETA_RANGE), ("z0", z0, Z0_RANGE)):
        good = np.isfinite(v) & (v >= lo) & (v <= hi)
        if not np.all(good):
            raise ValueError(
                f"{name} values must be finite and in [{lo:g}, {hi:g}], got {v[~good][:3]}"
            )


INDENTERS = ("paraboloid", "sphere")
"""The indenter shapes by name (``--indenter``; ``lubjax.Paraboloid``, ``lubjax.Sphere``)."""


def max_travel_over_radius(indenter: str) -> float:
    """The largest travel or gap, in radii, that the ``indenter`` (one of :data:`INDENTERS`)
    models: :data:`MAX_TRAVEL_OVER_RADIUS` for the paraboloid,
    :data:`MAX_SPHERE_TRAVEL_OVER_RADIUS` for the sphere."""
    check_choice("indenter", indenter, INDENTERS)
    return MAX_SPHERE_TRAVEL_OVER_RADIUS if indenter == "sphere" else MAX_TRAVEL_OVER_RADIUS


def travel_over_radius_problem(name: str, value: float, radius: float,
                               indenter: str = "paraboloid", radius_name: str = "--radius"):
    """None where a travel or gap ``value`` [m] is within the ``indenter``'s limit for a sphere of
    ``radius`` [m] (:func:`max_travel_over_radius`), else the message that says so and names
    the fix: the sphere's true profile past the paraboloid's limit, a unit check past the
    sphere's."""
    limit = max_travel_over_radius(indenter)
    if is_traced(value) or is_traced(radius) or value <= limit * radius:
        return None
    said = (f"{name} {value:g} m is {value / radius:.3g} radii ({radius_name} {radius:g} m); "
            f"the {indenter} indenter models at most {limit:g} R")
    if indenter == "paraboloid" and value <= MAX_SPHERE_TRAVEL_OVER_RADIUS * radius:
        return (f"{said} (its r²/2R profile needs travel and gap ≪ R). For deep indentation "
                f"give --indenter sphere, the sphere's true profile (Sneddon's contact, to "
                f"{MAX_SPHERE_TRAVEL_OVER_RADIUS:g} R)")
    return (f"{said}, and no indenter models more than {MAX_SPHERE_TRAVEL_OVER_RADIUS:g} R. "
            "Are the lengths in metres?")
