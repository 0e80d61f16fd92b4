"""The stepper toolkit: the pieces :func:`lubjax.relax` is built from, for users who run the
error-controlled loop themselves (fits, custom batches, gradients of anything it returns).

A run is three calls::

    disc = discretise(mesh, substrate)                  # mesh + influence matrix (cached)
    traj = rollout(disc, beta, z0, drive, t_end, Tolerance(...), substrate=substrate)
    force = evaluate(traj.steps, times, "force")        # the stepper's interpolant, traceable

``rollout`` is a pure function of its arguments (``jit``, ``vmap``, ``jvp``/``jacfwd``,
``vjp``/``jax.grad``). ``Settings.mesh()`` and ``Settings.tolerance()`` give the shared mesh
and the tolerance of a :class:`lubjax.Settings` (``relax``'s own mesh: :func:`lubjax.mesh_for`).
"""

from ._controller import Status, Tolerance, stop_reason
from ._discretisation import Discretisation, discretise, displacement, film_thickness
from ._influence import force_weights, influence_matrix, kernel
from ._layer import layer_influence_matrix
from ._loop import State
from ._output import Entry, Trajectory, evaluate, evaluate_host
from ._rollout import rollout

__all__ = [
    "Discretisation",
    "Entry",
    "State",
    "Status",
    "Tolerance",
    "Trajectory",
    "discretise",
    "displacement",
    "evaluate",
    "evaluate_host",
    "film_thickness",
    "force_weights",
    "influence_matrix",
    "kernel",
    "layer_influence_matrix",
    "rollout",
    "stop_reason",
]
