r"""(a) The paper's scheme as published (Liu et al. 2022, eqs 17-22), ported the way a user would:
plain numpy, uniform mesh, uniform Δt̄, and the dense 2N×2N system in (p̄, w̄) solved with
``numpy.linalg.solve`` every step.

Unknowns x = [p̄_1..p̄_N, w̄_1..w̄_N] (1-based in the paper, 0-based here). Rows:

* i = 1:           p̄_1 - p̄_2 = 0                                   (22a)
* 2 ≤ i ≤ N-1:     -D w̄_i + (2m³ + m²nΔr̄) p̄_i - (m³ + m²nΔr̄) p̄_{i+1} - m³ p̄_{i-1}
                   = -D (w̄_i^j + z̄^{j+1} - z̄^j)        (20a; p̄_{i-1} sign as in MODEL.md)
* i = N:           p̄_N = 0                                          (22b)
* N rows:          w̄_i + Σ_m Ŵ_im p̄_m = 0                           (21a)

with m_i = z̄^j + r̄_i²/2 - w̄_i^j, n_i = 3(r̄_i - (w̄_{i+1}^j - w̄_i^j)/Δr̄) + m_i/r̄_i (19, 20b) and
D = Δr̄²/(β Δt̄). The force is F̄ = 2π Σ p̄_m ∫_{cell m} r̄ dr̄ for the same piecewise-constant
pressure as Ŵ (first cell [0, Δr̄/2], last cell [L̄-Δr̄/2, L̄]).

Ŵ (eq 21b,c) for a pressure constant on each cell, computed once per (Δr̄, L̄) with care for the
log singularity of K at ū = r̄_i: cells within one cell of r̄_i by ``scipy.integrate.quad`` split
at r̄_i (``points``) with 1 - m evaluated without cancellation (``ellipkm1``), the others (smooth
integrand) by 12-point Gauss-Legendre. Cached in memory and on disk (benchmarks/out/cache).
"""

from __future__ import annotations

import functools
import os
import time
from pathlib import Path

import numpy as np
from scipy.integrate import quad
from scipy.special import ellipkm1

from .common import at_outputs, make_info, travel, uniform_grid

_CACHE = Path(__file__).resolve().parents[1] / "out" / "cache"


def _kernel(u, r):
    """G(ū, r̄) = ū/(ū+r̄) K(4ūr̄/(ū+r̄)²), with 1 - m = ((ū-r̄)/(ū+r̄))²."""
    s = u + r
    return np.where(s > 0, u / np.where(s > 0, s, 1.0) * ellipkm1(((u - r) / np.where(s > 0, s,
                                                                                    1.0)) ** 2),
                    0.0)


def cell_edges(dr: float, length: float):
    n = int(round(length / dr)) + 1
    r = np.linspace(0.0, (n - 1) * dr, n)
    lo = np.maximum(r - dr / 2, 0.0)
    hi = np.minimum(r + dr / 2, r[-1])
    return r, lo, hi


@functools.lru_cache(maxsize=8)
def influence_constant(dr: float, length: float) -> np.ndarray:
    """Ŵ_im = (8/π²) ∫_{cell m} G(ū, r̄_i) dū for piecewise-constant pressure (eq 21b,c)."""
    path = _CACHE / f"paper_W_dr{dr:g}_L{length:g}.npy"
    if path.exists():
        return np.load(path)
    r, lo, hi = cell_edges(dr, length)
    n = r.size
    x, w = np.polynomial.legendre.leggauss(12)
    half = 0.5 * (hi - lo)
    mid = 0.5 * (hi + lo)
    u = mid[:, None] + half[:, None] * x[None, :]  # (cells, 12)
    wq = half[:, None] * w[None, :]
    W = np.empty((n, n))
    for i in range(n):
        W[i] = np.sum(_kernel(u, r[i]) * wq, axis=1)
        for m in range(max(0, i - 1), min(n, i + 2)):
            a, b = lo[m], hi[m]

            def f(uu, ri=r[i]):
                s = uu + ri
                return uu / s * ellipkm1(((uu - ri) / s) ** 2) if s > 0 else 0.0

            if a < r[i] < b:
                W[i, m] = (quad(f, a, r[i], limit=200, epsabs=1e-14, epsrel=1e-12)[0]
                           + quad(f, r[i], b, limit=200, epsabs=1e-14, epsrel=1e-12)[0])
            else:
                W[i, m] = quad(f, a, b, limit=200, epsabs=1e-14, epsrel=1e-12)[0]
    W *= 8.0 / np.pi**2
    try:
        _CACHE.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.npy")
        np.save(tmp, W)
        os.replace(tmp, path)
    except OSError:
        pass
    return W


