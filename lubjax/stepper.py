"""The stepper toolkit: the pieces :func:`lubjax.relax` is built from, for users who run the
error-controlled loop themselves (fits, custom batches, gradients of anything it returns).

A run is three calls::

    disc = discretise(mesh, substrate)                  # mesh + influence matrix (cached)
    traj = rollout(disc, beta, z0, drive, t_end, Tolerance(...), substrate=substrate)
    force = evaluate(traj.steps, times, "force")        # the stepper's interpolant, traceable

``rollout`` is a pure function of its arguments (``jit``, ``vmap``, ``jvp``/``jacfwd``,
``vjp``/``jax.grad``). The mesh a run of :func:`lubjax.relax` gets is
:func:`lubjax.mesh_for`; ``Settings.mesh()`` and ``Settings.tolerance()`` give the shared mesh and
the tolerance of a :class:`lubjax.Settings`.

Contents:

* the loop: :func:`rollout`, its :class:`State`, one output entry per attempt :class:`Entry`, the
  whole :class:`Trajectory`, :func:`evaluate` (a field at any times) and the controller's
  :class:`Tolerance`;
* the discretisation: :class:`Discretisation`, :func:`discretise`, :func:`film_thickness`
  (h̄ = z̄ + r̄²/2 - w̄), :func:`displacement` (w̄ = -Ŵp̄);
* the elastic kernels: :func:`kernel`, :func:`influence_matrix` (half-space),
  :func:`layer_influence_matrix` (a layer on a rigid base), :func:`force_weights`
  (F̄ = c·p̄, eq 11b).
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
