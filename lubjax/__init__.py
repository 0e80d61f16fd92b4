"""lubjax: soft elastohydrodynamic lubrication of a sphere on an elastic half-space, in JAX.

The non-iterative scheme of Liu, Dong, Jagota & Hui, Soft Matter 18 (2022) 1219 (one linear
solve per time step), on a graded mesh with a second-order linearly implicit step whose size
an embedded error estimate controls (``Settings.rtol``).

Importing lubjax enables float64 in JAX (``jax_enable_x64``): the solver refuses to run without it.
"""

import jax

jax.config.update("jax_enable_x64", True)

from . import stepper  # noqa: E402
from ._analytic import (  # noqa: E402
    hertz_displacement,
    hertz_force,
    hertz_pressure,
    rigid_squeeze_force,
    rigid_squeeze_pressure,
)
from ._checks import (  # noqa: E402
    BETA_RANGE,
    LAYER_BASES,
    POISSON_RANGE,
    Z0_RANGE,
    check_parameters,
)
from ._compile_cache import enable_compilation_cache  # noqa: E402
from ._drives import FreeSphere, Load, Spring, Travel, as_drive, restitution  # noqa: E402
from ._indenter import RampHold, SampledTravel  # noqa: E402
from ._layer import layer_thickness_bar  # noqa: E402
from ._mesh import Mesh, graded_mesh, mesh_for, uniform_mesh  # noqa: E402
from ._result import Result  # noqa: E402
from ._settings import Settings  # noqa: E402
from ._shape import Paraboloid, Sphere, sneddon_sphere  # noqa: E402
from ._solve import Plan, SolverError, force_curve, make_plan, relax  # noqa: E402
from ._substrate import HalfSpace, Layer, Viscoelastic  # noqa: E402
from ._sweep import SweepResult, sweep  # noqa: E402
from ._units import (  # noqa: E402
    Collision,
    CreepTest,
    RelaxationTest,
    contact_modulus,
    hertz_indentation,
    modulus_for_beta,
    plane_strain_modulus,
    reduced_radius,
    si_scales,
    spring_stiffness_bar,
)

#: The user API. The stepper toolkit (rollout, discretise, evaluate, ...) is lubjax.stepper.
__all__ = [
    "BETA_RANGE",
    "Collision",
    "CreepTest",
    "FreeSphere",
    "HalfSpace",
    "LAYER_BASES",
    "Layer",
    "Load",
    "Mesh",
    "POISSON_RANGE",
    "Paraboloid",
    "Plan",
    "RampHold",
    "RelaxationTest",
    "Result",
    "SampledTravel",
    "Settings",
    "SolverError",
    "Sphere",
    "Spring",
    "SweepResult",
    "Travel",
    "Viscoelastic",
    "Z0_RANGE",
    "as_drive",
    "check_parameters",
    "contact_modulus",
    "enable_compilation_cache",
    "force_curve",
    "graded_mesh",
    "hertz_displacement",
    "hertz_force",
    "hertz_indentation",
    "hertz_pressure",
    "layer_thickness_bar",
    "make_plan",
    "mesh_for",
    "modulus_for_beta",
    "plane_strain_modulus",
    "reduced_radius",
    "relax",
    "restitution",
    "rigid_squeeze_force",
    "rigid_squeeze_pressure",
    "si_scales",
    "sneddon_sphere",
    "spring_stiffness_bar",
    "stepper",
    "sweep",
    "uniform_mesh",
]
__version__ = "0.1.0"
