"""The finite layer's influence matrix (lubjax/_layer.py) against independent computations:
the layer BVP solved numerically, real-space quadrature, the half-space and thin-layer limits."""

import math

import jax
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import j0

import lubjax
from lubjax import _layer


def _bvp_transfer(t, nu, interface):
    """C(t) from the plane-strain layer BVP solved as a 4×4 linear system (k = 1, G = 1, H = t).

    u_x = U(z) sin x, u_z = W(z) cos x, z downward from the surface; Navier's equations give
    U = Σ± (A± + B± z) e^{±z}, W = -(A+ + B+ z - κB+) e^{z} + (A- + B- z + κB-) e^{-z}
    (each basis solution checked below). Surface: σ_zz = -1, σ_xz = 0; base z = t: bonded
    U = W = 0, frictionless W = σ_xz = 0. C = W(0) E*/2 (the half-space has W(0) = 2/E*).
    """
    kappa = 3 - 4 * nu
    lam = 2 * nu / (1 - 2 * nu)

    def fields(z):
        ep, em = math.exp(z), math.exp(-z)
        # Rows: coefficients of (A+, B+, A-, B-) in U, W, U', W'.
        U = np.array([ep, z * ep, em, z * em])
        W = np.array([-ep, -(z - kappa) * ep, em, (z + kappa) * em])
        dU = np.array([ep, (1 + z) * ep, -em, (1 - z) * em])
        dW = np.array([-ep, -(1 + z - kappa) * ep, -em, (1 - z - kappa) * em])
        return U, W, dU, dW

    def stresses(z):
        U, W, dU, dW = fields(z)
        return lam * (U + dW) + 2 * dW, dU - W  # σ_zz, σ_xz (cos, sin amplitudes)

    rows, rhs = [], []
    szz, sxz = stresses(0.0)
    rows += [szz, sxz]
    rhs += [-1.0, 0.0]
    U, W, _, _ = fields(t)
    rows += [U, W] if interface == "bonded" else [W, stresses(t)[1]]
    rhs += [0.0, 0.0]
    coef = np.linalg.solve(np.array(rows), np.array(rhs))

    # Each of the four basis solutions satisfies Navier's equations (k = G = 1) exactly.
    z = 0.5 * t
    U, W, dU, dW = fields(z)
    ep, em = math.exp(z), math.exp(-z)
    d2U = np.array([ep, (2 + z) * ep, em, (z - 2) * em])
    d2W = np.array([-ep, -(2 + z - kappa) * ep, em, (z + kappa - 2) * em])
    scale = (lam + 2) * (ep + em) * (1 + z + kappa)
    assert np.abs(-(lam + 2) * U + d2U - (lam + 1) * dW).max() < 1e-13 * scale
    assert np.abs((lam + 1) * dU - W + (lam + 2) * d2W).max() < 1e-13 * scale
    w_surface = fields(0.0)[1] @ coef
    e_star = 2 / (1 - nu)  # E/(1-ν²) with E = 2G(1+ν), G = 1
    return w_surface * e_star / 2


@pytest.mark.parametrize("interface", ["bonded", "frictionless"])
@pytest.mark.parametrize("nu", [-0.5, 0.0, 0.3, 0.45, 0.4999])
def test_transfer_function_solves_the_layer_bvp(interface, nu):
    for t in (0.01, 0.2, 1.0, 2.5, 6.0):
        ref = _bvp_transfer(t, nu, interface)
        assert _layer.transfer(t, nu, interface) == pytest.approx(ref, rel=1e-9, abs=1e-13)
    # Far tail: C - 1 written without cancellation, and the cut-off t_max where it drops out.
    tm = _layer._t_max(nu, interface)
    assert 15 < tm < 30 and abs(_layer.transfer_minus_one(tm, nu, interface)) < 1e-17


def test_thin_limits_of_the_transfer_function():
    t = 1e-3
    nu = 0.3
    assert _layer.transfer(t, nu, "bonded") == pytest.approx(
        t * (1 - 2 * nu) / (2 * (1 - nu) ** 2), rel=1e-5)
    assert _layer.transfer(t, 0.5, "bonded") == pytest.approx(2 * t**3 / 3, rel=1e-5)
    # Frictionless: C = t/2 + O(t⁵) for every ν (the layer slides on its base).
    for nu in (0.0, 0.3, 0.5):
        assert _layer.transfer(t, nu, "frictionless") == pytest.approx(t / 2, rel=1e-10)


