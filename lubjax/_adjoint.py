"""The derivatives of a run: its accepted steps replayed with their times and formulae held
fixed, forward (a tangent per step) or in reverse (an adjoint over checkpointed blocks).

The rollout is a ``custom_jvp`` (lubjax/_rollout.py) whose tangent is a linear map of the input
tangents (``jax.custom_derivatives.linear_call``) with two implementations,

* forward (``jvp``, ``jacfwd``): the accepted steps replayed from the start, each with its
  tangent (:func:`forward_sensitivity`);
* reverse (``vjp``, ``grad``): the loop stores its state every ``B ≈ √max_steps`` accepted
  steps; the adjoint runs back over those blocks, each replayed from its checkpoint and pulled
  back (:func:`adjoint_sensitivity`). The cost follows the steps taken, not the attempt
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

from ._loop import Inputs, Record, block_size, initial_state
from ._output import Entry, Profiles, Series, Trajectory, save_profiles, series_of
from ._stepper import push, step


def _replay_start(inputs: Inputs):
    """The replay's start (history and profiles at rest) and its output entry."""
    state = initial_state(inputs)
    zero = jnp.zeros((), inputs.disc.r.dtype)
    return (state.history, state.output.profiles), series_of(inputs.disc, state.history,
                                                             zero, zero)


def _replay_step(inputs: Inputs, point, t, t_new, order):
    """One accepted step of the run again, from (history, profiles) ``point``: the same
    :func:`lubjax._stepper.step` on the same times and formula."""
    history, profiles = point
    candidate = step(inputs.disc, inputs.beta, inputs.drive, inputs.substrate, history, t,
                     t_new, order, inputs.tol.order)
    profiles = save_profiles(profiles, t, t_new, history, candidate, inputs.profile_times)
    history = push(history, candidate.level)
    return (history, profiles), series_of(inputs.disc, history, candidate.outflow,
                                          candidate.dissipation)


def _scheduled(rec: Record, m, n_accepted):
    """Accepted step m's times and formula. Past the run's end (m ≥ ``n_accepted``: a masked
    step of the adjoint's last sub-block, or any step of a batched one) a backward Euler step
    from the run's last time a thousandth of its last step long: close to the state it starts
    from, so the masked step computes nothing singular whose zero cotangent would turn NaN."""
    active = m < n_accepted
    inside = jnp.minimum(m, rec.t.shape[0] - 1)
    last = jnp.maximum(n_accepted - 1, 0)
    end, last_dt = rec.t_new[last], rec.t_new[last] - rec.t[last]
    t = jnp.where(active, rec.t[inside], end)
    t_new = jnp.where(active, rec.t_new[inside],
                      end + 1e-3 * jnp.where(last_dt > 0, last_dt, 1.0))
    return t, t_new, jnp.where(active, rec.order[inside], 1)


