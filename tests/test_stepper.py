"""The error-controlled stepper: reverse-mode gradients, outputs at any time, budgets, corners."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lubjax

from helpers import ACCURACY_T_OUT, COARSE, SCENES, accuracy_reference


@pytest.mark.slow
def test_grad_agrees_with_jacfwd_under_bdf3():
    """jax.grad (the checkpointed adjoint) of a scalar loss of the force curve equals forward
    mode (the forward replay) with BDF3's formulas: two implementations of one derivative
    (BDF2's, the default: test_adjoint_at_block_ends_past_the_run_and_batched)."""
    plan = lubjax.make_plan(2.0, settings=lubjax.Settings(**COARSE, max_steps=2000, order=3),
                            times=np.linspace(0.1, 2.0, 40))
    target = jnp.linspace(0.5, 0.1, 40)

    def loss(p):
        return jnp.sum((lubjax.force_curve(plan, p[0], p[1]) - target) ** 2)

    x = jnp.array([80.0, 0.7])
    assert np.isfinite(float(loss(x)))  # the run finished inside its budget
    g_rev = np.asarray(jax.jit(jax.grad(loss))(x))
    g_fwd = np.asarray(jax.jit(jax.jacfwd(loss))(x))
    assert np.all(np.isfinite(g_rev))
    np.testing.assert_allclose(g_rev, g_fwd, rtol=1e-6)


@pytest.mark.slow
def test_adjoint_at_block_ends_past_the_run_and_batched():
    """The adjoint runs each checkpointed block in sub-blocks and masks the steps past the
    block's or the run's end (lubjax/_adjoint.py): grad in (β, z̄0) equals the forward replay's
    to 1e-9 for runs that stop inside a sub-block, on a block's last step and with the budget
    spent, alone and under vmap (where every sub-block runs, masked)."""
    from lubjax import _sharding
    from lubjax._adjoint import sub_blocks
    from lubjax._loop import block_size

    max_steps = 300
    block = block_size(max_steps)
    count, size = sub_blocks(block)
    assert count * size > block  # so some steps of every block are masked
    settings = lubjax.Settings(**COARSE, max_steps=max_steps)
    disc, tol = lubjax.stepper.discretise(settings.mesh()), settings.tolerance()
    times = jnp.linspace(0.05, 1.0, 12)

    def run(p, t_end):
        return lubjax.stepper.rollout(disc, p[0], p[1], lubjax.Travel(), t_end, tol)

    def loss(p, t_end):
        force = lubjax.stepper.evaluate(run(p, t_end).steps, times, "force")
        return jnp.sum(jnp.where(jnp.isfinite(force), force, 0.0) * jnp.arange(1.0, 13.0))

    x = jnp.array([80.0, 0.7])
    # Runs ending mid-sub-block and on a block's last step (t_end on an accepted time of a
    # longer run: the same steps up to there), and one whose budget runs out.
    full = jax.jit(run)(x, 1.0)
    t, accepted = np.asarray(full.steps.t), np.asarray(full.steps.accepted)
    levels = t[accepted & np.isfinite(t)]  # levels[k]: the time after k accepted steps
    k_block = (int(full.accepted) // block) * block
    k_sub = next(k for k in range(k_block - 1, 0, -1) if (k % block) % size)
    ends = {"block": levels[k_block], "sub-block": levels[k_sub], "budget": 3.0}
    for case, k in (("block", k_block), ("sub-block", k_sub)):
        assert int(jax.jit(run)(x, ends[case]).accepted) == k, case
    assert int(jax.jit(run)(x, 3.0).status) == lubjax.stepper.Status.BUDGET_SPENT
    grad = jax.jit(jax.grad(loss))
    forward = jax.jit(jax.jacfwd(loss))
    for case, t_end in ends.items():
        g, f = np.asarray(grad(x, t_end)), np.asarray(forward(x, t_end))
        assert np.all(np.isfinite(g)) and np.all(g != 0.0), case
        np.testing.assert_allclose(g, f, rtol=1e-9, err_msg=case)
    # Batched as an accelerator batches (a CPU maps a batch, each member alone): one vmapped
    # loop, in which the members' runs end at different steps and every sub-block runs.
    batch = jnp.array([ends["sub-block"], ends["block"], ends["budget"]])
    vmapped = _sharding.batch(jax.grad(loss), (False, True), "vmap")
    g_batch = np.asarray(jax.jit(vmapped)(x, batch))
    np.testing.assert_allclose(g_batch, [np.asarray(forward(x, t)) for t in batch], rtol=1e-9)


def test_a_differentiated_run_has_the_values_of_the_plain_run():
    """Under jvp and vjp the loop also records the steps the derivatives replay: the values it
    returns are the plain run's."""
    plan = lubjax.make_plan(1.5, settings=lubjax.Settings(**COARSE, max_steps=2000))
    plain = lubjax.force_curve(plan, 50.0, 0.8)
    forward, _ = jax.jvp(lambda b: lubjax.force_curve(plan, b, 0.8), (50.0,), (1.0,))
    reverse, _ = jax.vjp(lambda b: lubjax.force_curve(plan, b, 0.8), 50.0)
    np.testing.assert_allclose(forward, plain, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(reverse, plain, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("order", [2, pytest.param(3, marks=pytest.mark.slow)])
def test_results_do_not_depend_on_requested_times(order):
    s = lubjax.Settings(**COARSE, order=order)
    a = lubjax.relax(100.0, 0.7, 3.0, settings=s)
    b = lubjax.relax(100.0, 0.7, 3.0, settings=s, profile_times=[0.123, 1.0, 2.71])
    np.testing.assert_array_equal(a.t, b.t)
    np.testing.assert_array_equal(a.force, b.force)
    # Profiles are the stepper's interpolant, consistent with the force read at those times.
    weights = np.asarray(lubjax.stepper.force_weights(lubjax.Mesh(tuple(b.r))))
    np.testing.assert_allclose(b.pressure @ weights, b.at([0.123, 1.0, 2.71]), rtol=1e-12)
    # Thousands of output times cost no steps.
    plan = lubjax.make_plan(3.0, settings=s, times=np.linspace(0, 3, 5000))
    f = np.asarray(lubjax.force_curve(plan, 100.0, 0.7))
    np.testing.assert_allclose(f[np.searchsorted(plan.t, a.t[-1])], a.force[-1], rtol=1e-12)


def test_velocity_jumps_are_step_boundaries():
    res = lubjax.relax(100.0, 0.5, 2.0, history=lubjax.RampHold(t_accel=0.2))
    assert np.any(res.t == 0.0) and np.any(res.t == 1.0) and res.t[0] == -0.2


def test_short_run_has_loading_accuracy():
    """Issue: relax(100, 0.5, t_end=1) used to grow its steps to 0.08 (F̄(1) off by 4.8e-3)."""
    short = lubjax.relax(100.0, 0.5, 1.0)
    long = lubjax.relax(100.0, 0.5, 5.0)
    assert short.force[-1] == pytest.approx(long.at([1.0])[0], rel=1e-3)


@functools.cache
def _coarse_run(rtol, order):
    """relax(30, 0.8, 3) on the coarse mesh: the time-error tests share these runs (the BDF3
    reference at rtol 1e-10 and the run at 1e-6 serve both of them)."""
    s = lubjax.Settings(rtol=rtol, order=order, **COARSE, max_steps=200_000)
    return lubjax.relax(30.0, 0.8, 3.0, settings=s)


@pytest.mark.slow
def test_time_error_converges_at_the_observed_order_in_rtol():
    """Local error control of a method of order p: global error ∝ rtol^{p/(p+1)} (fitted
    slope): BDF2 2/3, backward Euler throughout 1/2, BDF3 3/4. The BDF3 reference is checked
    against the BDF2 one, a different method."""
    times = np.linspace(0.1, 3.0, 60)

    def force(rtol, order):
        return _coarse_run(rtol, order).at(times)

    refs = {2: force(1e-9, 2), 1: force(1e-8, 1), 3: force(1e-10, 3)}
    assert np.max(np.abs(refs[3] - refs[2])) < 1e-6 * np.max(refs[2])
    sweeps = {2: [1e-3, 1e-4, 1e-5], 1: [1e-2, 1e-3, 1e-4], 3: [1e-4, 1e-5, 1e-6]}
    for order, expected in [(2, 2 / 3), (1, 1 / 2), (3, 3 / 4)]:
        rtols = np.array(sweeps[order])
        errs = [np.max(np.abs(force(r, order) - refs[order])) for r in rtols]
        slope = np.polyfit(np.log(rtols), np.log(errs), 1)[0]
        assert abs(slope - expected) < 0.15, (order, slope, errs)


@pytest.mark.slow
def test_bdf3_output_between_steps_is_as_accurate_as_at_them():
    """BDF3 steps are read by a cubic through four levels (its own dense output): between the
    steps the force is as accurate as at them. Measured, rtol 1e-6: midpoints 1.005× the error
    at the levels; BDF2's quadratic read of the same steps gave 1.46×."""
    ref, run = _coarse_run(1e-10, 3), _coarse_run(1e-6, 3)
    levels = run.t[run.t > 0.05]
    mid = 0.5 * (levels[1:] + levels[:-1])
    at_levels, between = (np.max(np.abs(run.at(t) - ref.at(t))) for t in (levels, mid))
    assert between < 1.1 * at_levels, (between, at_levels)


@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.slow
def test_bdf3_takes_every_drive_and_substrate(scene):
    """Settings(order=3) through the one code path: against a converged BDF2 run (rtol 1e-9),
    within 3 rtol of the quantity's range at rtol 1e-5, in fewer steps than BDF2 at that rtol
    (measured: errors 0.3-1.7 rtol and 55-70 % of BDF2's steps, where BDF2 is 2.4-7.7 rtol off)."""
    kwargs, beta, z0, field = SCENES[scene]
    settings = dict(COARSE, max_steps=200_000)
    t = np.linspace(0.05, 3.0, 100)
    ref = lubjax.relax(beta, z0, 3.0, settings=lubjax.Settings(rtol=1e-9, **settings), **kwargs)
    expected = ref.at(t, field)
    scale = np.max(np.abs(expected - (expected[0] if field == "gap" else 0.0)))
    runs = {
        order: lubjax.relax(
            beta, z0, 3.0, settings=lubjax.Settings(rtol=1e-5, order=order, **settings), **kwargs
        )
        for order in (2, 3)
    }
    error = np.max(np.abs(runs[3].at(t, field) - expected)) / scale
    assert error < 3e-5, error
    assert runs[3].accepted < 0.8 * runs[2].accepted, (runs[3].accepted, runs[2].accepted)


def test_step_budget_exhaustion_is_never_silent():
    s = lubjax.Settings(**COARSE, max_steps=20)
    with pytest.raises(lubjax.SolverError, match="max_steps"):
        lubjax.relax(100.0, 0.5, 5.0, settings=s)
    res = lubjax.relax(100.0, 0.5, 5.0, settings=s, check="flag")
    assert not res.finished and not res.ok and res.t[-1] < 5.0
    # The differentiable path: times the run did not reach are NaN, not stale values.
    reached = res.t[-1]
    plan = lubjax.make_plan(5.0, settings=s, times=[0.5 * reached, 2 * reached, 4.0])
    f = np.asarray(lubjax.force_curve(plan, 100.0, 0.5))
    assert f[0] == pytest.approx(res.at([0.5 * reached])[0], rel=1e-12)
    assert np.all(np.isnan(f[1:]))


def test_nan_parameters_stop_the_run_with_a_status():
    disc = lubjax.stepper.discretise(lubjax.Settings(**COARSE).mesh())
    traj = lubjax.stepper.rollout(disc, jnp.nan, 0.5, lubjax.RampHold(), 1.0)
    assert not bool(traj.finished)
    with pytest.raises(ValueError, match="beta"):
        lubjax.relax(float("nan"), 0.5)


@pytest.mark.slow
@pytest.mark.parametrize("order", [2, 3])
@pytest.mark.parametrize("beta, z0", [(0.1, 0.05), (0.1, 5.0), (1e6, 0.05), (1e6, 5.0)])
def test_corners_of_the_parameter_box_to_a_million(beta, z0, order):
    """β ∈ [10⁻¹, 10⁶] × z̄0 ∈ [0.05, 5] held to t̄ = 10⁶: finite, positive film, non-negative
    force, and the right end state (Hertz for z̄0 < 1, no force for z̄0 > 1); BDF2 and BDF3."""
    # Default tolerance (at rtol = 1e-3 the coarser mesh's neck at β = 10⁶, z̄0 = 0.05 keeps
    # failing positivity and the run needs > 20000 attempts: known weakness, see README).
    settings = lubjax.Settings(error_estimate=False, order=order)
    res = lubjax.relax(beta, z0, 1e6, settings=settings)
    assert res.ok and res.accepted < 5000
    peak = res.force.max()
    assert res.force.min() >= 0.0
    assert np.all(res.film_min > 0)
    if z0 < 1:
        assert res.force[-1] == pytest.approx(lubjax.hertz_force(z0), rel=2e-3)
    else:
        assert res.force[-1] < 1e-9 * peak


@pytest.mark.slow
def test_error_estimate_bounds_the_error():
    """Result.force_error of a default run (ramp, hold to t̄ = 10³) against the accuracy table's
    converged reference (benchmarks/accuracy.py: rtol 1e-7, dr = 0.005, growth 1.05 to L̄ = 2000,
    itself checked against a coarser far field and a coarser fine zone; cached in
    benchmarks/out/cache, recomputed in minutes if missing), for β, z̄0 = (10, 0.9), (100, 1),
    (1000, 1.11), (10, 2) (an open film, where a smaller safety factor failed): it bounds the
    error pointwise at >= 95 % of the output times where the error
    is above 1e-6 of the peak, and it is not an empty bound: its maximum is at most 20x the
    largest error in every case and at most 10x in the median case. (Per case 20x, not 10x:
    the error itself can be small by accident. At (1000, 1.11) the same code gave a max error of
    6e-6 in one session's environment (905 steps) and 3.3e-6 in another's (898 steps: the step
    sequences differ by rounding), while the estimate stayed 3.3-3.7e-5: est/err 5.6 and 11.3.)"""
    ratios = []
    for beta, z0 in [(10.0, 0.9), (100.0, 1.0), (1000.0, 1.11), (10.0, 2.0)]:
        ref = accuracy_reference(beta, z0)["force"]
        res = lubjax.relax(beta, z0, ACCURACY_T_OUT[-1])
        # The table's own measure: the estimate read at the output times by linear interpolation
        # of its step values, against the true error where that is above 1e-6 of the peak.
        true = np.abs(res.at(ACCURACY_T_OUT) - ref)
        est = np.interp(ACCURACY_T_OUT, res.t, res.force_error)
        significant = true > 1e-6 * np.max(ref)
        ratio = np.max(est) / max(np.max(true), 1e-300)
        bounded = (float(np.mean(est[significant] >= true[significant])) if significant.any()
                   else 1.0)
        assert bounded >= 0.95, (beta, z0, bounded)
        assert 1.0 <= ratio <= 20.0, (beta, z0, ratio)
        ratios.append(ratio)
    assert np.median(ratios) <= 10.0, ratios


def test_a_decaying_tail_never_changes_sign():
    """An open film's hold (z̄0 > 1): F̄ decays to zero and never below it, at the steps and
    between them. BDF2 let the tail, once below the force's absolute tolerance, oscillate through
    zero (-3e-14 at every rtol); the stepper takes backward-Euler steps there."""
    s = lubjax.Settings(**COARSE)
    res = lubjax.relax(10.0, 2.0, 20.0, settings=s)
    assert res.force[-1] < 1e-20 * res.force.max()  # the tail was reached
    assert res.force.min() >= 0.0
    dense = res.at(np.linspace(0.0, 20.0, 20_001))
    assert dense.min() >= 0.0
