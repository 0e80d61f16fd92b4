"""Indenter histories: the travel d̄(t̄) of the sphere toward the substrate, z̄(t̄) = z̄0 - d̄(t̄).

Every history, ideal or measured, reaches the stepper the same way: ``travel(t)`` evaluated
wherever the step-size controller puts a step. The initial gap z̄0 stays a separate scalar so
that it can be differentiated, swept with ``vmap`` and fitted without rebuilding the history.

``breakpoints`` are times where the indenter velocity jumps; the stepper lands a step on each
and restarts there with a short step (the pressure responds on the fast time scale 1/β after a
velocity jump). Both histories are pytrees: a batch of measured histories (same sample count)
can be stacked and ``vmap``-ed.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np


@dataclasses.dataclass(frozen=True)
class RampHold:
    """The relaxation test of eqs 8c,d: travel t̄ for 0 ≤ t̄ < 1, then 1 (hold).

    With ``t_accel`` = t̄₁ > 0 the start is smoothed as in eq 23: the sphere starts from rest at
    t̄ = -t̄₁ with constant acceleration, z̄ = z̄0 - (t̄ + t̄²/(2t̄₁)) for -t̄₁ ≤ t̄ ≤ 0, so it has
    travelled -t̄₁/2 at t̄ = 0 (it starts t̄₁/2 above z̄0) and reaches unit speed there.
    """

    t_accel: float = 0.0

    def __post_init__(self):
        if not (np.isfinite(self.t_accel) and 0.0 <= self.t_accel < 1.0):
            raise ValueError(f"t_accel must be in [0, 1), got {self.t_accel}")

    @property
    def t_start(self) -> float:
        return -self.t_accel

    @property
    def breakpoints(self) -> tuple[float, ...]:
        return (0.0, 1.0) if self.t_accel > 0 else (1.0,)

    def breakpoints_array(self):
        return jnp.asarray(self.breakpoints)

    def travel(self, t):
        t = jnp.asarray(t)
        ramp = jnp.clip(t, 0.0, 1.0)
        if self.t_accel > 0:
            accel = t + t**2 / (2.0 * self.t_accel)
            ramp = jnp.where(t < 0.0, accel, ramp)
        return ramp


@dataclasses.dataclass(frozen=True, eq=False)
class SampledTravel:
    """A measured travel history d̄(t̄), linearly interpolated; held constant after the last sample.

    Args:
        t: sample times (dimensionless), strictly increasing.
        travel: travel toward the substrate at those times (dimensionless, units of d_c).
        breakpoints: times where the velocity jumps (default: detected start and end of motion).
    """

    t: np.ndarray
    travel_samples: np.ndarray
    breakpoints: tuple[float, ...] = ()

    def __post_init__(self):
        t = np.asarray(self.t, dtype=np.float64)
        d = np.asarray(self.travel_samples, dtype=np.float64)
        if t.ndim != 1 or t.shape != d.shape or t.size < 2:
            raise ValueError("t and travel must be 1-D arrays of the same length >= 2")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(d))):
            raise ValueError("t and travel must be finite")
        if np.any(np.diff(t) <= 0):
            raise ValueError("t must be strictly increasing")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "travel_samples", d)
        if not len(self.breakpoints):
            object.__setattr__(self, "breakpoints", _motion_breakpoints(t, d))
        bp = np.asarray(self.breakpoints, dtype=np.float64).ravel()
        if not np.all(np.isfinite(bp)):
            raise ValueError(f"breakpoints must be finite, got {self.breakpoints}")
        object.__setattr__(self, "breakpoints", tuple(float(b) for b in bp))

    @property
    def t_start(self):
        return self.t[0]

    def breakpoints_array(self):
        return jnp.asarray(self.breakpoints)

    def travel(self, t):
        return jnp.interp(jnp.asarray(t), self.t, self.travel_samples)


def _motion_breakpoints(t: np.ndarray, d: np.ndarray) -> tuple[float, ...]:
    """Start and end of motion: first and last sample where the travel differs from its ends."""
    span = np.max(d) - np.min(d)
    if span == 0:
        return ()
    tol = 1e-3 * span
    moving = np.flatnonzero(np.abs(d - d[0]) > tol)
    settled = np.flatnonzero(np.abs(d - d[-1]) > tol)
    start = t[max(moving[0] - 1, 0)]
    end = t[min(settled[-1] + 1, t.size - 1)]
    return tuple(sorted({float(start), float(end)}))


def _flatten_sampled(h: SampledTravel):
    # Validated objects hold a tuple; unflattened ones already hold the leaf (array or tracer).
    bp = h.breakpoints
    bp = np.asarray(bp, np.float64) if isinstance(bp, tuple) else bp
    return (h.t, h.travel_samples, bp), None


def _unflatten_sampled(_, children):
    # Bypass __post_init__: under jit/vmap the leaves are tracers (validated when first built),
    # and the breakpoints stay an array.
    obj = object.__new__(SampledTravel)
    for name, value in zip(("t", "travel_samples", "breakpoints"), children):
        object.__setattr__(obj, name, value)
    return obj


jax.tree_util.register_pytree_node(SampledTravel, _flatten_sampled, _unflatten_sampled)
jax.tree_util.register_pytree_node(
    RampHold, lambda h: ((), h.t_accel), lambda aux, _: RampHold(aux)
)
