"""The dimensional layer: SI inputs to β, z̄0 and the scales of eqs 7, 8e and 11b."""

from __future__ import annotations

import dataclasses
import math

import jax.numpy as jnp

from ._checks import (
    INDENTERS,
    check_choice,
    check_poisson,
    check_quantity,
    is_traced,
    travel_over_radius_problem,
)


def _sqrt(x):
    """√x: ``math.sqrt`` for a number, ``jnp.sqrt`` for a traced value (a derivative in an SI
    quantity is being taken), so the numbers stay those of ``math``."""
    return jnp.sqrt(x) if is_traced(x) else math.sqrt(x)


def _check_fields(obj, fields) -> None:
    """Validate and store each (name, unit) field of a frozen dataclass as a positive float."""
    for name, unit in fields:
        object.__setattr__(obj, name, check_quantity(name, getattr(obj, name), unit))


def si_scales(E_star, radius, d_c, *, t_c=None, speed=None, viscosity=None) -> dict:
    """The SI scales of the dimensionless variables (eqs 7, 8e and 11b) of one scene.

    Args:
        E_star: E*, plane-strain (or reduced, eq 24) modulus [Pa].
        radius: R, sphere (or reduced, eq 24) radius [m].
        d_c: d_c, the depth scale [m] (h, z, w are in units of d_c).
        t_c: t_c, the time scale [s]; give exactly one of ``t_c`` and ``speed``.
        speed: v = d_c/t_c [m/s], instead of ``t_c``.
        viscosity: η, film viscosity [Pa s]; with it the result also holds β.

    Returns:
        dict: ``time_s`` (t = t_c t̄), ``length_m`` (r = √(R d_c) r̄), ``gap_m`` (d_c),
        ``pressure_Pa`` ((2E*/π) √(d_c/R), eq 7), ``force_N`` (F_s = 2E* d_c^{3/2} √R/π,
        eq 11b) and, with a ``viscosity``, ``beta`` = E* d_c^{5/2}/(6π η v R^{3/2}) (eq 8e).

    Raises:
        ValueError: neither or both of ``t_c`` and ``speed``.
    """
    if (t_c is None) == (speed is None):
        raise ValueError("si_scales needs exactly one of t_c and speed")
    out = {
        "time_s": d_c / speed if t_c is None else t_c,
        "length_m": _sqrt(radius * d_c),
        "gap_m": d_c,
        "pressure_Pa": 2 * E_star / math.pi * _sqrt(d_c / radius),
        "force_N": 2 * E_star * d_c**1.5 * _sqrt(radius) / math.pi,
    }
    if viscosity is not None:
        if speed is not None:
            out["beta"] = E_star * d_c**2.5 / (6 * math.pi * viscosity * speed * radius**1.5)
        else:
            out["beta"] = E_star * d_c**1.5 * t_c / (6 * math.pi * viscosity * radius**1.5)
    return out


def modulus_for_beta(beta, radius, d_c, *, speed, viscosity) -> float:
    """Eq 8e solved for the modulus: E* = 6π β η v R^{3/2}/d_c^{5/2}.

    Args:
        beta: β, dimensionless (eq 8e).
        radius: R, sphere radius [m].
        d_c: d_c, the depth scale [m].
        speed: v, approach speed [m/s].
        viscosity: η, film viscosity [Pa s].

    Returns:
        E* [Pa].
    """
    return beta * 6 * math.pi * viscosity * speed * radius**1.5 / d_c**2.5


def spring_stiffness_bar(k, E_star, radius, d_c) -> float:
    """A spring's stiffness in the units F_s/d_c of :class:`lubjax.Spring` (F_s of eq 11b).

    Args:
        k: k, spring stiffness [N/m].
        E_star: E*, plane-strain modulus [Pa].
        radius: R, sphere radius [m].
        d_c: d_c, the depth scale [m].

    Returns:
        K̄ = π k/(2E*√(R d_c)), dimensionless.
    """
    return math.pi * k / (2 * E_star * _sqrt(radius * d_c))


