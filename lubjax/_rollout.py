r"""The loop over attempted steps, the saver, reading a run at any time, and its derivatives.

Each attempt (:func:`_attempt`) is the shape diffrax's loop has:

    attempt   = controller.propose(...)          # lands breakpoints, picks the formula
    candidate = step(...)                        # one factorisation: a candidate level + error
    decision  = controller.adapt(...)            # error norm; accept or reject, next Δt̄, status
    state     = where(accept, new, kept)         # one tree_map
    entry     = the output entry of the attempt (the saver)

The loop is a ``lax.while_loop`` that stops when the run is done. Its derivatives are those of
the accepted steps alone, with the steps' times and formulae held fixed (the controller's
choices are not differentiated, as in diffrax): a ``custom_jvp`` whose tangent is a linear map
of the input tangents (``jax.custom_derivatives.linear_call``) with two implementations,

* forward (``jvp``, ``jacfwd``): the accepted steps replayed from the start, each with its
  tangent (:func:`_forward_sensitivity`);
* reverse (``vjp``, ``grad``): the loop stores its state every ``B ≈ √max_steps`` accepted
  steps; the adjoint runs back over those blocks, each replayed from its checkpoint and pulled
  back (:func:`_adjoint_sensitivity`). The cost follows the steps taken, not the attempt
  budget, and the memory is ~2√max_steps states.

Each replayed step's tangent is that of the fully implicit step (lubjax/_stepper.py).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _controller as ctrl
from ._controller import BUDGET_SPENT, DEFAULT_TOLERANCE, DONE, RUNNING, Tolerance
from ._discretisation import Discretisation, elastic_part, film_thickness
from ._drives import as_drive
from ._linear_call import linear_call
from ._multistep import dense_output
from ._stepper import History, Level, push, start_history, step
from ._substrate import as_substrate


class Profiles(NamedTuple):
    """The profiles requested at the run's profile times, interpolated so far."""

    pressure: jax.Array  # p̄ (P, N)
    gap: jax.Array  # z̄ (P,)
    film: jax.Array  # h̄ (P, N)


class Output(NamedTuple):
    """The saver's state: which output entries hold the levels the history keeps, and the
    profiles interpolated so far."""

    entries: jax.Array  # output entries of levels n, n-1, n-2 (int, (3,))
    profiles: Profiles


class State(NamedTuple):
    """The loop's state at the last accepted level tⁿ. A pytree.

    Attributes:
        t: tⁿ, the last accepted time t̄ (units of t_c).
        history: the accepted levels the BDF formula needs, newest first
            (``lubjax._stepper.History`` of ``Level``).
        controller: the step-size controller's state (``lubjax._controller.ControllerState``,
            the running peaks inside).
        accepted: the number of accepted steps so far.
        rejected: the number of rejected attempts so far.
        status: how the run stands (:class:`Status`, as an integer).
        output: the saver's state (``Output``): where the kept levels' entries are and the
            profiles interpolated so far.
    """

    t: jax.Array
    history: History  # accepted levels, newest first (lubjax._stepper.Level)
    controller: ctrl.ControllerState
    accepted: jax.Array  # counters
    rejected: jax.Array
    status: jax.Array  # lubjax._controller.Status
    output: Output


class Series(NamedTuple):
    """The per-level values an output entry reports (the float fields of :class:`Step`)."""

    force: jax.Array
    film_center: jax.Array
    film_min: jax.Array
    outflow: jax.Array
    gap: jax.Array
    velocity: jax.Array
    elastic_energy: jax.Array
    dissipation: jax.Array


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


class Inputs(NamedTuple):
    """Everything a run depends on (the arguments of :func:`rollout`, normalised)."""

    disc: Discretisation
    beta: jax.Array
    z0: jax.Array
    drive: object
    substrate: object
    t_end: jax.Array
    tol: Tolerance
    profile_times: jax.Array


