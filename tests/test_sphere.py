r"""The sphere's true profile (``lubjax.Sphere``) for deep indentation, against Sneddon's rigid
sphere on the half-space.

Sneddon's closed form (``lubjax.sneddon_sphere``) is checked first against his general
axisymmetric punch integrals by quadrature, and against Hertz as a/R → 0; then the solver's
near-dry hold against it at δ/R from 0.1 to 0.9, its convergence under mesh refinement at the
observed order, the paraboloid as ε = d_c/R → 0, a held film converging onto it, the
derivatives and batches in ε, the mesh rule's contact radius and the command line's limits.

Scales: δ/R = ε δ̄ and a/R = √ε ā (δ̄ = δ/d_c, ā = a/√(R d_c)); Sneddon's F/(E* R²) is
F̄ = (π/2) ε^{-3/2} F/(E* R²) (eq 11b).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

import lubjax
from lubjax import Sphere, sneddon_sphere
from lubjax._cli import main as lubjax_main
from lubjax._mesh import final_contact_radius

FAST = lubjax.Settings(rtol=1e-3, error_estimate=False)
#: A near-dry hold: at β = 10⁸ the film left at t̄ = 20 is h̄ ~ 10⁻⁵, below every tolerance here.
DRY_BETA, DRY_T = 1e8, 20.0


def sneddon_force_bar(eps, z0):
    """Sneddon's dry force in the units of eq 11b for the run's final depth δ̄ = 1 - z̄0."""
    depth = eps * (1.0 - z0)
    a = brentq(lambda x: sneddon_sphere(x)[0] - depth, 1e-12, 1.0 - 1e-15, xtol=1e-15)
    return float(sneddon_sphere(a)[1]) * np.pi / 2.0 * eps**-1.5


@pytest.mark.parametrize("a", [0.05, 0.3, 0.6, 0.9, 0.99])
def test_sneddon_closed_form_is_his_punch_integrals(a):
    # Sneddon (1965): a punch of profile f(r) presses δ = ∫₀^a f'(x) a/√(a² - x²) dx and
    # F = 2E* ∫₀^a x² f'(x)/√(a² - x²) dx; the sphere's f' = x/√(R² - x²), R = 1.
    def slope(x):
        return x / np.sqrt(1.0 - x * x)

    kw = dict(weight="alg", wvar=(0.0, -0.5), epsabs=0, epsrel=1e-13, limit=200)
    # a/√(a²-x²) = a/√(a+x) · (a-x)^{-1/2}: the endpoint singularity goes to the quadrature weight
    depth = quad(lambda x: slope(x) * a / np.sqrt(a + x), 0.0, a, **kw)[0]
    force = 2.0 * quad(lambda x: x * x * slope(x) / np.sqrt(a + x), 0.0, a, **kw)[0]
    d, f = sneddon_sphere(a)
    assert d == pytest.approx(depth, rel=1e-11)
    assert f == pytest.approx(force, rel=1e-11)


def test_sneddon_tends_to_hertz():
    a = np.array([1e-4, 1e-3, 1e-2])
    d, f = sneddon_sphere(a)
    # δ = a² (1 + a²/3 + ...), F = (4/3) a³ (1 + ...): Hertz's δ = a²/R, F = (4/3) E* a³/R
    assert np.allclose(d / a**2 - 1, a**2 / 3, rtol=1e-3, atol=1e-15)
    assert np.allclose(f / (4 / 3 * a**3), 1.0, rtol=2 * a[-1] ** 2)


def test_sphere_profile_is_the_sphere_and_continues_past_the_equator():
    eps = 0.5
    r = np.linspace(0.0, 3.0, 301)
    s = Sphere(eps).profile(r)
    on = eps * r**2 < 1
    radius = 1.0 / eps  # R in units of d_c; r̄√(R d_c) = r̄ √ε R
    exact = radius - np.sqrt(radius**2 - r[on] ** 2 / eps)
    assert np.allclose(s[on], exact, rtol=1e-13, atol=1e-15)
    edge = 1.0 / np.sqrt(eps)
    # √(1 - ε r̄²) at the rounded equator: ~1e-8, the sphere's vertical tangent
    assert Sphere(eps).profile(np.array([edge]))[0] == pytest.approx(1.0 / eps, rel=1e-7)
    assert np.all(np.diff(s) > 0)  # a gap growing outward, continuous through the equator
    assert np.array_equal(Sphere(0.0).profile(r), lubjax.Paraboloid().profile(r))
    # the sphere lies above its paraboloid: the same depth presses a smaller contact
    assert np.all(s[1:] > 0.5 * r[1:] ** 2)
    g = jax.grad(lambda e: jnp.sum(Sphere(e).profile(jnp.asarray(r))))(eps)
    assert np.isfinite(g)


def test_the_mesh_rule_refines_sneddons_contact_edge():
    eps, z0 = 0.5, 0.1
    a = final_contact_radius(lubjax.Travel(), z0, 0.014, Sphere(eps))
    depth = sneddon_sphere(a * np.sqrt(eps))[0] / eps
    assert depth == pytest.approx(1.0 - z0, rel=1e-12)
    assert a < final_contact_radius(lubjax.Travel(), z0, 0.014)  # Hertz's √(1 - z̄0)
    assert Sphere(1e-9).contact_radius(0.9) == pytest.approx(np.sqrt(0.9), rel=1e-9)


def test_a_load_on_the_sphere_sinks_to_sneddons_depth_and_the_mesh_follows():
    """Under a load the sphere's dry depth is Sneddon's (deeper than Hertz's, 2 % at
    δ∞ = 0.3 R): depth_under_load inverts sneddon_sphere, the mesh refines that contact's edge,
    and a near-dry creep ends there to 3e-4 where Hertz's depth is 2 % off."""
    eps, load = 0.3, 2.0 * np.pi / 3.0  # the Load's plateau: Hertz's depth 1
    sphere = Sphere(eps)
    depth = sphere.depth_under_load(load)
    x = sphere.contact_radius(depth) * np.sqrt(eps)
    assert sneddon_sphere(x)[1] * np.pi / 2 / eps**1.5 == pytest.approx(load, rel=1e-10)
    assert lubjax.Paraboloid().depth_under_load(load) == pytest.approx(1.0, rel=1e-14)
    assert Sphere(1e-9).depth_under_load(load) == pytest.approx(1.0, rel=1e-6)
    edge = final_contact_radius(lubjax.Load(), 0.5, 0.014, sphere)
    assert edge == pytest.approx(sphere.contact_radius(depth), rel=1e-12)
    res = lubjax.relax(1e6, 0.5, 5.0, drive=lubjax.Load(), indenter=sphere)
    assert -res.gap[-1] == pytest.approx(depth, rel=3e-4)
    assert abs(depth - 1.0) > 50 * abs(-res.gap[-1] / depth - 1)