def _hat(r, j, s):
    s = np.asarray(s, float)
    out = np.zeros_like(s)
    if j > 0:
        a, b = r[j - 1], r[j]
        m = (s >= a) & (s <= b)
        out[m] = (s[m] - a) / (b - a)
    if j < r.size - 1:
        a, b = r[j], r[j + 1]
        m = (s >= a) & (s <= b)
        out[m] = (b - s[m]) / (b - a)
    return out


def _real_space_entry(r, i, j, thickness, nu, interface):
    """ΔŴ_ij = ∫ φ_j(s) s D(s, r_i) ds with D(s, r) = (4/π)∫₀^∞ (C - 1) J₀(ks) J₀(kr) dk,
    both by adaptive scipy quadrature (order of integration swapped against the module)."""
    k_max = 40.0 / thickness  # |C - 1| < 1e-30 beyond

    def kernel(s):
        f = lambda k: (_layer.transfer_minus_one(k * thickness, nu, interface)  # noqa: E731
                       * j0(k * s) * j0(k * r[i]))
        return 4 / math.pi * quad(f, 0, k_max, limit=2000, epsabs=1e-15, epsrel=1e-13)[0]

    total = 0.0
    for a, b in ((r[max(j - 1, 0)], r[j]), (r[j], r[min(j + 1, r.size - 1)])):
        if b > a:
            total += quad(lambda s: _hat(r, j, s)[()] * s * kernel(s), a, b,
                          epsabs=1e-14, epsrel=1e-12)[0]
    return total


@pytest.mark.parametrize("thickness,nu,interface", [(1.0, 0.5, "bonded"),
                                                    (0.4, 0.3, "frictionless")])
def test_entries_match_real_space_quadrature(thickness, nu, interface):
    mesh = lubjax.graded_mesh(dr=0.1, r_fine=1.0, length=6.0, growth=1.3)
    r = mesh.r
    n = r.size
    delta = _layer.layer_correction(mesh, thickness, nu, interface)
    scale = np.abs(lubjax.stepper.influence_matrix(mesh)).max()
    for i, j in [(0, 0), (4, 4), (4, 5), (0, n - 1), (n - 1, 2), (n - 2, n - 1)]:
        ref = _real_space_entry(r, i, j, thickness, nu, interface)
        assert abs(delta[i, j] - ref) <= 1e-11 * scale, (i, j, delta[i, j], ref)  # measured 2e-14


@pytest.mark.parametrize("interface", ["bonded", "frictionless"])
def test_a_thick_layer_is_the_half_space(interface):
    """H̄ → ∞: ΔŴ_ij = -(4/π)(c₀/H̄) φ̃_j(0) + O(L̄²/H̄³), c₀ = ∫₀^∞ (1 - C(t)) dt, φ̃_j(0) = ∫φ_j s ds
    (odd powers of 1/H̄ only: φ̃_j(k) J₀(k r̄_i) is even in k). The rigid base at depth H̄ lifts
    the whole surface by ∝ F/H̄ (the half-space's far field w ∝ F/r is cut off at r ~ H̄), so
    the matrices converge only as 1/H̄: on this mesh (L̄ = 20) max|Ŵ_layer - Ŵ_half| is 1.8e-3
    of the largest entry at H̄ = 10⁴ and 1e-6 needs H̄ ~ 10⁷. Beyond the leading term the
    remainder is 7e-6 at H̄ = 10³ and falls as H̄⁻³."""
    mesh = lubjax.graded_mesh(dr=0.05, r_fine=1.0, length=20.0, growth=1.2)
    half = lubjax.stepper.influence_matrix(mesh, weighted=False)  # the layer's representation
    c0 = quad(lambda t: -_layer.transfer_minus_one(t, 0.5, interface), 0, 60, limit=200)[0]
    # ∫ φ_j s ds of the plain hats (ΔŴ's representation; Ŵ_half weights them, lubjax/_layer.py)
    r = mesh.r
    moment = np.zeros_like(r)
    moment[:-1] += np.diff(r) * (2 * r[:-1] + r[1:]) / 6
    moment[1:] += np.diff(r) * (r[:-1] + 2 * r[1:]) / 6
    scale = np.abs(half).max()
    rest = {}
    for thickness in (1e3, 1e4):
        layer = lubjax.stepper.layer_influence_matrix(mesh, thickness, 0.5, interface)
        lead = -(4 / np.pi) * c0 / thickness * np.broadcast_to(moment, half.shape)
        rest[thickness] = np.abs(layer - half - lead).max() / scale
    assert rest[1e3] < 1e-5 and rest[1e4] == pytest.approx(rest[1e3] * 1e-3, rel=0.01), rest
    layer = lubjax.stepper.layer_influence_matrix(mesh, 1e7, 0.5, interface)
    assert np.abs(layer - half).max() < 2e-6 * scale


