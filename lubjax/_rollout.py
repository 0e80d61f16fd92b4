r"""The loop over attempted steps, the saver, and reading a run at any time.

Each attempt (:func:`_attempt`) is the shape diffrax's loop has:

    t_new, lands = propose(...)                  # the controller lands breakpoints
    candidate    = step(...)                     # one factorisation: a candidate level + error
    ratio        = error_ratio(...)              # the error norm
    decision     = adapt(ratio, ...)             # accept or reject, next Δt̄, status
    state        = where(accept, new, kept)      # one tree_map
    entry        = the output entry of the attempt (the saver)

The loop is a ``lax.while_loop`` (``mode="forward"``: stops when done; jit, vmap, jvp) or a
``lax.scan`` over a fixed budget of attempts with finished attempts masked by ``lax.cond`` and
each body under ``jax.checkpoint`` (``mode="reverse"``: also vjp / ``jax.grad``, memory ∝
budget × state, not a factorisation per step). Both run the same attempt function.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _controller as ctrl
from ._controller import DEFAULT_TOLERANCE, DONE, RUNNING, Tolerance
from ._discretisation import Discretisation, film_thickness
from ._drives import as_drive
from ._multistep import dense_output
from ._stepper import History, Level, push, start_history, step
from ._substrate import as_substrate


class Output(NamedTuple):
    """The saver's state: which output entries hold the levels the history keeps, and the
    profiles interpolated so far."""

    entries: jax.Array  # output entries of levels n, n-1, n-2 (int, (3,))
    profiles: jax.Array  # p̄ at the requested profile times (P, N)
    profile_gaps: jax.Array  # z̄ at the requested profile times (P,)
    profile_films: jax.Array  # h̄ at the requested profile times (P, N)


class State(NamedTuple):
    """The loop's state at the last accepted level tⁿ. A pytree.

    Attributes:
        t: tⁿ, the last accepted time t̄ (units of t_c).
        history: the accepted levels the BDF formula needs, newest first
            (``lubjax._stepper.History`` of ``Level``).
        peaks: running maxima the error norm scales by (``lubjax._controller.Peaks``).
        controller: the step-size controller's memory (``lubjax._controller.ControllerState``).
        accepted: the number of accepted steps so far.
        rejected: the number of rejected attempts so far.
        status: how the run stands (:class:`Status`, as an integer).
        output: the saver's state (``Output``): where the kept levels' entries are and the
            profiles interpolated so far.
    """

    t: jax.Array
    history: History  # accepted levels, newest first (lubjax._stepper.Level)
    peaks: ctrl.Peaks  # running maxima the error norm scales by
    controller: ctrl.ControllerState
    accepted: jax.Array  # counters
    rejected: jax.Array
    status: jax.Array  # lubjax._controller.Status
    output: Output


class Step(NamedTuple):
    """One output entry per attempt (entry 0: the initial state). A rejected attempt, or one after
    the run ended, repeats the last accepted level, so the entries are sorted in ``t``.

    In a :class:`Trajectory` every field has a leading axis of ``max_steps + 1`` entries.

    Attributes:
        t: t̄ of the entry (units of t_c).
        force: F̄ (eq 11b; units of F_s).
        film_center: h̄ at r̄ = 0 (units of d_c).
        film_min: min_i h̄_i (units of d_c).
        outflow: volume flux out through the last face, per unit 2π (units of R d_c²/t_c).
        gap: z̄, the sphere's position (units of d_c; its approach is z̄0 - z̄).
        velocity: dz̄/dt̄ (units of d_c/t_c; the step's BDF derivative, or the free sphere's
            velocity).
        elastic_energy: Ū = π Σ A_i p̄_i (Ŵp̄)_i = ½ ∫ p̄ (-w̄) dĀ (units of F_s d_c).
        dissipation: the viscous power D̄ = 2π Σ_faces g (Δp̄)² (units of F_s d_c/t_c).
        accepted: whether this entry is a new accepted level.
        stencil: the entries of levels n-2, n-1 and n, for the interpolant, shape (3,).
        degree: the degree of the step's interpolant: 1 (backward Euler), 2 (BDF2) or
            3 (BDF3).
    """

    t: jax.Array
    force: jax.Array  # F̄ (eq 11b)
    film_center: jax.Array  # h̄ at r̄ = 0
    film_min: jax.Array  # min_i h̄_i
    outflow: jax.Array  # volume flux out through the last face, per unit 2π
    gap: jax.Array  # z̄ (the sphere's position; its approach is z̄0 - z̄)
    velocity: jax.Array  # dz̄/dt̄ (BDF derivative of the step; the free sphere's velocity)
    elastic_energy: jax.Array  # Ū = π Σ A_i p̄_i (Ŵp̄)_i = ½ ∫ p̄ (-w̄) dĀ, units F_s d_c
    dissipation: jax.Array  # viscous power D̄ = 2π Σ_faces g (Δp̄)², same units per t_c
    accepted: jax.Array  # this entry is a new accepted level
    stencil: jax.Array  # entries of levels n-2, n-1 and n (for the interpolant), (3,)
    degree: jax.Array  # of the step's interpolant: 1 (backward Euler), 2 (BDF2), 3 (BDF3)


class Trajectory(NamedTuple):
    """What :func:`rollout` returns: the step entries, the profiles, and how the run ended.

    Attributes:
        steps: the :class:`Step` entries, leading axis ``max_steps + 1``.
        profiles: p̄ at the requested profile times, shape (P, N).
        profile_gaps: z̄ at the requested profile times, shape (P,).
        profile_films: h̄ at the requested profile times, shape (P, N).
        status: how the run ended (:class:`Status` as an integer; :func:`stop_reason`).
        accepted: the number of accepted steps.
        rejected: the number of rejected attempts.
        t_final: the last accepted time t̄ (``t_end`` when it finished).
    """

    steps: Step  # leading axis: max_steps + 1 entries
    profiles: jax.Array  # p̄ at the requested times, (P, N)
    profile_gaps: jax.Array  # z̄ at the requested times, (P,)
    profile_films: jax.Array  # h̄ at the requested times, (P, N)
    status: jax.Array
    accepted: jax.Array
    rejected: jax.Array
    t_final: jax.Array

    @property
    def finished(self):
        """t_end reached (not stopped by the attempt budget or a collapsing step)."""
        return self.status == DONE


def _initial_state(disc, beta, drive, substrate, z0, tol: Tolerance, profile_times) -> State:
    """At rest at t_start, where the travel need not be zero (eq 23 starts t̄₁/2 above z̄0; a
    measured history starts wherever its first sample is)."""
    dtype = disc.r.dtype
    zero = jnp.zeros_like(disc.r)
    n_memory = jnp.shape(substrate.compliance()[1])[0]
    z_start = jnp.asarray(drive.initial_gap(z0), dtype)
    h = film_thickness(disc, z_start, zero)
    v0 = jnp.asarray(drive.initial_velocity(), dtype)
    scalar_zero = jnp.zeros((), dtype)
    rest = Level(
        dt=jnp.ones((), dtype), pressure=zero, elastic_load=zero,
        memory=jnp.zeros((n_memory, disc.r.shape[0]), dtype), film=h, gap=z_start,
        gap_step=jnp.zeros_like(z_start), velocity=v0, force=scalar_zero,
    )
    n_profiles = profile_times.shape[0]
    integer = functools.partial(jnp.asarray, dtype=jnp.int32)
    return State(
        t=jnp.asarray(drive.t_start, dtype),
        history=start_history(rest, tol.order),
        peaks=ctrl.Peaks(force=scalar_zero, velocity=jnp.abs(v0),
                         excursion=jnp.zeros_like(z_start)),
        controller=ctrl.initial_controller(tol, beta, dtype),
        accepted=integer(0),
        rejected=integer(0),
        status=integer(RUNNING),
        output=Output(
            entries=jnp.zeros(3, jnp.int32),
            profiles=jnp.zeros((n_profiles, disc.r.shape[0]), dtype),
            # (the initial state answers profile times at t̄_start)
            profile_gaps=jnp.full((n_profiles,), z_start, dtype),
            profile_films=jnp.broadcast_to(h, (n_profiles, h.shape[0])),
        ),
    )


def _entry_of(disc, state: State, outflow, dissipation, accepted, degree, stencil) -> Step:
    """The output entry of a state's newest level."""
    level = jax.tree_util.tree_map(lambda x: x[0], state.history)
    elastic = level.film - level.gap - 0.5 * disc.r**2  # Ŵū = -w̄
    return Step(
        t=state.t,
        force=level.force,
        film_center=level.film[0],
        film_min=jnp.min(level.film),
        outflow=outflow,
        gap=level.gap,
        velocity=level.velocity,
        elastic_energy=jnp.pi * jnp.sum(disc.cell_area * level.pressure * elastic),
        dissipation=dissipation,
        accepted=accepted,
        stencil=stencil,
        degree=degree,
    )


