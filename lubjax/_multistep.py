r"""Variable-step multistep formulae: BDF(1-3) weights, Milne's error constants, the predictor
and the dense output, all polynomials through the accepted levels (Lagrange form).

Notation: the step Δt = t_{n+1} - t_n, the previous steps Δt₁ = t_n - t_{n-1},
Δt₂ = t_{n-1} - t_{n-2}, Δt₃ = t_{n-2} - t_{n-3}; the distances of the formula's levels before
t_{n+1} are u₀ = 0, u₁ = Δt, u₂ = Δt + Δt₁, u₃ = Δt + Δt₁ + Δt₂, u₄ = u₃ + Δt₃.

BDF-k (paper eq 19 is k = 1): Σ_j a_j y^{n+1-j} = Δt ẏ^{n+1} with a_j = Δt ℓ_j'(t_{n+1}), ℓ_j
the Lagrange basis of the levels t_{n+1}, ..., t_{n+1-k}; Σ_j a_j = 0. At constant steps:
(1, -1), (3/2, -2, 1/2), (11/6, -3, 3/2, -1/3).

Milne's device (Hairer, Nørsett & Wanner I §III.7): the corrector's local error is
C_c y^{(k+1)}, the predictor's (the polynomial through the last k + 1 accepted levels, at
t_{n+1}) C_p y^{(k+1)}, with

    C_c = Σ_j a_j u_j^{k+1} / ((k+1)! a₀),        C_p = u₁ u₂ ... u_{k+1} / (k+1)!,

so the corrector's error is C_c/(C_p - C_c) × (corrector - predictor), at no extra solve. For
constant BDF2 steps this is the classical -2/11.

The weights and the predictor are closed forms rather than calls of :func:`lagrange`: their
rounding fixes the step sequences (a generic evaluation moves the error estimate at the last ulp
and can flip an accept/reject near ε = 1). tests/test_multistep.py checks each against an
independent Lagrange construction.
"""

from __future__ import annotations

import jax.numpy as jnp


def lagrange(x, offsets, values):
    """The polynomial through the points (-offsets[i], values[i]), at x (distinct offsets)."""
    total = 0.0
    for i, (si, yi) in enumerate(zip(offsets, values)):
        weight = 1.0
        for j, sj in enumerate(offsets):
            if j != i:
                weight = weight * (x + sj) / (sj - si)
        total = total + weight * yi
    return total


def bdf12_weights(order, omega):
    """(a₀, a₁, a₂) of variable-step BDF2 (``order`` 2, ω = Δt/Δt₁) or backward Euler (1)."""
    a0 = jnp.where(order == 2, (1 + 2 * omega) / (1 + omega), 1.0)
    a1 = jnp.where(order == 2, -(1 + omega), -1.0)
    a2 = jnp.where(order == 2, omega**2 / (1 + omega), 0.0)
    return a0, a1, a2


def bdf3_weights(dt, dt1, dt2):
    """(a₀, a₁, a₂, a₃) of variable-step BDF3, a_j = Δt ℓ_j'(t_{n+1}) through u₀..u₃."""
    u1, u2, u3 = dt, dt + dt1, dt + dt1 + dt2
    a0 = dt * (1.0 / u1 + 1.0 / u2 + 1.0 / u3)
    a1 = -dt * u2 * u3 / (u1 * (u2 - u1) * (u3 - u1))
    a2 = dt * u1 * u3 / (u2 * (u2 - u1) * (u3 - u2))
    a3 = -dt * u1 * u2 / (u3 * (u3 - u1) * (u3 - u2))
    return a0, a1, a2, a3


def milne_factor(order, dt, dt1, dt2, a0, a1, a2, third=None):
    """C_c/(C_p - C_c) of the step's formula (``order`` 1, 2, or 3 where ``third`` is given):
    multiplies (corrector - predictor) to estimate the corrector's local error. ``third`` =
    (Δt₃, a₃) where the step may be BDF3; None: orders 1 and 2 only."""
    bdf2_c = -(a1 * dt**3 + a2 * (dt + dt1) ** 3) / (6.0 * a0)
    bdf2_p = dt * (dt + dt1) * (dt + dt1 + dt2) / 6.0
    be_c = -0.5 * dt**2
    be_p = 0.5 * dt * (dt + dt1)
    c = jnp.where(order == 2, bdf2_c, be_c)
    p = jnp.where(order == 2, bdf2_p, be_p)
    if third is not None:
        dt3, a3 = third
        u1, u2, u3 = dt, dt + dt1, dt + dt1 + dt2
        c = jnp.where(order == 3, (a1 * u1**4 + a2 * u2**4 + a3 * u3**4) / (24.0 * a0), c)
        p = jnp.where(order == 3, u1 * u2 * u3 * (u3 + dt3) / 24.0, p)
    return c / (p - c)


def predict(order, dt, dt1, dt2, y, y1, y2, third=None):
    """The predictor: the polynomial through the last ``order + 1`` accepted levels, at t_n + Δt.

    y, y1, y2 are the values at t_n, t_n - Δt₁, t_n - Δt₁ - Δt₂; ``third`` = (Δt₃, y3), the
    level before those, where the step may be BDF3 (the cubic).
    """
    lin = y + dt / dt1 * (y - y1)
    s1, s2 = dt1, dt1 + dt2
    l0 = (dt + s1) * (dt + s2) / (s1 * s2)
    l1 = dt * (dt + s2) / (-s1 * (s2 - s1))
    l2 = dt * (dt + s1) / (s2 * (s2 - s1))
    quad = l0 * y + l1 * y1 + l2 * y2
    out = jnp.where(order == 2, quad, lin)
    if third is not None:
        dt3, y3 = third
        out = jnp.where(order == 3, lagrange(dt, (0.0, s1, s2, s2 + dt3), (y, y1, y2, y3)), out)
    return out


def dense_output(t_query, times, values, degree, xp=jnp):
    """The step's interpolant at t_query ∈ [t_n, t_{n+1}]: its own dense output, of the step's
    ``degree`` (its order): linear through the last two levels (backward Euler), quadratic
    through the last three (BDF2), cubic through four (BDF3).

    ``times`` and ``values``: the levels oldest first, the new one last; three of them where no
    step can be BDF3, four where one can. ``xp``: jax.numpy, or numpy for results already on
    the host.
    """
    if len(times) == 3:
        times, values = (None, *times), (None, *values)
    tm, t0, t1, t2 = times
    ym, y0, y1, y2 = values
    # Levels a lower degree does not use may coincide with t1 (a segment's first steps): move
    # them so no branch divides by zero (a NaN in an unselected branch would still poison
    # reverse-mode gradients).
    t0 = xp.where(degree == 1, 2.0 * t1 - t2, t0)
    x = t_query - t2
    lin = lagrange(x, (t2 - t1, 0.0), (y1, y2))
    quad = lagrange(x, (t2 - t0, t2 - t1, 0.0), (y0, y1, y2))
    if tm is None:
        return xp.where(degree == 1, lin, quad)
    tm = xp.where(degree < 3, 2.0 * t0 - t1, tm)
    cubic = lagrange(x, (t2 - tm, t2 - t0, t2 - t1, 0.0), (ym, y0, y1, y2))
    return xp.where(degree == 1, lin, xp.where(degree == 2, quad, cubic))