def _initial_state(inputs: Inputs) -> State:
    """At rest at t_start, where the travel need not be zero (eq 23 starts t̄₁/2 above z̄0; a
    measured history starts wherever its first sample is)."""
    disc, drive, tol = inputs.disc, inputs.drive, inputs.tol
    dtype = disc.r.dtype
    zero = jnp.zeros_like(disc.r)
    n_memory = jnp.shape(inputs.substrate.compliance()[1])[0]
    z_start = jnp.asarray(drive.initial_gap(inputs.z0), dtype)
    h = film_thickness(disc, z_start, zero)
    v0 = jnp.asarray(drive.initial_velocity(), dtype)
    scalar_zero = jnp.zeros((), dtype)
    rest = Level(
        dt=jnp.ones((), dtype), pressure=zero, elastic_load=zero,
        memory=jnp.zeros((n_memory, disc.r.shape[0]), dtype), film=h, gap=z_start,
        gap_step=jnp.zeros_like(z_start), velocity=v0, force=scalar_zero,
    )
    n_profiles = inputs.profile_times.shape[0]
    integer = functools.partial(jnp.asarray, dtype=jnp.int32)
    return State(
        t=jnp.asarray(drive.t_start, dtype),
        history=start_history(rest, tol.order),
        controller=_controller(inputs).init(v0, dtype),
        accepted=integer(0),
        rejected=integer(0),
        status=integer(RUNNING),
        output=Output(
            entries=jnp.zeros(3, jnp.int32),
            profiles=Profiles(
                pressure=jnp.zeros((n_profiles, disc.r.shape[0]), dtype),
                # (the initial state answers profile times at t̄_start)
                gap=jnp.full((n_profiles,), z_start, dtype),
                film=jnp.broadcast_to(h, (n_profiles, h.shape[0])),
            ),
        ),
    )


def _series_of(disc, history: History, outflow, dissipation) -> Series:
    """The reported values of a history's newest level."""
    level = jax.tree_util.tree_map(lambda x: x[0], history)
    elastic = elastic_part(disc, level.film, level.gap)  # Ŵū = -w̄
    return Series(
        force=level.force,
        film_center=level.film[0],
        film_min=jnp.min(level.film),
        outflow=outflow,
        gap=level.gap,
        velocity=level.velocity,
        elastic_energy=jnp.pi * jnp.sum(disc.cell_area * level.pressure * elastic),
        dissipation=dissipation,
    )


def _entry_of(disc, state: State, outflow, dissipation, accepted, degree, stencil) -> Step:
    """The output entry of a state's newest level."""
    series = _series_of(disc, state.history, outflow, dissipation)
    return Step(t=state.t, **series._asdict(), accepted=accepted, stencil=stencil,
                degree=degree)


def _save_profiles(profiles: Profiles, t, t_new, history: History, candidate,
                   profile_times) -> Profiles:
    """The saver on an accepted step t → t_new: profiles requested in (t, t_new] are the
    step's dense output of p̄, z̄ and h̄."""
    level = candidate.level
    depth = history.pressure.shape[0]  # levels the dense output may use besides the new one
    dts = history.dt
    times = (t - dts[0] - dts[1], t - dts[0], t, t_new)[-(depth + 1):]
    in_step = (profile_times > t) & (profile_times <= t_new)

    def interpolant(new, levels, kept):
        values = (*(levels[j] for j in reversed(range(depth))), new)
        at = jax.vmap(lambda tq: dense_output(tq, times, values, candidate.order))(profile_times)
        return jnp.where(in_step.reshape(-1, *(1,) * (kept.ndim - 1)), at, kept)

    return Profiles(
        pressure=interpolant(level.pressure, history.pressure, profiles.pressure),
        gap=interpolant(level.gap, history.gap, profiles.gap),
        film=interpolant(level.film, history.film, profiles.film),
    )


def _controller(inputs: Inputs) -> ctrl.Controller:
    return ctrl.Controller(inputs.tol, inputs.drive, inputs.beta, inputs.z0, inputs.t_end)


