"""(c) lubjax's error-controlled linearly implicit step with one idea switched at a time, through
the low-level API (``discretise`` / ``Tolerance`` / ``rollout`` / ``evaluate``):

* mesh="graded" (``Settings(rtol).mesh()``, the default) or "uniform" (``lubjax.uniform_mesh``,
  e.g. the paper's Δr̄ on L̄ = 4: the domain truncation of the published scheme);
* order=2 (BDF2, default) or 1 (backward Euler throughout: the paper's time discretisation, under
  the same error controller).

The old variants "fixed Δt̄" and "growing/capped Δt̄" no longer exist in lubjax (the controller
chooses every step); the fixed-grid comparison methods keep their own grids (common.py).
Outputs at ``t_out`` by the stepper's interpolant. wall_s excludes compilation (compile_s).
"""

from __future__ import annotations

import time

import jax
import numpy as np

import lubjax
from lubjax._threads import single_threaded_blas

from .common import make_info

_COMPILED: dict = {}


def _compiled(disc, tol, history):
    key = (disc.r.shape[0], tol)
    if key not in _COMPILED:
        fn = jax.jit(lambda d, b, z, h, te: lubjax.stepper.rollout(d, b, z, h, te, tol))
        start = time.perf_counter()
        _COMPILED[key] = fn.lower(disc, 1.0, 1.0, history, 1.0).compile()
        return _COMPILED[key], time.perf_counter() - start
    return _COMPILED[key], 0.0


def build(*, rtol=3e-4, atol=1e-14, mesh="graded", dr=None, length=None, r_fine=1.6,
          mesh_growth=None, order=2, max_steps=20_000, initial_step=1e-5):
    if mesh == "graded":
        settings = lubjax.Settings(rtol=rtol, atol=atol, dr=dr, length=length, r_fine=r_fine,
                                   mesh_growth=mesh_growth)
        m = settings.mesh()
    else:
        m = lubjax.uniform_mesh(0.02 if dr is None else dr, 4.0 if length is None else length)
    tol = lubjax.stepper.Tolerance(rtol, atol, initial_step, order, max_steps)
    return lubjax.stepper.discretise(m), tol


def run(beta, z0, t_out, **opts):
    t_out = np.asarray(t_out, dtype=np.float64)
    start = time.perf_counter()
    disc, tol = build(**opts)
    history = lubjax.RampHold()
    setup_s = time.perf_counter() - start
    fn, compile_s = _compiled(disc, tol, history)
    with single_threaded_blas():
        start = time.perf_counter()
        traj = jax.block_until_ready(fn(disc, float(beta), float(z0), history, float(t_out[-1])))
        wall = time.perf_counter() - start
    steps = traj.steps
    keep = np.asarray(steps.accepted)
    force = np.asarray(lubjax.stepper.evaluate(steps, t_out, "force"))
    info = make_info(wall_s=wall, compile_s=compile_s + setup_s,
                     force=np.asarray(steps.force)[keep],
                     film_min=np.asarray(steps.film_min)[keep],
                     converged=bool(traj.finished), n_steps=int(traj.accepted),
                     rejected=int(traj.rejected), n_nodes=int(disc.r.shape[0]))
    return force, info
