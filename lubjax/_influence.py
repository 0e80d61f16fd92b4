r"""Elastic influence matrix of the half-space (paper eqs 8b, 21).

The dimensionless Boussinesq displacement is (eq 8b)

    w̄(r̄) = -(8/π²) ∫₀^∞ ū/(ū + r̄) p̄(ū) K(m) dū,   m = 4ūr̄/(ū + r̄)²,

with K the complete elliptic integral of the first kind (parameter m). We write it as
w̄ = -Ŵ p̄ for a pressure represented between the mesh nodes as

    p̄(ū) = ψ(ū) Σ_j (p̄_j/ψ(r̄_j)) φ_j(ū),   ψ(ū) = (1 + ū²/2)⁻²,               (P)

hat functions φ_j times a fixed weight ψ (the nodal values are still p̄_j), so

    Ŵ_ij = (8/π²) ∫ ψ(ū)/ψ(r̄_j) φ_j(ū) G(ū, r̄_i) dū,   G(ū, r̄) = ū/(ū + r̄) K(m),

and the force F̄ = 2π ∫ p̄ r̄ dr̄ = c·p̄ of the same representation (eq 11b).

Departs from the paper's constant-per-cell p̄ (eq 21): hats are second order on a graded mesh,
and ψ follows the squeeze film's r̄⁻⁴ tail (eq 12b) on the coarse outer cells, so they can grow
by 1.15 instead of 1.05 (docs/design.md, "Departures from the paper"). The log singularity of K
at ū = r̄_i always sits at an element end: tanh-sinh quadrature, with |ū - r̄_i| taken from the
nearer end without cancellation (``ellipkm1`` takes 1 - m directly). Cached per mesh.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.special import ellipkm1

from ._mesh import Mesh

# tanh-sinh abscissae x = tanh(π/2 sinh τ), step 1/20 over |τ| ≤ 3.3: ~1e-14 (mpmath, tests).
_TAU = np.arange(-3.3, 3.3 + 1e-12, 0.05)
_S = 0.5 * np.pi * np.sinh(_TAU)
# Fractions of the element from its left (fa) and right (fb) end, without cancellation.
_FA = 1.0 / (1.0 + np.exp(-2.0 * _S))
_FB = 1.0 / (1.0 + np.exp(2.0 * _S))
_WT = 0.05 * (0.5 * np.pi * np.cosh(_TAU) / np.cosh(_S) ** 2) / 2.0  # ∫₀¹ dξ, ξ = (1+x)/2
# Gauss-Legendre for the force: ψ's poles at ±i√2 lie ≳ 6 half-widths from any element.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(12)
_GL_X, _GL_W = 0.5 * (_GL_X + 1.0), 0.5 * _GL_W


def pressure_weight(r):
    """ψ(r̄) = (1 + r̄²/2)⁻² of the pressure representation (P): the squeeze film's decay."""
    r = np.asarray(r, dtype=np.float64)
    return 1.0 / (1.0 + 0.5 * r * r) ** 2


def kernel(u: np.ndarray, r: float | np.ndarray, distance: np.ndarray | None = None) -> np.ndarray:
    """The kernel of the elastic integral (eqs 8b, 21): G(ū, r̄) = ū/(ū+r̄) K(4ūr̄/(ū+r̄)²).

    Args:
        u: ū, source radii (units of √(R d_c)); an array.
        r: r̄, the collocation radius or radii (units of √(R d_c)), broadcast with ``u``.
        distance: ū - r̄ where it is known more accurately than the difference (near the
            singularity); None (default) computes it.

    Returns:
        G, dimensionless, broadcast shape of ``u`` and ``r``.
    """
    u = np.asarray(u, dtype=np.float64)
    d = (u - r) if distance is None else distance
    s = u + r
    m1 = (d / s) ** 2  # 1 - m, computed without cancellation
    return u / s * ellipkm1(m1)


@functools.lru_cache(maxsize=32)
def influence_matrix(mesh: Mesh, weighted: bool = True) -> np.ndarray:
    """The half-space's influence matrix (eq 21): w̄_i = -Σ_j Ŵ_ij p̄_j.

    Ŵ_ij of the representation (P) (module docstring), cached per mesh.

    Args:
        mesh: the :class:`lubjax.Mesh`.
        weighted: True (default) for the ψ-weighted representation; False for plain hat
            functions (ψ ≡ 1: the finite layer's representation).

    Returns:
        Ŵ, an (N, N) float64 array, read-only.
    """
    r = mesh.r
    n = r.size
    length = np.diff(r)
    a = r[:-1, None]
    b = r[1:, None]
    da = length[:, None] * _FA[None, :]
    db = length[:, None] * _FB[None, :]
    u = np.where(_FA[None, :] <= 0.5, a + da, b - db)
    psi_u = pressure_weight(u) if weighted else np.ones_like(u)
    psi = pressure_weight(r) if weighted else np.ones_like(r)
    weight = psi_u * (_WT[None, :] * length[:, None])
    w = np.zeros((n, n))
    for i, ri in enumerate(r):
        near_a = np.abs(ri - a) <= np.abs(ri - b)
        dist = np.where(near_a, (a - ri) + da, (b - ri) - db)
        g = kernel(u, ri, dist) * weight
        left = g @ _FB  # weight of node k (hat decreasing on [r_k, r_k+1])
        right = g @ _FA  # weight of node k+1
        w[i, :-1] += left
        w[i, 1:] += right
    w *= (8.0 / np.pi**2) / psi[None, :]
    w.setflags(write=False)
    return w


def force_weights(mesh: Mesh) -> np.ndarray:
    """The force weights: F̄ = c·p̄ = 2π ∫ p̄ r̄ dr̄ (eq 11b), exact for the representation (P).

    Args:
        mesh: the :class:`lubjax.Mesh`.

    Returns:
        numpy.ndarray: c, N float64 weights (F̄ per unit p̄ at each node).
    """
    r = mesh.r
    a, b = r[:-1, None], r[1:, None]
    u = a + (b - a) * _GL_X[None, :]
    # ∫_a^b r ψ φ dr over the hat halves: left node (b-r)/(b-a), right node (r-a)/(b-a).
    g = u * pressure_weight(u) * (b - a) * _GL_W[None, :]
    c = np.zeros_like(r)
    c[:-1] += g @ (1.0 - _GL_X)
    c[1:] += g @ _GL_X
    return 2.0 * np.pi * c / pressure_weight(r)