def _attempt(inputs: Inputs, state: State, k):
    """Attempt one step from ``state``; returns the new state, output entry ``k + 1`` and
    the attempt's formula."""
    disc = inputs.disc
    t, controller = state.t, _controller(inputs)
    attempt = controller.propose(state.controller, t, state.history)
    t_new, order = attempt.t_new, attempt.order
    candidate = step(disc, inputs.beta, inputs.drive, inputs.substrate, state.history, t, t_new,
                     order, inputs.tol.order)
    decision = controller.adapt(state.controller, t, attempt, candidate, state.history,
                                state.status)
    new = State(
        t=t_new,
        history=push(state.history, candidate.level),
        controller=decision.state,
        accepted=state.accepted + 1,
        rejected=state.rejected,
        status=decision.status,
        output=Output(
            entries=jnp.stack([jnp.asarray(k + 1, jnp.int32), state.output.entries[0],
                               state.output.entries[1]]),
            profiles=_save_profiles(state.output.profiles, t, t_new, state.history, candidate,
                                    inputs.profile_times),
        ),
    )
    kept = state._replace(controller=decision.state, rejected=state.rejected + 1,
                          status=decision.status)
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
    return out_state, out, order


class Record(NamedTuple):
    """What the loop keeps for the derivatives: the accepted steps' times and formulae, and
    checkpoints of the state the replay restarts from."""

    t: jax.Array  # tⁿ of accepted step m (max_steps,)
    t_new: jax.Array  # tⁿ⁺¹ of accepted step m (max_steps,)
    order: jax.Array  # its formula (max_steps,)
    checkpoints: tuple  # (history, profiles) after j·B accepted steps, leading axis j


def _block_size(max_steps: int) -> int:
    """Accepted steps per checkpoint, ~√max_steps: the adjoint holds a block's residuals and
    the checkpoints, ~2√max_steps states."""
    return max(1, math.isqrt(max_steps - 1) + 1)


def _blank_steps(first: Step, n: int, dtype) -> Step:
    """Entries not yet written: t = +inf and NaN values, so a read past the end of an
    unfinished run gives NaN rather than a stale value."""

    def blank(a):
        fill = jnp.inf if a is first.t else (np.nan if a.dtype == dtype else 0)
        return jnp.full((n + 1, *a.shape), fill, a.dtype).at[0].set(a)

    return Step(*(blank(a) for a in first))