def _save(output: Output, entry, t, t_new, history: History, candidate, profile_times) -> Output:
    """The saver on an accepted step t → t_new: the entry indices shift, and profiles requested
    in (t, t_new] are the step's dense output of p̄, z̄ and h̄."""
    level = candidate.level
    depth = history.pressure.shape[0]  # levels the dense output may use besides the new one
    dts = history.dt
    times = (t - dts[0] - dts[1], t - dts[0], t, t_new)[-(depth + 1):]
    in_step = (profile_times > t) & (profile_times <= t_new)

    def interpolant(new, levels, kept):
        values = (*(levels[j] for j in reversed(range(depth))), new)
        at = jax.vmap(lambda tq: dense_output(tq, times, values, candidate.order))(profile_times)
        return jnp.where(in_step.reshape(-1, *(1,) * (kept.ndim - 1)), at, kept)

    return Output(
        entries=jnp.stack([jnp.asarray(entry, jnp.int32), output.entries[0], output.entries[1]]),
        profiles=interpolant(level.pressure, history.pressure, output.profiles),
        profile_gaps=interpolant(level.gap, history.gap, output.profile_gaps),
        profile_films=interpolant(level.film, history.film, output.profile_films),
    )


def _attempt(disc, beta, z0, drive, substrate, t_end, tol: Tolerance, profile_times,
             state: State, k):
    """Attempt one step from ``state``; returns the new state and output entry ``k + 1``."""
    t, controller = state.t, state.controller
    t_new, lands = ctrl.propose(t, controller.dt_next, drive.breakpoints_array(), t_end)
    previous = jax.tree_util.tree_map(lambda x: x[0], state.history)
    order = ctrl.choose_order(controller, previous.force, state.peaks, tol.order,
                              state.history, t_new - t)
    candidate = step(disc, beta, drive, substrate, state.history, t, t_new, order, tol.order)
    gap_start = jnp.asarray(drive.initial_gap(z0), candidate.level.gap.dtype)
    film_scale = ctrl.film_scale(candidate.level, previous, tol.film_error, beta)
    ratio = ctrl.error_ratio(candidate.estimate, candidate.level, previous, state.peaks, tol,
                             drive, gap_start, film_scale)
    valid = ctrl.admissible(candidate.level, state.peaks, drive)
    decision = ctrl.adapt(ratio, valid, controller, order, t, t_new, lands, t_end, state.status,
                          ctrl.restart_step(tol, beta))
    new = State(
        t=t_new,
        history=push(state.history, candidate.level),
        peaks=ctrl.update_peaks(state.peaks, candidate.level, gap_start),
        controller=decision.accepted,
        accepted=state.accepted + 1,
        rejected=state.rejected,
        status=decision.status_accepted,
        output=_save(state.output, k + 1, t, t_new, state.history, candidate, profile_times),
    )
    kept = state._replace(controller=decision.rejected, rejected=state.rejected + 1,
                          status=decision.status_rejected)
    accept = decision.accept
    out_state = jax.tree_util.tree_map(lambda a, b: jnp.where(accept, a, b), new, kept)
    zero = jnp.zeros_like(t)
    out = _entry_of(
        disc, out_state, jnp.where(accept, candidate.outflow, zero),
        jnp.where(accept, candidate.dissipation, zero), accept,
        # (a rejected entry repeats the accepted level before it; never read past that level)
        jnp.where(accept, jnp.asarray(order, jnp.int32), 2),
        state.output.entries[::-1],
    )
    return out_state, out