@pytest.mark.parametrize("eps, z0", [(0.1, 0.05), (0.35, 0.1), (0.6, 0.1), (0.95, 0.05)])
def test_near_dry_hold_is_sneddons_sphere(eps, z0):
    res = lubjax.relax(DRY_BETA, z0, DRY_T, settings=FAST, indenter=Sphere(eps))
    sneddon = sneddon_force_bar(eps, z0)
    assert res.force[-1] == pytest.approx(sneddon, rel=3e-4)
    # and where it matters: the paraboloid is off by far more than that (Hertz's force)
    hertz = float(lubjax.hertz_force(z0))
    assert abs(hertz / sneddon - 1) > 20 * abs(res.force[-1] / sneddon - 1)


@pytest.mark.slow
def test_sphere_converges_under_mesh_refinement():
    eps, z0 = 0.6, 0.1
    sneddon = sneddon_force_bar(eps, z0)
    drs = np.array([0.056, 0.04, 0.028, 0.02, 0.014])
    errors = []
    for dr in drs:
        settings = lubjax.Settings(rtol=1e-4, error_estimate=False, dr=dr, contact_radius=None)
        res = lubjax.relax(DRY_BETA, z0, DRY_T, settings=settings, indenter=Sphere(eps))
        errors.append(res.force[-1] / sneddon - 1)
    errors = np.abs(errors)
    # measured: 1.2e-3, 4.8e-4, -4.6e-5 (the contact's edge crossing a node), 1.1e-4, 5.6e-5:
    # order ~2 with the scatter of an edge moving through the cells, below the 3/2 of the √
    # edge that the error estimate assumes (lubjax/_solve.py) everywhere
    order = np.polyfit(np.log(drs), np.log(errors), 1)[0]
    assert 1.5 < order < 3.0, (order, errors)
    assert np.all(errors < 0.1 * drs**1.5), errors


