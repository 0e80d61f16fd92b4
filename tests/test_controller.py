"""The controller on its own (lubjax/_controller.py): the error norm, acceptance, the PI
factor's limits, breakpoint landing, restarts, collapse, and the status messages."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lubjax
from lubjax import _controller as ctrl
from lubjax._mesh import NEAR_DRY_BETA
from lubjax._stepper import Estimate, Level

TOL = ctrl.Tolerance(rtol=1e-4, atol=1e-9)


def _controller(since_restart=5, error_prev=0.5, last_rejected=False, dt_next=0.1):
    peaks = ctrl.Peaks(jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(0.0))
    return ctrl.ControllerState(jnp.asarray(dt_next), jnp.asarray(error_prev),
                                jnp.asarray(last_rejected), jnp.asarray(since_restart), peaks)


def _adapt(error, valid=True, controller=None, t=1.0, dt=0.1, lands=False, t_end=10.0,
           first_step=1e-7):
    controller = _controller() if controller is None else controller
    return ctrl.decide(jnp.asarray(error), jnp.asarray(valid), controller, 2, jnp.asarray(t),
                       jnp.asarray(t + dt), jnp.asarray(lands), t_end,
                       jnp.asarray(ctrl.RUNNING), first_step)


def test_accepts_within_tolerance_and_rejects_beyond_it():
    assert bool(_adapt(0.99).accept) and not bool(_adapt(1.01).accept)
    d = _adapt(1.01)
    assert bool(d.rejected.last_rejected) and float(d.rejected.dt_next) < 0.1
    # the PI memory and the segment count do not move on a rejection
    assert float(d.rejected.error_prev) == 0.5 and int(d.rejected.since_restart) == 5


def test_rejects_what_is_not_admissible_whatever_its_error():
    d = _adapt(1e-6, valid=False)
    assert not bool(d.accept)
    assert float(d.rejected.dt_next) == pytest.approx(0.1 * ctrl.INVALID_SHRINK)
    d = _adapt(float("nan"))
    assert not bool(d.accept)


@pytest.mark.parametrize("error", [1e-12, 1e-6, 1e-2, 0.5, 1.0])
def test_grows_no_faster_than_its_limit(error):
    assert float(_adapt(error).accepted.dt_next) <= 0.1 * ctrl.MAX_GROWTH * (1 + 1e-15)
    # straight after a rejection: no growth at all
    after = _adapt(error, controller=_controller(last_rejected=True))
    assert float(after.accepted.dt_next) <= 0.1 * (1 + 1e-15)


def test_shrinks_a_rejected_step_within_its_limits():
    for error in (1.5, 10.0, 1e6):
        factor = float(_adapt(error).rejected.dt_next) / 0.1
        assert ctrl.MIN_SHRINK - 1e-15 <= factor <= ctrl.SAFETY + 1e-15


def test_a_segments_first_step_has_no_estimate():
    d = _adapt(50.0, controller=_controller(since_restart=0))
    assert bool(d.accept)
    assert float(d.accepted.dt_next) == pytest.approx(0.1 * ctrl.MAX_GROWTH)


def test_lands_on_breakpoints_exactly_and_restarts_there():
    breakpoints = jnp.asarray([0.5, 2.0])
    t_new, lands = ctrl.propose_end(jnp.asarray(0.3), jnp.asarray(1.0), breakpoints, 10.0)
    assert float(t_new) == 0.5 and bool(lands)
    t_new, lands = ctrl.propose_end(jnp.asarray(0.3), jnp.asarray(0.1), breakpoints, 10.0)
    assert float(t_new) == pytest.approx(0.4) and not bool(lands)
    t_new, lands = ctrl.propose_end(jnp.asarray(2.5), jnp.asarray(100.0), breakpoints, 10.0)
    assert float(t_new) == 10.0 and bool(lands)  # t_end is landed on too
    d = _adapt(0.5, lands=True)
    assert float(d.accepted.dt_next) == 1e-7 and int(d.accepted.since_restart) == 0
    assert int(d.status_accepted) == ctrl.RUNNING
    d = _adapt(0.5, t=9.9, dt=0.1, lands=True)
    assert int(d.status_accepted) == ctrl.DONE


def test_reports_collapse():
    d = _adapt(5.0, dt=1e-20, t=1.0)
    assert not bool(d.accept) and int(d.status_rejected) == ctrl.STEP_TOO_SMALL
    assert int(_adapt(5.0).status_rejected) == ctrl.RUNNING


def test_stop_reasons_name_the_cause():
    assert ctrl.stop_reason(ctrl.DONE, 100) == ""
    assert "collapsed" in ctrl.stop_reason(ctrl.STEP_TOO_SMALL, 100)
    assert "max_steps = 123" in ctrl.stop_reason(ctrl.BUDGET_SPENT, 123)
    with pytest.raises(ValueError):  # a finished run is never left "running"
        ctrl.stop_reason(ctrl.RUNNING, 123)


def test_relax_reports_the_controllers_reason():
    res = lubjax.relax(100.0, 0.5, 5.0, settings=lubjax.Settings(
        max_steps=30, error_estimate=False, dr=0.1, length=50.0, mesh_growth=1.2,
        contact_radius=None), check="flag")
    assert not res.finished
    assert res.stop_reason == ctrl.stop_reason(ctrl.BUDGET_SPENT, 30)
    assert any(res.stop_reason in p for p in res.problems())


@pytest.mark.parametrize("since, max_order, expected", [
    (0, 2, 1), (1, 2, 1), (2, 2, 2), (3, 2, 2), (2, 3, 2), (3, 3, 3), (5, 1, 1),
])
def test_chooses_the_order_of_the_segment(since, max_order, expected):
    peaks = ctrl.Peaks(jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(0.0))
    order = ctrl.choose_order(_controller(since_restart=since), jnp.asarray(0.5), peaks,
                              max_order)
    assert int(order) == expected


def test_a_decayed_tail_steps_by_backward_euler():
    peaks = ctrl.Peaks(jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(0.0))
    tail = jnp.asarray(ctrl.BACKWARD_EULER_FORCE / 2)
    assert int(ctrl.choose_order(_controller(), tail, peaks, 3)) == 1
    # a force still emerging from zero (never above the threshold) keeps BDF2
    young = ctrl.Peaks(jnp.asarray(ctrl.BACKWARD_EULER_FORCE / 4), *peaks[1:])
    assert int(ctrl.choose_order(_controller(), tail, young, 2)) == 2


class _Drive:
    prescribes_gap, prescribes_force, inertia, force_nonnegative = True, False, False, True


def _level(force, film=1.0, gap=0.5, velocity=0.0):
    n = 4
    return Level(dt=jnp.asarray(0.1), pressure=jnp.ones(n), elastic_load=jnp.ones(n),
                 memory=jnp.zeros((0, n)), film=jnp.full(n, film), gap=jnp.asarray(gap),
                 gap_step=jnp.asarray(0.0), velocity=jnp.asarray(velocity),
                 force=jnp.asarray(force))


def _ratio(force_error, force, peak, drive=_Drive, gap_error=0.0, gap=0.5, excursion=0.0):
    est = Estimate(film=jnp.zeros(4), force=jnp.asarray(force_error),
                   gap=jnp.asarray(gap_error), velocity=jnp.asarray(0.0))
    peaks = ctrl.Peaks(jnp.asarray(peak), jnp.asarray(0.0), jnp.asarray(excursion))
    level, previous = _level(force, gap=gap), _level(force)
    film = jnp.maximum(jnp.abs(level.film), jnp.abs(previous.film))  # the relative control
    return float(ctrl.error_ratio(est, level, previous, peaks, TOL, drive, jnp.asarray(0.5),
                                  film))


def test_error_norm_holds_the_force_relative_to_itself():
    assert _ratio(0.5e-4, 1.0, 1.0) == pytest.approx(0.5, rel=1e-6)


def test_error_norm_tightens_in_a_decayed_tail():
    """Two decades below the peak the relative tolerance is rtol/(1 + 3·2)."""
    at_peak = _ratio(1e-6, 1e-2, 1e-2)
    in_tail = _ratio(1e-6, 1e-2, 1.0)
    # (to the force's absolute floor FORCE_ATOL, 1e-6 of these scales)
    assert in_tail == pytest.approx(at_peak * (1 + ctrl.TAIL_TIGHTENING * 2), rel=1e-4)


def test_error_norm_ignores_a_prescribed_force_and_floors_a_tiny_one():
    class Load(_Drive):
        prescribes_force = True

    assert _ratio(1.0, 1.0, 1.0, drive=Load()) == 0.0
    # far below force_floor × peak the floor sets the scale, not the force itself
    floor = TOL.force_floor * 1.0
    assert _ratio(1e-20, 1e-15, 1.0) < _ratio(1e-20, 1e-15, 1e-15)
    assert _ratio(TOL.rtol * floor, 1e-15, 1.0) < 1.0


def test_error_norm_holds_a_free_gap_relative_to_its_excursion():
    class Free(_Drive):
        prescribes_gap = False

    # excursion so far 0.1: the gap's error is held to rtol × 0.1 (+ atol)
    r = _ratio(0.0, 1.0, 1.0, drive=Free(), gap_error=0.5e-5, gap=0.45, excursion=0.1)
    assert r == pytest.approx(0.5e-5 / (TOL.atol + TOL.rtol * 0.1), rel=1e-9)
    # a prescribed gap is not the solver's error
    assert _ratio(0.0, 1.0, 1.0, gap_error=1.0) == 0.0


def test_admissible_refuses_a_negative_film_and_force():
    peaks = ctrl.Peaks(jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(0.0))
    assert bool(ctrl.admissible(_level(0.5), peaks, _Drive()))
    assert not bool(ctrl.admissible(_level(0.5, film=-1e-9), peaks, _Drive()))
    assert not bool(ctrl.admissible(_level(-1e-3), peaks, _Drive()))
    nan_pressure = _level(0.5)._replace(pressure=jnp.full(4, jnp.nan))
    assert not bool(ctrl.admissible(nan_pressure, peaks, _Drive()))
    # a negative force is physics where the drive can pull (no monotone approach)
    class Pull(_Drive):
        force_nonnegative = False

    assert bool(ctrl.admissible(_level(-1e-3), peaks, Pull()))


# ------------------------------------------------------------------ the film's error by the force


def test_force_film_error_is_the_relative_one_without_a_contact():
    """No indentation (z̄0 > 1 never touches): the force's scale is zero and the run is the
    relative control's, bit for bit."""
    runs = [lubjax.relax(100.0, 2.0, 3.0, settings=lubjax.Settings(
        error_estimate=False, film_error=mode)) for mode in ("relative", "force")]
    assert runs[0].accepted == runs[1].accepted
    np.testing.assert_array_equal(runs[0].force, runs[1].force)


