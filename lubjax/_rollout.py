"""A run from rest to t_end: the loop (lubjax/_loop.py) with the derivatives of its accepted
steps (lubjax/_adjoint.py).

Its derivatives are those of the accepted steps alone, with the steps' times and formulae held
fixed (the controller's choices are not differentiated, as in diffrax). A differentiated run
takes its steps with the near-dry film held tighter than a plain run's
(``Tolerance.for_tangents``).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ._adjoint import Live, adjoint_sensitivity, forward_sensitivity, trajectory_tangent
from ._controller import DEFAULT_TOLERANCE, Tolerance
from ._discretisation import Discretisation
from ._drives import as_drive
from ._linear_call import linear_call
from ._loop import Inputs, loop
from ._output import Trajectory
from ._sharding import batch, batching_mode
from ._substrate import as_substrate


def _batched_by_map(fn):
    """``fn`` of one run, which under ``vmap`` maps over the batch on a CPU (``lax.map``: each
    member its own steps, as :func:`lubjax.sweep` does) and ``vmap``s it on an accelerator
    (:func:`lubjax._sharding.batching_mode`). Why: a ``vmap``ped loop runs every member until
    the slowest is done and computes both branches of every ``cond``, and on a CPU its batched
    LU is only a loop of LAPACK calls; ``vmap(relax)`` and ``vmap(force_curve)`` would be many
    times slower than the same batch mapped."""
    batched_fn = jax.custom_batching.custom_vmap(fn)

    @batched_fn.def_vmap
    def _rule(axis_size, in_batched, inputs):
        leaves, treedef = jax.tree_util.tree_flatten(inputs)
        flags = tuple(jax.tree_util.tree_leaves(in_batched))
        if not any(flags):
            out = fn(inputs)
            return out, jax.tree_util.tree_map(lambda _: False, out)
        out = batch(lambda *x: fn(jax.tree_util.tree_unflatten(treedef, x)), flags,
                    batching_mode())(*leaves)
        return out, jax.tree_util.tree_map(lambda _: True, out)

    return batched_fn


_plain_loop = _batched_by_map(lambda inputs: loop(inputs, record=False)[0])

#: Why a second derivative of a run is refused (:func:`_recorded_loop`).
SECOND_DERIVATIVES = (
    "second derivatives of a lubjax run (jax.hessian, jvp of grad, grad of jvp, jacfwd of "
    "jacfwd) are not implemented: a run's derivative replays its accepted steps with their "
    "times and factorisations held fixed, and that replay is not differentiated again. For a "
    "Hessian take central differences of jax.grad, or the Gauss-Newton J^T J of jax.jacfwd.")


@jax.custom_jvp
def _recorded_loop(inputs: Inputs):
    """The run with its records for the derivatives (:func:`_rollout_jvp`). Its own derivative
    would be a derivative of the derivative: JAX would fail deep inside (an assertion in
    ``linear_call``'s rule, or a loop it cannot linearize), so it is refused at once with
    :data:`SECOND_DERIVATIVES`."""
    return _recorded_loop_batched(inputs)


@_recorded_loop.defjvp
def _recorded_loop_jvp(primals, tangents):
    raise NotImplementedError(SECOND_DERIVATIVES)


_recorded_loop_batched = _batched_by_map(lambda inputs: loop(inputs, record=True))


@jax.custom_jvp
def _rollout(inputs: Inputs) -> Trajectory:
    return _plain_loop(inputs)


def _rollout_jvp(primals, tangents):
    (inputs,), (inputs_dot,) = primals, tangents
    # A run whose derivatives are taken holds a near-dry film tighter (Tolerance.for_tangents):
    # its values are those of that run, within the tolerance of the plain run's.
    inputs = inputs._replace(tol=inputs.tol.for_tangents())
    traj, rec = _recorded_loop(inputs)
    leaves, treedef = jax.tree_util.tree_flatten(inputs)
    dots = jax.tree_util.tree_leaves(
        inputs_dot, is_leaf=lambda x: isinstance(x, jax.custom_derivatives.SymbolicZero))
    mask = tuple(not isinstance(d, jax.custom_derivatives.SymbolicZero) for d in dots)
    static = Live(treedef, mask,
                  tuple(jax.ShapeDtypeStruct(jnp.shape(x), jnp.result_type(x)) for x in leaves))
    live = tuple(d for d, m in zip(dots, mask) if m)
    residuals = (inputs, rec, traj.accepted)
    sensitivity = linear_call(
        functools.partial(forward_sensitivity, static),
        functools.partial(adjoint_sensitivity, static), residuals, live)
    return traj, trajectory_tangent(traj, sensitivity)


_rollout.defjvp(_rollout_jvp, symbolic_zeros=True)

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
