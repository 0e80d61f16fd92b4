"""The elastic influence matrix against independent quadrature and against Hertz (eqs 8b, 15)."""

import mpmath as mp
import numpy as np
import pytest

import lubjax


def _psi(u):
    """The pressure representation's weight ψ = (1 + u²/2)⁻² (lubjax/_influence.py, (P))."""
    return 1 / (1 + u * u / 2) ** 2


def _reference_entry(r, i, j, dps=30):
    """Ŵ_ij by mpmath's adaptive quadrature at 30 digits, from eq 8b with the basis function
    ψ(u)/ψ(r_j) times a hat function."""
    mp.mp.dps = dps
    ri = mp.mpf(r[i])
    rj = mp.mpf(r[j])

    def g(u):
        m1 = ((u - ri) / (u + ri)) ** 2
        if m1 == 0:
            return mp.mpf(0)
        return u / (u + ri) * mp.ellipk(1 - m1) * _psi(u) / _psi(rj)

    total = mp.mpf(0)
    if j > 0:
        a, b = mp.mpf(r[j - 1]), mp.mpf(r[j])
        total += mp.quad(lambda u: g(u) * (u - a) / (b - a), [a, b])
    if j < len(r) - 1:
        a, b = mp.mpf(r[j]), mp.mpf(r[j + 1])
        total += mp.quad(lambda u: g(u) * (b - u) / (b - a), [a, b])
    return float(total * 8 / mp.pi**2)


def test_entries_match_high_precision_quadrature():
    mesh = lubjax.graded_mesh(dr=0.02, r_fine=1.0, length=30.0, growth=1.1)
    W = lubjax.stepper.influence_matrix(mesh)
    r = mesh.r
    n = r.size
    # Diagonal (log-singular), neighbours (singular at the shared node), the axis, the far
    # field, the fine/graded junction and the outer boundary.
    pairs = [(0, 0), (0, 1), (1, 0), (7, 7), (7, 8), (7, 6), (49, 50), (50, 50), (51, 50),
             (n - 1, n - 1), (n - 1, n - 2), (3, n - 1), (n - 1, 3), (60, 10), (10, 60)]
    for i, j in pairs:
        ref = _reference_entry(r, i, j)
        assert abs(W[i, j] - ref) <= 1e-9 * abs(ref), (i, j, W[i, j], ref)


def test_matrix_is_cached_per_mesh():
    mesh = lubjax.graded_mesh(dr=0.05, r_fine=1.0, length=10.0, growth=1.2)
    assert lubjax.stepper.influence_matrix(mesh) is lubjax.stepper.influence_matrix(
        lubjax.graded_mesh(dr=0.05, r_fine=1.0, length=10.0, growth=1.2)
    )


def test_force_weights_integrate_the_represented_pressure_exactly():
    """p̄ = ψ (a + b r̄) is represented exactly, so c·p̄ must be its 2π ∫ p̄ r̄ dr̄ to rounding.
    With u = r̄/√2: ∫ r ψ dr = -1/(1 + r²/2), ∫ r² ψ dr = √2 (arctan u - u/(1 + u²))."""
    mesh = lubjax.graded_mesh(dr=0.05, r_fine=1.0, length=50.0, growth=1.5)
    r = mesh.r
    p = _psi(r) * (3.0 - 0.05 * r)
    u = r[-1] / np.sqrt(2)
    first = 1 - 1 / (1 + r[-1] ** 2 / 2)
    second = np.sqrt(2) * (np.arctan(u) - u / (1 + u * u))
    exact = 2 * np.pi * (3.0 * first - 0.05 * second)
    assert lubjax.stepper.force_weights(mesh) @ p == pytest.approx(exact, rel=1e-13)


def test_hertz_pressure_gives_parabolic_displacement_at_order_one_and_a_half():
    """Eq 15: under p̄ = √(a² - r̄²) the surface is the parabola w̄ = -(a² - r̄²/2) inside.

    Hat functions interpolate p̄ to O(Δr²) where it is smooth, but the √ edge leaves an O(Δr^½)
    error over one cell, so the displacement error is O(Δr^{3/2}). The contact edge a = 0.75 sits
    on a node of every mesh so the error is not polluted by the edge's position in a cell.
    """
    a = 0.75
    z0 = 1 - a**2
    drs = np.array([0.05, 0.025, 0.0125, 0.00625])
    errors = []
    for dr in drs:
        mesh = lubjax.uniform_mesh(dr, 2.0)
        r = mesh.r
        w = -lubjax.stepper.influence_matrix(mesh) @ lubjax.hertz_pressure(r, z0)
        errors.append(np.max(np.abs(w - lubjax.hertz_displacement(r, z0))))
        inside = r <= a
        assert np.max(np.abs(w[inside] + (a**2 - r[inside] ** 2 / 2))) <= errors[-1] + 1e-15
    errors = np.array(errors)
    assert np.all(np.diff(errors) < 0)
    order = np.polyfit(np.log(drs), np.log(errors), 1)[0]
    assert 1.25 < order < 1.6, order
    assert errors[-1] < 5e-4
