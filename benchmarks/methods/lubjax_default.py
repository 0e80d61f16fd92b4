"""(b) lubjax as a user calls it: ``lubjax.relax`` with ``Settings(rtol=...)`` (rtol is the one
accuracy knob: it sets the step controller's tolerance and the mesh), outputs read at ``t_out``
by the stepper's own interpolant (``Result.at``), so the steps do not depend on ``t_out``.

wall_s is the wall time of a whole second ``relax`` call (compiled executables and the per-mesh
influence matrix are cached by then); compile_s is the first call's extra time (compilation and
the influence matrix). ``Settings.error_estimate`` is off unless the caller's settings turn it
on (the estimate runs two more coarse-mesh solutions: about +30-60 % run time).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

import lubjax

from .common import make_info


def run(beta, z0, t_out, *, settings: lubjax.Settings | None = None, warmup=True,
        history=None, **overrides):
    settings = settings or lubjax.Settings(error_estimate=False)
    if overrides:
        settings = dataclasses.replace(settings, **overrides)
    t_out = np.asarray(t_out, dtype=np.float64)
    t_end = float(t_out[-1])
    kw = dict(settings=settings, check="flag", history=history)
    first_s = 0.0
    if warmup:
        start = time.perf_counter()
        lubjax.relax(beta, z0, t_end, **kw)
        first_s = time.perf_counter() - start
    start = time.perf_counter()
    res = lubjax.relax(beta, z0, t_end, **kw)
    wall = time.perf_counter() - start - res.compile_s
    setup_s = max(first_s - wall, 0.0) if warmup else res.compile_s
    force = res.at(t_out) if res.finished else np.interp(t_out, res.t, res.force,
                                                           right=np.nan)
    info = make_info(wall_s=wall, compile_s=setup_s, force=res.force, film_min=res.film_min,
                     converged=res.finished, n_steps=res.accepted, n_nodes=res.r.size,
                     run_s=res.run_s, rejected=res.rejected,
                     force_error=float(np.nanmax(res.force_error)) if res.force_error.size
                     else float("nan"))
    return np.asarray(force), info
