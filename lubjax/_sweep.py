"""Batches of relaxation tests in one compiled call, sharded over JAX devices (each device maps
or ``vmap``-s over its pairs: :func:`lubjax._sharding.batching_mode`).

The batch of (β, z̄0) pairs is padded to a multiple of the device count and laid out on a
one-axis device mesh (``NamedSharding(mesh, P("batch"))``); the discretisation, drive, substrate,
t̄_end and output times are replicated (``P()``). One ``jax.jit`` of a ``shard_map`` of the
batched rollout then runs as one SPMD program: each device runs the one-device program on
its slice, so a member's result is bit-identical to the one-device sweep (tests/test_sharding.py)
and a device stops at its own slowest member. It is compiled ahead of time
(``.lower(...).compile()``) so the compile time is reported apart, and cached per device count,
mesh size, drive, output count, tolerance and batch size. The helpers and the reason several
CPU host devices need ``PJRT_NPROC`` > N (jaxlib's batched LAPACK deadlocks a smaller XLA:CPU
pool) are in :mod:`lubjax._sharding`; with one device the call is a plain ``jit``.
"""

from __future__ import annotations

import functools
import time
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from . import _compiler, _sharding
from ._checks import any_traced, check_parameter_arrays
from ._controller import DONE
from ._indenter import RampHold, SampledTravel
from ._output import evaluate
from ._rollout import rollout
from ._settings import Settings
from ._solve import _check_x64, make_plan
from ._threads import single_threaded_blas


class SweepResult(NamedTuple):
    """A flattened batch of runs (:func:`sweep`): ``force[k]`` and ``film_min[k]`` belong to
    ``(beta[k], z0[k])``.

    Attributes:
        beta: β of each run (eq 8e), shape (B,).
        z0: z̄0 = z0/d_c of each run (eq 8e), shape (B,).
        t: the output times t̄ all runs share (units of t_c), shape (T,).
        force: F̄ at ``t`` (units of F_s, eq 11b), shape (B, T), by each run's own
            interpolant.
        film_min: min h̄ at ``t`` (units of d_c), shape (B, T).
        gap: z̄, the sphere's position at ``t`` (units of d_c), shape (B, T) (free under a
            load, a spring or a free sphere).
        ok: whether each run finished, with a positive film at every output time, shape (B,).
        steps: the accepted steps of each run, shape (B,).
        compile_s: wall time of compilation [s] (0 when cached).
        run_s: wall time of the batch's run [s].
        devices: the number of devices the batch was spread over.
    """

    beta: np.ndarray
    z0: np.ndarray
    t: np.ndarray
    force: np.ndarray
    film_min: np.ndarray
    gap: np.ndarray
    ok: np.ndarray
    steps: np.ndarray
    compile_s: float
    run_s: float
    devices: int


def _one(tol, disc, history, substrate, t_end, times, b, z):
    traj = rollout(disc, b, z, history, t_end, tol, substrate=substrate)
    film_min = evaluate(traj.steps, times, "film_min")
    # (the accepted steps' films are positive by the controller; between them the
    # interpolant's need not be)
    ok = (traj.status == DONE) & ~jnp.any(film_min <= 0)
    return (
        evaluate(traj.steps, times, "force"),
        film_min,
        evaluate(traj.steps, times, "gap"),
        ok,
        traj.accepted,
    )


#: _one's arguments after the tolerance: the shared inputs, then β and z̄0 (one per member).
_BATCHED = (False,) * 5 + (True, True)


@functools.lru_cache(maxsize=8)
def _batched(tol, mode: str):
    """The rollout over the β, z̄0 axis: ``vmap``-ed, or one pair after another (``lax.map``,
    ``mode="map"``: each run its own steps; :func:`lubjax._sharding.batching_mode`)."""
    return _sharding.batch(functools.partial(_one, tol), _BATCHED, mode)


_COMPILED: dict = {}


def _compiled_for(tol, args, mesh, mode):
    """AOT-compile once per (device count, mesh size, drive, output count, tolerance, batch
    size); returns (fn, seconds). With a mesh the shared inputs are replicated and β, z̄0 and
    every output split over it: one jit of a shard_map, one SPMD program for all devices
    (lubjax/_sharding.py)."""
    disc, history, substrate, _, times, b, _ = args
    leaves, treedef = jax.tree_util.tree_flatten((history, substrate))
    shapes = tuple(np.shape(x) for x in leaves)
    n_dev = 1 if mesh is None else mesh.size
    key = (n_dev, disc.r.shape[0], treedef, shapes, times.shape[0], tol, b.shape[0], mode)

    def build():
        fn = jax.jit(_sharding.over_batch(_batched(tol, mode), mesh, _BATCHED))
        return _compiler.compile_one(fn.lower(*args))

    return _compiler.cached(_COMPILED, key, build)