def _gaussian_case(thickness, nu, interface, width=2.0):
    mesh = lubjax.graded_mesh(dr=0.01, r_fine=3 * width, length=8 * width, growth=1.05)
    r = mesh.r
    p = np.exp(-((r / width) ** 2))
    w = -lubjax.stepper.layer_influence_matrix(mesh, thickness, nu, interface) @ p
    return r, p, w


@pytest.mark.parametrize("interface", ["bonded", "frictionless"])
def test_thin_compressible_layer_is_a_winkler_foundation(interface):
    """ν = 0.3, Gaussian pressure of width 2 ≫ H̄. Dimensional Winkler laws (w = -p H/k):
    bonded, uniaxial strain, k = (1-ν)E/((1-2ν)(1+ν)); frictionless k = E* (the layer slides on
    its base). In eq 8 units (p = (2E*/π)√(d_c/R) p̄, H = H̄√(R d_c)) both read
    w̄ = -(2/π) H̄ p̄ × {(1-2ν)/(1-ν)² bonded, 1 frictionless}. The bonded error shrinks like
    (H̄/width)² (C = c₁t + c₃t³); the frictionless C = t/2 + O(t⁵), its error is at the mesh's
    interpolation floor."""
    nu = 0.3
    factor = (1 - 2 * nu) / (1 - nu) ** 2 if interface == "bonded" else 1.0
    hs = np.array([0.05, 0.1, 0.2])
    errors = []
    for h in hs:
        r, p, w = _gaussian_case(h, nu, interface)
        winkler = -(2 / np.pi) * h * factor * p
        errors.append(np.abs(w - winkler).max() / np.abs(winkler).max())
    errors = np.array(errors)
    if interface == "bonded":
        slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
        assert 1.8 < slope < 2.2 and errors[0] < 3e-4, (slope, errors)
    else:
        assert np.all(errors < 1e-4) and errors[-1] > errors[0], errors


def test_thin_incompressible_bonded_layer():
    """ν = ½, bonded: w = (H³/(3G)) ∇²p (E* = 4G), i.e. w̄ = (8/(3π)) H̄³ ∇̄²p̄; the next term of
    C = (2t³/3)(1 - 9t²/5) makes the error ∝ (H̄/width)²."""
    hs = np.array([0.05, 0.1, 0.2])
    width = 2.0
    errors = []
    for h in hs:
        r, p, w = _gaussian_case(h, 0.5, "bonded", width)
        lap = p * (4 * r**2 / width**4 - 4 / width**2)
        thin = 8 / (3 * np.pi) * h**3 * lap
        errors.append(np.abs(w - thin).max() / np.abs(thin).max())
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.7 < slope < 2.2 and errors[0] < 0.015, (slope, errors)


def test_matrix_is_cached_and_read_only():
    mesh = lubjax.graded_mesh(dr=0.05, r_fine=1.0, length=10.0, growth=1.2)
    a = lubjax.Layer(2.0).influence(mesh)
    assert a is lubjax.stepper.layer_influence_matrix(mesh, 2.0, 0.5, "bonded")
    assert not a.flags.writeable and a.dtype == np.float64 and a.shape == (mesh.size,) * 2


def test_too_thin_a_layer_for_the_mesh_is_refused():
    mesh = lubjax.Settings().mesh()
    with pytest.raises(ValueError, match=r"thickness H̄ = 0\.01 .*shorter mesh"):
        lubjax.Layer(0.01).influence(mesh)
    # The same layer on a short mesh is fine.
    lubjax.Layer(0.01).influence(lubjax.graded_mesh(dr=0.005, r_fine=0.5, length=2.0))


@pytest.mark.parametrize("kwargs", [dict(thickness=0.0), dict(thickness=-1.0),
                                    dict(thickness=float("nan")), dict(thickness=1.0, poisson=0.6),
                                    dict(thickness=1.0, poisson=-1.0),
                                    dict(thickness=1.0, interface="glued")])
