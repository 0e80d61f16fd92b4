"""(f) Method of lines with an adaptive stiff integrator: scipy ``solve_ivp`` (BDF by default,
or Radau) on lubjax's FV semi-discretisation in the film (h̄) formulation:

    dh̄_i/dt̄ = (T(h̄) p̄)_i / A_i,   p̄ = Ŵ⁻¹ (h̄ - z̄(t̄) - r̄²/2)   (inner nodes; p̄_{N-1} = 0),

with the exact dense Jacobian from ``jax.jacfwd`` (jit-compiled; the RHS too). z̄(t̄) has a kink
at t̄ = 1, so [0, 1] and [1, t_end] are integrated separately. Accuracy is set by rtol (atol =
rtol·1e-3 on h̄); dense output is not used: t_out are passed as ``t_eval``.
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

from .common import face_conductance, fv_setup, make_info

_COMPILED: dict = {}


def _functions(disc, winv):
    r_in = disc.r[:-1]
    area = disc.cell_area[:-1]
    w_last = disc.influence[-1, :-1]

    def rhs(t, h_in, beta, z0):
        z = z0 - jnp.clip(t, 0.0, 1.0)
        p_in = winv @ (h_in - z - 0.5 * r_in**2)
        p = jnp.concatenate([p_in, jnp.zeros(1, p_in.dtype)])
        h_last = z + 0.5 * disc.r[-1] ** 2 + w_last @ p_in
        h = jnp.concatenate([h_in, h_last[None]])
        g = beta * face_conductance(disc, h, z)
        q = g * (p[1:] - p[:-1])
        div = q - jnp.concatenate([jnp.zeros(1, q.dtype), q[:-1]])
        return div / area

    return rhs


def run(beta, z0, t_out, *, method="BDF", rtol=1e-6, atol=None, mesh="graded", dr=0.02,
        length=None, **grid):
    t_out = np.asarray(t_out, dtype=np.float64)
    t_end = float(t_out[-1])
    start = time.perf_counter()
    disc, _ = fv_setup(t_out, mesh=mesh, dr=dr, length=length, steps="fixed", dt=t_end, **grid)
    W = np.asarray(disc.influence)
    winv = jnp.asarray(np.linalg.inv(W[:-1, :-1]))
    force_w = np.asarray(disc.force_weights)[:-1]
    winv_np = np.asarray(winv)
    r_in = np.asarray(disc.r)[:-1]
    w_last = W[-1, :-1]
    r_last = float(disc.r[-1])
    setup_s = time.perf_counter() - start
    key = int(disc.r.shape[0])
    compile_s = 0.0
    if key not in _COMPILED:
        rhs = _functions(disc, winv)
        f = jax.jit(rhs)
        j = jax.jit(jax.jacfwd(rhs, argnums=1))
        start = time.perf_counter()
        h_test = np.asarray(1.0 + 0.5 * r_in**2)
        f(np.float64(0.5), h_test, 1.0, 1.0).block_until_ready()
        j(np.float64(0.5), h_test, 1.0, 1.0).block_until_ready()
        compile_s = time.perf_counter() - start
        _COMPILED[key] = (f, j)
    f, j = _COMPILED[key]
    b, zz = float(beta), float(z0)
    atol = rtol * 1e-3 if atol is None else atol

    def fun(t, y):
        return np.asarray(f(np.float64(t), np.asarray(y, np.float64), b, zz))

    def jac(t, y):
        return np.asarray(j(np.float64(t), np.asarray(y, np.float64), b, zz))

    start = time.perf_counter()
    y = zz + 0.5 * r_in**2
    ts, hs = [np.array([0.0])], [y[None, :]]
    nfev = njev = nlu = 0
    success = True
    message = ""
    for a, bnd in ((0.0, min(1.0, t_end)), (1.0, t_end)):
        if bnd <= a:
            continue
        te = t_out[(t_out > a) & (t_out <= bnd)]
        sol = solve_ivp(fun, (a, bnd), y, method=method, t_eval=te, rtol=rtol, atol=atol,
                        jac=jac)
        nfev += sol.nfev
        njev += sol.njev
        nlu += sol.nlu
        if not sol.success:
            success = False
            message = sol.message
            break
        ts.append(sol.t)
        hs.append(sol.y.T)
        y = sol.y[:, -1] if sol.t.size and sol.t[-1] == bnd else y
    wall = time.perf_counter() - start
    t_all = np.concatenate(ts)
    h_all = np.concatenate(hs)
    z_all = zz - np.clip(t_all, 0.0, 1.0)
    p_all = (h_all - z_all[:, None] - 0.5 * r_in**2) @ winv_np.T
    force = p_all @ force_w
    h_last = z_all + 0.5 * r_last**2 + p_all @ w_last
    hmin = np.minimum(h_all.min(axis=1), h_last)
    out = np.full(t_out.size, np.nan)
    idx = np.searchsorted(t_out, t_all - 1e-12)
    out[idx] = force
    info = make_info(wall_s=wall, compile_s=compile_s + setup_s, force=out, film_min=hmin,
                     converged=success, n_steps=0, n_nodes=int(disc.r.shape[0]), nfev=nfev,
                     njev=njev, nlu=nlu, message=str(message))
    return out, info
