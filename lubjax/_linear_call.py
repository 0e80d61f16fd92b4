"""``jax.custom_derivatives.linear_call`` with a batching rule, which JAX does not define.

:func:`lubjax._rollout.rollout` takes its derivatives through ``linear_call`` (a linear map with
its own transpose: the forward replay and the checkpointed adjoint). Under ``vmap`` of a
derivative the call meets batched inputs; this rule maps the callee and its transpose over the
batch axis (batched inputs brought to the front, every output batched there).
"""

from __future__ import annotations

import jax
from jax._src import core
from jax._src.custom_derivatives import linear_call_p
from jax._src.interpreters import batching

from ._sharding import batch, batching_mode

linear_call = jax.custom_derivatives.linear_call


def _batched(axis_data, args, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
    n_fixed = num_callee_consts + num_res
    # Inputs the batch does not vary stay unbatched: the replay's values are then computed once,
    # exactly as in the unbatched call (a batched LU rounds differently, and near dry the
    # derivatives are sensitive to the values at rounding level).
    in_axes = [None if d is None else 0 for d in dims]
    args = [a if d is None else jax.numpy.moveaxis(a, d, 0) for a, d in zip(args, dims)]
    # Batched residuals are a batch of runs: mapped over on a CPU, like their values
    # (lubjax/_rollout.py); a batch of tangents of one run is vmapped, one replay for all.
    over = _mapped if any(d is not None for d in in_axes[:n_fixed]) else jax.vmap
    batched_callee = jax.make_jaxpr(over(core.jaxpr_as_fun(callee), in_axes=in_axes))(*args)

    def batched_transpose():
        transpose, consts = transpose_thunk()

        def run(*a):
            return core.jaxpr_as_fun(transpose)(*consts, *a)

        size = axis_data.size
        cotangents = [jax.ShapeDtypeStruct((size, *a.shape), a.dtype) for a in callee.out_avals]
        fixed = [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in args[:n_fixed]]
        axes = in_axes[:n_fixed] + [0] * len(cotangents)
        return jax.make_jaxpr(over(run, in_axes=axes))(*fixed, *cotangents), ()

    out = linear_call_p.bind(*args, callee=batched_callee, transpose_thunk=batched_transpose,
                             num_callee_consts=0, num_res=n_fixed)
    return out, [0] * len(out)


def _mapped(fn, in_axes):
    """``fn`` over the leading axis of the arguments whose axis is 0, the others shared: mapped
    or vmapped as :func:`lubjax._sharding.batching_mode` says."""
    return batch(fn, tuple(axis == 0 for axis in in_axes), batching_mode())


batching.fancy_primitive_batchers[linear_call_p] = _batched