def _idle(disc, state: State, k):
    """An attempt after the run ended: nothing changes."""
    zero = jnp.zeros_like(state.t)
    return state, _entry_of(disc, state, zero, zero, jnp.asarray(False),
                            jnp.asarray(2, jnp.int32), state.output.entries[::-1])


def rollout(
    disc: Discretisation,
    beta,
    z0,
    drive,
    t_end,
    tol: Tolerance = DEFAULT_TOLERANCE,
    profile_times=None,
    *,
    substrate=None,
    mode: str = "forward",
) -> Trajectory:
    """Integrate a run (eq 8, with the drive's closing row) from rest to ``t_end`` with error
    control.

    Every drive and substrate takes this one code path. Pure and jit/vmap/jvp-compatible in
    ``beta``, ``z0``, ``t_end`` and the drive's and substrate's leaves. Read values at any
    times with :func:`evaluate`.

    Args:
        disc: the :class:`Discretisation`, from ``discretise(mesh, substrate)`` (the
            geometry's influence matrix).
        beta: β (eq 8e), dimensionless, > 0; may be traced.
        z0: z̄0 = z0/d_c (eq 8e), dimensionless; may be traced.
        drive: what moves the sphere (``lubjax.Travel``, ``Load``, ``Spring``,
            ``FreeSphere``), or a bare travel history (``RampHold``, ``SampledTravel``) for a
            prescribed travel.
        t_end: final time t̄ (units of t_c), > t̄_start; may be traced.
        tol: the controller's :class:`Tolerance` (default ``DEFAULT_TOLERANCE``).
        profile_times: times t̄ at which p̄, z̄ and h̄ profiles are interpolated (None: none).
        substrate: ``lubjax.HalfSpace()`` (None, the default), a ``Layer`` or a
            ``Viscoelastic``; the same geometry as ``disc``.
        mode: "forward" (default; a ``while_loop``: jvp and vmap) or "reverse" (a checkpointed
            ``lax.scan`` over ``tol.max_steps`` attempts: also vjp and ``jax.grad``).

    Returns:
        Trajectory: the step entries, profiles and final status.

    Raises:
        ValueError: an unknown ``mode``, or ``tol.order`` not 1, 2 or 3.
        TypeError: ``drive`` or ``substrate`` of the wrong kind.
    """
    if mode not in ("forward", "reverse"):
        raise ValueError(f"mode must be 'forward' or 'reverse', got {mode!r}")
    if tol.order not in (1, 2, 3):
        raise ValueError(
            f"order must be 1 (backward Euler), 2 (BDF2) or 3 (BDF3), got {tol.order}"
        )
    dtype = disc.r.dtype
    profile_times = (
        jnp.zeros((0,), dtype) if profile_times is None else jnp.asarray(profile_times, dtype)
    )
    drive = as_drive(drive)
    substrate = as_substrate(substrate)
    state0 = _initial_state(disc, beta, drive, substrate, z0, tol, profile_times)
    zero = jnp.zeros((), dtype)
    first = _entry_of(disc, state0, zero, zero, jnp.asarray(True), jnp.asarray(2, jnp.int32),
                      jnp.zeros(3, jnp.int32))
    attempt = functools.partial(
        _attempt, disc, beta, z0, drive, substrate, t_end, tol, profile_times
    )
    idle = functools.partial(_idle, disc)

    def body(state, k):
        return jax.lax.cond(state.status == RUNNING, attempt, idle, state, k)

    n = tol.max_steps
    if mode == "reverse":
        final, entries = jax.lax.scan(jax.checkpoint(body), state0, jnp.arange(n))
        steps = jax.tree_util.tree_map(
            lambda a, b: jnp.concatenate([a[None], b]), first, entries
        )
    else:
        # Unwritten entries: t = +inf and NaN values, so a read past the end of an unfinished
        # run gives NaN rather than a stale value.
        def blank(a):
            fill = jnp.inf if a is first.t else (np.nan if a.dtype == dtype else 0)
            return jnp.full((n + 1, *a.shape), fill, a.dtype).at[0].set(a)

        buffers = Step(*(blank(a) for a in first))

        def loop_body(carry):
            state, k, buf = carry
            state, entry = attempt(state, k)
            buf = jax.tree_util.tree_map(lambda b, e: b.at[k + 1].set(e), buf, entry)
            return state, k + 1, buf

        def running(carry):
            state, k, _ = carry
            return (state.status == RUNNING) & (k < n)

        final, _, steps = jax.lax.while_loop(running, loop_body, (state0, jnp.int32(0), buffers))
    return Trajectory(
        steps=steps,
        profiles=final.output.profiles,
        profile_gaps=final.output.profile_gaps,
        profile_films=final.output.profile_films,
        status=final.status,
        accepted=final.accepted,
        rejected=final.rejected,
        t_final=final.t,
    )


