"""(d) Fixed-point (Picard) iteration with under-relaxation, in the style of Davis, Serayssol &
Hinch (1986): the same fully implicit backward-Euler step as ``newton`` (lubjax's FV
discretisation), solved by alternating the two physics instead of a Newton step.

split="elastic" (default, the classic EHL split): with the film h̄ᵏ frozen, Reynolds is a
tridiagonal solve for p̄,   -T(h̄ᵏ) p̄ = -A (h̄ᵏ - h̄ⁿ)/Δt̄;   then the elasticity gives
h̃ = z̄ⁿ⁺¹ + r̄²/2 + Ŵp̄ and the film is under-relaxed, h̄ᵏ⁺¹ = (1-ω) h̄ᵏ + ω h̃.
Linearised, the error is multiplied by 1 - ω(1 + μ) with μ ~ Ŵ(-T)⁻¹A/Δt̄ ~ 1/(β h̄³ Δt̄) for the
smooth modes: a thin film needs ω < 2/(1+μ), i.e. stalls — the difficulty the paper's
linearly implicit step avoids.

split="mobility": only the mobility is iterated (each iteration is lubjax's linear step with
the elastic coupling implicit, mobility from h̄ᵏ), which converges much more easily.

Converged when ||h̄ᵏ⁺¹ - h̄ᵏ||∞ ≤ tol (1 + ||h̄ᵏ||∞); a step that has not after ``max_iter``
iterations is a stall (the step is accepted anyway and the run goes on, flagged).
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from .common import (
    at_outputs,
    film,
    fv_setup,
    make_info,
    run_iterative_rollout,
    travel,
    tridiag_parts,
)


def _rollout(disc, beta, z, dt, omega, tol, max_iter, split):
    area = disc.cell_area[:-1]
    n = disc.r.shape[0] - 1

    def full(p_in):
        return jnp.concatenate([p_in, jnp.zeros(1, p_in.dtype)])

    def solve_p(h, h_old, z_new, dtj):
        lower, diag, upper = tridiag_parts(disc, beta, h, z_new)
        if split == "elastic":
            rhs = -area * (h[:-1] - h_old[:-1]) / dtj
            return jax.lax.linalg.tridiagonal_solve(lower, diag, upper, rhs[:, None])[:, 0]
        mat = disc.area_influence / dtj
        idx = jnp.arange(n)
        mat = mat.at[idx, idx].add(diag).at[idx[1:], idx[:-1]].add(lower[1:])
        mat = mat.at[idx[:-1], idx[1:]].add(upper[:-1])
        rhs = -area * (z_new + 0.5 * disc.r[:-1] ** 2 - h_old[:-1]) / dtj
        return jnp.linalg.solve(mat, rhs)

    zs_prev = z[:-1]

    def body(carry, xs):
        z_new, dtj, z_old = xs
        h_old = carry

        def cond(s):
            _, _, it, err = s
            return (it < max_iter) & (err > tol) & jnp.isfinite(err)

        def iterate(s):
            h, _, it, _ = s
            p = full(solve_p(h, h_old, z_new, dtj))
            h_new = (1.0 - omega) * h + omega * film(disc, z_new, p)
            err = jnp.max(jnp.abs(h_new - h)) / (1.0 + jnp.max(jnp.abs(h)))
            return h_new, p, it + 1, err

        h_guess = h_old + (z_new - z_old)
        h, p, it, err = jax.lax.while_loop(
            cond, iterate, (h_guess, jnp.zeros(n + 1), 0, jnp.asarray(1e300)))
        # carry (and report) the film consistent with the last pressure
        h_rep = film(disc, z_new, p)
        return h_rep, (disc.force_weights @ p, jnp.min(h_rep), it, err <= tol)

    h0 = film(disc, z[0], jnp.zeros(n + 1))
    _, outs = jax.lax.scan(body, h0, (z[1:], dt, zs_prev))
    return outs, jnp.min(h0)


def run(beta, z0, t_out, *, omega=0.5, tol=1e-8, max_iter=200, split="elastic", **grid):
    t_out = np.asarray(t_out, dtype=np.float64)
    start = time.perf_counter()
    disc, t = fv_setup(t_out, **grid)
    z = jnp.asarray(z0 - travel(t))
    dt = jnp.asarray(np.diff(t))
    setup_s = time.perf_counter() - start
    key = ("picard", disc.r.shape[0], t.size, omega, tol, max_iter, split)
    force, hmin, iters, conv, wall, compile_s = run_iterative_rollout(
        key, lambda d, b, zz, dd: _rollout(d, b, zz, dd, omega, tol, max_iter, split),
        disc, beta, z, dt)
    info = make_info(wall_s=wall, compile_s=compile_s + setup_s, force=force, film_min=hmin,
                     converged=bool(np.all(conv)), n_steps=t.size - 1,
                     n_nodes=int(disc.r.shape[0]), iterations=int(iters.sum()),
                     max_iterations=int(iters.max()), stalled_steps=int((~conv).sum()))
    return at_outputs(t, force, t_out), info
