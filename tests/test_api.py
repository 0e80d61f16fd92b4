"""Inputs, outputs, checks, units and the differentiable / vmappable core."""

import dataclasses
import json
import math
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lubjax


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(E_star=0.0), "E_star"),
        (dict(E_star=float("nan")), "E_star"),
        (dict(radius=-1e-3), "radius"),
        (dict(viscosity=0.0), "viscosity"),
        (dict(speed=-1.0), "speed"),
        (dict(indent=0.0), "indent"),
        (dict(gap=float("inf")), "gap"),
    ],
)
def test_invalid_si_inputs_name_the_parameter(kwargs, name):
    base = dict(E_star=3.92e6, radius=2e-3, viscosity=100.0, speed=1e-4, indent=140e-6, gap=140e-6)
    base.update(kwargs)
    with pytest.raises(ValueError, match=name):
        lubjax.RelaxationTest(**base)


@pytest.mark.parametrize("nu", [-1.0, 0.51, float("nan")])
def test_poisson_ratio_range(nu):
    with pytest.raises(ValueError, match=r"\(-1, 0.5\]"):
        lubjax.plane_strain_modulus(2.94e6, nu)


def test_dimensionless_groups_of_the_paper_experiment():
    """Section 3.2 / docs/model.md: E = 2.94 MPa, ν = 0.5, η = 100 Pa s, R = 2 mm, v0 = 0.1 mm/s,
    z0 = 140 μm, d_c = 140 μm gives z̄0 = 1 and β ≈ 54."""
    test = lubjax.RelaxationTest.from_E(
        2.94e6, 0.5, radius=2e-3, viscosity=100.0, speed=1e-4, indent=140e-6, gap=140e-6
    )
    assert test.E_star == pytest.approx(3.92e6)
    assert test.z0_bar == pytest.approx(1.0)
    assert test.beta == pytest.approx(54, abs=0.5)
    assert test.time_scale == pytest.approx(1.4)
    # Hertz (eq 16) in SI equals the scaled dimensionless force.
    dc, z0 = 154e-6, 140e-6
    t2 = lubjax.RelaxationTest(3.92e6, 2e-3, 100.0, 1e-4, dc, z0)
    f_si = 4 / 3 * 3.92e6 * math.sqrt(2e-3) * (dc - z0) ** 1.5
    assert t2.force_scale * lubjax.hertz_force(t2.z0_bar) == pytest.approx(f_si, rel=1e-12)


@pytest.mark.slow
def test_si_gradient_through_a_relaxation_test_matches_central_differences():
    """The force of a RelaxationTest in newtons, differentiated in SI (E*, η, z0) through the
    scene's scales and relax: central differences of the same runs (rtol 1e-5 on a fixed mesh,
    steps of 1e-4 of each value), within 1e-3 of each derivative."""
    settings = lubjax.Settings(dr=0.05, mesh_growth=1.2, length=50.0, rtol=1e-5,
                               error_estimate=False)

    def force_N(p):
        test = lubjax.RelaxationTest(E_star=p[0], radius=5e-3, viscosity=p[1], speed=1e-5,
                                     indent=1e-4, gap=p[2])
        run = lubjax.relax(test.beta, test.z0_bar, 1.0, settings=settings, mesh=settings.mesh())
        return run.at(0.5)[0] * test.force_scale

    p = np.array([3e6, 100.0, 5e-5])
    grad = np.asarray(jax.grad(force_N)(jnp.asarray(p)))
    for k in range(3):
        h = 1e-4 * p[k]
        e = np.zeros(3)
        e[k] = h
        central = (float(force_N(p + e)) - float(force_N(p - e))) / (2 * h)
        assert grad[k] == pytest.approx(central, rel=1e-3), k


