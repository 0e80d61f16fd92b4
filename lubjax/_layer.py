r"""Elastic influence matrix of a finite layer on a rigid base (bonded or frictionless).

The layer (thickness H, Poisson ratio ν, E* = E/(1-ν²)) rests on a rigid base and carries the
film pressure p on its free surface (no shear). By Hankel transform, p̃(k) = ∫₀^∞ p(s) J₀(ks) s ds,
the surface deflection is (the half-space's eq 4 times a transfer function C)

    w(r) = -(2/E*) ∫₀^∞ C(kH) p̃(k) J₀(kr) dk,                                     (L1)

with C → 1 as kH → ∞ (the half-space, eq 4). C is the layer's plane-strain Fourier transfer
function: Navier's equations for u_x = U(z) sin kx, u_z = W(z) cos kx with σ_zz = -p̂,
σ_xz = 0 on the surface and, at depth H, u_x = u_z = 0 (bonded) or u_z = σ_xz = 0
(frictionless), give (t = kH, κ = 3 - 4ν)

    bonded:        C(t) = (2κ sinh 2t - 4t) / (2κ cosh 2t + 4t² + κ² + 1),
    frictionless:  C(t) = (cosh 2t - 1) / (sinh 2t + 2t),                          (L2)

the first the classical bonded-layer kernel (Chandler & Vella, Proc. R. Soc. A 476, 2020;
tests/test_layer.py solves the 4×4 boundary-value problem against both). Thin limits (t → 0):

* bonded, ν < ½:  C ≈ t (1-2ν)/(2(1-ν)²): w = -p H (1-2ν)(1+ν)/((1-ν)E), uniaxial strain
  (a Winkler foundation of modulus λ + 2G);
* bonded, ν = ½:  C ≈ 2t³/3: w = (H³/(3G)) ∇²p (E* = 4G), the incompressible thin layer;
* frictionless, any ν: C ≈ t/2: w = -p H/E* (the layer slides on its base: not uniaxial
  strain, and the incompressible layer is compressible in this limit).

Dimensionless form (eq 8b scales, k̄ = k √(R d_c), H̄ = H/√(R d_c)): with hat functions φ_j on the
mesh as in ``_influence`` (w̄_i = -Σ_j Ŵ_ij p̄_j),

    Ŵ_ij = (4/π) ∫₀^∞ C(k̄H̄) φ̃_j(k̄) J₀(k̄ r̄_i) dk̄,   φ̃_j(k) = ∫ φ_j(s) J₀(ks) s ds,   (L3)

and C ≡ 1 is the half-space matrix (8/π²)∫φ_j s/(s+r̄_i) K ds of ``influence_matrix``. So

    Ŵ_layer = Ŵ_half + ΔŴ,   ΔŴ_ij = (4/π) ∫₀^∞ (C(k̄H̄) - 1) φ̃_j(k̄) J₀(k̄ r̄_i) dk̄:   (L4)

the log singularity stays in Ŵ_half (tanh-sinh quadrature, ``_influence``), and ΔŴ is a smooth
remainder, its integrand cut off where |C - 1| ~ (4t² + ...) e^{-2t} < 1e-17.

Both parts use plain hats (``influence_matrix(mesh, weighted=False)``), not the half-space's
weighted ones: ΔŴ's transforms are closed-form only for plain hats, and on a thin layer
Ŵ_layer is the small difference of Ŵ_half and -ΔŴ, which must share one representation.

Hat transforms in closed form: integrating by parts once, with Φ(s) = s J₁(ks)/k (Φ' = s J₀(ks)),

    φ̃_j = ⟨Φ⟩_{e_j} - ⟨Φ⟩_{e_{j-1}}   (element means; ⟨Φ⟩_{e_{-1}} = 0, and for the last node
                                        Φ(r̄_{N-1}) - ⟨Φ⟩_{e_{N-2}}),
    ⟨Φ⟩_{[a,b]} = (Ψ(kb) - Ψ(ka)) / ((b - a) k³),   Ψ(x) = ∫₀^x t J₁(t) dt = ∫₀^x J₀ - x J₀(x),

Ψ by its power series for x < 2 (where ∫J₀ - xJ₀ cancels), else with ∫₀^x J₀ from Chebyshev
interpolants of Neumann's series 2 Σ_m J_{2m+1}(x) on [2, 42] (``itj0y0`` is off by up to 1e-9
there) and ``itj0y0`` beyond.

Quadrature in k̄: 48-point Gauss-Legendre panels on [0, t_max/H̄], each spanning at most 100 rad
of the fastest phase (r̄_i + r̄_j) k̄ and 2 of k̄H̄; ≈ 9.6 L̄ t_max/H̄ nodes, refused above
``MAX_NODES``. ΔŴ accumulates in chunks A (N×K_c) @ B (K_c×N), A = J₀(k̄ r̄_i),
B = w_k (C - 1) φ̃_j.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy.special import itj0y0, j0, j1, jv

from ._checks import check_layer_base, check_poisson, check_positive
from ._influence import influence_matrix
from ._mesh import Mesh

#: Gauss-Legendre points per k̄-panel, its largest half-phase (rad) and k̄H̄ span.
_PANEL_POINTS = 48
_PANEL_PHASE = 50.0
_PANEL_T = 2.0
_GL_X, _GL_W = np.polynomial.legendre.leggauss(_PANEL_POINTS)

#: |C(t) - 1| below this is dropped (the integrand's tail beyond t_max).
_TAIL = 1e-17

#: Most k̄ nodes we accept (≈ 15-25 s on 2 shared cores); past it the layer is too thin for the mesh.
MAX_NODES = 150_000

#: Entries (N × k̄ nodes) per chunk of the A @ B product: ≈ 9 MB per work array, whatever N.
_CHUNK_ENTRIES = 1 << 20

#: Ψ(x) = Σ_m (-1)^m x^{2m+3} / ((2m+3) 2^{2m+1} m! (m+1)!), 16 terms: exact for x < 2.
_PSI_SERIES = np.array(
    [(-1) ** m / ((2 * m + 3) * 2.0 ** (2 * m + 1) * math.factorial(m) * math.factorial(m + 1))
     for m in range(16)]
)


def layer_thickness_bar(H: float, R: float, d_c: float) -> float:
    """A layer's thickness in the units of r̄ (docs/model.md, Substrates).

    Args:
        H: H, the layer's thickness [m], > 0.
        R: R, the sphere's radius [m], > 0.
        d_c: d_c, the indentation depth [m], > 0.

    Returns:
        H̄ = H/√(R d_c), dimensionless.

    Raises:
        ValueError: a length not a finite number > 0.
    """
    for name, value in (("H", H), ("R", R), ("d_c", d_c)):
        check_positive(f"layer_thickness_bar: {name}", value, "m")
    return float(H) / math.sqrt(float(R) * float(d_c))


def transfer_minus_one(t: np.ndarray, poisson: float, interface: str) -> np.ndarray:
    """C(t) - 1 of (L2), written so that neither e^{2t} overflows nor 1 - C cancels at large t."""
    t = np.asarray(t, dtype=np.float64)
    if check_layer_base("interface", interface) == "bonded":
        e2 = np.exp(-2.0 * t)
        e4 = e2 * e2
        kappa = 3.0 - 4.0 * poisson
        # (L2) minus 1, numerator and denominator multiplied by e^{-2t}.
        num = 2.0 * kappa * e4 + (4.0 * t * t + 4.0 * t + kappa * kappa + 1.0) * e2
        den = kappa * (1.0 + e4) + (4.0 * t * t + kappa * kappa + 1.0) * e2
        return -num / den
    # frictionless: small t as 2 sinh²t/(sinh 2t + 2t) (no cancellation), large t exponential;
    # ts = 1 at t = 0 only keeps 0/0 out of the unused branch.
    small = t < 1.0
    ts = np.where(small & (t > 0), t, 1.0)
    tl = np.where(small, 1.0, t)
    c_small = 2.0 * np.sinh(ts) ** 2 / (np.sinh(2.0 * ts) + 2.0 * ts) - 1.0
    c_small = np.where(t > 0, c_small, -1.0)
    e2l = np.exp(-2.0 * tl)
    e4l = e2l * e2l
    c_large = 2.0 * (e4l - (1.0 + 2.0 * tl) * e2l) / (1.0 - e4l + 4.0 * tl * e2l)
    return np.where(small, c_small, c_large)


def transfer(t: np.ndarray, poisson: float, interface: str) -> np.ndarray:
    """The layer's transfer function C(kH) of (L1)-(L2); 1 for the half-space."""
    return 1.0 + transfer_minus_one(t, poisson, interface)


