"""Analytic limits of the relaxation test (paper Section 4), used as checks and as fit starts."""

from __future__ import annotations

import numpy as np


def rigid_squeeze_pressure(r, z, velocity, beta):
    """Rigid squeeze film, eq 12b: p̄ = (-dz̄/dt̄) / (4β (z̄ + r̄²/2)²), valid for β ≫ 1, early t̄."""
    return -velocity / (4.0 * beta * (z + 0.5 * np.asarray(r) ** 2) ** 2)


def rigid_squeeze_force(z, velocity, beta):
    """F̄ = π (-dz̄/dt̄) / (2β z̄): eq 12b integrated (dimensionally Reynolds' F = 6πηR²v/z)."""
    return np.pi * -velocity / (2.0 * beta * np.asarray(z))


def hertz_pressure(r, z0):
    """Fully relaxed Hertz pressure, eq 14: p̄ = √(1 - z̄0 - r̄²) inside r̄∞ = √(1 - z̄0), else 0."""
    a2 = 1.0 - z0
    return np.sqrt(np.clip(a2 - np.asarray(r) ** 2, 0.0, None))


def hertz_displacement(r, z0):
    """Surface displacement under the Hertz pressure, eq 15 inside the contact and the classical
    outer solution outside: w̄ = -(a² - r̄²/2) for r̄ ≤ a, else
    w̄ = -(1/π)[(2a² - r̄²) asin(a/r̄) + a √(r̄² - a²)], a = √(1 - z̄0)."""
    r = np.asarray(r, dtype=np.float64)
    a2 = 1.0 - z0
    a = np.sqrt(max(a2, 0.0))
    inside = -(a2 - 0.5 * r**2)
    rs = np.maximum(r, a if a > 0 else 1.0)
    asin = np.arcsin(np.clip(a / rs, 0, 1))
    outside = -((2 * a2 - rs**2) * asin + a * np.sqrt(rs**2 - a2)) / np.pi
    return np.where(r <= a, inside, outside)


def hertz_force(z0):
    """Long-time force for z̄0 < 1, eq 16: F̄∞ = (2π/3)(1 - z̄0)^{3/2}; 0 for z̄0 ≥ 1."""
    return 2.0 * np.pi / 3.0 * np.clip(1.0 - np.asarray(z0), 0.0, None) ** 1.5
