"""lubjax: soft elastohydrodynamic lubrication of a sphere on an elastic half-space, in JAX.

The non-iterative scheme of Liu, Dong, Jagota & Hui, Soft Matter 18 (2022) 1219 (one linear
solve per time step), on a graded mesh with a second-order linearly implicit step whose size
an embedded error estimate controls (``Settings.rtol``).

Importing lubjax enables float64 in JAX (``jax_enable_x64``): the solver refuses to run without it.
"""

import jax

jax.config.update("jax_enable_x64", True)

from ._analytic import (  # noqa: E402
    hertz_displacement,
    hertz_force,
    hertz_pressure,
    rigid_squeeze_force,
    rigid_squeeze_pressure,
)
from ._compile_cache import enable_compilation_cache  # noqa: E402
from ._controller import Tolerance  # noqa: E402
from ._discretisation import (  # noqa: E402
    Discretisation,
    discretise,
    displacement,
    film_thickness,
)
from ._drives import FreeSphere, Load, Spring, Travel, as_drive, restitution  # noqa: E402
from ._indenter import RampHold, SampledTravel  # noqa: E402
from ._influence import force_weights, influence_matrix, kernel  # noqa: E402
from ._layer import layer_influence_matrix, layer_thickness_bar  # noqa: E402
from ._mesh import Mesh, graded_mesh, uniform_mesh  # noqa: E402
from ._rollout import State, Step, Trajectory, evaluate, rollout  # noqa: E402
from ._solve import (  # noqa: E402
    BETA_RANGE,
    Z0_RANGE,
    Plan,
    Result,
    Settings,
    SolverError,
    check_parameters,
    force_curve,
    make_plan,
    relax,
)
from ._substrate import HalfSpace, Layer, Viscoelastic  # noqa: E402
from ._sweep import SweepResult, sweep  # noqa: E402
from ._units import (  # noqa: E402
    Collision,
    CreepTest,
    RelaxationTest,
    contact_modulus,
    hertz_indentation,
    plane_strain_modulus,
    reduced_radius,
)

__all__ = [
    "BETA_RANGE",
    "Collision",
    "CreepTest",
    "Z0_RANGE",
    "Discretisation",
    "FreeSphere",
    "HalfSpace",
    "Layer",
    "Load",
    "Mesh",
    "Plan",
    "RampHold",
    "RelaxationTest",
    "Result",
    "SampledTravel",
    "Settings",
    "SolverError",
    "Spring",
    "State",
    "Step",
    "SweepResult",
    "Tolerance",
    "Trajectory",
    "Travel",
    "Viscoelastic",
    "as_drive",
    "check_parameters",
    "contact_modulus",
    "discretise",
    "displacement",
    "enable_compilation_cache",
    "evaluate",
    "film_thickness",
    "force_curve",
    "force_weights",
    "graded_mesh",
    "hertz_displacement",
    "hertz_force",
    "hertz_indentation",
    "hertz_pressure",
    "influence_matrix",
    "kernel",
    "layer_influence_matrix",
    "layer_thickness_bar",
    "make_plan",
    "plane_strain_modulus",
    "reduced_radius",
    "relax",
    "rigid_squeeze_force",
    "restitution",
    "rigid_squeeze_pressure",
    "rollout",
    "sweep",
    "uniform_mesh",
]
__version__ = "0.1.0"
