"""(c) lubjax's linearly implicit step with one idea switched at a time, through the low-level
API (``discretise``/``bdf_coefficients``/``rollout``):

* mesh="graded" (default Settings mesh) or "uniform" (``lubjax.uniform_mesh(dr, length)``,
  e.g. the paper's L̄ = 4);
* order=2 (BDF2) or 1 (backward Euler, lagged mobility like the paper);
* steps="grow" (dt_min after each jump, growing by ``growth``, uncapped in the hold),
  "cap" (same, but capped at dt in the hold too) or "fixed" (uniform Δt̄ everywhere).

The output times are always grid nodes. wall_s excludes compilation (compile_s).
"""

from __future__ import annotations

import time

import jax
import numpy as np

import lubjax

from .common import at_outputs, growing_grid, make_info, travel, uniform_grid

_COMPILED: dict = {}


def _compiled(disc, coeffs, tr):
    key = (disc.r.shape[0], tr.shape[0])
    if key not in _COMPILED:
        fn = jax.jit(lambda d, b, z, trv, c: lubjax.rollout(d, b, z, trv, c))
        start = time.perf_counter()
        _COMPILED[key] = (fn.lower(disc, 1.0, 1.0, tr, coeffs).compile(),
                          time.perf_counter() - start)
        return _COMPILED[key][0], _COMPILED[key][1]
    return _COMPILED[key][0], 0.0


def build(t_out, *, mesh="graded", dr=0.02, length=None, r_fine=1.6, mesh_growth=1.04,
          order=2, steps="grow", dt=5e-3, dt_min=1e-6, growth=1.1):
    t_out = np.asarray(t_out, dtype=np.float64)
    t_end = float(t_out[-1])
    if mesh == "graded":
        m = lubjax.graded_mesh(dr, r_fine, 100.0 if length is None else length, mesh_growth)
    else:
        m = lubjax.uniform_mesh(dr, 4.0 if length is None else length)
    if steps == "fixed":
        t = uniform_grid(t_end, dt, t_out)
    else:
        t = growing_grid(t_end, dt, dt_min, growth, t_out=t_out,
                         hold_dt_max=dt if steps == "cap" else None)
    disc = lubjax.discretise(m)
    coeffs = lubjax.bdf_coefficients(t, order)
    return disc, coeffs, t


def run(beta, z0, t_out, **opts):
    t_out = np.asarray(t_out, dtype=np.float64)
    start = time.perf_counter()
    disc, coeffs, t = build(t_out, **opts)
    tr = jax.numpy.asarray(travel(t))
    setup_s = time.perf_counter() - start
    fn, compile_s = _compiled(disc, coeffs, tr)
    start = time.perf_counter()
    out = jax.block_until_ready(fn(disc, float(beta), float(z0), tr, coeffs))
    wall = time.perf_counter() - start
    force, hmin = np.asarray(out.force), np.asarray(out.film_min)
    info = make_info(wall_s=wall, compile_s=compile_s + setup_s, force=force, film_min=hmin,
                     n_steps=t.size - 1, n_nodes=int(disc.r.shape[0]))
    return at_outputs(t, force, t_out), info