def evaluate(steps: Step, times, field: str = "force"):
    """A field of the run at any times, by the stepper's own interpolant (of each step's order:
    cubic for BDF3 steps, quadratic for BDF2, linear for backward Euler).

    Differentiable and vmappable; the values do not depend on which other times are asked.

    Args:
        steps: the run's :class:`Step` entries (``Trajectory.steps``).
        times: t̄ (units of t_c); a scalar or an array.
        field: a per-step series of :class:`Step`: "force" (default), "film_min",
            "film_center", "outflow", "gap", "velocity", "elastic_energy" or "dissipation".

    Returns:
        jax.Array: the field at ``times``, shaped as ``times``; NaN past the end of the run,
        the initial value before its start.
    """
    return _evaluate(jnp, steps, times, field)


def evaluate_host(steps: Step, times, field: str = "force") -> np.ndarray:
    """:func:`evaluate` in NumPy, for a finished run on the host: the same arithmetic without
    compiling anything (compiling even this small program costs ~0.2 s, for every new length
    of ``times``).

    Args:
        steps: the run's :class:`Step` entries (``Trajectory.steps``; JAX or NumPy arrays).
        times: t̄ (units of t_c); a scalar or an array.
        field: a per-step series of :class:`Step`, as for :func:`evaluate` (default "force").

    Returns:
        numpy.ndarray: the field at ``times``, float64, shaped as ``times``.
    """
    steps = Step(*(np.asarray(a) for a in steps))
    return _evaluate(np, steps, np.asarray(times, np.float64), field)


def _evaluate(xp, steps: Step, times, field):
    values = getattr(steps, field)
    times = xp.asarray(times, values.dtype)
    k = xp.clip(xp.searchsorted(steps.t, times, side="left"), 0, steps.t.shape[0] - 1)
    im, i0, i1 = steps.stencil[k, 0], steps.stencil[k, 1], steps.stencil[k, 2]
    degree = xp.where(i0 == i1, 1, steps.degree[k])
    with np.errstate(invalid="ignore", divide="ignore"):  # NumPy: the unselected branch
        at = dense_output(
            times, (steps.t[im], steps.t[i0], steps.t[i1], steps.t[k]),
            (values[im], values[i0], values[i1], values[k]), degree, xp,
        )
    at = xp.where(k == 0, values[0], at)
    # An unfinished scan run repeats its last level: nothing is known past it.
    return xp.where(times > steps.t[-1], xp.nan, at)
