"""(d) Fully implicit backward Euler solved by Newton's method, on lubjax's FV discretisation
(same mesh arrays, same harmonic-Simpson mobility), in JAX (jit + scan + while_loop).

Per step, unknowns p̄_0..p̄_{N-2} (p̄_{N-1} = 0) solve

    R(p̄) = A (h̄(p̄) - h̄ⁿ)/Δt̄ - T(h̄(p̄)) p̄ = 0,   h̄(p̄) = z̄ⁿ⁺¹ + r̄²/2 + Ŵp̄,

with the mobility at the *new* level (the nonlinearity the paper avoids). The Jacobian is dense
(Ŵ); it is formed by ``jax.jacfwd`` and factorised every iteration (plain, undamped Newton from
p̄ⁿ). A step that has not met ||δp̄||∞ ≤ tol (1 + ||p̄||∞) after ``max_iter`` iterations is a stall.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from .common import (
    at_outputs,
    film,
    flux_divergence,
    fv_setup,
    make_info,
    run_iterative_rollout,
    travel,
)


def _rollout(disc, beta, z, dt, tol, max_iter):
    area = disc.cell_area[:-1]

    def full(p_in):
        return jnp.concatenate([p_in, jnp.zeros(1, p_in.dtype)])

    def residual(p_in, h_old, z_new, dtj):
        p = full(p_in)
        h = film(disc, z_new, p)
        return area * (h[:-1] - h_old[:-1]) / dtj - flux_divergence(disc, beta, h, z_new, p)[:-1]

    jac = jax.jacfwd(residual)

    def body(carry, xs):
        p_in, h_old = carry
        z_new, dtj = xs

        def cond(s):
            _, it, err = s
            return (it < max_iter) & (err > tol) & jnp.isfinite(err)

        def newton(s):
            q, it, _ = s
            dq = jnp.linalg.solve(jac(q, h_old, z_new, dtj), -residual(q, h_old, z_new, dtj))
            return q + dq, it + 1, jnp.max(jnp.abs(dq)) / (1.0 + jnp.max(jnp.abs(q)))

        q, it, err = jax.lax.while_loop(cond, newton, (p_in, 0, jnp.asarray(1e300)))
        p = full(q)
        h = film(disc, z_new, p)
        out = (disc.force_weights @ p, jnp.min(h), it, err <= tol)
        return (q, h), out

    p0 = jnp.zeros(disc.r.shape[0] - 1)
    h0 = film(disc, z[0], full(p0))
    _, outs = jax.lax.scan(body, (p0, h0), (z[1:], dt))
    return outs, jnp.min(h0)


def run(beta, z0, t_out, *, tol=1e-10, max_iter=25, **grid):
    t_out = np.asarray(t_out, dtype=np.float64)
    start = time.perf_counter()
    disc, t = fv_setup(t_out, **grid)
    z = jnp.asarray(z0 - travel(t))
    dt = jnp.asarray(np.diff(t))
    setup_s = time.perf_counter() - start
    key = ("newton", disc.r.shape[0], t.size, tol, max_iter)
    force, hmin, iters, conv, wall, compile_s = run_iterative_rollout(
        key, lambda d, b, zz, dd: _rollout(d, b, zz, dd, tol, max_iter), disc, beta, z, dt)
    info = make_info(wall_s=wall, compile_s=compile_s + setup_s, force=force, film_min=hmin,
                     converged=bool(np.all(conv)), n_steps=t.size - 1,
                     n_nodes=int(disc.r.shape[0]), iterations=int(iters.sum()),
                     max_iterations=int(iters.max()), stalled_steps=int((~conv).sum()))
    return at_outputs(t, force, t_out), info
