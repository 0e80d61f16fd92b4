"""Indenter histories: the travel d̄(t̄) of the sphere toward the substrate, z̄(t̄) = z̄0 - d̄(t̄).

The stepper evaluates ``travel(t)`` wherever it puts a step, and lands a short step on each of
the ``breakpoints``, where the velocity jumps (the pressure responds on the time scale 1/β).
z̄0 stays a separate scalar (differentiated, swept, fitted); histories are pytrees.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ._checks import check_finite_array, check_increasing, concrete, is_traced
from ._pytree import register


@dataclasses.dataclass(frozen=True)
class RampHold:
    """The relaxation test of eqs 8c,d: travel t̄ for 0 ≤ t̄ < 1, then 1 (hold).

    With ``t_accel`` = t̄₁ > 0 the start is smoothed as in eq 23: the sphere starts from rest at
    t̄ = -t̄₁ with constant acceleration, z̄ = z̄0 - (t̄ + t̄²/(2t̄₁)) for -t̄₁ ≤ t̄ ≤ 0, so it has
    travelled -t̄₁/2 at t̄ = 0 (it starts t̄₁/2 above z̄0) and reaches unit speed there.

    Attributes:
        t_accel: t̄₁, the acceleration time (units of t_c), in [0, 1); 0 (default) starts at
            unit speed.

    Raises:
        ValueError: ``t_accel`` not in [0, 1).
    """

    t_accel: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.t_accel) and 0.0 <= self.t_accel < 1.0):
            raise ValueError(f"t_accel must be in [0, 1), got {self.t_accel}")

    @property
    def t_start(self) -> float:
        """t̄ at which the motion starts: -t̄₁ (units of t_c)."""
        return -self.t_accel

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """The times t̄ of the velocity jumps: 1 (the hold), and 0 with an acceleration."""
        return (0.0, 1.0) if self.t_accel > 0 else (1.0,)

    def breakpoints_array(self):
        """The ``breakpoints`` as an array.

        Returns:
            A 1-D JAX array of t̄.
        """
        return jnp.asarray(self.breakpoints)

    monotone = True  # never retracts

    def travel(self, t):
        """The travel toward the substrate (eqs 8c,d; eq 23 with ``t_accel``).

        Args:
            t: t̄ (units of t_c); a scalar or an array.

        Returns:
            jax.Array: d̄(t̄) (units of d_c), shaped as ``t``; t̄ + t̄²/(2t̄₁) on [-t̄₁, 0), t̄ on [0, 1),
            1 after.
        """
        t = jnp.asarray(t)
        ramp = jnp.clip(t, 0.0, 1.0)
        if self.t_accel > 0:
            accel = t + t**2 / (2.0 * self.t_accel)
            ramp = jnp.where(t < 0.0, accel, ramp)
        return ramp


@dataclasses.dataclass(frozen=True, eq=False)
class SampledTravel:
    """A measured travel history d̄(t̄), interpolated by a monotone cubic (Fritsch–Carlson, i.e.
    PCHIP: C¹, no overshoot; docs/design.md, "Numerical hygiene"); held constant before the
    first and after the last sample.

    The travel samples may be traced (a derivative of a run with respect to the record, e.g.
    a calibration factor of the piezo); the sample times may not.

    Attributes:
        t: sample times t̄ (units of t_c), strictly increasing, at least 2.
        travel_samples: d̄, the travel toward the substrate at those times (units of d_c), as
            many as ``t``.
        breakpoints: times t̄ where the velocity jumps (default: the detected start and end of
            the motion; found from the samples' values, so to be given where those are traced
            under ``jit`` or ``vmap``).

    Raises:
        ValueError: ``t`` and ``travel_samples`` not finite 1-D arrays of one length ≥ 2,
            ``t`` not strictly increasing, ``breakpoints`` not finite, or not given for
            samples whose values are unknown (under ``jit`` or ``vmap``).
        NotImplementedError: traced sample times.
    """

    t: np.ndarray
    travel_samples: np.ndarray
    breakpoints: tuple[float, ...] = ()

    def __post_init__(self):
        if is_traced(self.t):
            raise NotImplementedError(
                "SampledTravel: the sample times t cannot be traced (a run has no derivative in "
                "the times of its record); its travel samples can")
        t = np.asarray(self.t, dtype=np.float64)
        traced = is_traced(self.travel_samples)
        xp = jnp if traced else np
        d = xp.asarray(self.travel_samples, dtype=np.float64)
        if t.ndim != 1 or t.shape != d.shape or t.size < 2:
            raise ValueError("t and travel must be 1-D arrays of the same length >= 2")
        known = concrete(d)  # the samples' values (None under jit or vmap)
        for a in (t, known):
            if a is not None:
                check_finite_array("t and travel", a, shown=None)
        check_increasing("t", t)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "travel_samples", d)
        object.__setattr__(self, "slopes", _monotone_slopes(t, d, xp))
        # A leaf, not static, so stacked histories of both kinds still vmap together.
        object.__setattr__(self, "monotone", xp.bool_(xp.all(xp.diff(d) >= 0)))
        if not len(self.breakpoints):
            if known is None:
                raise ValueError(
                    "SampledTravel: give breakpoints= where the travel samples are traced under "
                    "jit or vmap (by default they are found from the samples' values)")
            object.__setattr__(self, "breakpoints", _motion_breakpoints(t, known))
        bp = check_finite_array("breakpoints", np.ravel(self.breakpoints),
                                shown=self.breakpoints)
        object.__setattr__(self, "breakpoints", tuple(float(b) for b in bp))

    @property
    def t_start(self):
        """t̄ at which the record starts: the first sample time (units of t_c)."""
        return self.t[0]

    def breakpoints_array(self):
        """The ``breakpoints`` as an array.

        Returns:
            A 1-D JAX array of t̄.
        """
        return jnp.asarray(self.breakpoints)

    def travel(self, t):
        """The interpolated travel.

        Args:
            t: t̄ (units of t_c); a scalar or an array.

        Returns:
            jax.Array: d̄(t̄) (units of d_c), shaped as ``t``; the monotone cubic through the samples,
            constant before the first and after the last.
        """
        t = jnp.asarray(t)
        knots, d, m = (jnp.asarray(a) for a in (self.t, self.travel_samples, self.slopes))
        i = jnp.clip(jnp.searchsorted(knots, t, side="right") - 1, 0, knots.shape[0] - 2)
        h = knots[i + 1] - knots[i]
        s = jnp.clip((t - knots[i]) / h, 0.0, 1.0)
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2
        h01 = s**2 * (3 - 2 * s)
        h11 = s**2 * (s - 1)
        return h00 * d[i] + h10 * h * m[i] + h01 * d[i + 1] + h11 * h * m[i + 1]


def _monotone_slopes(t: np.ndarray, d, xp=np):
    """Fritsch–Carlson slopes (as scipy's PchipInterpolator): zero at local extrema, the
    weighted harmonic mean of the neighbouring secants elsewhere, one-sided at the ends.
    ``xp``: ``numpy``, or ``jax.numpy`` for traced samples (the same arithmetic; the secants
    a zero slope does not use are replaced before they divide, so no NaN reaches a
    derivative)."""
    h = np.diff(t)
    delta = xp.diff(d) / h
    if d.shape[0] == 2:
        return xp.full(2, delta[0])
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    same = (delta[:-1] * delta[1:]) > 0
    before, after = xp.where(same, delta[:-1], 1.0), xp.where(same, delta[1:], 1.0)
    inner = xp.where(same, (w1 + w2) / (w1 / before + w2 / after), 0.0)

    def end(h0, h1, d0, d1):
        slope = ((2 * h0 + h1) * d0 - h0 * d1) / (h0 + h1)
        slope = xp.where(xp.sign(slope) != xp.sign(d0), 0.0, slope)
        return xp.where((xp.sign(d0) != xp.sign(d1)) & (xp.abs(slope) > xp.abs(3 * d0)),
                        3 * d0, slope)

    first = end(h[0], h[1], delta[0], delta[1])
    last = end(h[-1], h[-2], delta[-1], delta[-2])
    return xp.concatenate([xp.reshape(first, (1,)), inner, xp.reshape(last, (1,))])


def _motion_breakpoints(t: np.ndarray, d: np.ndarray) -> tuple[float, ...]:
    """Start and end of motion: the last sample before the travel leaves its first value and the
    first sample after it settles at its last (exactly, where the record is exactly still there;
    else by a threshold of 10⁻³ of the span, for noisy records)."""
    span = np.max(d) - np.min(d)
    if span == 0:
        return ()
    return tuple(sorted({float(motion_start(t, d)), float(motion_end(t, d))}))


def motion_start(t: np.ndarray, d: np.ndarray) -> float:
    """Last sample at rest before the motion (see :func:`_motion_breakpoints`)."""
    tol = 1e-3 * (np.max(d) - np.min(d))
    k = int(np.flatnonzero(np.abs(d - d[0]) > tol)[0])
    changed = np.flatnonzero(d[:k + 1] != d[0])
    exact = int(changed[0]) if changed.size else k
    return t[max(exact - 1, 0)]


def motion_end(t: np.ndarray, d: np.ndarray) -> float:
    """First sample at rest after the motion (see :func:`_motion_breakpoints`)."""
    tol = 1e-3 * (np.max(d) - np.min(d))
    k = int(np.flatnonzero(np.abs(d - d[-1]) > tol)[-1])
    changed = np.flatnonzero(d[k:] != d[-1])
    exact = k + int(changed[-1]) if changed.size else k
    return t[min(exact + 1, t.size - 1)]


def _breakpoints_leaf(bp):
    # Validated objects hold a tuple; unflattened ones already hold the leaf (array or tracer).
    return np.asarray(bp, np.float64) if isinstance(bp, tuple) else bp


register(SampledTravel, ("t", "travel_samples", "slopes", "breakpoints", "monotone"),
         leaf={"breakpoints": _breakpoints_leaf})
register(RampHold, static=("t_accel",))
