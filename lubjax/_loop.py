r"""The error-controlled loop over attempted steps.

Each attempt (:func:`attempt`) is the shape diffrax's loop has::

    attempt   = controller.propose(...)          # lands breakpoints, picks the formula
    candidate = step(...)                        # one factorisation: a candidate level + error
    decision  = controller.adapt(...)            # error norm; accept or reject, next Δt̄, status
    state     = where(accept, new, kept)         # one tree_map
    entry     = the output entry of the attempt (the saver)

The loop is a ``lax.while_loop`` that stops when the run is done; asked to, it also keeps the
:class:`Record` the derivatives replay (lubjax/_adjoint.py).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import _controller as ctrl
from ._controller import BUDGET_SPENT, RUNNING, Tolerance
from ._discretisation import Discretisation, film_thickness
from ._output import Output, Profiles, Trajectory, blank_steps, entry_of, save_profiles
from ._stepper import History, Level, push, start_history, step


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

def initial_state(inputs: Inputs) -> State:
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
        controller=controller_of(inputs).init(v0, dtype),
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

def controller_of(inputs: Inputs) -> ctrl.Controller:
    return ctrl.Controller(inputs.tol, inputs.drive, inputs.beta, inputs.z0, inputs.t_end)


def attempt(inputs: Inputs, state: State, k):
    """Attempt one step from ``state``; returns the new state, output entry ``k + 1`` and
    the attempt's formula."""
    disc = inputs.disc
    t, controller = state.t, controller_of(inputs)
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
            profiles=save_profiles(state.output.profiles, t, t_new, state.history, candidate,
                                   inputs.profile_times),
        ),
    )
    kept = state._replace(controller=decision.state, rejected=state.rejected + 1,
                          status=decision.status)
    accept = decision.accept
    out_state = jax.tree_util.tree_map(lambda a, b: jnp.where(accept, a, b), new, kept)
    zero = jnp.zeros_like(t)
    out = entry_of(
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


def block_size(max_steps: int) -> int:
    """Accepted steps per checkpoint, ~√max_steps: the adjoint holds a block's residuals and
    the checkpoints, ~2√max_steps states."""
    return max(1, math.isqrt(max_steps - 1) + 1)


def loop(inputs: Inputs, record: bool):
    """The error-controlled loop: attempts until t_end (or the budget, or a collapsed step).
    With ``record`` it also keeps the :class:`Record` the derivatives replay."""
    disc = inputs.disc
    dtype = disc.r.dtype
    n = inputs.tol.max_steps
    state0 = initial_state(inputs)
    zero = jnp.zeros((), dtype)
    first = entry_of(disc, state0, zero, zero, jnp.asarray(True), jnp.asarray(2, jnp.int32),
                     jnp.zeros(3, jnp.int32))
    steps0 = blank_steps(first, n, dtype)
    block = block_size(n)
    n_blocks = -(-n // block)
    saved = (state0.history, state0.output.profiles)
    rec0 = Record(
        t=jnp.zeros(n, dtype), t_new=jnp.zeros(n, dtype), order=jnp.zeros(n, jnp.int32),
        checkpoints=jax.tree_util.tree_map(
            lambda x: jnp.broadcast_to(x, (n_blocks, *x.shape)), saved),
    ) if record else None

    def body(carry):
        state, k, buf, rec = carry
        new, entry, order = attempt(inputs, state, k)
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