def plane_strain_modulus(E: float, poisson_ratio: float) -> float:
    """The plane-strain modulus E* = E/(1 - ν²) (docs/model.md, Physics).

    Args:
        E: E, Young's modulus [Pa], > 0.
        poisson_ratio: ν, Poisson's ratio, dimensionless, in ``POISSON_RANGE``.

    Returns:
        E* [Pa].

    Raises:
        ValueError: E not a positive finite number or ν out of range.
    """
    E = check_quantity("E", E, "Pa")
    nu = check_poisson("poisson_ratio", poisson_ratio)
    return E / (1.0 - nu**2)


def contact_modulus(E1: float, nu1: float, E2: float = math.inf, nu2: float = 0.0) -> float:
    """The reduced modulus of two elastic bodies, eq 24: 1/E* = (1-ν1²)/E1 + (1-ν2²)/E2.

    Args:
        E1: E1, Young's modulus of the substrate [Pa], > 0.
        nu1: ν1, its Poisson's ratio, dimensionless, in ``POISSON_RANGE``.
        E2: E2, Young's modulus of the indenter [Pa], > 0; infinity (default) for a rigid one.
        nu2: ν2, its Poisson's ratio, in ``POISSON_RANGE`` (ignored for a rigid indenter).

    Returns:
        E* [Pa].

    Raises:
        ValueError: a modulus not positive and finite, or a Poisson's ratio out of range.
    """
    E1 = check_quantity("E1", E1, "Pa")
    nu1 = check_poisson("nu1", nu1)
    nu2 = check_poisson("nu2", nu2)
    inv = (1 - nu1**2) / E1
    if not math.isinf(E2):
        inv += (1 - nu2**2) / check_quantity("E2", E2, "Pa")
    return 1.0 / inv


def reduced_radius(R1: float, R2: float = math.inf) -> float:
    """The reduced radius of two spheres, eq 24: 1/R = 1/R1 + 1/R2.

    Args:
        R1: R1, radius of the first sphere [m], > 0.
        R2: R2, radius of the second [m], > 0; infinity (default) for a sphere on a flat.

    Returns:
        R [m].

    Raises:
        ValueError: a radius not positive and finite.
    """
    R1 = check_quantity("R1", R1, "m")
    if math.isinf(R2):
        return R1
    return 1.0 / (1.0 / R1 + 1.0 / check_quantity("R2", R2, "m"))


class _Scene:
    """What every SI scene derives from its ``_si_scales()`` (:func:`si_scales`)."""

    def _si_scales(self) -> dict:
        raise NotImplementedError

    def _check_indenter(self, **lengths) -> None:
        """Check ``indenter`` and each of ``lengths`` (name: metres) against its limit."""
        check_choice("indenter", self.indenter, INDENTERS)
        for name, value in lengths.items():
            problem = travel_over_radius_problem(name, value, self.radius, self.indenter,
                                                 "radius")
            if problem:
                raise ValueError(problem)

    @property
    def shape(self):
        """The shape :func:`lubjax.relax` takes (``indenter=``): ``Paraboloid()``, or for
        ``indenter="sphere"`` ``Sphere(d_c/R)`` with this scene's depth scale d_c."""
        from ._shape import Paraboloid, Sphere

        if self.indenter == "sphere":
            return Sphere(self.scales["gap_m"] / self.radius)
        return Paraboloid()

    @property
    def scales(self) -> dict:
        """The scales the scene reports (time, length, gap, pressure, force), β apart."""
        return {k: v for k, v in self._si_scales().items() if k != "beta"}

    @property
    def beta(self) -> float:
        """β = E* d_c^{5/2} / (6π η v R^{3/2}) with v = d_c/t_c, eq 8e."""
        return self._si_scales()["beta"]

    @property
    def length_scale(self) -> float:
        """√(R d_c) [m]: r = √(R d_c) r̄ (h, z, w scale with d_c)."""
        return self.scales["length_m"]

    @property
    def pressure_scale(self) -> float:
        """p = (2E*/π) √(d_c/R) p̄ [Pa], eq 7f."""
        return self.scales["pressure_Pa"]

    @property
    def force_scale(self) -> float:
        """F = (2 E* d_c^{3/2} √R / π) F̄ [N], eq 11b."""
        return self.scales["force_N"]


