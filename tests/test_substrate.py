"""Substrates against truth: a viscoelastic solid's instantaneous and relaxed limits are the
elastic solver at E*₀ and E*∞, a nearly dry contact relaxes as Lee & Radok's solution, the
Prony conversion inverts the modulus exactly, and the memory differentiates both ways."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import quad

import lubjax

FAST = lubjax.Settings(dr=0.03, error_estimate=False)


def test_elastic_substrate_is_the_default():
    a = lubjax.relax(100, 0.5, 2.0, settings=FAST)
    b = lubjax.relax(100, 0.5, 2.0, substrate=lubjax.HalfSpace(), settings=FAST)
    np.testing.assert_array_equal(a.force, b.force)


@pytest.mark.parametrize("stiffening", [2.0, 5.0])
def test_viscoelastic_limits_are_the_elastic_solver(stiffening):
    """Scaled with the relaxed modulus E*∞: a solid that never relaxes (λ → ∞) is the elastic
    solver at E*₀ = m E*∞, i.e. β → mβ and F̄ → m F̄(mβ); one that relaxes at once is E*∞."""
    times = np.linspace(0.2, 4.0, 20)
    instant = lubjax.Viscoelastic.standard_linear_solid(stiffening, 1e9)
    relaxed = lubjax.Viscoelastic.standard_linear_solid(stiffening, 1e-9)
    f_inst = lubjax.relax(100, 0.5, 4.0, substrate=instant, settings=FAST).at(times)
    f_e0 = stiffening * lubjax.relax(100 * stiffening, 0.5, 4.0, settings=FAST).at(times)
    np.testing.assert_allclose(f_inst, f_e0, rtol=2e-3)
    f_rel = lubjax.relax(100, 0.5, 4.0, substrate=relaxed, settings=FAST).at(times)
    f_einf = lubjax.relax(100, 0.5, 4.0, settings=FAST).at(times)
    np.testing.assert_allclose(f_rel, f_einf, rtol=2e-3)


def _lee_radok(t, stiffening, tau, z0):
    """Lee & Radok (1960): for a growing contact F(t) = (4/3)√R ∫ E*(t - s) d[δ^{3/2}], i.e.
    F̄ = (2π/3) ∫ Ē(t - s) d[δ̄(s)^{3/2}] with δ̄ = t̄ - z̄0 on the ramp; Ē = 1 + (m - 1)e^{-t/τ}."""

    def integrand(s):
        return (1 + (stiffening - 1) * np.exp(-(t - s) / tau)) * 1.5 * (s - z0) ** 0.5

    return 2 * np.pi / 3 * quad(integrand, z0, min(t, 1.0), limit=200)[0]


@pytest.mark.slow
def test_nearly_dry_contact_relaxes_as_lee_radok():
    """At large β the film drains at once and the contact is Hertz's with the modulus's
    history: the force tends to Lee & Radok's as β grows (error ∝ β^-0.6 measured)."""
    m, tau, z0 = 2.0, 1.0, 0.5
    solid = lubjax.Viscoelastic.standard_linear_solid(m, tau)
    times = np.array([0.8, 1.0, 1.5, 2.0, 3.0, 5.0])
    exact = np.array([_lee_radok(t, m, tau, z0) for t in times])
    err = []
    for beta in (1e4, 1e5):
        run = lubjax.relax(beta, z0, 5.0, substrate=solid,
                           settings=lubjax.Settings(error_estimate=False))  # fmt: skip
        err.append(np.max(np.abs(run.at(times) / exact - 1)))
    assert err[1] < 5e-3
    assert err[0] / err[1] > 3


def test_prony_conversion_inverts_the_modulus():
    """s Ē(s) · s J̄(s) = 1 for all s (the compliance is the modulus's inverse in Laplace
    space), and one term reproduces the closed-form standard linear solid."""
    g, tau = np.array([1.5, 0.7, 3.0]), np.array([0.1, 2.0, 30.0])
    solid = lubjax.Viscoelastic.from_prony(g, tau)
    j0, jk, lam = (np.asarray(x) for x in solid.compliance())
    for s in (1e-3, 0.05, 1.0, 7.0, 1e3):
        modulus = 1 + np.sum(g * s / (s + 1 / tau))
        compliance = j0 + np.sum(jk / lam / (s + 1 / lam))
        assert modulus * compliance == pytest.approx(1.0, rel=1e-12)
    one = lubjax.Viscoelastic.from_prony([1.0], [2.0])
    sls = lubjax.Viscoelastic.standard_linear_solid(2.0, 2.0)
    np.testing.assert_allclose(one.retardation, sls.retardation, rtol=1e-12)
    np.testing.assert_allclose(one.times, sls.times, rtol=1e-12)


@pytest.mark.slow
def test_viscoelastic_gradients_reverse_equals_forward():
    """d F̄(t)/d(E₀/E∞, τ) through the internal variables: the checkpointed adjoint = the
    forward replay, and both = central differences (ε sized to the adaptive solution's
    step-choice noise, as in test_stepper)."""
    settings = lubjax.Settings(rtol=1e-6, dr=0.05, length=20.0, mesh_growth=1.2,
                               error_estimate=False)  # fmt: skip
    plan = lubjax.make_plan(3.0, settings=settings, times=np.array([0.5, 1.0, 3.0]))

    def curve(p):
        solid = lubjax.Viscoelastic.standard_linear_solid(p[0], p[1])
        traj = lubjax.stepper.rollout(plan.disc, 50.0, 0.5, plan.drive, plan.t_end, plan.tol,
                              substrate=solid)  # fmt: skip
        return lubjax.stepper.evaluate(traj.steps, plan.t, "force")

    p0 = jnp.array([3.0, 0.7])
    rev = jax.jit(jax.jacrev(curve))(p0)
    fwd = jax.jit(jax.jacfwd(curve))(p0)
    assert np.all(np.isfinite(rev))
    np.testing.assert_allclose(rev, fwd, rtol=1e-6, atol=1e-14)
    f = jax.jit(curve)
    for j in range(2):
        h = 1e-3 * float(p0[j])
        e = jnp.zeros(2).at[j].set(h)
        fd = (np.asarray(f(p0 + e)) - np.asarray(f(p0 - e))) / (2 * h)
        assert np.max(np.abs(fwd[:, j] - fd)) < 2e-3 * np.max(np.abs(fd)), (j, fwd[:, j], fd)


def test_bad_substrates_are_refused():
    with pytest.raises(ValueError, match="stiffening"):
        lubjax.Viscoelastic.standard_linear_solid(0.5, 1.0)
    with pytest.raises(ValueError, match="relaxation_time"):
        lubjax.Viscoelastic.standard_linear_solid(2.0, -1.0)
    with pytest.raises(ValueError, match="retardation"):
        lubjax.Viscoelastic([0.7, 0.4], [1.0, 2.0])
    with pytest.raises(ValueError, match="Layer.thickness"):
        lubjax.Layer(0.0)
    with pytest.raises(ValueError, match="Layer.poisson"):
        lubjax.Layer(3.0, poisson=0.6)
    with pytest.raises(ValueError, match="interface"):
        lubjax.Layer(3.0, interface="glued")
    with pytest.raises(TypeError, match="substrate"):
        lubjax.relax(10, 0.5, substrate="rubber")
