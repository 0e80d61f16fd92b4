"""The user-facing solver: settings, a precomputed plan, ``relax`` and its result."""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._indenter import RampHold, SampledTravel
from ._mesh import Mesh, graded_mesh
from ._stepper import (
    Discretisation,
    StepCoefficients,
    bdf_coefficients,
    discretise,
    displacement,
    film_thickness,
    rollout,
)
from ._timegrid import time_grid


class SolverError(RuntimeError):
    """A run produced NaN or a negative film: the discretisation is too coarse for the case."""


@dataclasses.dataclass(frozen=True)
class Settings:
    """Discretisation settings. The defaults keep F̄(t̄) within 0.1 % (relative to its peak) of the
    converged answer for β ∈ [1, 10³], z̄0 ∈ [0.5, 2] (README: refinement table, reproduced by
    ``python benchmarks/refinement.py``).

    Attributes:
        dr: mesh spacing in the fine zone [0, r_fine].
        r_fine: edge of the uniform fine zone (covers the Hertz radius √(1-z̄0) ≤ 1 and its rim).
        length: domain length L̄ with p̄(L̄) = 0; force truncation ~ 2z̄/L̄².
        mesh_growth: cell-size ratio beyond r_fine.
        dt: largest step in the loading phase.
        dt_min: first step after a velocity jump.
        time_growth: step growth ratio after a jump (unbounded in the hold).
        order: 2 (BDF2, default) or 1 (backward Euler, the paper's).
    """

    dr: float = 0.02
    r_fine: float = 1.6
    length: float = 100.0
    mesh_growth: float = 1.04
    dt: float = 5e-3
    dt_min: float = 1e-6
    time_growth: float = 1.1
    order: int = 2

    def mesh(self) -> Mesh:
        return graded_mesh(self.dr, self.r_fine, self.length, self.mesh_growth)


class Plan(NamedTuple):
    """Everything that does not depend on (β, z̄0): reuse it across runs, fits and sweeps."""

    disc: Discretisation
    coeffs: StepCoefficients
    t: np.ndarray  # grid nodes t̄
    travel: jax.Array  # indenter travel d̄ at the nodes
    mesh: Mesh


def make_plan(
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    settings: Settings | None = None,
    include: tuple[float, ...] = (),
) -> Plan:
    """Build mesh, influence matrix (cached per mesh), time grid and travel for a run."""
    history = RampHold() if history is None else history
    settings = Settings() if settings is None else settings
    if not (isinstance(t_end, (int, float)) and math.isfinite(t_end) and t_end > history.t_start):
        raise ValueError(f"t_end must be finite and > {history.t_start}, got {t_end!r}")
    mesh = settings.mesh()
    t = time_grid(
        t_end,
        dt=settings.dt,
        dt_min=settings.dt_min,
        growth=settings.time_growth,
        t_start=history.t_start,
        breakpoints=history.breakpoints,
        include=include,
    )
    return Plan(
        disc=discretise(mesh),
        coeffs=bdf_coefficients(t, settings.order),
        t=t,
        travel=jnp.asarray(history.travel(t)),
        mesh=mesh,
    )


def force_curve(plan: Plan, beta, z0):
    """F̄ at the plan's grid nodes: a pure function of (β, z̄0), for ``jit``, ``vmap``, ``jacfwd``.

    Differentiate in forward mode (``jax.jacfwd``/``jax.jvp``): its memory does not grow with the
    step count. Reverse mode is not available: the step safeguard's ``while_loop`` has no
    transpose (and reverse mode would store one LU factorisation per step anyway).
    """
    return rollout(plan.disc, beta, z0, plan.travel, plan.coeffs).force


def _check_x64():
    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            "lubjax needs float64 but jax_enable_x64 is off. Call "
            "jax.config.update('jax_enable_x64', True) (importing lubjax does this) and do not "
            "turn it off afterwards."
        )


def _check_params(beta, z0):
    for name, v, rng in [("beta", beta, "(0, inf)"), ("z0", z0, "(0, inf)")]:
        try:
            f = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{name} must be a number in {rng}, got {v!r}") from None
        if not (math.isfinite(f) and f > 0):
            raise ValueError(f"{name} must be finite and in {rng}, got {v!r}")