@dataclasses.dataclass(frozen=True)
class RelaxationTest(_Scene):
    """A relaxation test in SI units (eq 5): gap z0, pushed at speed v0 by d_c, then held.

    Attributes:
        E_star: plane-strain (or reduced, eq 24) modulus E* [Pa].
        radius: sphere (or reduced, eq 24) radius R [m].
        viscosity: film viscosity η [Pa s].
        speed: approach speed v0 [m/s].
        indent: travel d_c [m].
        gap: initial gap z0 [m].
        indenter: "paraboloid" (default, eq 8a: d_c, z0 ≪ R) or "sphere" (its true profile,
            for deep indentation; ``shape``).

    Raises:
        ValueError: a value not positive and finite, an unknown ``indenter``, or ``indent``
            or ``gap`` beyond the indenter's limit (0.2 R for the paraboloid, the message
            naming the sphere; R for the sphere).
    """

    E_star: float
    radius: float
    viscosity: float
    speed: float
    indent: float
    gap: float
    indenter: str = "paraboloid"

    def __post_init__(self):
        _check_fields(
            self,
            [
                ("E_star", "Pa"),
                ("radius", "m"),
                ("viscosity", "Pa s"),
                ("speed", "m/s"),
                ("indent", "m"),
                ("gap", "m"),
            ],
        )
        self._check_indenter(indent=self.indent, gap=self.gap)

    @classmethod
    def from_E(cls, E: float, poisson_ratio: float, **kw) -> RelaxationTest:
        """The test on a substrate of Young's modulus E and Poisson's ratio ν.

        Args:
            E: E, Young's modulus [Pa], > 0.
            poisson_ratio: ν, Poisson's ratio, dimensionless, in ``POISSON_RANGE``.
            **kw: the other fields (``radius``, ``viscosity``, ``speed``, ``indent``, ``gap``).

        Returns:
            RelaxationTest: the test, with E* = E/(1 - ν²).

        Raises:
            ValueError: a value out of its range (the message names it).
        """
        return cls(E_star=plane_strain_modulus(E, poisson_ratio), **kw)

    def _si_scales(self) -> dict:
        return si_scales(self.E_star, self.radius, self.indent, speed=self.speed,
                         viscosity=self.viscosity)

    @property
    def z0_bar(self) -> float:
        """z̄0 = z0/d_c, eq 8f."""
        return self.gap / self.indent

    @property
    def time_scale(self) -> float:
        """t_c = d_c/v0 [s]: t = t_c t̄."""
        return self._si_scales()["time_s"]


def hertz_indentation(E_star: float, radius: float, load: float) -> float:
    """Hertz's indentation under a load (docs/model.md, Drives).

    Args:
        E_star: E*, plane-strain modulus [Pa].
        radius: R, sphere radius [m].
        load: F, the load [N], ≥ 0.

    Returns:
        δ = (3F/(4E*√R))^{2/3} [m].
    """
    return (3 * load / (4 * E_star * _sqrt(radius))) ** (2 / 3)


