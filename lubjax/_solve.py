"""Running the solver: ``relax`` (a JAX function), ``make_plan`` and ``force_curve``."""

from __future__ import annotations

import time
import warnings
from typing import NamedTuple

import jax
import numpy as np

from . import _compiler
from ._checks import (
    any_traced,
    check_choice,
    check_parameters,
    check_t_end,
    check_times,
    concrete,
)
from ._controller import DONE, Tolerance, stop_reason
from ._discretisation import Discretisation, discretise
from ._drives import as_drive
from ._estimate import estimate_runs
from ._indenter import RampHold, SampledTravel
from ._mesh import Mesh, mesh_for
from ._output import evaluate
from ._result import Result, result_of, traced_result
from ._rollout import rollout
from ._settings import Settings
from ._shape import Paraboloid, as_indenter
from ._substrate import HalfSpace, as_substrate
from ._threads import single_threaded_blas


class SolverError(RuntimeError):
    """A run produced NaN or a negative film, or could not reach t_end (:func:`relax` with
    ``check="raise"``); the message says which, and where (``Result.problems()``)."""


class Plan(NamedTuple):
    """Everything that does not depend on (β, z̄0): reuse it across runs, fits and sweeps.

    Build it with :func:`make_plan`.

    Attributes:
        disc: the discretisation of ``mesh`` on ``substrate`` (:func:`lubjax.stepper.discretise`).
        tol: the step controller's tolerance (:class:`lubjax.stepper.Tolerance`).
        drive: the drive (``lubjax.Travel``, ``Load``, ``Spring``, ``FreeSphere``).
        t_end: final time t̄ (units of t_c).
        t: output times t̄ of :func:`force_curve` (a 1-D float64 array).
        mesh: the :class:`lubjax.Mesh`.
        substrate: ``lubjax.HalfSpace()`` (default), a ``Layer`` or a ``Viscoelastic``.
        indenter: ``lubjax.Paraboloid()`` (default) or ``lubjax.Sphere(d_c/R)``.
    """

    disc: Discretisation
    tol: Tolerance
    drive: object
    t_end: float
    t: np.ndarray
    mesh: Mesh
    substrate: object = HalfSpace()
    indenter: object = Paraboloid()


def _drive_of(history, drive):
    if history is not None and drive is not None:
        raise ValueError(
            "give either history= (a prescribed travel) or drive=, not both: "
            "drive=lubjax.Travel(history) is the same as history=history"
        )
    return as_drive(drive if drive is not None else history)


def make_plan(
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    drive=None,
    substrate=None,
    settings: Settings | None = None,
    times=None,
    indenter=None,
) -> Plan:
    """Mesh and influence matrix (cached per mesh), tolerance, drive and output times.

    The mesh is ``settings.mesh()``, one for every (β, z̄0) the plan serves: without the
    per-run refinement of :func:`relax` (:func:`lubjax.mesh_for` says what that changes).

    Args:
        t_end: final time t̄ (units of t_c), after the drive's start.
        history: a prescribed travel (default ``RampHold()``).
        drive: instead of ``history``, any drive.
        substrate: ``HalfSpace()`` (default), ``Layer``, ``Viscoelastic``.
        settings: tolerance and mesh (default ``Settings()``).
        times: where :func:`force_curve` reports F̄ (t̄, units of t_c; default 501 equally
            spaced times from the drive's start to ``t_end``).
        indenter: ``Paraboloid()`` (default) or ``Sphere(d_c/R)`` (lubjax/_shape.py).

    Returns:
        Plan: the fixed (not differentiated) half of :func:`force_curve`'s inputs.

    Raises:
        ValueError: both ``history`` and ``drive``, a ``t_end`` not after the start, or
            ``times`` outside [start, t_end] (the message names the parameter).

    Example:
        ```python
        import lubjax
        import numpy as np

        plan = lubjax.make_plan(2.0, settings=lubjax.Settings(rtol=1e-3, error_estimate=False),
                                times=np.linspace(0.0, 2.0, 21))
        force = lubjax.force_curve(plan, 100.0, 0.5)
        assert force.shape == (21,)
        ```
    """
    drive = _drive_of(history, drive)
    settings = Settings() if settings is None else settings
    t_start = float(drive.t_start)
    t_end = check_t_end(t_end, t_start)
    if times is None:
        times = np.linspace(t_start, t_end, 501)
    times = check_times(times, "times", t_start, t_end)
    mesh = settings.mesh()
    substrate, indenter = as_substrate(substrate), as_indenter(indenter)
    return Plan(discretise(mesh, substrate, indenter), settings.tolerance(), drive, t_end, times,
                mesh, substrate, indenter)


