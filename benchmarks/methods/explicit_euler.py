"""(e) Explicit (forward) Euler on the method-of-lines ODE of lubjax's FV discretisation.

State p̄ (p̄_{N-1} = 0). From A dh̄/dt̄ = T(h̄)p̄ and h̄ = z̄ + r̄²/2 + Ŵp̄ (eliminating ḣ):
    dp̄/dt̄ = Ŵ⁻¹ (A⁻¹ T(h̄) p̄ - dz̄/dt̄)       (inner nodes; Ŵ⁻¹ formed once),
    p̄ⁿ⁺¹ = p̄ⁿ + Δt̄ [Ŵ⁻¹ (A⁻¹ T(h̄ⁿ) p̄ⁿ) - Ŵ⁻¹ 1 (z̄ⁿ⁺¹ - z̄ⁿ)/Δt̄].
The stiffest mode has rate ~ β h̄³/(Δr̄² ·Ŵ-scale Δr̄) ⇒ Δt̄ ≲ Δr̄³/(β h̄³): stable only with tiny
steps. The run stops being meaningful at the first NaN/overflow (flagged, not stopped early:
one compiled scan).
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from .common import at_outputs, film, flux_divergence, fv_setup, make_info, travel

_COMPILED: dict = {}


def _rollout(disc, winv, beta, z, dt):
    area = disc.cell_area[:-1]
    ones = winv @ jnp.ones(area.shape[0])

    def body(p_in, xs):
        z_old, z_new, dtj = xs
        p = jnp.concatenate([p_in, jnp.zeros(1, p_in.dtype)])
        h = film(disc, z_old, p)
        rate = winv @ (flux_divergence(disc, beta, h, z_old, p)[:-1] / area)
        p_new = p_in + dtj * rate - ones * (z_new - z_old)
        p_full = jnp.concatenate([p_new, jnp.zeros(1, p_in.dtype)])
        h_new = film(disc, z_new, p_full)
        return p_new, (disc.force_weights @ p_full, jnp.min(h_new))

    p0 = jnp.zeros(area.shape[0])
    _, outs = jax.lax.scan(body, p0, (z[:-1], z[1:], dt))
    return outs


def run(beta, z0, t_out, *, mesh="graded", dr=0.05, length=20.0, dt=1e-5, **grid):
    t_out = np.asarray(t_out, dtype=np.float64)
    start = time.perf_counter()
    disc, t = fv_setup(t_out, mesh=mesh, dr=dr, length=length, dt=dt, steps="fixed", **grid)
    winv = jnp.asarray(np.linalg.inv(np.asarray(disc.influence)[:-1, :-1]))
    z = jnp.asarray(z0 - travel(t))
    dts = jnp.asarray(np.diff(t))
    setup_s = time.perf_counter() - start
    key = (disc.r.shape[0], t.size)
    compile_s = 0.0
    if key not in _COMPILED:
        fn = jax.jit(_rollout)
        start = time.perf_counter()
        _COMPILED[key] = fn.lower(disc, winv, 1.0, z, dts).compile()
        compile_s = time.perf_counter() - start
    start = time.perf_counter()
    force, hmin = jax.block_until_ready(_COMPILED[key](disc, winv, float(beta), z, dts))
    wall = time.perf_counter() - start
    with np.errstate(invalid="ignore"):
        force = np.concatenate([[0.0], np.asarray(force)])
        hmin = np.concatenate([[float(np.min(z0 + 0.5 * np.asarray(disc.r) ** 2))],
                               np.asarray(hmin)])
    info = make_info(wall_s=wall, compile_s=compile_s + setup_s, force=force, film_min=hmin,
                     n_steps=t.size - 1, n_nodes=int(disc.r.shape[0]))
    return at_outputs(t, force, t_out), info


def stability_limit(beta, z0, *, mesh="graded", dr=0.02, length=None, **grid):
    """2/max|λ| of the explicit-Euler Jacobian Ŵ⁻¹A⁻¹T(h̄) at t̄ = 0 (p̄ = 0): the largest stable
    step at the start (the film thins later, so this is optimistic in the contact but the
    stiffest modes sit in the thick outer film, where h̄ barely changes)."""
    from .common import tridiag_parts

    disc, _ = fv_setup([0.0, 1.0], mesh=mesh, dr=dr, length=length, **grid)
    n = disc.r.shape[0] - 1
    h = film(disc, z0, jnp.zeros(n + 1))
    lo, d, up = (np.asarray(x) for x in tridiag_parts(disc, beta, h, z0))
    T = -(np.diag(d) + np.diag(lo[1:], -1) + np.diag(up[:-1], 1))
    J = np.linalg.solve(np.asarray(disc.influence)[:-1, :-1],
                        T / np.asarray(disc.cell_area)[:-1, None])
    return 2.0 / float(np.max(np.abs(np.linalg.eigvals(J))))