def test_bad_layers_are_refused(kwargs):
    with pytest.raises(ValueError, match="Layer"):
        lubjax.Layer(**kwargs)


def test_a_traced_layer_is_refused_with_a_reason():
    """A derivative in the layer's thickness or Poisson's ratio (or a vmap over them) is not
    available (the influence matrix is built outside JAX): said as such, not as a value out of
    range. A layer passed through jit is rebuilt from its static fields and still runs."""
    for field in ("thickness", "poisson"):
        with pytest.raises(NotImplementedError, match="Layer.thickness and Layer.poisson"):
            jax.grad(lambda x, f=field: lubjax.Layer(**{"thickness": 10.0, f: x}).thickness)(
                0.4 if field == "poisson" else 10.0)
    layer = jax.jit(lambda s: s)(lubjax.Layer(10.0, 0.4))
    assert (layer.thickness, layer.poisson, layer.interface) == (10.0, 0.4, "bonded")


def test_layer_thickness_bar():
    # The paper's sample: H = 5 mm, R = 2 mm, d_c = 140 μm.
    assert lubjax.layer_thickness_bar(5e-3, 2e-3, 140e-6) == pytest.approx(
        5e-3 / math.sqrt(2e-3 * 140e-6))
    for bad, name in [((0.0, 2e-3, 1e-4), "H"), ((1e-3, -2e-3, 1e-4), "R"),
                      ((1e-3, 2e-3, float("inf")), "d_c"), ((True, 2e-3, 1e-4), "H")]:
        with pytest.raises(ValueError, match=rf"\b{name} must be"):
            lubjax.layer_thickness_bar(*bad)


def _dry_contact(W, r, delta):
    """Frictionless dry contact of the rigid paraboloid at depth δ̄: p̄ ≥ 0, gap
    -δ̄ + r̄²/2 + Ŵp̄ ≥ 0, complementary (active-set iteration on the contact nodes)."""
    contact = r < 0.9 * math.sqrt(2 * delta)
    for _ in range(100):
        p = np.zeros_like(r)
        p[contact] = np.linalg.solve(W[np.ix_(contact, contact)], delta - r[contact] ** 2 / 2)
        gap = -delta + r**2 / 2 + W @ p
        new = (contact & (p > 0)) | (~contact & (gap < 0))
        if np.array_equal(new, contact):
            return p
        contact = new
    raise AssertionError("active set did not settle")


def test_dry_contact_on_a_thin_incompressible_bonded_layer():
    """A rigid sphere pressed δ into a bonded incompressible layer with a ≫ H: the thin-layer
    equation w = (H³/(3G))∇²p with w = -(δ - r²/(2R)) inside, p = p' = 0 at the edge, gives
    p = 3G(a² - r²)²/(32 H³ R), a² = 4Rδ, F = 2πGR²δ³/H³ (the δ³ law of thin incompressible
    layers, against Hertz's δ^{3/2}); in eq 8 units F̄ = π²δ̄³/(4H̄³). The computed force tends
    to it with an error ∝ (H/a)^1.9 (measured: 18 %, 4.9 %, 1.3 % at H/a = 0.1, 0.05, 0.025;
    the 4.9 % is the same, 1.04879, on a mesh twice as fine at H̄ = 0.05, δ̄ = 0.25)."""
    thickness = 0.1
    mesh = lubjax.graded_mesh(dr=0.01, r_fine=4.5, length=8.0, growth=1.1)
    r = mesh.r
    W = lubjax.stepper.layer_influence_matrix(mesh, thickness, 0.5, "bonded")
    c = lubjax.stepper.force_weights(mesh)
    deltas = np.array([0.25, 1.0, 4.0])
    excess = np.array([c @ _dry_contact(W, r, d) / (np.pi**2 * d**3 / (4 * thickness**3)) - 1
                       for d in deltas])
    ratio = thickness / (2 * np.sqrt(deltas))  # H/a
    slope = np.polyfit(np.log(ratio), np.log(excess), 1)[0]
    assert np.all(excess > 0) and excess[-1] < 0.015 and 1.6 < slope < 2.2, (excess, slope)


# --- Dry contact on a bonded incompressible layer of finite thickness (issue 10) ---------------


