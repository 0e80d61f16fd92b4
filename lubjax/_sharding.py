"""Split a batch axis over JAX devices with ``jax.sharding`` (shared by ``sweep`` and the fits).

A batch (the (β, z̄0) pairs of a sweep, the traces of a batched fit) is one ``jit`` of a
batched function: ``lax.map``-ed on CPU, ``vmap``-ed on accelerators (:func:`batching_mode`).
To run it on several devices the leading axis of the per-member inputs is
laid out over a one-axis :class:`jax.sharding.Mesh` (``"batch"``) with
``NamedSharding(mesh, P("batch"))`` and everything the members share (the discretisation, the
drive, the output times) is replicated (``NamedSharding(mesh, P())``). The call is one
``jit`` of a ``jax.shard_map`` of the batched function (:func:`over_batch`): one SPMD program
in which every device runs the one-device program on its slice. No hand-written per-device
loop; on accelerators the slices run concurrently.

``shard_map`` rather than a plain ``jit`` left to the SPMD partitioner (which also works, and
was tried first): the partitioner turns the ``vmap``-ed adaptive ``while_loop``'s condition
(the batch runs until its slowest member is done) into an all-reduce of one boolean per
iteration, so every device runs until the globally slowest member is done. Under ``shard_map``
there is no cross-device step at all, each device stops at its own slowest member, and a
member's result depends only on the members that share its device: a sweep's forces come out
bit-identical to the one-device sweep. (The fit's forward-mode model compiled this way rounds
differently from its one-device compilation when a device holds two or more traces, which can
flip an accept/reject decision at the model's tolerance; tests/test_sharding.py.)

The batch is padded to a multiple of the device count (by repeating the last member; the padded
rows are cut off again), since a sharded axis must split evenly.

Host devices (CPU, e.g. ``XLA_FLAGS=--xla_force_host_platform_device_count=N``): the devices'
programs run concurrently on XLA:CPU's one intra-op thread pool, whose size is the number of
schedulable cores unless the environment variable ``PJRT_NPROC`` (read once, when JAX creates
its CPU client) says otherwise. In jaxlib 0.10.2 the batched LAPACK kernels (the stepper's LU,
``lapack_dgetrf_ffi``) split their batch over that same pool and block until the pieces are
done (``jax::ParallelBatchMap`` → ``BlockingCounter::Wait``). With N device programs on a
pool of at most N threads every thread ends up waiting for pieces that no free thread can run:
a deadlock at 0 % CPU (gdb on a hung 2-device sweep on 2 cores: both ``tf_XLAEigen`` threads in
``BlockingCounter::Wait`` under ``lapack_dgetrf_ffi``). That is why the SPMD version once "hung"
on forced host devices, and most likely also the "concurrent single-threaded OpenBLAS"
deadlock of the old per-device loop: OpenBLAS is not involved, ``threadpoolctl`` and
``--xla_cpu_multi_thread_eigen=false`` change nothing, ``PJRT_NPROC=N+1`` (one thread more than
device programs) removes it. A per-device batch of one member does not fan out and does not
hang. :func:`batch_mesh` therefore refuses several host devices on a pool that is too small
instead of hanging. Accelerators do not run LAPACK on the host pool.

With one device (the default on a plain CPU) :func:`batch_mesh` returns ``None`` and the callers
run exactly as before: one unsharded ``jit`` call.

Several hosts: after ``jax.distributed.initialize()`` on every process, ``jax.devices()`` lists
the devices of all hosts and the same mesh spans them: ``jax.device_put`` builds the global
arrays from host data that every process passes alike, and :func:`to_host` gathers the results
back to every process. This path was not tested here, for want of a cluster.
"""

from __future__ import annotations

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


def batching_mode(batching: str = "auto") -> str:
    """``"map"`` or ``"vmap"`` for ``batching`` (see :data:`BATCHING`).

    Why not vmap on CPU: every member of a vmap-ed adaptive ``while_loop`` runs until the
    batch's slowest member is done, and every ``lax.cond`` in the step (accept/reject,
    restarts) becomes a select that computes both branches; on CPU the batched LU gains nothing
    from the batch (it is a loop of LAPACK calls). A sequential ``lax.map`` lets each member take
    its own steps (and a fit skip the traces whose fit has ended). An accelerator is the other
    way round: there the batch is what fills the device.
    """
    if batching not in BATCHING:
        raise ValueError(f"batching must be one of {', '.join(BATCHING)}, got {batching!r}")
    if batching == "auto":
        return "map" if jax.default_backend() == "cpu" else "vmap"
    return batching


def batch(fn, batched: tuple[bool, ...], mode: str):
    """``fn`` of one member over a leading batch axis of the positional arguments marked in
    ``batched`` (the others shared): ``jax.vmap`` for ``mode="vmap"``, a ``lax.map`` (one member
    after another, each with its own adaptive steps) for ``"map"``."""
    if mode == "vmap":
        return jax.vmap(fn, in_axes=tuple(0 if b else None for b in batched))

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
    Unchanged without a mesh. Wrap the result in ``jax.jit``.

    ``shard_map`` rather than letting the partitioner split a plain ``jit``: each device then
    runs exactly the single-device program on its slice (no cross-device step inside, not even
    the all-reduce of the ``while_loop``'s condition, so a device stops at its own slowest
    member), and a member's result depends only on the members that share its device."""
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
    # From host data, device_put also builds arrays that span several processes (each must pass
    # the same values; the inputs here are small and built identically everywhere).
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