def sweep(
    beta,
    z0,
    t_end: float = 5.0,
    *,
    history: RampHold | SampledTravel | None = None,
    drive=None,
    substrate=None,
    settings: Settings | None = None,
    devices: int | None = None,
    times=None,
    batching: str = "auto",
) -> SweepResult:
    """Run relaxation tests for all (β, z̄0) pairs (arrays broadcast together) in one compiled call.

    All runs share one mesh; each takes its own error-controlled steps and reports F̄ and min h̄
    at the shared output ``times`` by its own interpolant. Failed runs are flagged in ``ok``
    rather than raised, so one bad corner does not discard a map.

    Args:
        beta: β (eq 8e), each in [1e-4, 1e9]; an array broadcast with ``z0``.
        z0: z̄0 = z0/d_c, each in [1e-4, 1e3]; an array broadcast with ``beta``.
        t_end: final time t̄ (units of t_c).
        history: the prescribed travel (default ``RampHold()``).
        drive: instead of ``history``, any drive (shared by the batch).
        substrate: ``HalfSpace()`` (default), ``Layer``, ``Viscoelastic``.
        settings: tolerance and mesh (default ``Settings()``).
        devices: the batch is padded to a multiple of the device count and sharded across
            this many devices (default: all of ``jax.devices()``; several CPU host devices
            need ``PJRT_NPROC`` > ``devices``, lubjax/_sharding.py).
        times: the shared output times t̄ (units of t_c; default 501 equally spaced).
        batching: how each device runs its pairs, "map" (one after another, the default on
            CPU), "vmap" (all at once, the default on an accelerator; the batch then runs
            until its slowest member is done) or "auto".

    Returns:
        SweepResult: the flattened pairs, ``t``, ``force``, ``film_min`` and ``gap``
        of shape (pairs, times), ``ok`` and the accepted steps per pair, the compile and run
        times.

    Raises:
        ValueError: no pairs, a β or z̄0 out of range, or an unknown ``batching`` (the message
            names the parameter).
        TypeError: ``beta`` or ``z0`` traced (under ``jit``, ``vmap`` or a derivative: the
            message names ``force_curve`` and ``relax``, which are).

    Example:
        A regime map over a grid: ``B, Z = np.meshgrid(betas, z0s); sweep(B, Z)``, then
        ``res.force.reshape(*B.shape, -1)``.

        ```python
        import lubjax
        import numpy as np

        B, Z = np.meshgrid([10.0, 100.0], [0.5, 1.0])
        res = lubjax.sweep(B, Z, 1.0, times=np.linspace(0.0, 1.0, 11),
                           settings=lubjax.Settings(rtol=1e-3, error_estimate=False))
        force = res.force.reshape(*B.shape, -1)  # (z0s, betas, times)
        assert res.ok.all() and force.shape == (2, 2, 11)
        ```
    """
    _check_x64()
    if any_traced((beta, z0)):
        # (sweep compiles and times its own program on concrete pairs; the transformable
        # batch is jax.vmap of force_curve or relax, which the guide shows)
        raise TypeError(
            "sweep takes concrete (beta, z0) arrays: it compiles, shards and times its own "
            "program. Under jit, vmap or a derivative use jax.vmap(lambda b, z: "
            "lubjax.force_curve(plan, b, z)) with lubjax.make_plan, or jax.vmap of lubjax.relax")
    b, z = np.broadcast_arrays(np.asarray(beta, np.float64), np.asarray(z0, np.float64))
    b, z = b.ravel(), z.ravel()
    if b.size == 0:
        raise ValueError("sweep needs at least one (beta, z0) pair")
    check_parameter_arrays(b, z)
    mode = _sharding.batching_mode(batching)
    n_dev = _sharding.device_count(devices)
    plan = make_plan(
        t_end, history=history, drive=drive, substrate=substrate, settings=settings, times=times
    )
    # Pad to a multiple of the device count (a sharded axis splits evenly); cut off below.
    pad = _sharding.padding(b.size, n_dev)
    bp, zp = _sharding.pad_leading((b, z), pad)
    mesh = _sharding.batch_mesh(n_dev)
    args = (
        *_sharding.replicate((plan.disc, plan.drive, plan.substrate, plan.t_end, plan.t), mesh),
        *_sharding.shard_batch((bp, zp), mesh),
    )
    # Cached across calls; compile time reported apart (0 when cached).
    compiled, compile_s = _compiled_for(plan.tol, args, mesh, mode)
    start = time.perf_counter()
    with single_threaded_blas():
        outs = jax.block_until_ready(compiled(*args))
    run_s = time.perf_counter() - start
    force, film_min, gap, ok, steps = (
        _sharding.to_host(o)[: b.size] for o in outs
    )
    return SweepResult(b, z, plan.t, force, film_min, gap, ok, steps, compile_s, run_s, n_dev)
