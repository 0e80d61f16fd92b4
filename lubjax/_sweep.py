"""Batches of relaxation tests in one compiled, ``vmap``-ped call, sharded over JAX devices."""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._indenter import RampHold, SampledTravel
from ._solve import Settings, _check_x64, make_plan
from ._stepper import rollout


class SweepResult(NamedTuple):
    """Flattened batch: ``force[k]`` and ``film_min[k]`` belong to ``(beta[k], z0[k])``."""

    beta: np.ndarray  # (B,)
    z0: np.ndarray  # (B,)
    t: np.ndarray  # (T,) shared time grid
    force: np.ndarray  # (B, T)
    film_min: np.ndarray  # (B, T)
    ok: np.ndarray  # (B,) finite and positive film throughout
    compile_s: float
    run_s: float
    devices: int


_CACHE: dict = {}


def _batched_runner(n_devices: int):
    """jit(vmap(rollout)); with several devices the batch axis is sharded across them."""
    if n_devices in _CACHE:
        return _CACHE[n_devices]

    def one(disc, coeffs, travel, b, z):
        out = rollout(disc, b, z, travel, coeffs)
        return out.force, out.film_min

    batched = jax.vmap(one, in_axes=(None, None, None, 0, 0))
    if n_devices > 1:
        # shard_map, not jit sharding annotations: each device runs its own vmapped scan. With
        # plain sharding the step safeguard's while_loop (whose predicate is "any member of the
        # batch still retries") becomes an all-reduce in every step, which deadlocks on host
        # devices and would serialise real ones.
        mesh = jax.sharding.Mesh(np.array(jax.devices()[:n_devices]), ("batch",))
        spec, rep = jax.sharding.PartitionSpec("batch"), jax.sharding.PartitionSpec()
        fn = jax.jit(
            jax.shard_map(batched, mesh=mesh, in_specs=(rep, rep, rep, spec, spec),
                          out_specs=(spec, spec), check_vma=False)
        )
    else:
        fn = jax.jit(batched)
    _CACHE[n_devices] = fn
    return fn


def sweep(
    beta,
    z0,
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    settings: Settings | None = None,
    devices: int | None = None,
) -> SweepResult:
    """Run relaxation tests for all (β, z̄0) pairs (arrays broadcast together) in one compiled call.

    All runs share one mesh and one time grid (the default grid resolves the fast time 1/β of any
    β ≲ 10⁵ after a velocity jump). The batch is padded to a multiple of the device count and
    sharded across ``devices`` (default: all of ``jax.devices()``). Failed runs are flagged in
    ``ok`` rather than raised, so one bad corner does not discard a map.

    Example: a regime map over a grid, ``B, Z = np.meshgrid(betas, z0s); sweep(B, Z)``, then
    ``res.force.reshape(*B.shape, -1)``.
    """
    _check_x64()
    b, z = np.broadcast_arrays(np.asarray(beta, np.float64), np.asarray(z0, np.float64))
    b, z = b.ravel(), z.ravel()
    if b.size == 0:
        raise ValueError("sweep needs at least one (beta, z0) pair")
    for name, v in (("beta", b), ("z0", z)):
        if not np.all(np.isfinite(v) & (v > 0)):
            bad = v[~(np.isfinite(v) & (v > 0))][:3]
            raise ValueError(f"{name} values must be finite and > 0, got {bad}")
    n_dev = len(jax.devices()) if devices is None else int(devices)
    if not 1 <= n_dev <= len(jax.devices()):
        raise ValueError(f"devices must be in [1, {len(jax.devices())}], got {devices}")
    plan = make_plan(t_end, history=history, settings=settings)
    pad = (-b.size) % n_dev
    bp = np.concatenate([b, np.full(pad, b[-1])])
    zp = np.concatenate([z, np.full(pad, z[-1])])
    fn = _batched_runner(n_dev)
    args = (plan.disc, plan.coeffs, plan.travel, jnp.asarray(bp), jnp.asarray(zp))
    start = time.perf_counter()
    compiled = fn.lower(*args).compile()
    compile_s = time.perf_counter() - start
    start = time.perf_counter()
    force, film_min = jax.block_until_ready(compiled(*args))
    run_s = time.perf_counter() - start
    force = np.asarray(force)[: b.size]
    film_min = np.asarray(film_min)[: b.size]
    ok = np.all(np.isfinite(force), axis=1) & np.all(film_min > 0, axis=1)
    return SweepResult(b, z, plan.t, force, film_min, ok, compile_s, run_s, n_dev)