@dataclasses.dataclass(frozen=True)
class CreepTest(_Scene):
    """A creep test in SI units: a load ramped from 0 to ``load`` in ``ramp_time``, then held,
    on a sphere that starts at rest at the gap ``gap``.

    Attributes:
        E_star: E*, plane-strain (or reduced, eq 24) modulus [Pa].
        radius: R, sphere (or reduced, eq 24) radius [m].
        viscosity: η, film viscosity [Pa s].
        load: F, the held load [N].
        ramp_time: the load's ramp time t_c [s].
        gap: z0, the initial gap [m].
        indenter: "paraboloid" (default) or "sphere" (``shape``; d_c stays Hertz's δ∞).

    Scales: d_c = δ∞, Hertz's indentation under the load, and t_c = ``ramp_time``: the load's
    plateau is F̄ = 2π/3, the gap tends to z̄ = -1, β = E* d_c^{3/2} t_c/(6π η R^{3/2}).
    """

    E_star: float
    radius: float
    viscosity: float
    load: float
    ramp_time: float
    gap: float
    indenter: str = "paraboloid"

    def __post_init__(self):
        _check_fields(
            self,
            [
                ("E_star", "Pa"),
                ("radius", "m"),
                ("viscosity", "Pa s"),
                ("load", "N"),
                ("ramp_time", "s"),
                ("gap", "m"),
            ],
        )
        self._check_indenter(gap=self.gap)

    @property
    def indent(self) -> float:
        """d_c = δ∞ [m]."""
        return hertz_indentation(self.E_star, self.radius, self.load)

    @property
    def dry_depth(self) -> float:
        """The dry indentation under the load [m]: Hertz's δ∞ for the paraboloid, Sneddon's
        (a little deeper: 1.4 % at δ∞ = 0.2 R) for the sphere."""
        return self.indent * self.shape.depth_under_load(2.0 * math.pi / 3.0)

    @property
    def time_scale(self) -> float:
        """t_c = ``ramp_time`` [s]: t = t_c t̄."""
        return self.ramp_time

    @property
    def z0_bar(self) -> float:
        """z̄0 = z0/d_c, dimensionless."""
        return self.gap / self.indent

    @property
    def load_bar(self) -> float:
        """F̄ of the plateau (2π/3 by the choice of d_c)."""
        return self.load / self.force_scale

    def _si_scales(self) -> dict:
        return si_scales(self.E_star, self.radius, self.indent, t_c=self.time_scale,
                         viscosity=self.viscosity)

    def drive(self, history=None):
        """The drive :func:`lubjax.relax` takes for this test.

        Args:
            history: the load's shape in units of ``load`` against t̄ = t/t_c; None (default)
                for the ramp-and-hold, ``RampHold()``.

        Returns:
            lubjax.Load: F̄ = ``load_bar`` × the history.
        """
        from ._drives import Load
        from ._indenter import RampHold

        return Load(self.load_bar, RampHold() if history is None else history)


@dataclasses.dataclass(frozen=True)
class Collision(_Scene):
    """A free sphere approaching a wall through the film (Davis, Serayssol & Hinch 1986).

    Scales: d_c = x0 and t_c = x0/V (z̄ = 1, v̄ = -1 at the start); β = E* x0^{5/2}/(6π η V
    R^{3/2}), St = m V/(6π η R²), G = 2β/(π St), W̄ = W/F_s, and Davis et al.'s
    ε = 4θηVR^{3/2}/x0^{5/2}, θ = 1/(πE*) (their eq 2.6), is 2/(3π²β).

    Attributes:
        E_star: E*, plane-strain (or reduced, eq 24) modulus [Pa].
        radius: R, sphere (or reduced, eq 24) radius [m].
        viscosity: η, film viscosity [Pa s].
        mass: m, the sphere's mass [kg].
        speed: V, its speed toward the wall at the start [m/s].
        gap: x0, the gap at the start [m] (the depth scale d_c).
        weight: W, a constant load toward the wall, its weight less buoyancy [N], ≥ 0
            (default 0).
    """

    E_star: float
    radius: float
    viscosity: float
    mass: float
    speed: float
    gap: float
    weight: float = 0.0

    def __post_init__(self):
        _check_fields(
            self,
            [
                ("E_star", "Pa"),
                ("radius", "m"),
                ("viscosity", "Pa s"),
                ("mass", "kg"),
                ("speed", "m/s"),
                ("gap", "m"),
            ],
        )
        object.__setattr__(self, "weight", check_quantity("weight", self.weight, "N", zero=True))

    @property
    def time_scale(self) -> float:
        """t_c = x0/V [s]: t = t_c t̄."""
        return self._si_scales()["time_s"]

    @property
    def stokes(self) -> float:
        """The Stokes number St = m V/(6π η R²), dimensionless."""
        return self.mass * self.speed / (6 * math.pi * self.viscosity * self.radius**2)

    @property
    def elasticity(self) -> float:
        """Davis et al.'s ε = 2/(3π²β)."""
        return 2 / (3 * math.pi**2 * self.beta)

    def _si_scales(self) -> dict:
        return si_scales(self.E_star, self.radius, self.gap, speed=self.speed,
                         viscosity=self.viscosity)

    def drive(self):
        """The drive :func:`lubjax.relax` takes for this collision.

        Returns:
            lubjax.FreeSphere: G = 2β/(π St), v̄0 = -1, W̄ = W/F_s.
        """
        from ._drives import FreeSphere

        return FreeSphere(
            2 * self.beta / (math.pi * self.stokes), -1.0, self.weight / self.force_scale
        )
