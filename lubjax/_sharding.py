"""Split a batch axis over JAX devices with ``jax.sharding`` (shared by ``sweep`` and the fits).

A batch (a sweep's (β, z̄0) pairs, a batched fit's traces) is one ``jit`` of a batched function
(:func:`batching_mode`). On several devices its leading axis is laid out over a one-axis
:class:`jax.sharding.Mesh` (``"batch"``), padded to a multiple of the device count, the shared
inputs replicated, and the call is one ``jit`` of a ``jax.shard_map`` (:func:`over_batch`).
With one device :func:`batch_mesh` returns None: one unsharded call. Several CPU host devices
need ``PJRT_NPROC`` above the device count, else jaxlib's batched LAPACK kernels deadlock on
XLA:CPU's pool (docs/guide/sweeps.md, "Several devices"): :func:`batch_mesh` refuses them.
Several hosts (``jax.distributed.initialize()``) share one mesh; untested on a cluster.
"""

from __future__ import annotations

import contextvars
import os

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

AXIS = "batch"


def device_count(devices: int | None) -> int:
    """The number of devices to use: all of ``jax.devices()`` by default, else ``devices``
    (checked to be in [1, len(jax.devices())])."""
    available = len(jax.devices())
    n = available if devices is None else int(devices)
    if not 1 <= n <= available:
        raise ValueError(f"devices must be in [1, {available}], got {devices}")
    return n


def host_pool_size() -> int:
    """Threads of XLA:CPU's intra-op pool: ``PJRT_NPROC`` (or ``NPROC``) if set, else the
    schedulable cores (what the CPU client reads when it is created)."""
    for name in ("PJRT_NPROC", "NPROC"):
        value = os.environ.get(name, "")
        if value.strip().isdigit():
            return int(value)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()


def batch_mesh(n_devices: int) -> Mesh | None:
    """A one-axis mesh over the first ``n_devices`` devices; None for one device (unsharded).

    Raises RuntimeError for several CPU devices on an intra-op pool of at most as many threads
    (it would deadlock, see the module docstring)."""
    if n_devices == 1:
        return None
    pool = host_pool_size()
    if jax.devices()[0].platform == "cpu" and pool <= n_devices:
        raise RuntimeError(
            f"{n_devices} CPU devices on an XLA:CPU thread pool of {pool} threads would "
            f"deadlock in jaxlib's batched LAPACK kernels; set PJRT_NPROC={n_devices + 1} (or "
            f"more) in the environment before JAX starts, or pass devices=1"
        )
    return Mesh(np.array(jax.devices()[:n_devices]), (AXIS,))


#: How each device evaluates its part of a batch (sweeps, batched fits): "map" (one member
#: after another, ``lax.map``) or "vmap" (all at once). "auto": "map" on CPU, "vmap" on an
#: accelerator.
BATCHING = ("auto", "map", "vmap")


#: The mode a batch asked for by name is traced under (:func:`batch`): a run inside it that
#: meets ``vmap`` (lubjax/_rollout.py) batches as asked, not as "auto" would.
_ASKED: contextvars.ContextVar[str] = contextvars.ContextVar("lubjax_batching", default="auto")


def batching_mode(batching: str = "auto") -> str:
    """``"map"`` or ``"vmap"`` for ``batching`` (see :data:`BATCHING`; docs/design.md,
    "Differentiation and batching", says why CPU maps). "auto" inside a :func:`batch` that
    asked for "vmap" is "vmap"."""
    if batching not in BATCHING:
        raise ValueError(f"batching must be one of {', '.join(BATCHING)}, got {batching!r}")
    if batching == "auto":
        batching = _ASKED.get()
    if batching == "auto":
        return "map" if jax.default_backend() == "cpu" else "vmap"
    return batching


def batch(fn, batched: tuple[bool, ...], mode: str):
    """``fn`` of one member over a leading batch axis of the positional arguments marked in
    ``batched`` (the others shared): ``jax.vmap`` for ``mode="vmap"``, a ``lax.map`` (one member
    after another, each with its own adaptive steps) for ``"map"``."""
    if mode == "vmap":
        vmapped = jax.vmap(fn, in_axes=tuple(0 if b else None for b in batched))

        def all_at_once(*args):
            token = _ASKED.set("vmap")
            try:
                return vmapped(*args)
            finally:
                _ASKED.reset(token)

        return all_at_once

    def mapped(*args):
        def one(members):
            rest = iter(members)
            return fn(*(next(rest) if b else a for a, b in zip(args, batched, strict=True)))

        return jax.lax.map(one, tuple(a for a, b in zip(args, batched, strict=True) if b))

    return mapped


def over_batch(fn, mesh: Mesh | None, batched: tuple[bool, ...]):
    """``fn`` (a batched function of positional arguments, batched where ``batched`` says)
    as one SPMD function over the mesh: each device applies ``fn`` to its slice of the batch
    and the replicated rest (``jax.shard_map``), every output split along its leading axis.
    Unchanged without a mesh. Wrap the result in ``jax.jit``."""
    if mesh is None:
        return fn
    specs = tuple(P(AXIS) if b else P() for b in batched)
    # check_vma=False: the body has no collectives, and its while_loops start from replicated
    # constants that become per-device values, which the varying-axes type check rejects.
    return jax.shard_map(fn, mesh=mesh, in_specs=specs, out_specs=P(AXIS), check_vma=False)


def padding(size: int, n_devices: int) -> int:
    """How many members to append so that ``size`` splits evenly over the devices."""
    return (-size) % n_devices


def pad_leading(tree, pad: int):
    """Append ``pad`` copies of the last member along the leading axis of every leaf."""
    if pad == 0:
        return tree

    def one(x):
        x = np.asarray(x)
        return np.concatenate([x, np.repeat(x[-1:], pad, axis=0)])

    return jax.tree_util.tree_map(one, tree)


def batch_sharding(mesh: Mesh) -> NamedSharding:
    """Leading axis split over the mesh, the rest of each array whole on every device."""
    return NamedSharding(mesh, P(AXIS))


def replicated(mesh: Mesh) -> NamedSharding:
    """The whole array on every device."""
    return NamedSharding(mesh, P())


def _put(tree, sharding):
    # From host data alike on every process, device_put also builds multi-process arrays.
    return jax.device_put(tree, sharding)


def shard_batch(tree, mesh: Mesh | None):
    """Put a batch (leading axis) over the mesh; unchanged without a mesh."""
    return tree if mesh is None else _put(tree, batch_sharding(mesh))


def replicate(tree, mesh: Mesh | None):
    """Put shared inputs on every device of the mesh; unchanged without a mesh."""
    return tree if mesh is None else _put(tree, replicated(mesh))


def to_host(x) -> np.ndarray:
    """A (possibly sharded) result as one NumPy array on this process."""
    if jax.process_count() > 1 and not x.is_fully_addressable:
        from jax.experimental import multihost_utils

        return np.asarray(multihost_utils.process_allgather(x, tiled=True))
    return np.asarray(x)