def force_curve(plan: Plan, beta, z0, times=None):
    """F̄ at ``times`` (default ``plan.t``): a pure function of (β, z̄0) for ``jit``, ``vmap``,
    ``jax.grad``, ``jacfwd`` and ``jacrev``.

    Args:
        plan: mesh, tolerance, drive and output times (:func:`make_plan`).
        beta: β (eq 8e), in [1e-4, 1e9]; a traced scalar.
        z0: z̄0 = z0/d_c, in [1e-4, 1e3]; a traced scalar.
        times: where to report F̄ (t̄, units of t_c; default ``plan.t``).

    Returns:
        F̄ at ``times`` (a jax array; dimensionless, as ``Result.force``). Times the run did not
        reach (budget exhausted) come back as NaN.

    Example:
        ```python
        import jax
        import lubjax

        plan = lubjax.make_plan(1.0, settings=lubjax.Settings(rtol=1e-3, error_estimate=False),
                                times=[0.5, 1.0])
        peak = lambda beta: lubjax.force_curve(plan, beta, 0.5)[-1]
        dF_dbeta = jax.grad(peak)(100.0)  # sensitivity of F̄(t̄ = 1) to β
        assert float(dF_dbeta) != 0.0
        ```
    """
    times = plan.t if times is None else times
    traj = rollout(
        plan.disc, beta, z0, plan.drive, plan.t_end, plan.tol, substrate=plan.substrate
    )
    return evaluate(traj.steps, times, "force")


def _check_x64():
    if not jax.config.jax_enable_x64:
        raise RuntimeError(
            "lubjax needs float64 but jax_enable_x64 is off. Call "
            "jax.config.update('jax_enable_x64', True) (importing lubjax does this) and do not "
            "turn it off afterwards."
        )


_COMPILED: dict = {}


def _forward_rollout(d, b, z, h, s, te, pt, t):
    return rollout(d, b, z, h, te, t, pt, substrate=s)


def _lower_rollout(disc, drive, substrate, tol, n_profiles):
    """Trace and lower :func:`relax`'s program for one mesh (β, z̄0, t_end, the profile times
    and the tolerance's numbers are its arguments)."""
    return jax.jit(_forward_rollout).lower(
        disc, 1.0, 1.0, drive, substrate, 1.0, np.zeros(n_profiles), tol
    )


def _compiled_rollouts(runs, drive, substrate) -> tuple[list, float]:
    """AOT-compile once per (mesh size, drive and substrate structure, tolerance structure,
    profile count): lets us report compile time apart. The tolerance's numbers are arguments,
    so the error estimate's run at 8·rtol reuses the program of the run at rtol. ``runs``:
    (discretisation, tolerance, profile times) each; the programs not yet compiled are traced
    one after another and compiled side by side (lubjax/_compiler.py). Returns the executables
    and the seconds spent (tracing, lowering and compiling)."""

    def key_of(disc, tol, ptimes):
        leaves, treedef = jax.tree_util.tree_flatten((drive, substrate, tol))
        return disc.r.shape[0], treedef, tuple(np.shape(x) for x in leaves), ptimes.size

    def lowerer(d, tol, pt):
        return lambda: _lower_rollout(d, drive, substrate, tol, pt.size)

    return _compiler.cached_all(_COMPILED, [key_of(*r) for r in runs],
                                [lowerer(*r) for r in runs])


