"""The dimensional layer: SI inputs to β, z̄0 and the scales of eqs 7, 8e and 11b."""

from __future__ import annotations

import dataclasses
import math


def _check_positive(name: str, value, unit: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive number in {unit}, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be finite and > 0 ({unit}), got {value!r}")
    return v


def _check_poisson(name: str, value) -> float:
    v = float(value)
    if not (math.isfinite(v) and -1.0 < v <= 0.5):
        raise ValueError(f"{name} must be in (-1, 0.5], got {value!r}")
    return v


def plane_strain_modulus(E: float, poisson_ratio: float) -> float:
    """E* = E/(1 - ν²)."""
    E = _check_positive("E", E, "Pa")
    nu = _check_poisson("poisson_ratio", poisson_ratio)
    return E / (1.0 - nu**2)


def contact_modulus(E1: float, nu1: float, E2: float = math.inf, nu2: float = 0.0) -> float:
    """Reduced modulus of two elastic bodies, eq 24: 1/E* = (1-ν1²)/E1 + (1-ν2²)/E2.

    Leave ``E2`` at infinity for a rigid indenter.
    """
    E1 = _check_positive("E1", E1, "Pa")
    nu1 = _check_poisson("nu1", nu1)
    nu2 = _check_poisson("nu2", nu2)
    inv = (1 - nu1**2) / E1
    if not math.isinf(E2):
        inv += (1 - nu2**2) / _check_positive("E2", E2, "Pa")
    return 1.0 / inv


def reduced_radius(R1: float, R2: float = math.inf) -> float:
    """1/R = 1/R1 + 1/R2 (eq 24); R2 = inf for a sphere on a flat."""
    R1 = _check_positive("R1", R1, "m")
    if math.isinf(R2):
        return R1
    return 1.0 / (1.0 / R1 + 1.0 / _check_positive("R2", R2, "m"))


@dataclasses.dataclass(frozen=True)
class RelaxationTest:
    """A relaxation test in SI units (eq 5): gap z0, pushed at speed v0 by d_c, then held.

    Attributes:
        E_star: plane-strain (or reduced, eq 24) modulus E* [Pa].
        radius: sphere (or reduced, eq 24) radius R [m].
        viscosity: film viscosity η [Pa s].
        speed: approach speed v0 [m/s].
        indent: travel d_c [m].
        gap: initial gap z0 [m].
    """

    E_star: float
    radius: float
    viscosity: float
    speed: float
    indent: float
    gap: float

    def __post_init__(self):
        for name, unit in [
            ("E_star", "Pa"),
            ("radius", "m"),
            ("viscosity", "Pa s"),
            ("speed", "m/s"),
            ("indent", "m"),
            ("gap", "m"),
        ]:
            object.__setattr__(self, name, _check_positive(name, getattr(self, name), unit))

    @classmethod
    def from_E(cls, E: float, poisson_ratio: float, **kw) -> RelaxationTest:
        return cls(E_star=plane_strain_modulus(E, poisson_ratio), **kw)

    @property
    def beta(self) -> float:
        """β = E* d_c^{5/2} / (6π η v0 R^{3/2}), eq 8e."""
        return (
            self.E_star
            * self.indent**2.5
            / (6 * math.pi * self.viscosity * self.speed * self.radius**1.5)
        )

    @property
    def z0_bar(self) -> float:
        """z̄0 = z0/d_c, eq 8f."""
        return self.gap / self.indent

    @property
    def time_scale(self) -> float:
        """t_c = d_c/v0 [s]: t = t_c t̄."""
        return self.indent / self.speed

    @property
    def length_scale(self) -> float:
        """√(R d_c) [m]: r = √(R d_c) r̄ (h, z, w scale with d_c)."""
        return math.sqrt(self.radius * self.indent)

    @property
    def pressure_scale(self) -> float:
        """p = (2E*/π) √(d_c/R) p̄ [Pa], eq 7f."""
        return 2 * self.E_star / math.pi * math.sqrt(self.indent / self.radius)

    @property
    def force_scale(self) -> float:
        """F = (2 E* d_c^{3/2} √R / π) F̄ [N], eq 11b."""
        return 2 * self.E_star * self.indent**1.5 * math.sqrt(self.radius) / math.pi