def test_force_film_scale_is_two_thirds_of_the_indentation_where_that_is_larger():
    """Inside an indentation δ_c = 0.3 a film thinner than 2δ_c/3 = 0.2 is held to 0.2 (the
    force's tolerance), a thicker one to itself; not indenting, every node to itself."""
    film = jnp.asarray([1e-4, 0.1, 0.5])
    previous = _level(1.0, film=0.0)._replace(film=jnp.asarray([2e-4, 0.1, 0.4]))
    level = previous._replace(film=film, gap=jnp.asarray(-0.3))
    np.testing.assert_allclose(np.asarray(ctrl.film_scale(level, previous, "force", 1.0)),
                               [0.2, 0.2, 0.5])
    np.testing.assert_allclose(np.asarray(ctrl.film_scale(level, previous, "relative", 1e9)),
                               [2e-4, 0.1, 0.5])
    free = level._replace(gap=jnp.asarray(0.1))
    np.testing.assert_allclose(np.asarray(ctrl.film_scale(free, previous, "force", 1.0)),
                               [2e-4, 0.1, 0.5])


def test_the_film_cap_bounds_the_force_norm_and_a_derivative_lowers_it():
    """Under the force norm a thin film is held to at most cap × rtol of itself: with the
    default cap (FILM_CAP = 10³) a film of 2e-4 in an indentation of 0.3 is held to 0.2, with
    TANGENT_FILM_CAP (100) to 0.02. Tolerance.for_tangents (a differentiated run's) lowers the
    cap to that and keeps a lower one."""
    film = jnp.asarray([1e-4, 0.1, 0.5])
    previous = _level(1.0, film=0.0)._replace(film=jnp.asarray([2e-4, 0.1, 0.4]))
    level = previous._replace(film=film, gap=jnp.asarray(-0.3))
    derived = TOL.for_tangents()
    assert TOL.film_cap == ctrl.FILM_CAP and float(derived.film_cap) == ctrl.TANGENT_FILM_CAP
    assert float(ctrl.Tolerance(film_cap=10.0).for_tangents().film_cap) == 10.0
    np.testing.assert_allclose(
        np.asarray(ctrl.film_scale(level, previous, "force", 1e9, derived.film_cap)),
        [0.02, 0.2, 0.5])