def test_paraboloid_is_the_sphere_as_epsilon_vanishes():
    base = lubjax.relax(100.0, 0.5, 2.0, settings=FAST)
    same = lubjax.relax(100.0, 0.5, 2.0, settings=FAST, indenter=Sphere(0.0))
    assert np.array_equal(base.force, same.force)
    forces = [lubjax.relax(100.0, 0.5, 2.0, settings=FAST, indenter=Sphere(e)).force[-1]
              for e in (1e-4, 1e-3, 1e-2)]
    gaps = np.abs(np.array(forces) / base.force[-1] - 1)
    # the sphere departs from the paraboloid linearly in ε (s = r̄²/2 + ε r̄⁴/8 + ...)
    assert gaps[0] < 1e-4
    assert gaps[2] / gaps[1] == pytest.approx(10.0, rel=0.2)
    assert gaps[1] / gaps[0] == pytest.approx(10.0, rel=0.2)


def test_rigid_squeeze_film_of_the_true_sphere():
    # β = 10⁶, z̄0 = 2 (no contact: rigid, eq 12b's limit) with ε = 0.05: Reynolds' film under
    # a rigid approach, p̄' = ż̄ r̄/(2β h̄³), p̄(L̄) = 0, gives F̄ = π(-ż̄)/(2β) ∫₀^L̄ r̄³/h̄³ dr̄
    # with h̄ = z̄ + s(r̄): 1/z̄ for the paraboloid, by quadrature for the sphere.
    beta, z0, eps = 1e6, 2.0, 0.05
    settings = lubjax.Settings(rtol=1e-5, error_estimate=False)
    res = lubjax.relax(beta, z0, 0.5, settings=settings, indenter=Sphere(eps))
    length, times = res.r[-1], np.linspace(0.1, 0.5, 5)
    edge = 1.0 / np.sqrt(eps)

    def integral(z):
        def f(r):
            return r**3 / (z + Sphere(eps).profile(np.array([r]))[0]) ** 3

        return sum(quad(f, lo, hi, epsrel=1e-12, limit=200)[0]
                   for lo, hi in ((0.0, edge), (edge, 10 * edge), (10 * edge, length)))

    exact = np.array([np.pi / (2 * beta) * integral(z0 - t) for t in times])
    assert np.max(np.abs(res.at(times) / exact - 1)) < 1e-3
    # the paraboloid's 1/z̄ is ~40 % above it at h/R = 0.075-0.1: the squeeze film's r̄⁻⁴ tail
    # reaches r ~ R, where the two part (relative -3 (h/R) ln(R/h) as h/R → 0)
    paraboloid = np.pi / (2 * beta * (z0 - times))
    assert np.all(paraboloid / exact - 1 > 0.3)


@pytest.mark.slow
def test_sphere_with_a_draining_film_tends_to_sneddon():
    eps, z0 = 0.6, 0.1
    sneddon = sneddon_force_bar(eps, z0)
    excess = []
    for beta in (1e3, 1e5):
        res = lubjax.relax(beta, z0, 200.0, settings=FAST, indenter=Sphere(eps))
        excess.append(res.force[-1] / sneddon - 1)
    # a film still in the contact adds force (δ̄ + h̄ pressed), less as it drains faster
    assert 0 < excess[1] < excess[0] < 0.05


@pytest.mark.slow
def test_sphere_derivatives_and_batches_in_epsilon():
    def peak(e):
        return lubjax.relax(100.0, 0.5, 1.0, settings=FAST, indenter=Sphere(e)).at([1.0])[0]

    eps, h = 0.3, 1e-4
    slope = jax.grad(peak)(eps)
    fd = (peak(eps + h) - peak(eps - h)) / (2 * h)
    assert float(slope) == pytest.approx(float(fd), rel=1e-3)
    assert float(slope) < 0  # the sphere's higher gap carries less force
    batch = jax.vmap(peak)(jnp.array([0.1, 0.3]))
    one = lubjax.relax(100.0, 0.5, 1.0, settings=FAST, mesh=FAST.mesh(),
                       indenter=Sphere(0.3)).at([1.0])[0]
    assert float(batch[1]) == pytest.approx(float(one), rel=1e-9)
    assert float(batch[0]) > float(batch[1])