def _loop(inputs: Inputs, record: bool):
    """The error-controlled loop: attempts until t_end (or the budget, or a collapsed step).
    With ``record`` it also keeps the :class:`Record` the derivatives replay."""
    disc = inputs.disc
    dtype = disc.r.dtype
    n = inputs.tol.max_steps
    state0 = _initial_state(inputs)
    zero = jnp.zeros((), dtype)
    first = _entry_of(disc, state0, zero, zero, jnp.asarray(True), jnp.asarray(2, jnp.int32),
                      jnp.zeros(3, jnp.int32))
    steps0 = _blank_steps(first, n, dtype)
    block = _block_size(n)
    n_blocks = -(-n // block)
    saved = (state0.history, state0.output.profiles)
    rec0 = Record(
        t=jnp.zeros(n, dtype), t_new=jnp.zeros(n, dtype), order=jnp.zeros(n, jnp.int32),
        checkpoints=jax.tree_util.tree_map(
            lambda x: jnp.broadcast_to(x, (n_blocks, *x.shape)), saved),
    ) if record else None

    def body(carry):
        state, k, buf, rec = carry
        new, entry, order = _attempt(inputs, state, k)
        buf = jax.tree_util.tree_map(lambda b, e: b.at[k + 1].set(e), buf, entry)
        if rec is not None:
            m = state.accepted  # the accepted step this attempt would be
            accept = entry.accepted
            keep = functools.partial(jnp.where, accept)
            rec = rec._replace(
                t=rec.t.at[m].set(keep(state.t, rec.t[m])),
                t_new=rec.t_new.at[m].set(keep(new.t, rec.t_new[m])),
                order=rec.order.at[m].set(keep(order, rec.order[m])),
            )
            j = new.accepted // block
            write = accept & (new.accepted % block == 0) & (j < n_blocks)
            point = (new.history, new.output.profiles)
            rec = rec._replace(checkpoints=jax.lax.cond(
                write,
                lambda c: jax.tree_util.tree_map(lambda b, x: b.at[j].set(x), c, point),
                lambda c: c, rec.checkpoints))
        return new, k + 1, buf, rec

    def running(carry):
        state, k, _, _ = carry
        return (state.status == RUNNING) & (k < n)

    final, _, steps, rec = jax.lax.while_loop(running, body,
                                              (state0, jnp.int32(0), steps0, rec0))
    profiles = final.output.profiles
    traj = Trajectory(
        steps=steps,
        profiles=profiles.pressure,
        profile_gaps=profiles.gap,
        profile_films=profiles.film,
        status=jnp.where(final.status == RUNNING, BUDGET_SPENT, final.status),
        accepted=final.accepted,
        rejected=final.rejected,
        t_final=final.t,
    )
    return traj, rec


# ------------------------------------------------------------------ the derivatives
def _replay_start(inputs: Inputs):
    """The replay's start (history and profiles at rest) and its output entry."""
    state = _initial_state(inputs)
    zero = jnp.zeros((), inputs.disc.r.dtype)
    return (state.history, state.output.profiles), _series_of(inputs.disc, state.history,
                                                              zero, zero)


def _replay_step(inputs: Inputs, point, t, t_new, order):
    """One accepted step of the run again, from (history, profiles) ``point``: the same
    :func:`lubjax._stepper.step` on the same times and formula."""
    history, profiles = point
    candidate = step(inputs.disc, inputs.beta, inputs.drive, inputs.substrate, history, t,
                     t_new, order, inputs.tol.order)
    profiles = _save_profiles(profiles, t, t_new, history, candidate, inputs.profile_times)
    history = push(history, candidate.level)
    return (history, profiles), _series_of(inputs.disc, history, candidate.outflow,
                                           candidate.dissipation)


def _scheduled(rec: Record, m, active):
    """Accepted step m's times and formula; a harmless backward Euler step where it is not
    ``active`` (past the run's end), so a masked branch computes nothing singular."""
    t = rec.t[m]
    t_new = jnp.where(active, rec.t_new[m], t + 1.0)
    return t, t_new, jnp.where(active, rec.order[m], 1)


class Sensitivity(NamedTuple):
    """The tangent (or cotangent) of a run: the series per accepted level (level 0 the start),
    and the final profiles."""

    series: Series  # each (max_steps + 1,)
    profiles: Profiles


def _zero_of(shape: jax.ShapeDtypeStruct):
    """The zero tangent of a value of this shape (float0 for an integer or boolean)."""
    if jnp.issubdtype(shape.dtype, jnp.inexact):
        return jnp.zeros(shape.shape, shape.dtype)
    return np.zeros(shape.shape, jax.dtypes.float0)


def _zero_tangent(x):
    x = jnp.asarray(x)
    return _zero_of(jax.ShapeDtypeStruct(x.shape, x.dtype))


def _add(a, b):
    return jax.tree_util.tree_map(
        lambda x, y: x + y if jnp.issubdtype(jnp.asarray(x).dtype, jnp.inexact) else x, a, b)


def _forward_sensitivity(static, residuals, live):
    """The tangent of a run from its inputs' (forward mode): the accepted steps replayed from
    the start with :func:`jax.jvp`."""
    inputs_dot = static.expand(live)
    inputs, rec, n_accepted = residuals
    dtype = inputs.disc.r.dtype
    n = inputs.tol.max_steps
    (point, series), (point_dot, series_dot) = jax.jvp(_replay_start, (inputs,), (inputs_dot,))
    buffer = jax.tree_util.tree_map(lambda s: jnp.zeros(n + 1, dtype).at[0].set(s), series_dot)

    block = _block_size(n)

    def body(carry):
        m, point, point_dot, buffer = carry
        # The run's own state at each checkpoint: near dry the values recomputed step after
        # step drift from the run's at rounding level (β = 10⁹: 10⁻⁶ after 700 steps), and
        # on the run's step sizes a drifted film can go negative.
        anchor = jax.tree_util.tree_map(lambda c: c[m // block], rec.checkpoints)
        point = jax.tree_util.tree_map(
            functools.partial(jnp.where, m % block == 0), anchor, point)
        t, t_new, order = _scheduled(rec, m, m < n_accepted)
        (point, _), (point_dot, series_dot) = jax.jvp(
            lambda p, i: _replay_step(i, p, t, t_new, order), (point, inputs),
            (point_dot, inputs_dot))
        buffer = jax.tree_util.tree_map(lambda b, s: b.at[m + 1].set(s), buffer, series_dot)
        return m + 1, point, point_dot, buffer

    _, _, point_dot, buffer = jax.lax.while_loop(
        lambda c: c[0] < n_accepted, body, (jnp.int32(0), point, point_dot, buffer))
    return Sensitivity(Series(*buffer), point_dot[1])


def _adjoint_sensitivity(static, residuals, cotangent: Sensitivity):
    """The cotangent of a run's inputs (reverse mode): back over the checkpointed blocks, each
    replayed from its checkpoint and pulled back by :func:`jax.vjp`."""
    inputs, rec, n_accepted = residuals
    n = inputs.tol.max_steps
    block = _block_size(n)
    padded = jax.tree_util.tree_map(
        lambda c: jnp.concatenate([c, jnp.zeros(block, c.dtype)]), cotangent.series)

    def run_block(j, point, inputs):
        def one(point, i):
            m = j * block + i
            active = m < n_accepted

            def go(point):
                t, t_new, order = _scheduled(rec, m, active)
                return _replay_step(inputs, point, t, t_new, order)

            def skip(point):
                zero = jnp.zeros((), inputs.disc.r.dtype)
                return point, Series(*(zero,) * len(Series._fields))

            return jax.lax.cond(active, go, skip, point)

        return jax.lax.scan(one, point, jnp.arange(block))

    def body(carry):
        j, point_ct, inputs_ct = carry
        start = jax.tree_util.tree_map(lambda c: c[j], rec.checkpoints)
        _, pullback = jax.vjp(functools.partial(run_block, j), start, inputs)
        series_ct = jax.tree_util.tree_map(
            lambda c: jax.lax.dynamic_slice_in_dim(c, j * block + 1, block), padded)
        point_ct, step_inputs_ct = pullback((point_ct, Series(*series_ct)))
        return j - 1, point_ct, _add(inputs_ct, step_inputs_ct)

    point = (jax.tree_util.tree_map(lambda c: c[0], rec.checkpoints[0]),
             jax.tree_util.tree_map(lambda c: c[0], rec.checkpoints[1]))
    point_ct = (jax.tree_util.tree_map(jnp.zeros_like, point[0]), cotangent.profiles)
    inputs_ct = jax.tree_util.tree_map(_zero_tangent, inputs)
    last = (n_accepted - 1) // block  # (-1 for a run without an accepted step)
    _, point_ct, inputs_ct = jax.lax.while_loop(
        lambda c: c[0] >= 0, body, (jnp.asarray(last, jnp.int32), point_ct, inputs_ct))
    _, pullback = jax.vjp(_replay_start, inputs)
    (start_ct,) = pullback((point_ct, Series(*(c[0] for c in cotangent.series))))
    return static.select(_add(inputs_ct, start_ct))


class _Live(NamedTuple):
    """Which input leaves carry a tangent (the others are symbolic zeros): linear_call's
    linear arguments are those alone, so a derivative with respect to some inputs does not
    hand the transpose a constant zero."""

    treedef: object
    mask: tuple
    shapes: tuple  # jax.ShapeDtypeStruct of every leaf

    def expand(self, live):
        it = iter(live)
        leaves = [next(it) if m else _zero_of(s) for m, s in zip(self.mask, self.shapes)]
        return jax.tree_util.tree_unflatten(self.treedef, leaves)

    def select(self, tree):
        return tuple(x for x, m in zip(jax.tree_util.tree_leaves(tree), self.mask) if m)


@jax.custom_jvp
def _rollout(inputs: Inputs) -> Trajectory:
    return _loop(inputs, record=False)[0]


def _rollout_jvp(primals, tangents):
    (inputs,), (inputs_dot,) = primals, tangents
    traj, rec = _loop(inputs, record=True)
    leaves, treedef = jax.tree_util.tree_flatten(inputs)
    dots = jax.tree_util.tree_leaves(
        inputs_dot, is_leaf=lambda x: isinstance(x, jax.custom_derivatives.SymbolicZero))
    mask = tuple(not isinstance(d, jax.custom_derivatives.SymbolicZero) for d in dots)
    static = _Live(treedef, mask,
                   tuple(jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)) for x in leaves))
    live = tuple(d for d, m in zip(dots, mask) if m)
    residuals = (inputs, rec, traj.accepted)
    sensitivity = linear_call(
        functools.partial(_forward_sensitivity, static),
        functools.partial(_adjoint_sensitivity, static), residuals, live)
    return traj, _trajectory_tangent(traj, sensitivity)


_rollout.defjvp(_rollout_jvp, symbolic_zeros=True)


def _trajectory_tangent(traj: Trajectory, sensitivity: Sensitivity) -> Trajectory:
    """The tangent of each output entry: its level's (a rejected entry repeats the level
    before it, with no outflow or dissipation); none for the times and the bookkeeping."""
    steps = traj.steps
    written = jnp.isfinite(steps.t)
    level = jnp.cumsum(steps.accepted.astype(jnp.int32)) - 1
    kept = written
    new = steps.accepted & written

    def gather(values, where_):
        return jnp.where(where_, values[level], 0.0)

    s = sensitivity.series
    step_dot = Step(
        t=jnp.zeros_like(steps.t),
        force=gather(s.force, kept), film_center=gather(s.film_center, kept),
        film_min=gather(s.film_min, kept), outflow=gather(s.outflow, new),
        gap=gather(s.gap, kept), velocity=gather(s.velocity, kept),
        elastic_energy=gather(s.elastic_energy, kept),
        dissipation=gather(s.dissipation, new),
        accepted=_zero_tangent(steps.accepted), stencil=_zero_tangent(steps.stencil),
        degree=_zero_tangent(steps.degree),
    )
    return Trajectory(
        steps=step_dot,
        profiles=sensitivity.profiles.pressure,
        profile_gaps=sensitivity.profiles.gap,
        profile_films=sensitivity.profiles.film,
        status=_zero_tangent(traj.status), accepted=_zero_tangent(traj.accepted),
        rejected=_zero_tangent(traj.rejected), t_final=jnp.zeros_like(traj.t_final),
    )


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
) -> Trajectory:
    """Integrate a run (eq 8, with the drive's closing row) from rest to ``t_end`` with error
    control.

    Every drive and substrate takes this one code path. A pure function for ``jit``, ``vmap``,
    ``jvp``/``jacfwd`` and ``vjp``/``grad``/``jacrev`` in ``beta``, ``z0`` and the drive's
    and substrate's leaves. Derivatives are those of the accepted steps with their times held
    fixed: the step times, and so ``t_end``, carry none. Read values at any times with
    :func:`evaluate`.

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

    Returns:
        Trajectory: the step entries, profiles and final status.

    Raises:
        ValueError: ``tol.order`` not 1, 2 or 3.
        TypeError: ``drive`` or ``substrate`` of the wrong kind.
    """
    if tol.order not in (1, 2, 3):
        raise ValueError(
            f"order must be 1 (backward Euler), 2 (BDF2) or 3 (BDF3), got {tol.order}"
        )
    dtype = disc.r.dtype
    profile_times = (
        jnp.zeros((0,), dtype) if profile_times is None else jnp.asarray(profile_times, dtype)
    )
    inputs = Inputs(disc, jnp.asarray(beta, dtype), jnp.asarray(z0, dtype), as_drive(drive),
                    as_substrate(substrate), jnp.asarray(t_end, dtype), tol, profile_times)
    return _rollout(inputs)


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
