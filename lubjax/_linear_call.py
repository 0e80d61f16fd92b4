"""``jax.custom_derivatives.linear_call`` with a batching rule, which JAX does not define.

:func:`lubjax._rollout.rollout` takes its derivatives through ``linear_call`` (a linear map with
its own transpose: the forward replay and the checkpointed adjoint). Under ``vmap`` of a
derivative the call meets batched inputs; this rule maps the callee and its transpose over the
batch axis (every input brought to the front, every output batched there).
"""

from __future__ import annotations

import jax
from jax._src import core
from jax._src.custom_derivatives import linear_call_p
from jax._src.interpreters import batching

linear_call = jax.custom_derivatives.linear_call


def _batched(axis_data, args, dims, *, callee, transpose_thunk, num_callee_consts, num_res):
    size = axis_data.size
    args = [batching.bdim_at_front(a, d, size) for a, d in zip(args, dims)]
    n_fixed = num_callee_consts + num_res
    batched_callee = jax.make_jaxpr(jax.vmap(core.jaxpr_as_fun(callee)))(*args)

    def batched_transpose():
        transpose, consts = transpose_thunk()

        def run(*a):
            return core.jaxpr_as_fun(transpose)(*consts, *a)

        cotangents = [jax.ShapeDtypeStruct((size, *a.shape), a.dtype) for a in callee.out_avals]
        fixed = [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in args[:n_fixed]]
        return jax.make_jaxpr(jax.vmap(run))(*fixed, *cotangents), ()

    out = linear_call_p.bind(*args, callee=batched_callee, transpose_thunk=batched_transpose,
                             num_callee_consts=0, num_res=n_fixed)
    return out, [0] * len(out)


batching.fancy_primitive_batchers[linear_call_p] = _batched