def sub_blocks(block: int) -> tuple[int, int]:
    """(count, size): the adjoint runs a block of ``block`` steps as ``count`` sub-blocks of
    ``size`` (~√block each, count·size ≥ block). Why: a sub-block past the run's end is skipped
    by a ``lax.cond``, and in reverse mode each cond costs about as much as two steps (its
    residuals are copied out whole): one per step made the adjoint 60 % slower, one per block
    would replay up to a block of needless steps at the run's end."""
    size = math.isqrt(block - 1) + 1
    count = -(-block // size)
    return count, -(-block // count)


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


def zero_tangent(x):
    x = jnp.asarray(x)
    return _zero_of(jax.ShapeDtypeStruct(x.shape, x.dtype))


def _add(a, b):
    return jax.tree_util.tree_map(
        lambda x, y: x + y if jnp.issubdtype(jnp.asarray(x).dtype, jnp.inexact) else x, a, b)


def forward_sensitivity(static, residuals, live):
    """The tangent of a run from its inputs' (forward mode): the accepted steps replayed from
    the start with :func:`jax.jvp`."""
    inputs_dot = static.expand(live)
    inputs, rec, n_accepted = residuals
    dtype = inputs.disc.r.dtype
    n = inputs.tol.max_steps
    (point, series), (point_dot, series_dot) = jax.jvp(_replay_start, (inputs,), (inputs_dot,))
    buffer = jax.tree_util.tree_map(lambda s: jnp.zeros(n + 1, dtype).at[0].set(s), series_dot)

    block = block_size(n)

    def body(carry):
        m, point, point_dot, buffer = carry
        # The run's own state at each checkpoint: near dry the values recomputed step after
        # step drift from the run's at rounding level (β = 10⁹: 10⁻⁶ after 700 steps), and
        # on the run's step sizes a drifted film can go negative.
        anchor = jax.tree_util.tree_map(lambda c: c[m // block], rec.checkpoints)
        point = jax.tree_util.tree_map(
            functools.partial(jnp.where, m % block == 0), anchor, point)
        t, t_new, order = _scheduled(rec, m, n_accepted)
        (point, _), (point_dot, series_dot) = jax.jvp(
            lambda p, i: _replay_step(i, p, t, t_new, order), (point, inputs),
            (point_dot, inputs_dot))
        buffer = jax.tree_util.tree_map(lambda b, s: b.at[m + 1].set(s), buffer, series_dot)
        return m + 1, point, point_dot, buffer

    _, _, point_dot, buffer = jax.lax.while_loop(
        lambda c: c[0] < n_accepted, body, (jnp.int32(0), point, point_dot, buffer))
    return Sensitivity(Series(*buffer), point_dot[1])


def adjoint_sensitivity(static, residuals, cotangent: Sensitivity):
    """The cotangent of a run's inputs (reverse mode): back over the checkpointed blocks, each
    replayed from its checkpoint and pulled back by :func:`jax.vjp`."""
    inputs, rec, n_accepted = residuals
    n = inputs.tol.max_steps
    block = block_size(n)
    count, size = sub_blocks(block)
    slots = count * size
    padded = jax.tree_util.tree_map(
        lambda c: jnp.concatenate([c, jnp.zeros(slots, c.dtype)]), cotangent.series)
    zero = jnp.zeros((), inputs.disc.r.dtype)

    def run_block(j, point, inputs):
        end = jnp.minimum((j + 1) * block, n_accepted)

        def one(point, m):
            # Steps past the block's end (the next block's) or the run's are masked: their
            # state is not kept and their series is zero, so no cotangent reaches them.
            active = m < end
            t, t_new, order = _scheduled(rec, m, n_accepted)
            new, series = _replay_step(inputs, point, t, t_new, order)
            keep = functools.partial(jnp.where, active)
            return (jax.tree_util.tree_map(keep, new, point),
                    jax.tree_util.tree_map(lambda s: keep(s, zero), series))

        def sub_block(point, k):
            steps = j * block + k * size + jnp.arange(size)

            def skip(point):
                return point, Series(*(jnp.zeros(size, zero.dtype),) * len(Series._fields))

            return jax.lax.cond(steps[0] < end, lambda p: jax.lax.scan(one, p, steps), skip,
                                point)

        point, series = jax.lax.scan(sub_block, point, jnp.arange(count))
        return point, jax.tree_util.tree_map(lambda s: s.reshape(slots), series)

    def body(carry):
        j, point_ct, inputs_ct = carry
        start = jax.tree_util.tree_map(lambda c: c[j], rec.checkpoints)
        _, pullback = jax.vjp(functools.partial(run_block, j), start, inputs)
        in_block = jnp.arange(slots) < block
        series_ct = jax.tree_util.tree_map(
            lambda c: jnp.where(in_block, jax.lax.dynamic_slice_in_dim(c, j * block + 1, slots),
                                0.0), padded)
        point_ct, step_inputs_ct = pullback((point_ct, Series(*series_ct)))
        return j - 1, point_ct, _add(inputs_ct, step_inputs_ct)

    point = (jax.tree_util.tree_map(lambda c: c[0], rec.checkpoints[0]),
             jax.tree_util.tree_map(lambda c: c[0], rec.checkpoints[1]))
    point_ct = (jax.tree_util.tree_map(jnp.zeros_like, point[0]), cotangent.profiles)
    inputs_ct = jax.tree_util.tree_map(zero_tangent, inputs)
    last = (n_accepted - 1) // block  # (-1 for a run without an accepted step)
    _, point_ct, inputs_ct = jax.lax.while_loop(
        lambda c: c[0] >= 0, body, (jnp.asarray(last, jnp.int32), point_ct, inputs_ct))
    _, pullback = jax.vjp(_replay_start, inputs)
    (start_ct,) = pullback((point_ct, Series(*(c[0] for c in cotangent.series))))
    return static.select(_add(inputs_ct, start_ct))


class Live(NamedTuple):
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

def trajectory_tangent(traj: Trajectory, sensitivity: Sensitivity) -> Trajectory:
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
    step_dot = Entry(
        t=jnp.zeros_like(steps.t),
        force=gather(s.force, kept), film_center=gather(s.film_center, kept),
        film_min=gather(s.film_min, kept), outflow=gather(s.outflow, new),
        gap=gather(s.gap, kept), velocity=gather(s.velocity, kept),
        elastic_energy=gather(s.elastic_energy, kept),
        dissipation=gather(s.dissipation, new),
        accepted=zero_tangent(steps.accepted), stencil=zero_tangent(steps.stencil),
        degree=zero_tangent(steps.degree),
    )
    return Trajectory(
        steps=step_dot,
        profiles=sensitivity.profiles.pressure,
        profile_gaps=sensitivity.profiles.gap,
        profile_films=sensitivity.profiles.film,
        status=zero_tangent(traj.status), accepted=zero_tangent(traj.accepted),
        rejected=zero_tangent(traj.rejected), t_final=jnp.zeros_like(traj.t_final),
    )