def test_a_film_falling_faster_than_bdf_stays_positive_makes_the_step_backward_euler():
    """BDF2's history term (1 + ω)h̄ⁿ - ω²/(1 + ω) h̄ⁿ⁻¹ is not positive where h̄ⁿ⁻¹ ≥
    (1 + 1/ω)² h̄ⁿ: a fourfold fall at equal steps, ninefold at a step half as long; BDF3's
    alike from its own weights. Such a step is backward Euler (as a fresh segment's are); a
    slower fall keeps its order."""
    from types import SimpleNamespace

    def history(now, previous, older=None, dt_prev=1e-3):
        older = previous if older is None else older
        return SimpleNamespace(dt=jnp.full(3, dt_prev),
                               film=jnp.asarray([[0.5, now], [0.5, previous], [0.5, older]]))

    def collapses(hist, dt, order=2, max_order=2):
        return bool(ctrl.film_collapses(hist, dt, order, max_order))

    assert collapses(history(1.0e-4, 4.01e-4), 1e-3)
    assert not collapses(history(1.0e-4, 3.99e-4), 1e-3)
    assert not collapses(history(1.0e-4, 8.99e-4), 0.5e-3)
    assert collapses(history(1.0e-4, 9.01e-4), 0.5e-3)
    assert not collapses(history(1.0e-4, 9.01e-4), 0.5e-3, order=1)
    # BDF3 at equal steps: -(a₁h̄ⁿ + a₂h̄ⁿ⁻¹ + a₃h̄ⁿ⁻²)/a₀ = (18h̄ⁿ - 9h̄ⁿ⁻¹ + 2h̄ⁿ⁻²)/11, positive
    # for any geometric fall (18 - 9q + 2q² > 0), not after a zigzag
    assert collapses(history(1.0e-4, 4.0e-4, 2.0e-4), 1e-3, order=3, max_order=3)
    assert not collapses(history(1.0e-4, 4.01e-4, 16.1e-4), 1e-3, order=3, max_order=3)
    assert collapses(history(1.0e-4, 4.01e-4, 16.1e-4), 1e-3, order=2, max_order=3)
    young = ctrl.Peaks(jnp.asarray(1.0), jnp.asarray(0.0), jnp.asarray(0.0))
    fast, slow = history(1.0e-4, 5e-4), history(1.0e-4, 2e-4)
    for max_order in (2, 3):
        assert int(ctrl.choose_order(_controller(), jnp.asarray(0.5), young, max_order, fast,
                                     jnp.asarray(1e-3))) == 1
        assert int(ctrl.choose_order(_controller(), jnp.asarray(0.5), young, max_order, slow,
                                     jnp.asarray(1e-3))) == max_order


