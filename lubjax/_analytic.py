"""Analytic limits of the relaxation test (paper Section 4), used as checks and as fit starts."""

from __future__ import annotations

import numpy as np


def rigid_squeeze_pressure(r, z, velocity, beta):
    """The rigid squeeze film's pressure, eq 12b: p̄ = (-dz̄/dt̄) / (4β (z̄ + r̄²/2)²).

    Valid for β ≫ 1 at early t̄, before the substrate deforms.

    Args:
        r: r̄, radius (units of √(R d_c)); a scalar or an array.
        z: z̄, the sphere's gap (units of d_c), > 0.
        velocity: dz̄/dt̄, the sphere's velocity (units of d_c/t_c; < 0 approaching).
        beta: β (eq 8e), dimensionless, > 0.

    Returns:
        p̄ at ``r`` (units of (2E*/π)√(d_c/R), eq 7), shaped as ``r``.
    """
    return -velocity / (4.0 * beta * (z + 0.5 * np.asarray(r) ** 2) ** 2)


def rigid_squeeze_force(z, velocity, beta):
    """The rigid squeeze film's force, eq 12b integrated: F̄ = π (-dz̄/dt̄) / (2β z̄).

    Dimensionally Reynolds' F = 6πηR²v/z; valid for β ≫ 1 at early t̄.

    Args:
        z: z̄, the sphere's gap (units of d_c), > 0; a scalar or an array.
        velocity: dz̄/dt̄, the sphere's velocity (units of d_c/t_c; < 0 approaching).
        beta: β (eq 8e), dimensionless, > 0.

    Returns:
        F̄ (units of F_s, eq 11b), shaped as ``z``.
    """
    return np.pi * -velocity / (2.0 * beta * np.asarray(z))


def hertz_pressure(r, z0):
    """The fully relaxed Hertz pressure, eq 14: p̄ = √(1 - z̄0 - r̄²) inside r̄∞ = √(1 - z̄0),
    0 outside.

    Args:
        r: r̄, radius (units of √(R d_c)); a scalar or an array.
        z0: z̄0 = z0/d_c (eq 8e), dimensionless; < 1 for a contact (else p̄ = 0).

    Returns:
        p̄ at ``r`` (units of (2E*/π)√(d_c/R), eq 7), shaped as ``r``.
    """
    a2 = 1.0 - z0
    return np.sqrt(np.clip(a2 - np.asarray(r) ** 2, 0.0, None))


def hertz_displacement(r, z0):
    """The surface displacement under the Hertz pressure: eq 15 inside the contact, the
    classical outer solution outside.

    w̄ = -(a² - r̄²/2) for r̄ ≤ a, else w̄ = -(1/π)[(2a² - r̄²) asin(a/r̄) + a √(r̄² - a²)],
    with a = √(1 - z̄0).

    Args:
        r: r̄, radius (units of √(R d_c)); a scalar or an array.
        z0: z̄0 = z0/d_c (eq 8e), dimensionless; < 1 for a contact.

    Returns:
        w̄ at ``r`` (units of d_c; ≤ 0, into the substrate), a float64 array shaped as ``r``.
    """
    r = np.asarray(r, dtype=np.float64)
    a2 = 1.0 - z0
    a = np.sqrt(max(a2, 0.0))
    inside = -(a2 - 0.5 * r**2)
    rs = np.maximum(r, a if a > 0 else 1.0)
    asin = np.arcsin(np.clip(a / rs, 0, 1))
    outside = -((2 * a2 - rs**2) * asin + a * np.sqrt(rs**2 - a2)) / np.pi
    return np.where(r <= a, inside, outside)


def hertz_force(z0):
    """The long-time force of the relaxation test, eq 16: F̄∞ = (2π/3)(1 - z̄0)^{3/2}.

    Args:
        z0: z̄0 = z0/d_c (eq 8e), dimensionless; a scalar or an array.

    Returns:
        F̄∞ (units of F_s, eq 11b); 0 where z̄0 ≥ 1 (no contact).
    """
    return 2.0 * np.pi / 3.0 * np.clip(1.0 - np.asarray(z0), 0.0, None) ** 1.5