@dataclasses.dataclass(frozen=True)
class Result:
    """A relaxation run (dimensionless). Arrays are numpy.

    Attributes:
        t: grid nodes t̄; force F̄, film_min min h̄, film_center h̄(0) at each node.
        outflow: volume flux through the outer boundary per unit 2π at each node.
        profile_times: the requested profile times; r: the mesh;
        pressure, displacement, film: p̄, w̄, h̄ at those times, shape (len(profile_times), N).
        finite: no NaN/inf anywhere; film_positive: h̄ > 0 everywhere at every step.
        compile_s, run_s: wall time of compilation (0 when cached) and of the run itself.
    """

    beta: float
    z0: float
    t: np.ndarray
    force: np.ndarray
    film_min: np.ndarray
    film_center: np.ndarray
    outflow: np.ndarray
    r: np.ndarray
    profile_times: np.ndarray
    pressure: np.ndarray
    displacement: np.ndarray
    film: np.ndarray
    finite: bool
    film_positive: bool
    compile_s: float
    run_s: float

    @property
    def ok(self) -> bool:
        return self.finite and self.film_positive

    def problems(self) -> list[str]:
        out = []
        if not self.finite:
            out.append("the solution contains NaN or inf")
        if not self.film_positive:
            i = int(np.nanargmin(self.film_min))
            h, t = self.film_min[i], self.t[i]
            out.append(f"the film went negative (h̄_min = {h:.3g} at t̄ = {t:.4g})")
        return out


_COMPILED: dict = {}


def _compiled_rollout(plan: Plan, save_profiles: bool):
    """AOT-compile once per (mesh size, step count, profiles): lets us report compile time apart."""
    key = (plan.disc.r.shape[0], plan.t.size, save_profiles)
    if key in _COMPILED:
        return _COMPILED[key], 0.0
    fn = jax.jit(lambda d, b, z, tr, c: rollout(d, b, z, tr, c, save_profiles=save_profiles))
    start = time.perf_counter()
    compiled = fn.lower(plan.disc, 1.0, 1.0, plan.travel, plan.coeffs).compile()
    _COMPILED[key] = compiled
    return compiled, time.perf_counter() - start


def relax(
    beta: float,
    z0: float,
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    settings: Settings | None = None,
    profile_times=(),
    check: str = "raise",
) -> Result:
    """Simulate a relaxation test (paper eqs 8, 11b) in dimensionless form.

    Args:
        beta: β > 0, eq 8e. z0: z̄0 = z0/d_c > 0.
        t_end: final time t̄ (t_c units). A hold to 10⁴ costs a few hundred extra steps.
        history: indenter travel, ``RampHold()`` (eqs 8c,d; eq 23 with ``t_accel``) or
            ``SampledTravel`` (a measured history).
        settings: discretisation (defaults: see :class:`Settings`).
        profile_times: times at which p̄, w̄, h̄ profiles are returned (made grid nodes).
        check: "raise" (default) raises SolverError on NaN or a negative film; "warn" warns;
            "flag" only sets ``Result.finite`` / ``Result.film_positive``.
    """
    _check_x64()
    _check_params(beta, z0)
    if check not in ("raise", "warn", "flag"):
        raise ValueError(f"check must be 'raise', 'warn' or 'flag', got {check!r}")
    ptimes = np.atleast_1d(np.asarray(profile_times, dtype=np.float64))
    history = RampHold() if history is None else history
    if ptimes.size and (np.any(ptimes < history.t_start) or np.any(ptimes > t_end)):
        raise ValueError(f"profile_times must lie in [{history.t_start}, {t_end}], got {ptimes}")
    plan = make_plan(t_end, history=history, settings=settings, include=tuple(ptimes))
    save = bool(ptimes.size)
    compiled, compile_s = _compiled_rollout(plan, save)
    start = time.perf_counter()
    out = compiled(plan.disc, float(beta), float(z0), plan.travel, plan.coeffs)
    out = jax.tree_util.tree_map(np.asarray, jax.block_until_ready(out))
    run_s = time.perf_counter() - start

    n = plan.disc.r.shape[0]
    if save:
        idx = np.searchsorted(plan.t, ptimes)
        p = out.pressure[idx]
        z = float(z0) - np.asarray(plan.travel)[idx]
        w = np.stack([np.asarray(displacement(plan.disc, pi)) for pi in p])
        h = np.stack([np.asarray(film_thickness(plan.disc, zi, pi)) for zi, pi in zip(z, p)])
    else:
        p = w = h = np.zeros((0, n))
    finite = bool(
        np.all(np.isfinite(out.force))
        and np.all(np.isfinite(out.film_min))
        and np.all(np.isfinite(p))
    )
    result = Result(
        beta=float(beta),
        z0=float(z0),
        t=plan.t,
        force=out.force,
        film_min=out.film_min,
        film_center=out.film_center,
        outflow=out.outflow,
        r=np.asarray(plan.disc.r),
        profile_times=ptimes,
        pressure=p,
        displacement=w,
        film=h,
        finite=finite,
        film_positive=bool(np.all(out.film_min > 0)),
        compile_s=compile_s,
        run_s=run_s,
    )
    if not result.ok and check != "flag":
        msg = (
            f"relax(beta={beta}, z0={z0}): "
            + "; ".join(result.problems())
            + ". Refine the mesh at the contact (Settings.dr) or the time step (Settings.dt, "
            "Settings.time_growth), or pass check='flag' to inspect the run."
        )
        if check == "raise":
            raise SolverError(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    return result