def _contact_edge(r, p):
    """Contact radius ā: the zero of p̄², linear in r̄ near a smooth Hertz-like edge
    (p ∝ √(a - r)), fitted through the last three loaded nodes."""
    k = np.nonzero(p > 0)[0][-1]
    slope, icpt = np.polyfit(r[k - 2:k + 1], p[k - 2:k + 1] ** 2, 1)
    return -icpt / slope


def _layer_contact_mesh():
    # H̄ = 1 is the unit: ā = a/h. Δr̄ = 0.005 (a/h = 0.2 spans 40 cells); the base cuts the
    # far field off at r ~ H, so L̄ = 20 H loses nothing. Results move < 0.7 % at Δr̄ = 0.0025.
    mesh = lubjax.graded_mesh(dr=0.005, r_fine=1.2, length=20.0, growth=1.1)
    return mesh, lubjax.stepper.layer_influence_matrix(mesh, 1.0, 0.5, "bonded")


def test_dry_contact_on_a_thick_bonded_layer_matches_its_asymptotics():
    """Rigid sphere, frictionless, on a bonded ν = ½ layer with a ≪ h: exact leading terms.

    For h ≫ a only k ≲ 1/h feels the base, where p̃(k)J₀(kr) ≈ (P/2π)(1 - k²(r² + ⟨s²⟩)/4), so the
    base adds Δw = (P/(πE*))[c₀/h - c₂(r² + ⟨s²⟩)/(4h³)] (c_n = ∫₀^∞ (1 - C(t)) tⁿ dt): a uniform
    lift (the 1/H̄ of test_a_thick_layer_is_the_half_space) and, at order (a/h)³, a curvature.
    The lift turns Hertz into δ + P c₀/(πE*h) = a²/R, so at fixed δ the load ratio
    q = P/P_Hertz(δ) solves q = (1 + A q x)^{3/2}, x = √(Rδ)/h, A = 4c₀/(3π):
    q = 1 + (3/2)A x + (21/8)A² x² + O(x³). Tested on F̄_layer(δ̄)/F̄_half(δ̄) on one mesh (the
    mesh's own error cancels; no contact radius needed): measured 1.126 and 1.44 against
    2c₀/π = 1.127 and (21/8)A² = 1.48 (the fitted x³ term absorbs some of the x²)."""
    mesh, W = _layer_contact_mesh()
    r = mesh.r
    half = lubjax.stepper.influence_matrix(mesh)
    c = lubjax.stepper.force_weights(mesh)
    c0 = quad(lambda t: -_layer.transfer_minus_one(t, 0.5, "bonded"), 0, 60, limit=200)[0]
    A = 4 * c0 / (3 * math.pi)
    x = np.array([0.1, 0.15, 0.2, 0.25, 0.3, 0.35])
    excess = np.array([c @ _dry_contact(W, r, d) / (c @ _dry_contact(half, r, d)) - 1
                       for d in x**2])
    a1, a2, _ = np.linalg.lstsq(np.c_[x, x**2, x**3], excess, rcond=None)[0]
    assert a1 == pytest.approx(1.5 * A, rel=0.01), (a1, 1.5 * A)
    assert a2 == pytest.approx(21 / 8 * A**2, rel=0.1), (a2, 21 / 8 * A**2)


def _shull_table():
    mesh, W = _layer_contact_mesh()
    r = mesh.r
    c = lubjax.stepper.force_weights(mesh)
    rows = []
    for d in (0.04, 0.09, 0.16, 0.25, 0.36, 0.49, 0.64):
        p = _dry_contact(W, r, d)
        x = _contact_edge(r, p)  # a/h
        load = (c @ p) / (2 * math.pi / 3 * x**3)  # P/P_H at this a (F̄_H = 2πā³/3)
        rows.append((x, load, 1 + 0.33 * x**3, d / x**2, 0.4 + 0.6 * math.exp(-1.8 * x)))
    return np.array(rows)


@pytest.mark.xfail(strict=True, reason="Shull's fitted corrections disagree with the exact "
                   "small-a/h terms and with the converged layer solution (docstring)")