@functools.lru_cache(maxsize=64)
def _t_max(poisson: float, interface: str) -> float:
    """Smallest t beyond which |C(t) - 1| < _TAIL (C - 1 decays monotonically there)."""
    t = np.arange(0.0, 80.0, 0.01)
    big = np.nonzero(np.abs(transfer_minus_one(t, poisson, interface)) >= _TAIL)[0]
    return float(t[big[-1] + 1])


#: Piecewise Chebyshev interpolation of ∫₀^x J₀ on [2, 42]: pieces of width 4, degree 20.
_CHEB_LO, _CHEB_WIDTH, _CHEB_PIECES, _CHEB_DEG = 2.0, 4.0, 10, 20


@functools.lru_cache(maxsize=1)
def _cheb_coefficients() -> np.ndarray:
    """Chebyshev coefficients (pieces × degree+1) of ∫₀^x J₀ = 2 Σ_m J_{2m+1}(x), 60 terms."""
    orders = 2 * np.arange(60) + 1
    coef = []
    for piece in range(_CHEB_PIECES):
        a = _CHEB_LO + piece * _CHEB_WIDTH
        coef.append(np.polynomial.chebyshev.chebinterpolate(
            lambda u, a=a: 2.0 * jv(orders, a + (u[..., None] + 1.0) * (_CHEB_WIDTH / 2)).sum(-1),
            _CHEB_DEG,
        ))
    return np.array(coef)