def test_the_scenes_numbers_differentiate_in_si():
    """What each SI scene hands relax (β, z̄0, its drive's numbers, its scales), differentiated
    in the SI inputs: central differences within 1e-6 as elasticities (smooth closed forms;
    β and the scales are power laws in E*, R, η), the same numbers
    as without a derivative (math.sqrt there, jnp.sqrt traced)."""
    scenes = {
        "relaxation": lambda x: lubjax.RelaxationTest(E_star=x[0], radius=x[1], viscosity=x[2],
                                                      speed=1e-5, indent=1e-4, gap=5e-5),
        "creep": lambda x: lubjax.CreepTest(E_star=x[0], radius=x[1], viscosity=x[2],
                                            load=0.1, ramp_time=1.0, gap=5e-5),
        "collision": lambda x: lubjax.Collision(E_star=x[0], radius=x[1], viscosity=x[2],
                                                mass=1e-5, speed=1e-2, gap=1e-5),
    }

    def numbers(scene, x):
        s = scenes[scene](x)
        names = ("beta", "z0_bar", "force_scale", "time_scale", "length_scale")
        values = [getattr(s, n) for n in names if hasattr(s, n)]
        if hasattr(s, "drive"):
            values += jax.tree_util.tree_leaves(s.drive())
        return jnp.stack([jnp.asarray(v, jnp.float64) for v in values])

    x = np.array([3e6, 5e-3, 100.0])
    for scene in scenes:
        J = np.asarray(jax.jacfwd(lambda x, s=scene: numbers(s, x))(jnp.asarray(x)))
        values = np.asarray(numbers(scene, x))
        np.testing.assert_array_equal(values, np.asarray(numbers(scene, jnp.asarray(x))))
        size = np.where(values != 0, np.abs(values), 1.0)
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1e-5 * x[k]
            central = (np.asarray(numbers(scene, x + e)) - np.asarray(numbers(scene, x - e))) / (
                2 * e[k])
            # as elasticities, d ln(number)/d ln(input): every number on one scale
            np.testing.assert_allclose(J[:, k] * x[k] / size, central * x[k] / size, atol=1e-6,
                                       err_msg=f"{scene}, input {k}")


def test_two_spheres_reduce_by_eq_24():
    assert lubjax.reduced_radius(2e-3, 2e-3) == pytest.approx(1e-3)
    assert lubjax.contact_modulus(1e6, 0.5, 1e6, 0.5) == pytest.approx(1e6 / 0.75 / 2)
    assert lubjax.contact_modulus(1e6, 0.5) == pytest.approx(1e6 / 0.75)


@pytest.mark.parametrize(
    "args, match",
    [((0.0, 0.5), "beta"), ((100.0, -1.0), "z0"), ((float("nan"), 0.5), "beta")],
)
def test_relax_rejects_bad_parameters(args, match):
    with pytest.raises(ValueError, match=match):
        lubjax.relax(*args)


def test_relax_rejects_bad_end_time():
    with pytest.raises(ValueError, match="t_end"):
        lubjax.relax(100.0, 0.5, t_end=0.0)


def test_refuses_float32():
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="float64"):
            lubjax.relax(100.0, 0.5, t_end=0.1)
    finally:
        jax.config.update("jax_enable_x64", True)


def test_bad_times_and_settings_are_clear_errors():
    for kwargs, match in [
        (dict(profile_times=[float("nan")]), "profile_times"),
        (dict(profile_times=[[1.0, 2.0]]), "1-D"),
        (dict(profile_times=[7.0]), "profile_times"),
        (dict(t_end=True), "t_end"),
        (dict(t_end=np.array([1.0, 2.0])), "t_end"),
    ]:
        with pytest.raises(ValueError, match=match):
            lubjax.relax(100.0, 0.5, **{"t_end": 5.0, **kwargs})
    assert lubjax.relax(100.0, 0.5, t_end=np.array(0.2)).t[-1] == 0.2
    for kwargs, match in [(dict(rtol=0.0), "rtol"), (dict(rtol=0.5), "rtol"),
                          (dict(order=4), "order"), (dict(max_steps=2.5), "max_steps"),
                          (dict(dr=-1.0), "dr"), (dict(contact_radius=2.0), "contact_radius"),
                          (dict(contact_radius="yes"), "contact_radius")]:
        with pytest.raises(ValueError, match=match):
            lubjax.Settings(**kwargs)
    with pytest.raises(ValueError, match=r"beta must be finite and in \[0.0001, 1e\+09\]"):
        lubjax.relax(1e300, 0.5)