def test_creep_with_the_sphere_compares_with_sneddons_depth(capsys):
    E, R, F, gap = 20e3, 10e-6, 2e-7, 0.5e-6
    args = ["creep", "--E-star", str(E), "--viscosity", "1", "--radius", str(R), "--load",
            str(F), "--ramp-time", "1", "--hold", "1", "--gap", str(gap), "--rtol", "1e-3"]
    # Sneddon's depth in SI: F = E* R² f(a/R), δ = R g(a/R)
    x = brentq(lambda x: sneddon_sphere(x)[1] - F / (E * R**2), 1e-9, 1 - 1e-12, xtol=1e-15)
    sneddon = R * float(sneddon_sphere(x)[0])
    hertz = (3 * F / (4 * E * np.sqrt(R))) ** (2 / 3)
    assert lubjax_main(args + ["--indenter", "sphere"]) == 0
    assert f"(Sneddon: {gap + sneddon:.5g} m)" in capsys.readouterr().out
    assert lubjax_main(args) == 0
    assert f"(Hertz: {gap + hertz:.5g} m)" in capsys.readouterr().out
    assert sneddon > 1.01 * hertz


def test_sphere_validity_and_the_paraboloids_message(capsys):
    si = ["relax", "--E-star", "3.92e6", "--viscosity", "100", "--radius", "2e-3",
          "--speed", "1e-4", "--gap", "1e-4", "--rtol", "1e-3"]
    assert lubjax_main(si + ["--indent", "1e-3"]) == 2
    err = capsys.readouterr().err
    assert "paraboloid indenter models at most 0.2 R" in err and "--indenter sphere" in err
    assert lubjax_main(si + ["--indent", "3e-3", "--indenter", "sphere"]) == 2
    assert "no indenter models more than 1 R" in capsys.readouterr().err
    assert lubjax_main(["relax", "--beta", "100", "--z0", "0.5", "--indenter", "sphere"]) == 2
    assert "--indenter sphere needs the SI parameters" in capsys.readouterr().err
    with pytest.raises(ValueError, match="epsilon"):
        Sphere(1.5)
    with pytest.raises(ValueError, match="indenter must be"):
        lubjax.RelaxationTest(3.92e6, 2e-3, 100.0, 1e-4, 1e-3, 1e-4, indenter="cone")
    test = lubjax.RelaxationTest(3.92e6, 2e-3, 100.0, 1e-4, 1e-3, 1e-4, indenter="sphere")
    assert test.shape == Sphere(0.5)


@pytest.mark.slow
def test_a_fit_with_the_sphere_recovers_a_deep_indentation():
    import fitting

    test = lubjax.RelaxationTest(3.92e6, 2e-3, 100.0, 1e-4, 0.8e-3, 0.1e-3, indenter="sphere")
    times = np.linspace(0.0, 3.0, 241)
    res = lubjax.relax(test.beta, test.z0_bar, 3.0, indenter=test.shape,
                       settings=lubjax.Settings(rtol=1e-5, error_estimate=False))
    trace = fitting.make_trace(times * test.time_scale, np.clip(times, 0, 1) * test.indent,
                               np.asarray(res.at(times)) * test.force_scale, test.radius,
                               name="sphere_0.4R")
    with pytest.raises(ValueError, match="--indenter sphere"):
        fitting.fit_trace(trace, settings=FAST)
    fit = fitting.fit_trace(trace, spec=fitting.ModelSpec(indenter="sphere"), settings=FAST)
    assert fit.values["E_star"] == pytest.approx(test.E_star, rel=2e-2)
    assert fit.values["viscosity"] == pytest.approx(test.viscosity, rel=5e-2)
    assert fit.values["z0"] == pytest.approx(test.gap, rel=5e-2)