def test_shull_finite_thickness_correction():
    """Shull's correction for a rigid sphere on a bonded ν = ½ layer (Shull, Mater. Sci. Eng. R
    36 (2002) 1; Shull et al., Macromol. Chem. Phys. 199 (1998) 489): P = P_H(1 + 0.33(a/h)³),
    δ = δ_H(0.4 + 0.6 e^{-1.8a/h}), P_H = 4E*a³/(3R), δ_H = a²/R; asserted here to 5 % over
    a/h = 0.2-1. Not confirmed: the library holds Shull's review only as an abstract, so the
    forms, the indenter's boundary condition in his finite-element fits (frictionless or no
    slip) and his stated accuracy are as the issue gives them, not re-read.

    It fails. The lubjax solution (frictionless sphere, the layer's exact kernel; Δr̄ = 0.005,
    within 0.7 % of Δr̄ = 0.0025), a/h: P/P_H [Shull] ; δ/δ_H [Shull]
        0.22: 1.013 [1.003] ; 0.848 [0.806]     0.48: 1.071 [1.036] ; 0.707 [0.655]
        0.77: 1.225 [1.151] ; 0.607 [0.550]     1.08: 1.487 [1.419] ; 0.546 [0.485]
    P(a) is within 3.4 % of Shull up to a/h ≈ 0.5, 5.0 % at 0.62, 6.5 % at 0.77-0.93; δ(a) is
    5-12 % off throughout (growing with a/h).
    Cause: the formulas' small-a/h terms are not the layer's. Exactly (see the asymptotics test
    above), δ/δ_H = 1 - (4c₀/3π)(a/h) + O((a/h)³) with 4c₀/(3π) = 0.751, where Shull's form has
    slope 1.08 (the uniform lift depends only on P and the layer, not on indenter friction), and
    P/P_H = 1 + (2c₂/3π)(a/h)³ + ... with 2c₂/(3π) = 0.813, not 0.33 (0.336 is the coefficient of
    a *frictionless* base). The measured (P/P_H - 1)/(a/h)³ falls from ≈ 0.8 toward 0.38 at
    a/h = 1.08, crossing 0.33 near a/h = 1.2, so a cubic with 0.33 can only be a fit over a
    wider range. The derivation and the test above are independent of Shull; this test records
    the disagreement (strict xfail: it is reported if it ever passes)."""
    t = _shull_table()
    x, load, load_shull, disp, disp_shull = t.T
    assert x.min() < 0.25 and x.max() > 1.0
    inside = x <= 1.0
    assert np.all(np.abs(load / load_shull - 1)[inside] < 0.05), t
    assert np.all(np.abs(disp / disp_shull - 1)[inside] < 0.05), t


@pytest.mark.slow
def test_a_layer_runs_a_smooth_start_on_the_default_mesh():
    """The stage's first-order lag (data/make_synthetic.py: v = 0 at the start) on a 5 mm layer,
    default Settings. This run's steps used to collapse to 1e-15 at t̄ = 2.4e-7 (a strict xfail
    here, and the layer traces of data/ were made with the force floor raised 100× to get
    through). Cause: the travel's increment Δz̄ was formed as (z̄0 - d̄(tⁿ⁺¹)) - z̄ⁿ, a difference
    of O(1) gaps, so below Δt̄ ~ 1e-11 (Δz̄ ~ 1e-16 in the t̄² start) it was rounded to the ulp of
    z̄: 0 or 2.2e-16 depending on Δt̄, and the squeeze velocity with it. The layer's force, 97 %
    far-field squeeze pressure at that moment, jumped 15 % between attempts that differed only
    in Δt̄, which no error test passes. Now Δz̄ = d̄(tⁿ) - d̄(tⁿ⁺¹) (lubjax/_drives.py). Checked
    pointwise against the same run at rtol 1e-6 (measured max 2.5e-3 relative, at t̄ = 1e-6
    where F̄ is 2e-7 of its value at t̄ = 0.01)."""
    tau = 0.05 / 1.26  # the stage lag in units of t_c (d_c = 126 μm)
    s = np.linspace(0.0, 0.01, 2001)
    d = s - tau * (1 - np.exp(-s / tau))
    drive = lubjax.Travel(lubjax.SampledTravel(s, d, breakpoints=(0.0,)))
    layer = lubjax.Layer(9.96)
    res = lubjax.relax(41.4, 1.11, 0.01, drive=drive, substrate=layer,
                       settings=lubjax.Settings(error_estimate=False))
    assert res.ok and res.accepted < 1000
    ref = lubjax.relax(41.4, 1.11, 0.01, drive=drive, substrate=layer,
                       settings=lubjax.Settings(rtol=1e-6, error_estimate=False))
    t = np.geomspace(1e-6, 0.01, 9)
    assert np.max(np.abs(res.at(t) / ref.at(t) - 1)) < 5e-3