def force_weights_constant(dr: float, length: float) -> np.ndarray:
    r, lo, hi = cell_edges(dr, length)
    return np.pi * (hi**2 - lo**2)


def run(beta, z0, t_out, *, dr=0.01, length=4.0, dt=1e-3, t_end=None, reduced=False,
        blowup=1e8):
    """The published scheme. ``reduced=True`` eliminates w̄ (an N×N solve with the same
    arithmetic up to rounding) — used only to make the stability map cheaper; the timing
    baseline is the published 2N×2N form. Stops early once |p̄| > ``blowup`` or NaN.
    """
    t_out = np.asarray(t_out, dtype=np.float64)
    t_end = float(t_out[-1]) if t_end is None else t_end
    start = time.perf_counter()
    W = influence_constant(float(dr), float(length))
    cw = force_weights_constant(float(dr), float(length))
    setup_s = time.perf_counter() - start

    r = cell_edges(dr, length)[0]
    n = r.size
    t = uniform_grid(t_end, dt, t_out)
    z = z0 - travel(t)
    force = np.full(t.size, np.nan)
    hmin = np.full(t.size, np.nan)
    force[0] = 0.0
    hmin[0] = np.min(z[0] + 0.5 * r**2)
    p = np.zeros(n)
    w = np.zeros(n)
    inner = np.arange(1, n - 1)
    # Static parts of the 2N×2N matrix.
    big = np.zeros((2 * n, 2 * n))
    big[0, 0], big[0, 1] = 1.0, -1.0
    big[n - 1, n - 1] = 1.0
    big[n:, :n] = W
    big[n:, n:] = np.eye(n)
    rhs = np.zeros(2 * n)
    start = time.perf_counter()
    for j in range(t.size - 1):
        dtj = t[j + 1] - t[j]
        D = dr**2 / (beta * dtj)
        m = z[j] + 0.5 * r[inner] ** 2 - w[inner]
        nn = 3.0 * (r[inner] - (w[inner + 1] - w[inner]) / dr) + m / r[inner]
        m3 = m**3
        m2n = m**2 * nn * dr
        if reduced:
            # w̄ = -Ŵp̄: rows become D(Ŵp̄)_i + (...)p̄ = -D(w̄^j + Δz̄).
            A = np.zeros((n, n))
            A[0, 0], A[0, 1] = 1.0, -1.0
            A[n - 1, n - 1] = 1.0
            A[inner] = D * W[inner]
            A[inner, inner] += 2 * m3 + m2n
            A[inner, inner + 1] -= m3 + m2n
            A[inner, inner - 1] -= m3
            b = np.zeros(n)
            b[inner] = -D * (w[inner] + z[j + 1] - z[j])
            p = np.linalg.solve(A, b)
            w = -W @ p
        else:
            big[1 : n - 1, :] = 0.0
            big[inner, n + inner] = -D
            big[inner, inner] = 2 * m3 + m2n
            big[inner, inner + 1] = -(m3 + m2n)
            big[inner, inner - 1] = -m3
            rhs[:] = 0.0
            rhs[inner] = -D * (w[inner] + z[j + 1] - z[j])
            x = np.linalg.solve(big, rhs)
            p, w = x[:n], x[n:]
        force[j + 1] = cw @ p
        hmin[j + 1] = np.min(z[j + 1] + 0.5 * r**2 - w)
        if not np.all(np.isfinite(p)) or np.max(np.abs(p)) > blowup:
            force[j + 1] = np.nan
            break
    wall = time.perf_counter() - start
    info = make_info(wall_s=wall, compile_s=setup_s, force=force, film_min=hmin,
                     n_steps=t.size - 1, n_nodes=n, setup="influence matrix (quad), cached")
    return at_outputs(t, force, t_out), info