def _int_j0(x: np.ndarray) -> np.ndarray:
    """∫₀^x J₀(t) dt for x ≥ 2, to ~1e-14 (``itj0y0`` alone is off by up to 1e-9 near x = 20)."""
    out = np.empty_like(x)
    mid = x < _CHEB_LO + _CHEB_PIECES * _CHEB_WIDTH
    if not np.all(mid):
        out[~mid] = itj0y0(x[~mid])[0]
    if np.any(mid):
        xm = x[mid]
        piece = np.clip(((xm - _CHEB_LO) // _CHEB_WIDTH).astype(int), 0, _CHEB_PIECES - 1)
        u = 2.0 * (xm - _CHEB_LO - piece * _CHEB_WIDTH) / _CHEB_WIDTH - 1.0
        c = _cheb_coefficients()[piece]
        b0 = np.zeros_like(xm)
        b1 = np.zeros_like(xm)
        for m in range(_CHEB_DEG, 0, -1):  # Clenshaw
            b0, b1 = c[:, m] + 2.0 * u * b0 - b1, b0
        out[mid] = c[:, 0] + u * b0 - b1
    return out


def _psi(x: np.ndarray) -> np.ndarray:
    """Ψ(x) = ∫₀^x t J₁(t) dt = ∫₀^x J₀ - x J₀(x), x ≥ 0, with J₀(x) passed back for reuse."""
    j0x = j0(x)
    psi = _int_j0(x) - x * j0x
    small = x < 2.0
    if np.any(small):
        xs = x[small]
        x2 = xs * xs
        psi[small] = xs * x2 * np.polynomial.polynomial.polyval(x2, _PSI_SERIES)
    return psi, j0x


def hat_transforms(r: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(φ̃_j(k_q), J₀(k_q r_i)) as N×K arrays: the hats' Hankel transforms and the kernel rows."""
    k = np.asarray(k, dtype=np.float64)
    x = r[:, None] * k[None, :]
    psi, j0x = _psi(x)
    h = np.diff(r)[:, None]
    means = (psi[1:] - psi[:-1]) / (h * k[None, :] ** 3)  # ⟨Φ⟩ over each element
    phi = np.empty_like(x)
    phi[0] = means[0]
    phi[1:-1] = means[1:] - means[:-1]
    phi[-1] = r[-1] * j1(k * r[-1]) / k - means[-1]
    return phi, j0x


def k_nodes(mesh: Mesh, thickness: float, poisson: float, interface: str):
    """Gauss-Legendre nodes and weights on [0, t_max/H̄] (see the module docstring)."""
    k_max = _t_max(poisson, interface) / thickness
    width = min(2.0 * _PANEL_PHASE / (2.0 * mesh.length), _PANEL_T / thickness)
    panels = max(1, math.ceil(k_max / width))
    count = panels * _PANEL_POINTS
    if count > MAX_NODES:
        raise ValueError(
            f"Layer thickness H̄ = {thickness:g} is too thin for a mesh of length "
            f"L̄ = {mesh.length:g}: its influence matrix would need {count:,} k-nodes "
            f"(> {MAX_NODES:,}; about 9.6 L̄ t_max/H̄ with t_max = {k_max * thickness:.0f}). "
            f"Use a thicker layer or a shorter mesh (Settings(length=...)); a layer much "
            f"thinner than the contact is close to a Winkler foundation"
        )
    edges = np.linspace(0.0, panels * width, panels + 1)
    half = 0.5 * width
    k = ((edges[:-1, None] + edges[1:, None]) * 0.5 + half * _GL_X[None, :]).ravel()
    w = np.tile(half * _GL_W, panels)
    return k, w


def layer_correction(mesh: Mesh, thickness: float, poisson: float, interface: str) -> np.ndarray:
    """ΔŴ of (L4): the layer matrix less the half-space one (N×N, not cached)."""
    r = mesh.r
    k, wk = k_nodes(mesh, thickness, poisson, interface)
    n = r.size
    out = np.zeros((n, n))
    chunk = max(256, _CHUNK_ENTRIES // n)
    for start in range(0, k.size, chunk):
        kc = k[start:start + chunk]
        phi, a = hat_transforms(r, kc)
        weight = wk[start:start + chunk] * transfer_minus_one(kc * thickness, poisson, interface)
        out += a @ (weight[:, None] * phi.T)
    out *= 4.0 / np.pi
    return out


@functools.lru_cache(maxsize=32)
def layer_influence_matrix(
    mesh: Mesh, thickness: float, poisson: float = 0.5, interface: str = "bonded"
) -> np.ndarray:
    """The influence matrix of a layer on a rigid base: w̄_i = -Σ_j Ŵ_ij p̄_j for the nodal
    pressures p̄ on ``mesh``, piecewise linear between them.

    The plain-hat half-space matrix plus the smooth remainder ΔŴ of C(kH) - 1 (L4), cached.

    Args:
        mesh: the :class:`lubjax.Mesh`.
        thickness: H̄ = H/√(R d_c), dimensionless, > 0.
        poisson: ν, dimensionless, in (-1, 0.5] (default 0.5).
        interface: "bonded" (default) or "frictionless" (``LAYER_BASES``).

    Returns:
        Ŵ, an (N, N) float64 array, read-only.

    Raises:
        ValueError: a thickness, Poisson's ratio or interface out of range, or a layer too
            thin for the mesh (the k̄ quadrature would exceed ``MAX_NODES``).
    """
    thickness = check_positive("layer thickness", float(thickness))
    poisson = check_poisson("layer poisson", float(poisson))
    check_layer_base("interface", interface)
    half = influence_matrix(mesh, weighted=False)
    w = half + layer_correction(mesh, thickness, poisson, interface)
    w.setflags(write=False)
    return w