def test_auto_film_scale_is_the_force_one_from_near_dry_beta_on():
    """"auto": the relative scale just below β = NEAR_DRY_BETA, the force's from it on, also
    for a traced β (a sweep over β mixes the two)."""
    film = jnp.asarray([1e-4, 0.1, 0.5])
    previous = _level(1.0, film=0.0)._replace(film=jnp.asarray([2e-4, 0.1, 0.4]))
    level = previous._replace(film=film, gap=jnp.asarray(-0.3))
    below = np.nextafter(NEAR_DRY_BETA, 0.0)
    scales = jax.vmap(lambda b: ctrl.film_scale(level, previous, "auto", b))(
        jnp.asarray([below, NEAR_DRY_BETA]))
    np.testing.assert_array_equal(np.asarray(scales[0]),
                                  np.asarray(ctrl.film_scale(level, previous, "relative", 1.0)))
    np.testing.assert_array_equal(np.asarray(scales[1]),
                                  np.asarray(ctrl.film_scale(level, previous, "force", 1.0)))


def test_auto_film_error_runs_are_the_relative_ones_below_near_dry_beta_and_force_above():
    """Whole runs that indent (z̄0 = 0.5, coarse): "auto" is "relative" bit for bit at
    β = 10⁴ and "force" bit for bit at β = 10⁶ (and there takes fewer steps than "relative")."""
    def run(beta, mode):
        return lubjax.relax(beta, 0.5, 1.2, settings=lubjax.Settings(
            rtol=1e-3, error_estimate=False, film_error=mode))

    for beta, same in ((1e4, "relative"), (1e6, "force")):
        auto, twin = run(beta, "auto"), run(beta, same)
        assert auto.accepted == twin.accepted
        np.testing.assert_array_equal(auto.force, twin.force)
    assert run(1e6, "auto").accepted < run(1e6, "relative").accepted


@pytest.mark.slow
def test_force_film_error_keeps_the_force_of_a_near_dry_contact_in_fewer_steps():
    """β = 10⁶, z̄0 = 0.5 (a stiff contact): against a run converged in time on the same mesh
    (rtol 1e-6; the norm changes only the time error), the force of the force-measured film is
    as accurate as the relative control's (both within 5 rtol of the peak and 1 % pointwise
    where F̄ > 1e-3 of it), in fewer steps."""
    times = np.linspace(0.05, 1.2, 120)
    kw = dict(error_estimate=False, max_steps=100_000, dr=0.02, mesh_growth=1.15, length=100.0)
    ref = lubjax.relax(1e6, 0.5, 1.2, settings=lubjax.Settings(
        rtol=1e-6, film_error="relative", **kw)).at(times)
    peak = np.max(ref)
    runs = {mode: lubjax.relax(1e6, 0.5, 1.2, settings=lubjax.Settings(film_error=mode, **kw))
            for mode in ("relative", "force")}
    big = ref > 1e-3 * peak
    for run in runs.values():
        f = run.at(times)
        assert np.max(np.abs(f - ref)) < 5e-4 * peak
        assert np.max(np.abs(f[big] / ref[big] - 1)) < 1e-2
    assert runs["force"].accepted < 0.5 * runs["relative"].accepted