@pytest.mark.slow
def test_sampled_history_matches_ideal_ramp():
    """One code path: a finely sampled ramp-and-hold gives the ideal ramp's force."""
    t = np.linspace(0.0, 3.0, 3001)
    sampled = lubjax.SampledTravel(t, np.clip(t, 0, 1))
    assert sampled.breakpoints == pytest.approx((0.0, 1.0), abs=2e-3)
    a = lubjax.relax(100.0, 1.0, t_end=3.0)
    b = lubjax.relax(100.0, 1.0, t_end=3.0, history=sampled)
    assert np.max(np.abs(a.at(b.t) - b.force)) < 2e-3 * a.force.max()


def test_sampled_history_is_the_monotone_cubic():
    """SampledTravel interpolates like scipy's PchipInterpolator (an independent
    implementation), and holds the end values outside the samples."""
    from scipy.interpolate import PchipInterpolator

    rng = np.random.default_rng(1)
    t = np.sort(rng.uniform(0, 3, 40))
    d = np.cumsum(rng.uniform(-0.1, 1, 40))
    hist = lubjax.SampledTravel(t, d)
    inside = np.linspace(t[0], t[-1], 997)
    np.testing.assert_allclose(hist.travel(inside), PchipInterpolator(t, d)(inside),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(hist.travel([t[0] - 1, t[-1] + 1]), [d[0], d[-1]], atol=0)


def test_sampled_history_takes_traced_samples():
    """A SampledTravel built from traced travel samples has the slopes of the concrete one
    (the monotone cubic's, in jax.numpy: the same to rounding, and no NaN in the derivative
    where a secant is flat); under jit it needs its breakpoints given (they are found from
    the samples' values), and traced sample times are refused with a reason."""
    t = np.linspace(0.0, 2.0, 21)
    shape = np.minimum(t, 1.0)  # flat secants after t = 1: slopes 0 there
    plain = lubjax.SampledTravel(t, shape)
    slopes, dslopes = jax.jvp(lambda s: lubjax.SampledTravel(t, s * shape).slopes, (2.0,),
                              (1.0,))
    np.testing.assert_allclose(slopes, 2.0 * plain.slopes, rtol=1e-14, atol=0)
    np.testing.assert_allclose(dslopes, plain.slopes, rtol=1e-14, atol=0)
    given = jax.jit(lambda s: lubjax.SampledTravel(t, s * shape, breakpoints=(0.0, 1.0)).slopes)
    np.testing.assert_allclose(given(2.0), 2.0 * plain.slopes, rtol=1e-14, atol=0)
    with pytest.raises(ValueError, match="give breakpoints= where the travel samples are traced"):
        jax.jit(lambda s: lubjax.SampledTravel(t, s * shape).slopes)(2.0)
    with pytest.raises(NotImplementedError, match="sample times t cannot be traced"):
        jax.grad(lambda c: lubjax.SampledTravel(c * t, shape).slopes[1])(1.0)


@pytest.mark.slow
def test_relax_differentiates_a_sampled_history_in_its_samples():
    """d F̄/d s of a measured ramp-and-hold scaled by s (a piezo's calibration), by jax.jvp of
    relax itself, against central differences of plain runs (step 10⁻², within 3·10⁻³ of
    their largest; seen 1.1·10⁻⁴), its values the plain run's."""
    t = np.linspace(0.0, 2.0, 401)
    shape = np.minimum(t, 1.0)
    times = jnp.array([0.5, 0.9, 1.5, 2.0])  # not on the breakpoint t̄ = 1
    settings = lubjax.Settings(dr=0.03, error_estimate=False, contact_radius=None)

    def force(s):
        return lubjax.relax(50.0, 0.8, 2.0, history=lubjax.SampledTravel(t, s * shape),
                            settings=settings).at(times)

    values, tangent = jax.jvp(force, (1.0,), (1.0,))
    np.testing.assert_allclose(values, force(1.0), rtol=1e-11, atol=0)
    h = 1e-2
    central = (np.asarray(force(1.0 + h)) - np.asarray(force(1.0 - h))) / (2 * h)
    np.testing.assert_allclose(tangent, central, rtol=0, atol=3e-3 * np.max(np.abs(central)))


@pytest.mark.slow
def test_smoothed_start_eq_23():
    ramp = lubjax.RampHold(t_accel=0.1)
    t = np.array([-0.1, -0.05, 0.0, 0.5, 1.0, 2.0])
    d = np.asarray(ramp.travel(t))
    # z̄ = z̄0 - (t + t²/(2 t1)) for -t1 ≤ t ≤ 0 (eq 23): at rest at t = -t1, unit speed at 0.
    assert d == pytest.approx([-0.05, -0.0375, 0.0, 0.5, 1.0, 1.0], abs=1e-15)
    res = lubjax.relax(100.0, 0.5, t_end=2.0, history=ramp)
    assert res.t[0] == pytest.approx(-0.1) and res.ok


def test_relax_under_jit_and_vmap_is_the_run_alone():
    """relax is a JAX function: under jit, and under jit of vmap, it is the run it makes alone
    on the same mesh (another compiled program: to rounding), and on a CPU a batch maps over
    its members, so each is the jitted run alone to the last bit."""
    settings = lubjax.Settings(dr=0.05, mesh_growth=1.2, length=50.0, rtol=1e-3,
                               error_estimate=False)
    times = [0.5, 1.0]
    betas = (30.0, 300.0)
    # the mesh's arrays first built under jit: the cache must keep them concrete
    lubjax._discretisation._discretise.cache_clear()
    jitted = jax.jit(lambda b: lubjax.relax(b, 0.5, 1.0, settings=settings).at(times))
    single = [np.asarray(jitted(b)) for b in betas]
    alone = [lubjax.relax(b, 0.5, 1.0, settings=settings, mesh=settings.mesh()).at(times)
             for b in betas]
    np.testing.assert_allclose(single, alone, rtol=1e-10)
    batched = jax.jit(jax.vmap(
        lambda b: lubjax.relax(b, 0.5, 1.0, settings=settings).at(times)))(jnp.array(betas))
    if lubjax._sharding.batching_mode() == "map":
        np.testing.assert_array_equal(batched, single)
    else:
        np.testing.assert_allclose(batched, single, rtol=1e-6)


def test_grad_of_relax_under_jit_is_the_plain_grad():
    """``jax.grad`` of a force value of relax read at a scalar time, as outside a
    transformation, under ``jit`` (the traced path, which ``vmap`` takes too): the gradient of
    the run alone on the same mesh, within rounding, and its ``Result.ok`` a traced boolean
    there."""
    settings = lubjax.Settings(dr=0.05, mesh_growth=1.2, length=50.0, rtol=1e-3,
                               error_estimate=False)

    def force_and_ok(z):
        run = lubjax.relax(100.0, z, 0.5, settings=settings, mesh=settings.mesh())
        return run.at(0.5)[0], run.ok

    plain = float(jax.grad(lambda z: force_and_ok(z)[0])(0.5))
    (_, ok), jitted = jax.jit(jax.value_and_grad(force_and_ok, has_aux=True))(0.5)
    assert math.isfinite(plain) and plain != 0.0 and bool(ok)
    np.testing.assert_allclose(float(jitted), plain, rtol=1e-10)


def test_second_derivatives_are_refused_with_a_reason():
    """A derivative of a run's derivative is not implemented (its replay is not differentiated
    again): every way to ask for one says so, with a NotImplementedError that names it."""
    settings = lubjax.Settings(dr=0.05, mesh_growth=1.2, length=50.0, rtol=1e-3,
                               error_estimate=False)

    def force(z):
        return lubjax.relax(100.0, z, 0.5, settings=settings).at(0.5)[0]

    asks = {
        "hessian": lambda: jax.hessian(force)(0.5),
        "jvp of grad": lambda: jax.jvp(jax.grad(force), (0.5,), (1.0,)),
        "grad of jvp": lambda: jax.grad(lambda z: jax.jvp(force, (z,), (1.0,))[1])(0.5),
        "jacfwd of jacfwd": lambda: jax.jacfwd(jax.jacfwd(force))(0.5),
    }
    for ask in asks.values():
        with pytest.raises(NotImplementedError, match="second derivatives of a lubjax run"):
            ask()


@pytest.mark.slow
def test_vmap_and_forward_gradient_in_beta_and_z0():
    """vmap of a jitted force_curve is each run alone (mapped on a CPU), and jax.jacfwd in
    (β, z̄0) agrees with central differences of the adaptive solution: the derivative of the
    discrete solution on its own steps (step sizes are not differentiated). The adaptive force
    is smooth in (β, z̄0) only up to its step choices (jumps of order the local error), so ε is
    sized to that noise, not to eps: ε = 1e-3·|x| at rtol = 1e-9 (truncation ε² ~ 1e-6); what
    the frozen steps leave out is O(rtol^{2/3}) and the first, unchecked step's error."""
    settings = lubjax.Settings(dr=0.05, mesh_growth=1.1, length=50.0, rtol=1e-9,
                               max_steps=100_000, error_estimate=False)
    plan = lubjax.make_plan(1.5, settings=settings, times=np.linspace(0, 1.5, 31))
    f = jax.jit(lambda b, z: lubjax.force_curve(plan, b, z))
    betas = jnp.array([50.0, 200.0])
    batched = jax.vmap(f, in_axes=(0, None))(betas, 0.8)
    for k, b in enumerate(betas):
        if lubjax._sharding.batching_mode() == "map":
            # on a CPU the batch's runs are mapped (lubjax/_rollout.py): each is its run alone
            np.testing.assert_array_equal(batched[k], f(b, 0.8))
        else:
            # batched and single LU solves round differently (condition numbers ~1e7: ~1e-9
            # relative), the error estimates with them, and the step sizes follow: the runs
            # agree far inside their tolerance, not to the last bit
            assert np.allclose(batched[k], f(b, 0.8), rtol=1e-6, atol=1e-14)
    jac = jax.jit(jax.jacfwd(lambda p: f(p[0], p[1])))
    x = jnp.array([100.0, 0.8])
    J = np.asarray(jac(x))
    for k in range(2):
        h = 1e-3 * abs(float(x[k]))
        e = np.zeros(2)
        e[k] = h
        fd = (np.asarray(f(*(x + e))) - np.asarray(f(*(x - e)))) / (2 * h)
        scale = np.max(np.abs(fd))
        assert np.max(np.abs(J[:, k] - fd)) < 1e-4 * scale, k


@pytest.mark.slow
def test_cli_dimensionless_and_si(tmp_path):
    out = tmp_path / "run.json"
    png = tmp_path / "run.png"
    cmd = [sys.executable, "-m", "lubjax", "relax", "--beta", "100", "--z0", "0.5",
           "--t-end", "2", "--out", str(out), "--plot", str(png)]
    subprocess.run(cmd, check=True, capture_output=True)
    data = json.loads(out.read_text())
    for key in ["t", "force", "h_min", "beta", "z0", "run_s", "compile_s"]:
        assert key in data
    assert png.stat().st_size > 10_000
    out2 = tmp_path / "si.json"
    cmd = [sys.executable, "-m", "lubjax", "relax", "--E-star", "3.92e6", "--viscosity", "100",
           "--radius", "2e-3", "--speed", "1e-4", "--indent", "140e-6", "--gap", "140e-6",
           "--t-end", "3", "--out", str(out2)]
    subprocess.run(cmd, check=True, capture_output=True)
    si = json.loads(out2.read_text())
    assert si["beta"] == pytest.approx(53.9, abs=0.1)
    assert si["t_s"][-1] == pytest.approx(3.0)
    force, force_n = np.array(si["force"]), np.array(si["force_N"])
    assert np.allclose(force_n, force * si["scales"]["force_N"], rtol=1e-12, atol=0)
    assert force_n.max() > 0


def test_cli_bad_input_is_a_clear_error():
    cmd = [sys.executable, "-m", "lubjax", "relax", "--E-star", "-1", "--viscosity", "100",
           "--radius", "2e-3", "--speed", "1e-4", "--indent", "140e-6", "--gap", "140e-6"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode != 0
    assert "E_star" in proc.stderr


def test_a_stopped_run_says_so_and_leaves_unreached_profiles_nan():
    # A budget too small for t̄ = 3: the run stops early, its flags and words say so, and a
    # profile time past the stop is NaN, not the initial state the saver started from.
    res = lubjax.relax(100.0, 0.5, 3.0, profile_times=[0.01, 2.5], check="flag",
                       settings=lubjax.Settings(max_steps=250, error_estimate=False))
    assert not res.finished and not res.ok
    assert res.t[-1] < 2.5
    assert np.all(np.isfinite(res.film[0])) and np.all(np.isnan(res.film[1]))
    assert np.all(np.isnan(res.pressure[1])) and np.all(np.isnan(res.displacement[1]))
    assert any("budget" in p for p in res.problems())
    with pytest.raises(lubjax.SolverError, match="stopped at"):
        lubjax.relax(100.0, 0.5, 3.0, settings=lubjax.Settings(max_steps=250,
                                                               error_estimate=False))


def test_the_profile_interpolant_can_dip_below_its_nodes_so_its_film_is_checked():
    # Accepted steps have positive films (the controller rejects any other); the profiles are
    # the step's quadratic interpolant, which through positive films 1, 0.01, 0.02 reaches
    # -0.11 at t = 1.49. That is the film Result.film_positive checks, and problems() words it.
    from lubjax._multistep import dense_output
    dip = dense_output(1.49, (0.0, 1.0, 2.0), (1.0, 0.01, 0.02), 2)
    assert float(dip) == pytest.approx(-0.11, abs=2e-3)
    res = lubjax.relax(100.0, 0.5, 1.0, profile_times=[0.5, 1.0], check="flag")
    assert res.ok and res.film_positive
    film = res.film.copy()
    film[1, 3] = -1e-4
    bad = dataclasses.replace(res, film=film, film_positive=False)
    assert not bad.ok
    assert bad.problems() == [f"the film profile at t̄ = 1 goes negative (h̄ = -0.0001 at "
                              f"r̄ = {res.r[3]:.4g})"]


def test_error_estimate_runs_that_stop_early_say_from_when_their_errors_are_nan(monkeypatch):
    # The coarse runs of the estimate given a budget too small (the main run keeps its own):
    # relax warns, naming the time they stopped, and the errors after it are NaN, not stale.
    import lubjax._solve as solve

    def short_budget(mesh, substrate, indenter, tol, ptimes):
        runs = lubjax._estimate.estimate_runs(mesh, substrate, indenter, tol, ptimes)
        return [(d, dataclasses.replace(t, max_steps=120), p) for d, t, p in runs]

    monkeypatch.setattr(solve, "estimate_runs", short_budget)
    with pytest.warns(RuntimeWarning, match=r"coarse runs stopped at t̄ = ") as caught:
        res = lubjax.relax(100.0, 0.5, 5.0)
    assert res.ok
    t_stop = float(str(caught[0].message).split("t̄ = ")[1].split(" ")[0])
    assert 0 < t_stop < 5.0
    assert np.all(np.isfinite(res.force_error[res.t < t_stop * (1 - 1e-3)]))
    assert np.all(np.isnan(res.force_error[res.t > t_stop * (1 + 1e-3)]))
