r"""Step-size control: the embedded error estimate and the PI controller.

Error estimate (Milne's device, Hairer, Nørsett & Wanner I §III.7). With the step
Δt = t_{n+1} - t_n, the previous steps Δt₁ = t_n - t_{n-1}, Δt₂ = t_{n-1} - t_{n-2}, the
variable-step BDF2 corrector a₀yⁿ⁺¹ + a₁yⁿ + a₂yⁿ⁻¹ = Δt f(yⁿ⁺¹) has the local error

    y(t_{n+1}) - yⁿ⁺¹ ≈ C_c y''',   C_c = -(a₁ Δt³ + a₂ (Δt + Δt₁)³) / (6 a₀),

and the quadratic extrapolation y_p through the last three accepted levels has

    y(t_{n+1}) - y_p ≈ C_p y''',    C_p = Δt (Δt + Δt₁)(Δt + Δt₁ + Δt₂) / 6,

so the computable difference yⁿ⁺¹ - y_p = (C_p - C_c) y''' estimates the corrector's error as
C_c/(C_p - C_c) (yⁿ⁺¹ - y_p) at no extra linear solve. For constant steps this is the classical
-2/11 (yⁿ⁺¹ - y_p). A backward-Euler step (C_c = -Δt²/2) is paired with linear extrapolation
(C_p = Δt(Δt + Δt₁)/2) in the same way, and a BDF3 step (``Settings(order=3)``) with the cubic
through four levels: with the distances u_j = t_{n+1} - t_{n+1-j} of the formula's levels,

    C_c = (a₁u₁⁴ + a₂u₂⁴ + a₃u₃⁴) / (24 a₀),   C_p = u₁u₂u₃u₄ / 24.

Controller: the PI controller of Gustafsson (Hairer & Wanner II §IV.2; diffrax's
``PIDController`` with ``pcoeff = 0.4, icoeff = 0.3``), on the error ratio ε = ‖est‖/tol:

    Δt_new = Δt · clip(safety · ε_n^{-(β₁)/k} · ε_{n-1}^{β₂/k}, f_min, f_max),   k = order + 1,

with β₁ = 0.7, β₂ = 0.4 (k = 4 for BDF3). The growth is capped at 1.5: variable-step BDF2 is
zero-stable only for step ratios below 1 + √2, and its error constant and Milne's estimate of
it degrade on the way: with a cap of 2, a ×2 step in the ramp of β = 100, z̄0 = 2 was accepted
with a force error 13 times its tolerance (1.1e-3 of the peak against the converged reference;
6.4e-4 with the cap 1.5, for 0.6 % more steps; benchmarks/accuracy.py). The same cap serves
BDF3, stable on grids whose step ratios stay below 2.553 (Z. Li & H.-l. Liao, "Stability of
variable-step BDF2 and BDF3 methods"). A rejected step shrinks by safety · ε^{-1/k} (at least
×0.1, at most ×0.9); a step that loses positivity or finiteness shrinks by ×0.25.
"""

from __future__ import annotations

import jax.numpy as jnp

SAFETY = 0.9
BETA_1 = 0.7
BETA_2 = 0.4
MAX_GROWTH = 1.5
MIN_SHRINK = 0.1
INVALID_SHRINK = 0.25


def milne_factor(order, dt, dt1, dt2, a0, a1, a2, third=None):
    """C_c/(C_p - C_c): multiplies (corrector - predictor) to estimate the corrector's error.
    ``third`` = (Δt₃, a₃) where the step may be BDF3 (order 3); None: orders 1 and 2 only."""
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


def extrapolate(order, dt, dt1, dt2, y, y1, y2, third=None):
    """Predictor: the polynomial through the last ``order + 1`` accepted levels, at t_n + Δt.

    y, y1, y2 are the values at t_n, t_n - Δt₁, t_n - Δt₁ - Δt₂ (Lagrange form); ``third`` =
    (Δt₃, y3), the level before those, where the step may be BDF3 (cubic predictor).
    """
    # Linear (order 1): through (t_n, y), (t_{n-1}, y1).
    lin = y + dt / dt1 * (y - y1)
    # Quadratic (order 2), nodes at offsets 0, -dt1, -(dt1+dt2) from t_n, evaluated at +dt.
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


def next_step_factor(accepted, valid, error_ratio, error_ratio_prev, order, last_rejected):
    """Factor multiplying Δt for the next attempt (see module docstring)."""
    k = order + 1.0
    ratio = jnp.maximum(error_ratio, 1e-10)
    ratio_prev = jnp.maximum(error_ratio_prev, 1e-10)
    grow = SAFETY * ratio ** (-BETA_1 / k) * ratio_prev ** (BETA_2 / k)
    # After a rejection do not grow straight away (Hairer & Wanner II, IV.2).
    grow = jnp.clip(grow, 1.0 / MAX_GROWTH, jnp.where(last_rejected, 1.0, MAX_GROWTH))
    shrink = jnp.clip(SAFETY * ratio ** (-1.0 / k), MIN_SHRINK, SAFETY)
    return jnp.where(valid, jnp.where(accepted, grow, shrink), INVALID_SHRINK)
