r"""The indenter's shape: the rigid gap profile s(r̄) in h̄ = z̄ + s(r̄) - w̄, and the radius of the
dry contact a depth presses.

* :class:`Paraboloid` (the default, the paper's): s = r̄²/2, Hertz's contact ā = √δ̄; a sphere
  while depth and gap are ≪ R (``MAX_TRAVEL_OVER_RADIUS``).
* :class:`Sphere`: the true profile s = (1 - √(1 - ε r̄²))/ε, ε = d_c/R, written
  r̄²/(1 + √(1 - ε r̄²)) to stay exact as ε → 0; Sneddon's dry contact δ = a artanh(a/R); for
  δ/R up to ~1 (``MAX_SPHERE_TRAVEL_OVER_RADIUS``). Only the rigid gap changes (docs/model.md,
  "The sphere's true profile").
"""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp
import numpy as np
from scipy.optimize import brentq

from ._checks import MAX_SPHERE_TRAVEL_OVER_RADIUS, any_traced, check_number
from ._pytree import register


@dataclasses.dataclass(frozen=True)
class Paraboloid:
    """The paraboloid s(r̄) = r̄²/2 (eq 8a): a sphere while depth and gap are ≪ R."""

    def profile(self, r):
        """The rigid gap profile.

        Args:
            r: r̄, radii (units of √(R d_c)); an array.

        Returns:
            s(r̄) = r̄²/2 (units of d_c), shaped as ``r``.
        """
        return 0.5 * r**2

    def contact_radius(self, depth: float) -> float:
        """Hertz's dry contact radius.

        Args:
            depth: δ̄, the indentation depth (units of d_c), ≥ 0.

        Returns:
            ā = √δ̄ (units of √(R d_c)).
        """
        return math.sqrt(depth)

    def depth_under_load(self, load: float) -> float:
        """Hertz's dry indentation under a load.

        Args:
            load: F̄ ≥ 0 (units of F_s).

        Returns:
            δ̄ = (3F̄/(2π))^{2/3} (units of d_c).
        """
        return (3.0 * max(load, 0.0) / (2.0 * math.pi)) ** (2.0 / 3.0)


@dataclasses.dataclass(frozen=True)
class Sphere:
    """The sphere's true profile, for indentation deeper than the paraboloid allows.

    Attributes:
        epsilon: ε = d_c/R, the depth scale over the sphere's radius (dimensionless), in
            [0, ``MAX_SPHERE_TRAVEL_OVER_RADIUS``]; 0 is the paraboloid. A JAX leaf: ``jit``,
            ``vmap`` and ``grad`` see it.

    Raises:
        ValueError: ``epsilon`` out of range.
    """

    epsilon: float

    def __post_init__(self):
        if not any_traced(self.epsilon):
            check_number("epsilon (d_c/R)", self.epsilon, 0.0, MAX_SPHERE_TRAVEL_OVER_RADIUS)
            object.__setattr__(self, "epsilon", float(self.epsilon))

    def profile(self, r):
        """The rigid gap profile, s(r̄) = r̄²/(1 + √(1 - ε r̄²)) up to the equator r̄ = 1/√ε,
        beyond it r̄²/2 + 1/(2ε) (a gap ≳ R carries no pressure; a finite one growing as r̄²
        suits the graded mesh and the pressure's weight).

        Args:
            r: r̄, radii (units of √(R d_c)); an array (a JAX one under ``jit``).

        Returns:
            s(r̄) (units of d_c), shaped as ``r``.
        """
        xp = jnp if any_traced((self.epsilon, r)) else np
        eps = self.epsilon
        under = 1.0 - eps * r**2
        beyond = under <= 0.0
        # both branches finite everywhere, so that a derivative through the other is 0, not NaN
        on_sphere = r**2 / (1.0 + xp.sqrt(xp.where(beyond, 1.0, under)))
        past = 0.5 * r**2 + 0.5 / xp.where(beyond, eps, 1.0)
        return xp.where(beyond, past, on_sphere)

    def contact_radius(self, depth: float) -> float:
        """Sneddon's dry contact radius: the root of δ/R = (a/R) artanh(a/R).

        Args:
            depth: δ̄, the indentation depth (units of d_c), ≥ 0.

        Returns:
            ā = a/√(R d_c); → √δ̄ (Hertz's) as ε δ̄ → 0.
        """
        target = self.epsilon * depth
        if target <= 0.0:
            return math.sqrt(max(depth, 0.0))
        x = brentq(lambda x: x * math.atanh(x) - target, 0.0, 1.0 - 1e-15, xtol=1e-15)
        return x / math.sqrt(self.epsilon)

    def depth_under_load(self, load: float) -> float:
        """Sneddon's dry indentation under a load: F̄ = (π/2) ε^{-3/2} F/(E* R²) with F/(E* R²)
        of :func:`sneddon_sphere` (F_s = (2/π) E* √R d_c^{3/2}), solved for a/R.

        Args:
            load: F̄ ≥ 0 (units of F_s).

        Returns:
            δ̄ (units of d_c); → Hertz's (3F̄/(2π))^{2/3} as ε → 0, deeper at finite ε.
        """
        if self.epsilon <= 0.0 or load <= 0.0:
            return Paraboloid().depth_under_load(load)
        target = load * self.epsilon**1.5 * 2.0 / math.pi
        x = brentq(lambda x: float(sneddon_sphere(x)[1]) - target, 0.0, 1.0 - 1e-12, xtol=1e-15)
        return float(sneddon_sphere(x)[0]) / self.epsilon


def as_indenter(indenter):
    """``indenter``, or the :class:`Paraboloid` for None.

    Args:
        indenter: None, ``Paraboloid()`` or ``Sphere(ε)``.

    Returns:
        The shape.

    Raises:
        TypeError: not a shape.
    """
    if indenter is None:
        return Paraboloid()
    if isinstance(indenter, (Paraboloid, Sphere)):
        return indenter
    raise TypeError(
        "indenter must be lubjax.Paraboloid() or lubjax.Sphere(d_c/R), "
        f"got {type(indenter).__name__}"
    )


def sneddon_sphere(a_over_r):
    """Sneddon's rigid sphere on the elastic half-space (dry, frictionless), in units of R:
    (δ/R, F/(E* R²)) at the contact radius a/R ∈ [0, 1):

        δ = (a/2) ln((R + a)/(R - a)),
        F = (E*/2) [(a² + R²) ln((R + a)/(R - a)) - 2aR],

    E* the plane-strain modulus. As a/R → 0: δ → a²/R and F → (4/3) E* a³/R, Hertz's.

    Args:
        a_over_r: a/R, the contact radius over the sphere's, in [0, 1); an array.

    Returns:
        tuple: δ/R and F/(E* R²), two float64 arrays shaped as ``a_over_r``.
    """
    a = np.asarray(a_over_r, np.float64)
    log = np.log1p(a) - np.log1p(-a)
    return 0.5 * a * log, 0.5 * ((a**2 + 1.0) * log - 2.0 * a)


register(Paraboloid)
register(Sphere, ("epsilon",))
