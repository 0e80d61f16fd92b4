r"""Elastic influence matrix of the half-space (paper eqs 8b, 21).

The dimensionless Boussinesq displacement is (eq 8b)

    w̄(r̄) = -(8/π²) ∫₀^∞ ū/(ū + r̄) p̄(ū) K(m) dū,   m = 4ūr̄/(ū + r̄)²,

with K the complete elliptic integral of the first kind (parameter m). We write it as
w̄ = -Ŵ p̄ for a pressure that is *piecewise linear* between the mesh nodes,
p̄(ū) = Σ_j p̄_j φ_j(ū) with hat functions φ_j, so

    Ŵ_ij = (8/π²) ∫ φ_j(ū) G(ū, r̄_i) dū,   G(ū, r̄) = ū/(ū + r̄) K(m).

Departure from the paper (eq 21): the paper holds p̄ constant on each cell, which is first-order
in the pressure representation at a mesh-size jump and does not integrate the force exactly.
Hat functions give a second-order representation on any (graded) mesh and the same matrix
cost. Every node r̄_i is an element end, so the log singularity of K at ū = r̄_i,
K ≈ ln(4(ū+r̄)/|ū-r̄|), always sits at an endpoint of an element integral. We integrate each
element with tanh-sinh (double-exponential) quadrature, which converges exponentially for
endpoint log singularities, and compute the distance |ū - r̄_i| from the nearer element end
without cancellation, so 1 - m = ((ū-r̄)/(ū+r̄))² is accurate right up to the singular point
(scipy's ``ellipkm1`` takes 1 - m directly).

The matrix depends only on the mesh: it is computed once in numpy and cached per mesh.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.special import ellipkm1

from ._mesh import Mesh

# tanh-sinh abscissae in τ: x = tanh(π/2 sinh τ). Step 1/20 over |τ| ≤ 3.3 reaches
# ~1e-14 relative accuracy for the log-singular kernels here (checked against mpmath in tests).
_TAU = np.arange(-3.3, 3.3 + 1e-12, 0.05)
_S = 0.5 * np.pi * np.sinh(_TAU)
# Fractions of the element length from the left end (fa) and from the right end (fb), both
# computed without cancellation, and the quadrature weight in units of the element length.
_FA = 1.0 / (1.0 + np.exp(-2.0 * _S))
_FB = 1.0 / (1.0 + np.exp(2.0 * _S))
# Weight for ∫₀¹ f(ξ) dξ with ξ = (1+x)/2: step · dx/dτ / 2.
_WT = 0.05 * (0.5 * np.pi * np.cosh(_TAU) / np.cosh(_S) ** 2) / 2.0


def kernel(u: np.ndarray, r: float | np.ndarray, distance: np.ndarray | None = None) -> np.ndarray:
    """G(ū, r̄) = ū/(ū+r̄) K(4ūr̄/(ū+r̄)²); ``distance`` = ū - r̄ if known more accurately."""
    u = np.asarray(u, dtype=np.float64)
    d = (u - r) if distance is None else distance
    s = u + r
    m1 = (d / s) ** 2  # 1 - m, computed without cancellation
    return u / s * ellipkm1(m1)


@functools.lru_cache(maxsize=32)
def influence_matrix(mesh: Mesh) -> np.ndarray:
    """Ŵ (N×N) with w̄_i = -Σ_j Ŵ_ij p̄_j for piecewise-linear p̄ on ``mesh``.

    Cached per mesh: a fit or a sweep reuses it. Returned read-only.
    """
    r = mesh.r
    n = r.size
    length = np.diff(r)
    # Vectorised over elements, looped over collocation nodes (n × (n-1) × Q kernel calls).
    a = r[:-1, None]
    b = r[1:, None]
    da = length[:, None] * _FA[None, :]
    db = length[:, None] * _FB[None, :]
    u = np.where(_FA[None, :] <= 0.5, a + da, b - db)
    w = np.zeros((n, n))
    for i, ri in enumerate(r):
        near_a = np.abs(ri - a) <= np.abs(ri - b)
        dist = np.where(near_a, (a - ri) + da, (b - ri) - db)
        g = kernel(u, ri, dist) * (_WT[None, :] * length[:, None])
        left = g @ _FB  # weight of node k (hat decreasing on [r_k, r_k+1])
        right = g @ _FA  # weight of node k+1
        w[i, :-1] += left
        w[i, 1:] += right
    w *= 8.0 / np.pi**2
    w.setflags(write=False)
    return w


def force_weights(mesh: Mesh) -> np.ndarray:
    """c with F̄ = c·p̄ = 2π ∫ p̄ r̄ dr̄ exactly for piecewise-linear p̄ (eq 11b)."""
    r = mesh.r
    c = np.zeros_like(r)
    a, b = r[:-1], r[1:]
    # ∫_a^b r φ dr over the hat halves: left node (b-r)/(b-a), right node (r-a)/(b-a).
    c[:-1] += (b - a) * (2 * a + b) / 6.0
    c[1:] += (b - a) * (a + 2 * b) / 6.0
    return 2.0 * np.pi * c