def relax(
    beta: float,
    z0: float,
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    drive=None,
    substrate=None,
    settings: Settings | None = None,
    profile_times=(),
    check: str = "raise",
    progress=None,
    mesh: Mesh | None = None,
    indenter=None,
) -> Result:
    """Simulate a relaxation test (paper eqs 8, 11b) in dimensionless form, error-controlled.

    A JAX function: ``jax.grad``, ``jacfwd``, ``jvp`` and ``vjp`` act on it directly (in β,
    z̄0 and the drive's and substrate's numbers; the step times, and so ``t_end``, carry no
    derivative), and so do ``jit`` and ``vmap``. Where the values are known (no ``jit`` or
    ``vmap`` around it) the run is checked and refined as always and its :class:`Result`
    holds the accepted steps, its arrays traced where a derivative is taken. Under ``jit`` or
    ``vmap`` nothing is known until the program runs: the mesh is ``mesh`` or the shared
    ``settings.mesh()`` (no per-run refinement, as :func:`make_plan`), the error estimate is
    not made, ``check`` acts as "flag", and the per-step series are the loop's entries padded
    to ``Settings.max_steps + 1`` (read them with :meth:`Result.at`).

    Near dry (β ≥ 10⁵ with the default ``film_error="auto"``) a differentiated run is a finer
    run: its contact mesh 1.4× finer (``mesh_for(..., derivatives=True)``) and its film held to
    100 rtol of itself instead of 10³, without which the derivative in a long hold at
    β ≳ 10⁸ can be off by per cents or NaN (docs/accuracy.md#derivatives). Its values are that
    run's, within the tolerance of the plain run's. It takes 1.8× the steps on 1.3× the nodes
    (β = 10⁹, z̄0 = 0.1, t̄ ≤ 5: ``python -m benchmarks.derivative_map --cost``).

    Args:
        beta: β (eq 8e), in [1e-4, 1e9].
        z0: z̄0 = z0/d_c (the initial gap in units of d_c), in [1e-4, 1e3].
        t_end: final time t̄ (units of t_c). Steps grow as the solution slows: a hold to
            t̄ = 10⁶ costs ~1900 steps at β = 100, z̄0 = 0.5 (the neck at the contact edge keeps
            thinning).
        history: indenter travel, ``RampHold()`` (eqs 8c,d; eq 23 with ``t_accel``) or
            ``SampledTravel`` (a measured history).
        drive: instead of ``history``, any drive: ``Travel(history)``, ``Load`` (force
            control, creep), ``Spring`` (a sphere on a spring), ``FreeSphere`` (inertia).
        substrate: ``HalfSpace()`` (default), ``Layer(thickness, poisson, interface)`` (a layer
            on a rigid base), ``Viscoelastic(...)`` (creep compliance; on either).
        settings: tolerance and mesh (defaults: see :class:`Settings`).
        profile_times: times t̄ (units of t_c) at which p̄, w̄, h̄ profiles are returned (by the
            stepper's interpolant: the steps do not depend on them).
        check: "raise" (default) raises SolverError on NaN, a negative film or a run that did
            not reach t_end; "warn" warns; "flag" only sets the flags of :class:`Result`.
        progress: None (quiet, the default), or a callable told each phase as it starts
            ("compiling the solver", "running the solver", "estimating the error"): the
            command line's progress line shows it.
        mesh: the mesh to run on (default: :func:`lubjax.mesh_for`, the one the run needs,
            told whether a derivative is taken).
        indenter: ``Paraboloid()`` (default, eq 8a) or ``Sphere(d_c/R)``, the sphere's true
            profile for deep indentation (lubjax/_shape.py); its ε = d_c/R is a leaf that
            ``jit``, ``vmap`` and ``grad`` see.

    Returns:
        Result: F̄, the gap and min h̄ at every accepted step, the profiles at
        ``profile_times``, the estimated errors (with ``Settings.error_estimate``) and the flags.

    Raises:
        ValueError: β, z̄0, ``t_end``, ``profile_times`` or ``check`` out of range (the message
            names the parameter and its range), or both ``history`` and ``drive``.
        SolverError: with ``check="raise"``, NaN, a negative film or a run that did not reach
            ``t_end``.

    Example:
        ```python
        import jax
        import lubjax

        res = lubjax.relax(100.0, 0.5, t_end=2.0, profile_times=[1.0],
                           settings=lubjax.Settings(rtol=1e-3, error_estimate=False))
        assert res.ok and res.film.shape == (1, res.r.size)
        f_end = res.force[-1]  # F̄ at t̄ = 2, during the hold
        # and its sensitivity to z̄0, through relax itself
        slope = jax.grad(lambda z: lubjax.relax(100.0, z, 2.0).at(2.0)[0])(0.5)
        ```
    """
    _check_x64()
    check_choice("check", check, ("raise", "warn", "flag"))
    drive = _drive_of(history, drive)
    settings = Settings() if settings is None else settings
    substrate, indenter = as_substrate(substrate), as_indenter(indenter)
    known = concrete((beta, z0, t_end, drive, substrate, indenter))
    if known is None:
        return _relax_traced(beta, z0, t_end, drive, substrate, settings, profile_times, mesh,
                             indenter)
    beta_v, z0_v, t_end_v, drive_v, substrate_v, indenter_v = known
    check_parameters(beta_v, z0_v)
    t_start = float(drive_v.t_start)
    t_end_v = check_t_end(t_end_v, t_start)
    ptimes = check_times(profile_times, "profile_times", t_start, t_end_v)
    # With a derivative to take, the run itself goes through jit with its inputs' derivatives
    # attached (on the mesh mesh_for gives a differentiated run); the error estimate's runs are
    # not differentiated.
    differentiated = any_traced((beta, z0, drive, substrate, indenter))
    if mesh is None:
        mesh = mesh_for(settings, drive=drive_v, beta=beta_v, z0=z0_v, t_end=t_end_v,
                        indenter=indenter_v, derivatives=differentiated)
    disc = discretise(mesh, substrate_v, indenter_v)
    tol = settings.tolerance()
    runs = [(disc, tol, ptimes)]
    if settings.error_estimate:
        runs += estimate_runs(mesh, substrate_v, indenter_v, tol, ptimes)
    report = progress if progress is not None else (lambda phase: None)
    report("compiling the solver")
    compiled, compile_s = _compiled_rollouts(runs[differentiated:], drive_v, substrate_v)
    report("running the solver")
    start = time.perf_counter()
    with single_threaded_blas():
        trajs = [
            jax.block_until_ready(
                fn(d, float(beta_v), float(z0_v), drive_v, substrate_v, t_end_v, pt, t))
            for fn, (d, t, pt) in zip(compiled, runs[differentiated:])
        ]
        if differentiated:
            trajs.insert(0, _differentiable_rollout(discretise(mesh, substrate_v, indenter), beta,
                                                    z0, drive, substrate, t_end_v, ptimes, tol))
    run_s = time.perf_counter() - start
    if settings.error_estimate:
        report("estimating the error")
    result = result_of(trajs, disc, beta_v, z0_v, t_end_v, ptimes, tol.max_steps, compile_s,
                       run_s)
    if not result.ok and check != "flag":
        msg = f"relax(beta={beta_v}, z0={z0_v}): " + "; ".join(result.problems())
        if check == "raise":
            raise SolverError(msg)
        warnings.warn(msg, RuntimeWarning, stacklevel=2)
    stopped = sorted((float(tr.t_final), int(tr.status)) for tr in trajs[1:]
                     if int(tr.status) != DONE)
    if stopped and result.ok and check != "flag":
        # the run is sound, its error bars are not: NaN after the coarse runs stopped
        warnings.warn(
            f"relax(beta={beta_v}, z0={z0_v}): the error estimate's coarse runs stopped at "
            f"t̄ = {stopped[0][0]:.4g} ({stop_reason(stopped[0][1], tol.max_steps).split(';')[0]}): "
            "force_error and the other estimated errors are NaN after it; raise "
            "Settings.max_steps",
            RuntimeWarning, stacklevel=2)
    return result


#: relax's run with derivatives to take (jit caches its programs per mesh size and drive).
_differentiable_rollout = jax.jit(_forward_rollout)


def _relax_traced(beta, z0, t_end, drive, substrate, settings, profile_times, mesh,
                  indenter) -> Result:
    """:func:`relax` under ``jit`` or ``vmap``: one run on ``mesh`` (or the shared mesh), its
    entries as the loop left them, its flags traced."""
    times = np.atleast_1d(np.asarray(profile_times, np.float64))
    if times.ndim != 1 or not np.all(np.isfinite(times)):
        raise ValueError(f"profile_times must be a 1-D sequence of finite numbers, got {times}")
    mesh = settings.mesh() if mesh is None else mesh
    disc = discretise(mesh, substrate, indenter)
    traj = _forward_rollout(disc, beta, z0, drive, substrate, t_end, times,
                            settings.tolerance())
    return traced_result(traj, disc, mesh.r, beta, z0, t_end, times)
